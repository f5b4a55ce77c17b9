"""The adaptive reference of SPEC §9 (thinfilm_jax/shading/ibl_adaptive.py) against the exhaustive
texel quadrature it replaces, and the resampling of large maps."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, albedo, envmap_radiance, load_envmap
from thinfilm_jax.shading.envmap import downsample
from thinfilm_jax.shading.ibl_adaptive import block_interpolant, block_size
from thinfilm_jax.shading.ibl_reference import exact_radiance, resample_factor

FILM = Film(600.0, 1.2, 2.0, 0.0)


def _points(k=6, seed=3):
    """Random normals and views, every third view grazing (85° from the normal)."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    t = rng.normal(size=(k, 3))
    t -= np.sum(t * n, -1, keepdims=True) * n
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    th = np.where(np.arange(k) % 3 == 0, 1.48, rng.uniform(0.1, 1.2, k))[:, None]
    return n, np.cos(th) * n + np.sin(th) * t


def _run(env, alpha, n, v, **kw):
    k = len(n)
    f = Film(*(jnp.full(k, float(x)) for x in FILM))
    return exact_radiance(f, jnp.full(k, alpha), jnp.asarray(n), jnp.asarray(v), env,
                          method="reference", observer="stiles_burch_1959_10", cross_band=True,
                          arithmetic="complex", one_film=True, return_estimate=True, **kw)


@pytest.mark.parametrize("alpha", [0.05, 0.1, 0.15, 0.25, 0.6, 1.0])
def test_adaptive_matches_exhaustive(alpha):
    """Same points, the shipped 128 × 256 sunset map: the adaptive rule (a second-order
    Taylor rule per 4 × 4-texel block with the light's exact moments, the texel interpolant
    in the K blocks it scores worst, s × s Gauss nodes in the K₃ texels it scores worst
    among theirs, `refine_counts`) agrees with every texel at s × s nodes to ≤ 1.5e-4 of
    each band's maximum, 2.5e-4 at α = 1 (measured 1.9e-6, 4.3e-6, 7.1e-5, 8.6e-5, 8.2e-5,
    1.7e-4 at α = 0.05, 0.1, 0.15, 0.25, 0.6, 1 on these 6 points, two of them at 85° from
    the normal; ≤ 3.3e-4 on 58 points of each shipped map at twelve α from 0.03 to 1); the
    SPEC's bound is 1e-3.
    The former fixed K₃ = 64 s² misses at α = 0.1 (2.5e-3): the lobe spans more texels than
    256. Without the sub-texel level the grazing points miss by 9e-3 at α = 0.05,
    without the texel rule by 0.42. The estimate of the neglected part is finite and ≥ 0
    (5e-5 to 0.17 of the band maximum here)."""
    env = load_envmap("venice_sunset")
    n, v = _points()
    old, _ = _run(env, alpha, n, v, exhaustive=True)
    new, est = _run(env, alpha, n, v)
    old, new, est = map(np.asarray, (old, new, est))
    scale = np.abs(old).max(axis=0)
    bound = 2.5e-4 if alpha == 1.0 else 1.5e-4
    assert np.all(np.abs(new - old).max(axis=0) <= bound * scale), np.abs(new - old).max(0) / scale
    assert np.all(np.isfinite(est)) and np.all(est >= 0)


def test_white_furnace_grazing_on_a_shipped_size_map():
    """A near-perfect mirror under a white 128 × 256 map reflects A(θ_o, α) (SPEC §9's
    white furnace) with the default counts, views to 86° from the normal and lobes that
    span the horizon: ≤ 8e-4 (measured 4.2e-4, 5.6e-4, 6.1e-4 at α = 0.25, 0.5, 1; the
    SPEC's bound is 1e-3 of the band maximum, 0.89 here). Refining 64 blocks instead of 256
    errs 1.0e-3, 1.5e-3, 2.9e-3: the block rule's small errors over the horizon add up."""
    mirror = Film(300.0, 1.0, 1.0, 1e4)
    env = load_envmap(np.ones((128, 256, 3)))
    theta = np.array([0.2, 0.9, 1.3, 1.5])
    k = len(theta)
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    v = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    f = Film(*(jnp.full(k, float(x)) for x in mirror))
    for alpha in (0.25, 0.5, 1.0):
        got, _ = exact_radiance(f, jnp.full(k, alpha), jnp.asarray(n), jnp.asarray(v), env,
                                method="reference", observer="stiles_burch_1959_10",
                                cross_band=True, arithmetic="complex", one_film=True,
                                return_estimate=True)
        want = np.asarray(albedo(theta, alpha))[:, None]
        assert np.abs(np.asarray(got) - want).max() <= 8e-4, (alpha, np.abs(got - want).max())


