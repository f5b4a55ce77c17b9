"""The vectorisable primitives of the Airy path against NumPy: `airy.sincos_turns` (range
reduction in turns + Taylor polynomials) and the hand-written complex √ and division of
`fresnel` (branch Im ≥ 0, signed zeros, scaling)."""

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.optics import airy
from thinfilm_jax.optics import fresnel


def test_sincos_turns_matches_numpy_any_argument():
    rng = np.random.default_rng(1234)
    u = np.concatenate([rng.uniform(-1, 1, 400_000), rng.uniform(-1e3, 1e3, 400_000),
                        rng.uniform(-1e12, 1e12, 100_000), 10.0 ** rng.uniform(-300, 0, 100_000),
                        np.arange(-8, 9) / 8.0, [2.0**52, -(2.0**53) + 1, 1e300]])
    c, s = (np.asarray(x) for x in jax.jit(airy.sincos_turns)(jnp.asarray(u)))
    # exact reduction in turns (u − round(u) is exact), then NumPy's libm on |x| ≤ π
    x = 2 * np.pi * (u - np.round(u))
    assert np.abs(c - np.cos(x)).max() <= 4.5e-16
    assert np.abs(s - np.sin(x)).max() <= 4.5e-16
    tiny = np.abs(x) < 1e-3  # relative accuracy where sin is small
    assert np.all(np.abs(s[tiny] - np.sin(x[tiny])) <= 2.3e-16 * np.abs(np.sin(x[tiny])))
    assert np.abs(c * c + s * s - 1).max() <= 4.5e-16
    # float32: same range reduction, shorter polynomials
    c32, s32 = jax.jit(airy.sincos_turns)(jnp.asarray(u[:800_000], jnp.float32))
    x32 = 2 * np.pi * (u[:800_000].astype(np.float32) - np.round(u[:800_000].astype(np.float32)))
    assert c32.dtype == jnp.float32
    assert np.abs(np.asarray(c32) - np.cos(x32)).max() <= 3e-7
    assert np.abs(np.asarray(s32) - np.sin(x32)).max() <= 3e-7


def test_sincos_turns_derivative_is_calculus():
    u = jnp.linspace(-3.0, 3.0, 101)
    dc = jax.vmap(jax.grad(lambda v: airy.sincos_turns(v)[0]))(u)
    ds = jax.vmap(jax.grad(lambda v: airy.sincos_turns(v)[1]))(u)
    np.testing.assert_allclose(dc, -2 * np.pi * np.sin(2 * np.pi * u), atol=1e-14)
    np.testing.assert_allclose(ds, 2 * np.pi * np.cos(2 * np.pi * u), atol=1e-14)


def test_sqrt_upper_and_safe_div_match_numpy():
    rng = np.random.default_rng(99)
    n = 20_000
    z = (rng.normal(size=n) * 10.0 ** rng.uniform(-150, 150, n)
         + 1j * rng.normal(size=n) * 10.0 ** rng.uniform(-150, 150, n))
    z[:4] = [4.0, -4.0, complex(-4.0, -0.0), complex(0.0, -2.0)]
    w = np.asarray(fresnel.sqrt_upper(jnp.asarray(z)))
    ref = np.sqrt(z)
    ref = np.where(ref.imag < 0, -ref, ref)
    assert np.all(w.imag >= 0)
    assert np.all(np.abs(w - ref) <= 4.5e-16 * np.abs(ref))
    assert np.asarray(fresnel.sqrt_upper(jnp.asarray([0j])))[0] == 0
    num = rng.normal(size=n) + 1j * rng.normal(size=n)
    den = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 10.0 ** rng.uniform(-150, 150, n)
    q = np.asarray(fresnel.safe_div(jnp.asarray(num), jnp.asarray(den)))
    assert np.all(np.abs(q - num / den) <= 6.7e-16 * np.abs(num / den))
    assert np.asarray(fresnel.safe_div(jnp.asarray([1 + 1j]), jnp.asarray([0j])))[0] == 0


def test_blocked_flat_layout_equals_direct_values_and_gradients():
    """Flat pairs above 2·BLOCK run in `lax.map` blocks; values and gradients must be those
    of the unblocked evaluation (a remainder block included)."""
    from thinfilm_jax import Film

    n = 2 * airy.BLOCK + 517
    rng = np.random.default_rng(7)
    film = Film(jnp.asarray(rng.uniform(0, 2000, n)), 1.35, 2.0, jnp.asarray(rng.uniform(0, 3, n)))
    c, lam = jnp.asarray(rng.uniform(0, 1, n)), jnp.asarray(rng.uniform(380, 780, n))

    def blocked(f, cc):
        return jnp.sum(airy._airy_jit(f, cc, lam, "complex") * jnp.linspace(0.5, 1.5, n))

    def direct(f, cc):
        return jnp.sum(airy._airy_direct(f, cc, lam, "complex") * jnp.linspace(0.5, 1.5, n))

    vb, gb = jax.value_and_grad(blocked, argnums=(0, 1))(film, c)
    vd, gd = jax.value_and_grad(jax.jit(direct), argnums=(0, 1))(film, c)
    np.testing.assert_allclose(float(vb), float(vd), rtol=1e-14)
    for a, b in zip(jax.tree.leaves(gb), jax.tree.leaves(gd)):
        # rounding differs between the fused programs (measured ≤ 3e-12 relative); a wrong
        # block assignment would be O(1)
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-13)
