"""Layer stacks (SPEC §12): `stack_reflectance` / `stack_transmittance` against `tmm`'s
`coh_tmm` (Byrnes), energy conservation, the bulk-metal limit of a thick metal layer, the
one-film Airy formula, finite differences, float32, and the boundary checks.

Compile count kept small: every random stack is one row of a batch with the same shapes
(12 stacks × 8 layers, zero-thickness layers padding the shorter ones), so each
(polarisation, quantity, dtype) compiles once.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

from thinfilm_jax import Film, airy_reflectance
from thinfilm_jax.core.stack import Stack
from thinfilm_jax.optics.stack import stack_reflectance, stack_transmittance

THETA = np.radians([0.0, 20.0, 45.0, 60.0, 75.0, 85.0, 89.9])
COS = np.cos(THETA)[:, None]  # (7, 1)
LAM = np.array([380.0, 450.0, 600.0, 800.0])  # (4,)
N_LAYERS = 8
N_STACKS = 12
METALS = (0.05 + 3.4j, 1.0 + 6.7j)  # Ag-like, Al-like


def random_stacks(seed, lossless=False):
    """(d (S,1,1,8), per-layer index arrays (S,1,1), base (S,1,1), active layer counts):
    1–8 active layers mixing dielectrics (n ∈ [1.2, 2.6]) and metals (complex n), the rest
    of the 8 zero-thickness pads (which change nothing: the recursion's identity)."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(0.0, 400.0, (N_STACKS, N_LAYERS))
    n = rng.uniform(1.2, 2.6, (N_STACKS, N_LAYERS)) + 0j
    if not lossless:
        metal = rng.random((N_STACKS, N_LAYERS)) < 0.35
        n[metal] = (rng.uniform(0.05, 3.0, metal.sum()) + 1j * rng.uniform(0.5, 7.0, metal.sum()))
        d[metal] = rng.uniform(0.0, 60.0, metal.sum())
    active = rng.integers(1, N_LAYERS + 1, N_STACKS)
    for s, a in enumerate(active):
        d[s, a:] = 0.0
    d[0, 0] = 0.0  # a zero-thickness layer inside the active part
    base = rng.uniform(1.0, 4.0, N_STACKS) + 0j
    if not lossless:
        base[::2] += 1j * rng.uniform(0.1, 4.0, N_STACKS // 2)
    return d, n, base, active


def as_stack(d, n, base):
    return Stack(d[:, None, None, :], tuple(n[:, i, None, None] for i in range(N_LAYERS)),
                 base[:, None, None])


def tmm_grid(pol, d, n, base, active):
    """R, T (S, 7, 4) from `tmm.coh_tmm` with only the active layers."""
    out = np.zeros((2, N_STACKS, len(THETA), len(LAM)))
    for s in range(N_STACKS):
        a = active[s]
        n_list = [1.0, *n[s, :a], base[s]]
        d_list = [np.inf, *d[s, :a], np.inf]
        for i, th in enumerate(THETA):
            for j, lam in enumerate(LAM):
                r = tmm.coh_tmm(pol, n_list, d_list, th, lam)
                out[:, s, i, j] = r["R"], r["T"]
    return out


@pytest.fixture(scope="module")
def absorbing():
    d, n, base, active = random_stacks(1)
    return as_stack(d, n, base), {p: tmm_grid(p, d, n, base, active) for p in "sp"}


@pytest.mark.parametrize("pol", ["s", "p"])
def test_matches_tmm(absorbing, pol):
    """R and T of 1–8 layer stacks (dielectrics and metals, dielectric and absorbing bases,
    0–89.9°) equal tmm's coh_tmm; measured max |ΔR|, |ΔT| 6.0e-14, 1.2e-13 (s), 7.3e-14,
    1.3e-13 (p)."""
    stack, ref = absorbing
    r = np.asarray(stack_reflectance(stack, COS, LAM, pol))
    t = np.asarray(stack_transmittance(stack, COS, LAM, pol))
    assert r.shape == t.shape == (N_STACKS, len(THETA), len(LAM))
    np.testing.assert_allclose(r, ref[pol][0], rtol=0, atol=1e-10)
    np.testing.assert_allclose(t, ref[pol][1], rtol=0, atol=1e-10)
    assert np.ptp(ref[pol][1]) > 0.1 and np.ptp(ref[pol][0]) > 0.5  # a non-trivial set


def test_unpolarised_is_the_mean(absorbing):
    stack, ref = absorbing
    r = np.asarray(stack_reflectance(stack, COS, LAM))
    t = np.asarray(stack_transmittance(stack, COS, LAM))
    np.testing.assert_allclose(r, 0.5 * (ref["s"][0] + ref["p"][0]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(t, 0.5 * (ref["s"][1] + ref["p"][1]), rtol=0, atol=1e-10)


def test_lossless_conserves_energy():
    """Lossless layers on a lossless base: R + T = 1; measured max |R + T − 1| 1.6e-15."""
    d, n, base, _ = random_stacks(2, lossless=True)
    stack = as_stack(d, n, base)
    total = stack_reflectance(stack, COS, LAM) + stack_transmittance(stack, COS, LAM)
    np.testing.assert_allclose(np.asarray(total), 1.0, rtol=0, atol=1e-12)


def bulk_metal(n_metal, cos):
    """|r_s|², |r_p|² of the bare air | metal interface (closed-form Fresnel)."""
    s2 = 1.0 - cos**2
    q1, q2 = cos + 0j, np.sqrt(n_metal**2 - s2)
    q2 = np.where(q2.imag < 0, -q2, q2)
    rs = (q1 - q2) / (q1 + q2)
    rp = (n_metal**2 * q1 - q2) / (n_metal**2 * q1 + q2)
    return np.abs(rs) ** 2, np.abs(rp) ** 2


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_thick_metal_is_bulk(dtype):
    """A 10 µm metal layer over anything is the bulk metal (T = 0, no overflow or NaN):
    measured max |ΔR| 1.1e-15 (float64), 3.1e-7 (float32)
    with the 10 µm layer alone on glass, and the same under the 12 × 8-layer batch here."""
    cdt = np.complex128 if dtype == np.float64 else np.complex64
    d = np.zeros((N_STACKS, N_LAYERS))
    d[:, 0] = 10_000.0
    d[:, 1:] = 50.0
    n = np.full((N_STACKS, N_LAYERS), 1.5 + 0j)
    n[:, 0] = [METALS[i % 2] for i in range(N_STACKS)]
    n[:, 1] = 0.2 + 3.0j
    base = np.full(N_STACKS, 1.52 + 0j)
    stack = Stack(jnp.asarray(d[:, None, None, :], dtype),
                  tuple(jnp.asarray(n[:, i, None, None], cdt) for i in range(N_LAYERS)),
                  jnp.asarray(base[:, None, None], cdt))
    cos, lam = jnp.asarray(COS, dtype), jnp.asarray(LAM, dtype)
    tol = 1e-12 if dtype == np.float64 else 1e-5
    for pol in ("s", "p"):
        r = stack_reflectance(stack, cos, lam, pol)
        t = stack_transmittance(stack, cos, lam, pol)
        assert r.dtype == t.dtype == dtype
        assert np.all(np.isfinite(r)) and np.all(np.isfinite(t))
        rs, rp = bulk_metal(n[:, 0, None, None], COS)
        ref = np.broadcast_to(rs if pol == "s" else rp, r.shape)
        np.testing.assert_allclose(np.asarray(r, float), ref, rtol=0, atol=tol)
        np.testing.assert_allclose(np.asarray(t, float), 0.0, rtol=0, atol=1e-30)  # e^(-4πdκ/λ)


def test_float32_close_to_float64(absorbing):
    """float32 is finite and within 1e-3 of float64 everywhere on the random set; measured
    max |ΔR| 1.3e-6, |ΔT| 9e-7."""
    stack, _ = absorbing
    s32 = Stack(jnp.asarray(stack.thickness, jnp.float32),
                tuple(jnp.asarray(e, jnp.complex64) for e in stack.eta),
                jnp.asarray(stack.eta_base, jnp.complex64))
    cos, lam = jnp.asarray(COS, jnp.float32), jnp.asarray(LAM, jnp.float32)
    for fn in (stack_reflectance, stack_transmittance):
        lo = np.asarray(fn(s32, cos, lam))
        hi = np.asarray(fn(stack, COS, LAM))
        assert lo.dtype == np.float32 and np.all(np.isfinite(lo))
        np.testing.assert_allclose(lo, hi, rtol=0, atol=1e-3)


@pytest.mark.parametrize("kappa", [0.0, 0.5])
def test_film_is_one_layer_stack(kappa):
    """`Stack.from_film(f)` gives `airy_reflectance(f)` (dielectric and absorbing bases,
    0–90°, 0–2 µm); measured max |ΔR| 2.2e-16 (κ = 0), 9.7e-16 (κ = 0.5)."""
    d = np.array([0.0, 120.0, 600.0, 2000.0])[:, None, None]
    film = Film(d, 1.33, 2.0, kappa)
    cos = np.cos(np.radians([0.0, 30.0, 60.0, 80.0, 90.0]))[:, None]
    ours = stack_reflectance(Stack.from_film(film), cos, LAM)
    np.testing.assert_allclose(np.asarray(ours), np.asarray(airy_reflectance(film, cos, LAM)),
                               rtol=0, atol=1e-12)


def _grad_stack(d, n2, nb):
    return Stack(d, (1.46, n2, 0.2 + 3.0j, 2.3), nb)


def test_thickness_gradient_matches_differences():
    """∂(Σ R)/∂d_k for each of 4 layers (a dielectric, a metal) against central differences
    (h = 1e-3 nm); measured max relative error 3e-10."""
    d = np.array([120.0, 80.0, 25.0, 60.0])
    cos, lam = COS[:4], LAM

    def loss(d):
        return jnp.sum(stack_reflectance(_grad_stack(d, 1.9, 1.52 + 0.1j), cos, lam))

    g = np.asarray(jax.grad(loss)(jnp.asarray(d)))
    h = 1e-3
    # every ± step as one batch (one forward program)
    steps = np.concatenate([d + h * np.eye(4), d - h * np.eye(4)])[:, None, None, :]
    rr = np.asarray(stack_reflectance(_grad_stack(steps, 1.9, 1.52 + 0.1j), cos, lam))
    fd = (rr[:4].sum(axis=(1, 2)) - rr[4:].sum(axis=(1, 2))) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    assert np.all(np.abs(g) > 1e-4)


def test_gradients_finite_at_singular_points():
    """Gradients in every thickness, index and cos θ are finite at d = 0, θ = 0, θ = 90°,
    κ = 0 (base and layer), and a layer matched to the outer medium (q = 0 at grazing)."""

    def f(d, n2, nb, c):
        st = Stack(d, (1.0, n2, 0.2 + 3.0j, 2.3), nb)
        return (jnp.sum(stack_reflectance(st, c, LAM))
                + jnp.sum(stack_transmittance(st, c, LAM)))

    d = jnp.array([0.0, 0.0, 10.0, 0.0])
    c = jnp.array([1.0, 0.5, 0.0])[:, None]
    for nb in (1.52 + 0j, 1.52 + 0.3j):
        gs = jax.grad(f, argnums=(0, 1, 2, 3), holomorphic=False)(d, 1.9 + 0j, nb, c)
        for g in jax.tree.leaves(gs):
            assert np.all(np.isfinite(np.asarray(g))), gs


def test_broadcasting_batches_and_grid():
    """cos θ (64, 1) × λ (100,) → (64, 100); a leading thickness batch broadcasts too."""
    st = Stack(np.array([[100.0, 50.0], [200.0, 10.0]])[:, None, None, :], (1.46, 2.3), 1.52)
    cos = np.linspace(0.0, 1.0, 64)[:, None]
    lam = np.linspace(400.0, 700.0, 100)
    assert stack_reflectance(st, cos, lam).shape == (2, 64, 100)
    one = Stack([100.0, 50.0], (1.46, 2.3), 1.52)
    assert stack_transmittance(one, cos, lam, "p").shape == (64, 100)


@pytest.mark.parametrize("stack, match", [
    (Stack([-1.0, 5.0], (1.5, 2.0), 1.5), r"stack\.thickness must lie in"),
    (Stack([np.nan, 5.0], (1.5, 2.0), 1.5), r"stack\.thickness must be finite"),
    (Stack([1.0, 5.0, 3.0], (1.5, 2.0), 1.5), r"stack\.thickness must hold the N .* = 2"),
    (Stack(5.0, (1.5,), 1.5), r"stack\.thickness must hold"),
    (Stack([1.0, 5.0], (1.5, 2.0 - 0.1j), 1.5), r"stack\.eta\[1\] must have kappa"),
    (Stack([1.0, 5.0], (1.5, np.inf), 1.5), r"stack\.eta\[1\] must be finite"),
    (Stack([1.0, 5.0], (1.5, 2.0), 1.5 - 1j), r"stack\.eta_base must have kappa"),
    (Stack([1.0, 5.0], (-1.5, 2.0), 1.5), r"stack\.eta\[0\] must have Re"),
    (Stack([1.0, 5.0], (1.5, 2.0), 1.5, 1.0 + 0.1j), r"stack\.eta_outer must be lossless"),
])
def test_errors(stack, match):
    with pytest.raises(ValueError, match=match):
        stack_reflectance(stack, 1.0, 550.0)
    with pytest.raises(ValueError, match=match):
        stack_transmittance(stack, 1.0, 550.0)


def test_other_argument_errors():
    st = Stack([1.0], (1.5,), 1.5)
    with pytest.raises(ValueError, match="polarisation"):
        stack_reflectance(st, 1.0, 550.0, "circular")
    with pytest.raises(ValueError, match="wavelength"):
        stack_reflectance(st, 1.0, 0.0)
    with pytest.raises(ValueError, match="cos_theta"):
        stack_transmittance(st, 1.5, 550.0)
    with pytest.raises(TypeError, match="Stack"):
        stack_reflectance(Film(1.0, 1.5, 1.5), 1.0, 550.0)


def test_thickness_list_of_traced_layers():
    """`Stack(thickness=[d0, d1], ...)` with each layer's thickness traced (the list a user
    writes inside `jax.grad`, `jit` or `vmap`): the list is stacked as it is traced, the
    checks skip the tracers. Gradient against central differences (h = 1e-3 nm, float64),
    `jit` and `vmap` against the concrete values."""
    def f(d0, d1):
        return stack_reflectance(Stack([d0, d1], [1.46, 2.0], 3.5 + 0.01j), 0.8, 550.0)

    g = jax.grad(f, argnums=(0, 1))(100.0, 80.0)
    h = 1e-3
    fd = [(f(100.0 + h, 80.0) - f(100.0 - h, 80.0)) / (2 * h),
          (f(100.0, 80.0 + h) - f(100.0, 80.0 - h)) / (2 * h)]
    np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-6)
    assert abs(float(jax.jit(f)(100.0, 80.0)) - float(f(100.0, 80.0))) < 1e-15
    got = jax.vmap(f)(jnp.array([100.0, 120.0]), jnp.array([80.0, 90.0]))
    np.testing.assert_allclose(got, [f(100.0, 80.0), f(120.0, 90.0)], rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="thickness"):  # concrete lists are still checked
        stack_reflectance(Stack([100.0, -1.0], [1.46, 2.0], 3.5), 0.8, 550.0)
