"""`shading.carpaint_ibl`: the car paint under uniform light and environment maps — a constant
map is the uniform-light patch, Monte Carlo within 4σ of the texel reference, the coat's mirror
term exact, the white furnace with the colour table, the patch's convergence, gradients and
errors. Small maps (16 × 32) and few points keep it fast."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax.brdf import carpaint as C
from thinfilm_jax.shading.carpaint_ibl import paint_envmap_radiance, paint_patch_radiance
from thinfilm_jax.shading.envmap import lookup_nearest

N = np.array([0.0, 0.0, 1.0])
WHITE = C.plain_colour([1.0, 1.0, 1.0])


def view(theta, phi=0.0):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


@pytest.fixture(scope="module")
def paints():
    return {k: f() for k, f in C.PAINTS.items()}


def test_constant_map_is_the_patch(paints):
    """A constant map c is c ⊙ the uniform-light patch (coat mirror term included): measured
    ≤ 2e-8 on a 16 × 32 map with the automatic sub-texel nodes."""
    c = np.array([0.5, 1.0, 2.0])
    env = np.ones((16, 32, 3)) * c
    th = np.array([0.0, 0.6, 1.3])
    for name, p in paints.items():
        patch = paint_patch_radiance(p, th)
        got = paint_envmap_radiance(p, N, np.stack([view(t, 0.7) for t in th]), env)
        np.testing.assert_allclose(got, patch * c, rtol=0, atol=1e-6, err_msg=name)


def test_patch_with_colour_one_is_the_albedos():
    p = C.car_paint(0.3, [0.4, 0.3], [0.07, 0.5], [0.9, 0.2], WHITE, 1.5)
    th = np.array([0.0, 0.8, 1.5, np.pi / 2])
    ref = C.coat_reflectance(p, np.cos(th)) + C.lobe_albedo(p, np.cos(th)).sum(-1)
    np.testing.assert_allclose(paint_patch_radiance(p, th), np.stack([ref] * 3, -1),
                               rtol=0, atol=1e-13)


def test_white_furnace_with_a_colour_table():
    """χ ≤ 1 (random table), a + Σ s ≤ 1, F₀ = 1: F(θ_o) + ∫ f cos ≤ 1 at every view, grazing
    included; χ ≡ 1 and one mirror-like lobe comes close to 1 at normal view."""
    rng = np.random.default_rng(0)
    th = np.concatenate([np.linspace(0, np.pi / 2, 9), [1.56]])
    for eta in (1.0, 1.5, 2.0):
        p = C.car_paint(0.25, [0.5, 0.25], [0.03, 0.6], [1.0, 1.0],
                        rng.uniform(0, 1, (6, 8, 3)), eta)
        L = paint_patch_radiance(p, th, quadrature=(32, 32), diffuse_quadrature=(16, 16))
        assert np.all(L <= 1 + 1e-12) and np.all(L >= 0), (eta, float(L.max()))


def test_patch_converged(paints):
    """Default orders against (256, 256)/(128, 128): measured 5e-14 (plain), 2.5e-9 (metallic),
    5.4e-8 (pearlescent; the bilinear table's kinks converge algebraically)."""
    th = np.array([0.0, 0.5, 1.2, 1.5])
    for name, tol in (("metallic", 1e-7), ("pearlescent", 1e-6)):
        a = paint_patch_radiance(paints[name], th)
        b = paint_patch_radiance(paints[name], th, quadrature=(256, 256),
                                 diffuse_quadrature=(128, 128))
        assert float(np.abs(a - b).max()) < tol, name


def test_mirror_term_is_exact():
    """No lobes and no Lambert term: only the coat's mirror, F(θ_o) L(ω_r) of the texel."""
    rng = np.random.default_rng(1)
    env = rng.uniform(0, 3, (16, 32, 3))
    p = C.car_paint(0.0, [0.0], [0.3], [0.5], WHITE, 1.6)
    nrm = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 0.93]])
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    v = np.stack([view(0.4, 1.0), view(1.1, 2.5)])
    co = np.sum(nrm * v, -1)
    wr = 2 * co[:, None] * nrm - v
    expect = C.coat_reflectance(p, co)[:, None] * lookup_nearest(jnp.asarray(env), wr)
    np.testing.assert_allclose(paint_envmap_radiance(p, nrm, v, env), expect, rtol=1e-14)
    np.testing.assert_allclose(paint_envmap_radiance(p, nrm, v, env, method="mc",
                                                     n_samples=64), expect, rtol=1e-14)