@pytest.mark.parametrize("height", [32, 64])
def test_white_furnace_on_small_maps(height):
    """Coarse maps (≤ 64 × 128) refine at least a quarter of the refined blocks' texels with
    sub-nodes: a near-mirror under a white map at α = 0.5 and 1, views to 86°, gives
    A(θ_o, α) to ≤ 5e-4 (measured 2.5e-4, 2.0e-4 on 32 rows; 7.2e-5, 2.4e-5 on 64). With
    K₃ = 256 the 32-row map erred 2.7e-3 at α = 1 (SPEC bound 1e-3)."""
    mirror = Film(300.0, 1.0, 1.0, 1e4)
    env = load_envmap(np.ones((height, 2 * height, 3)))
    theta = np.array([0.2, 0.9, 1.3, 1.4, 1.5])
    k = len(theta)
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    v = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    f = Film(*(jnp.full(k, float(x)) for x in mirror))
    for alpha in (0.5, 1.0):
        got = exact_radiance(f, jnp.full(k, alpha), jnp.asarray(n), jnp.asarray(v), env,
                             method="reference", observer="stiles_burch_1959_10",
                             cross_band=True, arithmetic="complex", one_film=True)
        want = np.asarray(albedo(theta, alpha))[:, None]
        assert np.abs(np.asarray(got) - want).max() <= 5e-4, (alpha, np.abs(got - want).max())


def test_map_tables_follow_the_map():
    """The adaptive rule keeps a map's tables while the map lives (`_map_geometry`): a second
    map of the same size has its own light (twice the radiance, twice the result to
    rounding), the first map again gives its own result, and an entry goes with its map."""
    import gc

    from thinfilm_jax.shading import ibl_adaptive

    n, v = _points()
    env1 = load_envmap(np.random.default_rng(0).uniform(size=(32, 64, 3)))
    env2 = load_envmap(2 * np.asarray(env1.radiance))
    first, _ = _run(env1, 0.3, n, v)
    double, _ = _run(env2, 0.3, n, v)
    again, _ = _run(env1, 0.3, n, v)
    np.testing.assert_allclose(np.asarray(double), 2 * np.asarray(first), rtol=1e-12, atol=0)
    np.testing.assert_array_equal(np.asarray(again), np.asarray(first))
    key = id(env2.radiance)
    assert key in ibl_adaptive._GEOMETRY
    del env2
    gc.collect()
    assert key not in ibl_adaptive._GEOMETRY


def test_unresolved_grazing_lobes_warn():
    """At a grazing view the reflected lobe is about 2α cos θ_o wide, and the texel nodes
    (sized by α alone) stop resolving it: the near-mirror under a white 128 × 256 map then
    misses A(θ_o, α) by 1.2e-2 at α = 0.05, θ_o = 88° (the exhaustive rule too), over the
    SPEC's 1e-3, and the call says so; at α = 0.25, θ_o = 86° (lobe 2.8 node spacings wide,
    error 6e-4) it does not warn."""
    mirror = Film(300.0, 1.0, 1.0, 1e4)
    env = load_envmap(np.ones((128, 256, 3)))
    n = np.array([0.0, 0.0, 1.0])
    for alpha, deg, unresolved in ((0.05, 88.0, True), (0.25, 86.0, False)):
        t = np.radians(deg)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            got = float(envmap_radiance(mirror, alpha, n, np.array([np.sin(t), 0.0, np.cos(t)]),
                                        env)[0])
        warned = any("not converged" in str(w.message) for w in caught)
        assert warned == unresolved, (alpha, deg, [str(w.message) for w in caught])
        err = abs(got - float(albedo(t, alpha)))
        assert (err > 5e-3) if unresolved else (err < 8e-4), (alpha, deg, err)