@pytest.mark.parametrize("name", ["metallic", "pearlescent", "plain"])
def test_mc_within_four_sigma(paints, name):
    rng = np.random.default_rng(2)
    env = rng.uniform(0, 2, (16, 32, 3))
    env[2:4, 5:9] *= 20  # a bright patch
    nrm = np.array([[0, 0, 1.0], [0.3, 0.2, 0.9], [0, 0, 1.0]])
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    v = np.stack([view(0.5), view(1.2, np.pi / 2), view(1.45)])
    ref = paint_envmap_radiance(paints[name], nrm, v, env)
    mc, err = paint_envmap_radiance(paints[name], nrm, v, env, method="mc", n_samples=8192,
                                    return_stderr=True)
    assert np.all(err > 0) and np.all(err < 0.05 * ref)
    assert np.all(np.abs(mc - ref) < 4 * err), (mc - ref) / err


def test_back_facing_is_zero(paints):
    env = np.ones((16, 32, 3))
    v = np.array([np.sin(0.3), 0.0, -np.cos(0.3)])
    assert float(np.abs(paint_envmap_radiance(paints["plain"], N, v, env)).max()) == 0.0
    assert float(np.abs(paint_envmap_radiance(paints["plain"], N, v, env, method="mc",
                                              n_samples=16)).max()) == 0.0


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_gradients_finite(dtype):
    rng = np.random.default_rng(3)
    env = jnp.asarray(rng.uniform(0, 2, (8, 16, 3)), dtype)
    nrm = jnp.asarray([[0.0, 0.0, 1.0]] * 2, dtype)
    v = jnp.asarray(np.stack([view(0.0), view(1.5)]), dtype)
    p = C.CarPaint(*(jnp.asarray(x, dtype) for x in C.PAINTS["pearlescent"]()))

    def loss(p):  # (the patch's nodes are differentiated in tests/brdf/test_carpaint.py)
        return jnp.sum(paint_envmap_radiance(p, nrm, v, env, subdivisions=2))

    g = jax.grad(loss)(p)
    for k, x in g._asdict().items():
        assert x.dtype == dtype and np.all(np.isfinite(np.asarray(x))), k
    assert float(jnp.abs(g.coat_ior)) > 0 and float(jnp.abs(g.lobe_alpha).sum()) > 0


def test_bad_input(paints):
    p, env = paints["plain"], np.ones((8, 16, 3))
    with pytest.raises(ValueError, match="method"):
        paint_envmap_radiance(p, N, view(0.3), env, method="nope")
    with pytest.raises(ValueError, match="normal"):
        paint_envmap_radiance(p, N[:2], view(0.3), env)
    with pytest.raises(ValueError, match="n_samples"):
        paint_envmap_radiance(p, N, view(0.3), env, method="mc", n_samples=1)
    with pytest.raises(ValueError, match="theta_o"):
        paint_patch_radiance(p, 2.0)
    with pytest.raises(ValueError, match="environment map"):
        paint_envmap_radiance(p, N, view(0.3), np.ones((8, 8, 3)))


def test_float32_agrees_with_float64(paints):
    """float32 paths against float64: measured ≤ 6e-6 relative (patch and 16 × 32 map)."""
    th = np.array([0.0, 0.7, 1.3, 1.55])
    env = np.random.default_rng(4).uniform(0, 2, (16, 32, 3))
    v = np.stack([view(t) for t in th])
    p = paints["metallic"]
    p32 = C.CarPaint(*(jnp.asarray(x, np.float32) for x in p))
    a, b = paint_patch_radiance(p, th), paint_patch_radiance(p32, th.astype(np.float32))
    assert b.dtype == np.float32
    np.testing.assert_allclose(b, a, rtol=5e-5)
    a = paint_envmap_radiance(p, N, v, env)
    b = paint_envmap_radiance(p32, N.astype(np.float32), v.astype(np.float32),
                              env.astype(np.float32))
    assert b.dtype == np.float32
    np.testing.assert_allclose(b, a, rtol=5e-5)