@pytest.mark.parametrize("shape", [(16, 32), (7, 14)])
def test_every_region_refined_is_the_exhaustive_rule(shape):
    """Refining every block by the texel rule and every texel by its s × s nodes
    (`refine=(T_B, T)`) gives the exhaustive rule to rounding: the three levels replace
    each other's values exactly (4 × 4 blocks on 16 × 32; one-texel blocks on 7 × 14, where
    level 3 refines the blocks). Random map, normals and views, grazing views included."""
    h, w = shape
    env = load_envmap(np.random.default_rng(1).uniform(0.0, 2.0, (h, w, 3)))
    n, v = _points(4, seed=7)
    b = block_size(h, w)
    old, _ = _run(env, 0.2, n, v, exhaustive=True, subdivisions=3)
    new, _ = _run(env, 0.2, n, v, subdivisions=3, refine=(h * w // b**2, h * w))
    old, new = np.asarray(old), np.asarray(new)
    np.testing.assert_allclose(new, old, rtol=0, atol=1e-13 * np.abs(old).max())


@pytest.mark.parametrize("b", [2, 4])
def test_texel_interpolant_integrates_polynomials(b):
    """`block_interpolant`: Σ_i A[r, i] θ_i^p = ∫_row θ^p sin θ dθ for p < b (the Lagrange
    interpolant through the block's b row centres reproduces polynomials of degree b − 1),
    closed form ∫ θ^p sin θ dθ by parts; likewise B for φ^q. Exact to 1e-14 of the
    texel's width times the largest θ^p (φ^q) (measured ~1e-16)."""
    h, w = 16, 32
    a, bm = block_interpolant(h, w, b)
    dth, dph = np.pi / h, 2 * np.pi / w
    for p in range(b):
        for r in range(h):
            centres = (r // b * b + np.arange(b) + 0.5) * dth
            t0, t1 = r * dth, (r + 1) * dth
            exact = _int_theta_pow_sin(p, t1) - _int_theta_pow_sin(p, t0)
            assert abs(a[r] @ centres**p - exact) <= 1e-14 * dth * np.pi**p, (p, r)
        for c in range(w):
            centres = (c // b * b + np.arange(b) + 0.5) * dph
            exact = (((c + 1) * dph) ** (p + 1) - (c * dph) ** (p + 1)) / (p + 1)
            assert abs(bm[c] @ centres**p - exact) <= 1e-14 * dph * (2 * np.pi)**p, (p, c)


def _int_theta_pow_sin(p, t):
    """An antiderivative of θ^p sin θ: −Σ_k p!/(p−k)! θ^(p−k) cos(θ + kπ/2)."""
    from math import factorial
    return -sum(factorial(p) / factorial(p - k) * t ** (p - k) * np.cos(t + k * np.pi / 2)
                for k in range(p + 1))


def test_resample_factor_rule():
    """Texel f·π/H ≤ α/8, never below 128 rows, only above max_height."""
    assert resample_factor(128, 0.01, 512) == 1
    assert resample_factor(1024, 0.3, 512) == 8  # 8π/1024 = 0.0245 ≤ 0.0375
    assert resample_factor(1024, 0.1, 512) == 4  # 4π/1024 = 0.0123 ≤ 0.0125 < 8π/1024
    assert resample_factor(1024, 0.6, 512) == 8  # stops at 128 rows
    assert resample_factor(1024, 0.3, None) == 1


def test_large_map_resampled_with_warning():
    """A 512 × 1024 map (the shipped forest map replicated, times a texture that varies
    inside each 4 × 4 block) is resampled by 4 at α = 0.3 with a warning; the result
    stays within 2e-3 of the full map's band maximum (measured 4e-4; the added error is the
    radiance contrast inside a block times the lobe's variation across it)."""
    base = np.asarray(load_envmap("forest_slope").radiance)
    rng = np.random.default_rng(0)
    big = np.kron(base, np.ones((4, 4, 1))) * rng.uniform(0.5, 1.5, (512, 1024, 1))
    env = load_envmap(big)
    n, v = _points(3, seed=5)
    with pytest.warns(UserWarning, match="resampled by 4"):
        got = np.asarray(envmap_radiance(FILM, 0.3, n, v, env))
    full, _ = _run(env, 0.3, n, v, max_height=None)
    full = np.asarray(full)
    scale = np.abs(full).max(axis=0)
    assert np.all(np.abs(got - full).max(axis=0) <= 2e-3 * scale), np.abs(got - full).max(0) / scale
    same = np.asarray(envmap_radiance(FILM, 0.3, n, v, downsample(env, 4)))
    np.testing.assert_allclose(got, same, rtol=1e-12)
