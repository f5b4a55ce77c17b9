"""Image-based lighting (SPEC §9): maps, the exact paths, the real-time paths, their limits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import (EnvMap, Film, ModelOptions, PrefilteredEnvMap, SHIPPED_ENVMAPS,
                          albedo, envmap_radiance, load_envmap, patch_radiance,
                          prefilter_envmap, rgb_reflectance)
from thinfilm_jax.shading.envmap import downsample, save_envmap, texel_centers, texel_solid_angles
from thinfilm_jax.brdf.microfacet import brdf_no_fresnel

FILM = Film(600.0, 1.3, 2.0, 0.5)
Z = np.array([0.0, 0.0, 1.0])


def view_at(theta, phi=0.0):
    theta = np.asarray(theta, float)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                     np.cos(theta)], -1)


@pytest.fixture(scope="module")
def forest():
    """The shipped forest map box-filtered to 32 × 64 (smooth, coloured light)."""
    return downsample(load_envmap("forest_slope"), 4)


@pytest.fixture(scope="module")
def forest_pref(forest):
    """`forest` prefiltered once (17 levels), shared by the real-time tests."""
    return prefilter_envmap(forest)


# ----------------------------------------------------------------------------- maps
def test_shipped_maps_load():
    for name in SHIPPED_ENVMAPS:
        env = load_envmap(name)
        assert env.radiance.shape == (128, 256, 3)
        assert np.all(np.isfinite(env.radiance)) and np.all(np.asarray(env.radiance) >= 0)
    sun = np.asarray(load_envmap("drakensberg").radiance)
    assert sun.max() > 1e3 * np.median(sun)  # the sun survives the box filter


def test_exr_and_hdr_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 50, (8, 16, 3))
    save_envmap(tmp_path / "m.exr", a)
    np.testing.assert_allclose(load_envmap(tmp_path / "m.exr").radiance, a, rtol=1e-6)
    save_envmap(tmp_path / "m.hdr", a)  # RGBE: 8-bit mantissas under a shared exponent
    err = np.abs(np.asarray(load_envmap(tmp_path / "m.hdr").radiance) - a)
    assert np.all(err <= a.max(axis=-1, keepdims=True) / 128)


@pytest.mark.parametrize("bad, match", [
    (np.ones((8, 8, 3)), "width must be 2 × height"),
    (np.ones((8, 16)), r"\(H, W, 3\)"),
    (np.full((8, 16, 3), np.nan), "non-finite"),
    (-np.ones((8, 16, 3)), "negative"),
])
def test_bad_arrays_rejected(bad, match):
    with pytest.raises(ValueError, match=match):
        load_envmap(bad)


def test_bad_files_rejected(tmp_path):
    with pytest.raises(ValueError, match="nope.hdr.*no such file"):
        load_envmap(tmp_path / "nope.hdr")
    junk = tmp_path / "junk.hdr"
    junk.write_bytes(b"this is not an image")
    with pytest.raises(ValueError, match="junk.hdr.*unreadable"):
        load_envmap(junk)


def test_downsample_preserves_integral(forest):
    full = np.asarray(load_envmap("forest_slope").radiance)
    small = np.asarray(forest.radiance)
    i_full = np.einsum("hwc,hw->c", full, texel_solid_angles(*full.shape[:2]))
    i_small = np.einsum("hwc,hw->c", small, texel_solid_angles(*small.shape[:2]))
    np.testing.assert_allclose(i_small, i_full, rtol=1e-12)


def test_texel_geometry():
    om = texel_solid_angles(16, 32)
    assert abs(om.sum() - 4 * np.pi) < 1e-12
    d = texel_centers(16, 32)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1, atol=1e-15)
    assert d[0, 0, 2] > 0.99 and d[-1, 0, 2] < -0.99  # row 0 is the top (z-up)
    assert d[8, 0, 0] > 0 and d[8, 8, 1] > 0  # φ from +x toward +y


# ----------------------------------------------------------------------------- exact paths
@pytest.fixture(scope="module")
def constant():
    """L ≡ (1, 1, 1) at 64 × 128 and its prefiltered maps."""
    env = load_envmap(np.ones((64, 128, 3)))
    return env, prefilter_envmap(env)


@pytest.mark.parametrize("alpha", [0.1, 0.25, 0.6])
def test_constant_environment_reproduces_patch(alpha, constant):
    """L ≡ (1, 1, 1) is the uniform light of SPEC §7: every method equals patch_radiance,
    the real-time ones to the prefilter's accuracy (A table, 17 levels, 64 × 128).
    Largest band difference measured over α ∈ {0.1, 0.25, 0.6} (float64): reference 1.9e-5,
    ideal 4.2e-5, filtered 6.1e-4, improved 7.7e-5 (all at α = 0.1 or 0.25, mostly at the
    grazing θ_o = 1.4; before the A table's view coordinate `prefilter.albedo_coordinate`:
    ideal 1.0e-4, filtered 5.7e-4, improved 7.2e-5); bounds 3e-5, 1.6e-4, 9e-4, 1.2e-4.
    Grazing views at small α and bare films: the tests below.
    This checks that each real-time path reads the map consistently with its uniform-light
    model, not that the model is accurate (a wrong film model is wrong in both): the pins
    of `improved` against the reference are `test_improved_pinned_under_an_environment` and
    tests/realtime/test_improved.py::test_pinned_accuracy_under_uniform_light."""
    theta = np.array([0.0, 0.6, 1.1, 1.4])
    v = view_at(theta, phi=0.3)
    for method, env, tol in (("reference", constant[0], 3e-5), ("ideal", constant[1], 1.6e-4),
                             ("filtered", constant[1], 9e-4), ("improved", constant[1], 1.2e-4)):
        got = np.asarray(envmap_radiance(FILM, alpha, Z, v, env, method=method))
        want = np.asarray(patch_radiance(FILM, theta, alpha, method=method))
        assert np.abs(got - want).max() < tol, (method, np.abs(got - want).max())


def test_light_spread_is_the_uniform_model_under_constant_light(constant):
    """`ModelOptions(light_spread=True)` scales each bin's spread by the ratio of its read's
    light-weighted variance of x = ⟨ω_o, ω_i⟩ to the kernel's, ½(1 − m₂) + ½(3m₂ − 1)x_d² −
    m₁²x_d² (`methods.improved.bin_radiance_parts`). Under L ≡ 1 the prefiltered second moments
    give that variance to within 5.4e-4 (measured here; 7.2e-4 over 4,000 points; the
    tolerance `VARIANCE_RESOLUTION` is 1e-3), so every spread is the uniform-light s_k
    exactly (without the tolerance they move) and the radiance is the option's absence to
    rounding (asserted 1e-12). A single bright disc on a black map narrows the spreads of
    the reads that see it (measured ratios 0.17–0.25 of s_k at a point whose mirror
    direction is the disc; asserted < 0.5)."""
    from thinfilm_jax.realtime.improved import bin_table, lookup_bins
    from _geometry import front_facing
    from thinfilm_jax.shading.methods.improved import bin_radiance_parts

    rng = np.random.default_rng(3)
    n, v = front_facing(rng, 400)
    co = np.sum(n * v, -1)
    alpha = rng.uniform(0.05, 0.5, size=400)
    tab = bin_table()
    _, sb = lookup_bins(tab, co, alpha)
    light = bin_radiance_parts(constant[1], tab, n, v, co, alpha, sb, light_spread=True)
    np.testing.assert_array_equal(np.asarray(light.spread), np.moveaxis(np.asarray(sb), -1, 0))
    theta = np.array([0.0, 0.6, 1.1, 1.4])
    views = view_at(theta, phi=0.3)
    for alpha in (0.1, 0.25):
        on, off = (np.asarray(envmap_radiance(FILM, alpha, Z, views, constant[1],
                                              method="improved",
                                              options=ModelOptions(shat="lut", light_spread=s)))
                   for s in (True, False))
        assert np.abs(on - off).max() < 1e-12
    # one bright disc, seen in the mirror direction of a point at θ_o = 45°
    img = np.full((64, 128, 3), 1e-3)
    img[15:17, 0:2] = 1e3  # near θ = 45°, φ = 0
    pref = prefilter_envmap(load_envmap(img), sources=0)
    th = np.pi / 4 - 1e-3
    d = np.array([np.sin(th) * np.cos(0.05), np.sin(th) * np.sin(0.05), np.cos(th)])
    nz = np.array([[0.0, 0.0, 1.0]])
    vv = (2 * d[2] * nz[0] - d)[None]  # ω_o with mirror direction d about n = z
    cos_o = np.sum(nz * vv, -1)
    _, s1 = lookup_bins(tab, cos_o, 0.1)
    lit = bin_radiance_parts(pref, tab, nz, vv, cos_o, 0.1, s1, light_spread=True)
    ratio = np.asarray(lit.spread) / np.moveaxis(np.asarray(s1), -1, 0)
    assert ratio.max() < 0.5, ratio


def test_constant_environment_at_reads_by_the_poles(constant):
    """L ≡ 1 read within half a texel row of a pole (ω_r ≈ ±z, normals tilted 10–80°, so
    θ_o ≈ 10–80° and ω_o far from the pole) still gives `improved`'s uniform-light model.
    There a bilinear read clamps to the first row: a constant map's read has the mean
    direction m₁ Σ w_t ω_t of its four texel centres, tilted from the read direction d by up
    to π/2h (0.025 at 64 rows), so comparing the light's ⟨ω_o, μ⟩ with m₁⟨ω_o, d⟩ moved the
    bins by up to 3.5e-3 in cos θ₁ (band difference 2.6e-3 at α = 0.02, 1.3e-3 at α = 0.1).
    `bin_radiance_parts` compares it with the read's own geometry
    (`prefilter._read_geometry`): measured shift 0 exactly at α = 0.1 and band differences
    6.1e-5 (α = 0.1) and 2.9e-4 (α = 0.02, where the polar rows' sampled narrow kernels
    leave shifts ≤ 9.3e-4); bounds ≈ measured × 1.6."""
    from thinfilm_jax.realtime.improved import bin_table, lookup_bins
    from thinfilm_jax.shading.methods.improved import bin_radiance_parts

    beta = np.deg2rad(np.arange(10, 81, 10.0))
    az = np.linspace(0.3, 5.9, beta.size)
    n = np.stack([np.sin(beta) * np.cos(az), np.sin(beta) * np.sin(az), np.cos(beta)], -1)
    r = np.stack([0.01 * np.cos(2 * az), 0.01 * np.sin(2 * az), np.ones_like(az)], -1)
    r /= np.linalg.norm(r, axis=-1, keepdims=True)  # within 0.01 rad of the pole
    v = 2 * np.sum(n * r, -1, keepdims=True) * n - r  # ω_o with mirror direction r
    pole = np.where(np.arange(beta.size) % 2, -1.0, 1.0)[:, None]  # north and south
    n, v = n * pole, v * pole
    cos_o = np.sum(n * v, -1)
    tab = bin_table()
    _, sb = lookup_bins(tab, cos_o, 0.1)
    light = bin_radiance_parts(constant[1], tab, n, v, cos_o, 0.1, sb)
    assert np.all(np.asarray(light.cos_shift) == 0.0)
    for alpha, tol in ((0.1, 1e-4), (0.02, 4.5e-4)):
        got = np.asarray(envmap_radiance(FILM, alpha, n, v, constant[1], method="improved"))
        want = np.asarray(patch_radiance(FILM, np.arccos(cos_o), alpha, method="improved"))
        assert np.abs(got - want).max() < tol, (alpha, np.abs(got - want).max())


def test_albedo_table_read_near_grazing():
    """The A(θ_o, α) table every real-time method reads (`prefilter.lookup_albedo`) against
    the quadrature it tabulates (`microfacet.albedo`). Near grazing A is a function of
    cos θ_o / α (a dip to ≈ 0.89 at cos θ_o ≈ α, back to 1 at 90°), so the table's view
    coordinate t = u(1 + k)/(u + k), u = √cos θ_o, k = √α (`albedo_coordinate`) puts the
    dip at the same t for every small α. Measured worst |Δ| on this grid of θ_o ∈ [0, 90°]
    × α ∈ [0.003, 1]: 4.4e-4 (uniform in √cos θ_o, as before: 1.6e-2); bound 7e-4."""
    from thinfilm_jax.shading.prefilter import albedo_table, lookup_albedo

    deg = np.concatenate([np.linspace(0.0, 80.0, 9), np.linspace(80.0, 90.0, 41)[1:]])
    theta = np.minimum(np.deg2rad(deg), np.pi / 2)
    alpha = np.array([0.003, 0.005, 0.008, 0.012, 0.02, 0.05, 0.1, 0.25, 0.6, 1.0])
    want = np.asarray(albedo(theta[:, None], alpha[None, :]))
    pref = PrefilteredEnvMap(None, None, None, jnp.asarray(albedo_table()), None)
    got = np.asarray(lookup_albedo(pref, jnp.asarray(np.cos(theta))[:, None],
                                   jnp.asarray(np.sqrt(alpha))[None, :]))
    assert np.abs(got - want).max() < 7e-4, np.abs(got - want).max()


def test_constant_environment_at_grazing_views_and_small_alpha(constant):
    """The contract of `test_constant_environment_reproduces_patch` (L ≡ 1: a real-time
    method's map path = its uniform-light model, ≤ 2e-3 in band radiance) where it broke:
    θ_o ≥ 86°, α ≤ 0.02, whose A is read near the table's grazing edge. Measured worst
    band difference 64 × 128, normal +z: ideal 3.9e-4, improved 3.7e-4 (before the table's
    view coordinate `prefilter.albedo_coordinate`: 8.9e-3 and 8.3e-3); bound 6.5e-4.
    benchmarks/envmap_consistency.py sweeps map sizes, presets, films and a
    tilted normal."""
    theta = np.deg2rad(np.array([86.0, 88.0, 89.0, 89.5]))
    alpha = np.array([0.005, 0.01, 0.02])[:, None]
    v = view_at(theta, phi=0.3)
    for method in ("ideal", "improved"):
        got = np.asarray(envmap_radiance(FILM, alpha, Z, v, constant[1], method=method))
        want = np.asarray(patch_radiance(FILM, theta, alpha, method=method))
        assert np.abs(got - want).max() < 6.5e-4, (method, np.abs(got - want).max())


def _bare_fresnel(cos_theta, eta=2.0 + 0.5j):
    """Unpolarised R of the air|η interface (Born & Wolf, Principles of Optics, §1.5.2 with
    a complex index, §14.2): the d = 0 film of `FILM`."""
    c = np.asarray(cos_theta, complex)
    ct = np.sqrt(1 - (1 - c * c) / eta**2)
    rs, rp = (c - eta * ct) / (c + eta * ct), (eta * c - ct) / (eta * c + ct)
    return (np.abs(rs) ** 2 + np.abs(rp) ** 2) / 2


def _ggx_patch(theta_o, alpha, refl, n_u=1500, n_phi=720):
    """∫ ρ̃ ⟨n,ω_i⟩ R(⟨h,ω_i⟩) dω_i (SPEC §7) for GGX, height-correlated Smith, by the half
    vector: tan²θ_h = α² u/(1 − u) makes D cos θ_h dω_h = du dφ/2π (Walter et al. 2007,
    eq. 35), so the integrand is G₂ ⟨h,ω_o⟩ R / (cos θ_o cos θ_h), Gauss–Legendre in u,
    midpoints in φ; ω_i = 2⟨h,ω_o⟩h − ω_o below the horizon contributes nothing."""
    x, w = np.polynomial.legendre.leggauss(n_u)
    u, wu = (x + 1) / 2, w / 2
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    t2 = alpha**2 * u / (1 - u)
    ch = 1 / np.sqrt(1 + t2)[:, None]
    sh = np.sqrt(t2)[:, None] * ch
    so, co = np.sin(theta_o), np.cos(theta_o)
    ho = so * sh * np.cos(phi) + co * ch
    ci = 2 * ho * ch - co
    ok = (ci > 0) & (ho > 0)

    def lam(c):  # Smith Λ of GGX
        return (-1 + np.sqrt(1 + alpha**2 * (1 - c * c) / (c * c))) / 2

    g2 = 1 / (1 + lam(co) + lam(np.where(ok, ci, 1.0)))
    f = np.where(ok, g2 * ho / (co * ch) * refl(np.clip(ho, 0, 1)), 0.0)
    return np.sum(f * wu[:, None]) / n_phi


def test_bare_film_under_constant_map(constant):
    """A film of thickness 0 is the bare air|base interface. `patch_radiance` takes its
    exact R₁₃ Ŝ_j(0) (`layer="auto"` → "bare"); the map path used to truncate the film's
    series at M = 2 (the C_m of D = 0 summed to M = 2 is not R₁₃): 4.9e-3 off here for
    `ideal`, 1.6e-3 for `improved`, 2.0e-3 for `filtered`. Which side is right, against a
    NumPy quadrature of the bare microfacet BRDF under uniform light with the textbook
    Fresnel R₁₃ (`_ggx_patch`, `_bare_fresnel`; Ŝ_j(0) = 1 for the unit-area bands): the
    exact patch within 1e-6 (measured 5.2e-8), `ideal`'s patch model A(θ_o, α) R₁₃(cos θ_o)
    within 1e-5 (measured 2.5e-7): the patch side. The map path now takes the bare
    interface too (`SplitSum.bare_cos`, `improved_envmap(layer="bare")`): `ideal` within
    3e-5 of A R₁₃ (measured 1.9e-5, the A table's read), and of their patch models ideal
    1.9e-5, improved 1.5e-5 (bound 3e-5), filtered 2.6e-4 (bound 4.5e-4; its moments read
    near grazing, θ_o = 84°)."""
    bare = Film(0.0, 1.3, 2.0, 0.5)
    theta = np.array([0.6, 1.1, 1.4, np.deg2rad(84.0)])
    alpha = 0.25
    ideal = np.array([_ggx_patch(t, alpha, lambda c: 1.0) * _bare_fresnel(np.cos(t))
                      for t in theta])[:, None]
    exact = np.array([_ggx_patch(t, alpha, _bare_fresnel) for t in theta])[:, None]
    assert np.abs(np.asarray(patch_radiance(bare, theta, alpha)) - exact).max() < 1e-6
    assert np.abs(np.asarray(patch_radiance(bare, theta, alpha, method="ideal"))
                  - ideal).max() < 1e-5
    v = view_at(theta, phi=0.3)
    got = np.asarray(envmap_radiance(bare, alpha, Z, v, constant[1], method="ideal"))
    assert np.abs(got - ideal).max() < 3e-5, np.abs(got - ideal).max()
    for method, tol in (("ideal", 3e-5), ("improved", 3e-5), ("filtered", 4.5e-4)):
        got = np.asarray(envmap_radiance(bare, alpha, Z, v, constant[1], method=method))
        want = np.asarray(patch_radiance(bare, theta, alpha, method=method))
        assert np.abs(got - want).max() < tol, (method, np.abs(got - want).max())
    with pytest.raises(ValueError, match="layer='bare'"):
        envmap_radiance(FILM, alpha, Z, v, constant[1], method="ideal",
                        options=ModelOptions(layer="bare"))


def test_reference_converged_by_refinement(forest):
    """SPEC §9: band error ≤ 1e-3 of the band's largest value; doubling s and n_cos moves
    the result by far less.

    This only compares the reference with a finer run of itself. The reference is checked
    against independent results by: `test_single_bright_texel_is_brdf_times_solid_angle`
    (one lit texel = ρ̃⟨n,ω_i⟩ R(⟨h,ω_i⟩) Ω, the closed form, rtol 2e-3),
    `test_white_furnace` (a near-perfect mirror under L ≡ 1 = the albedo A(θ_o, α) of the
    half-vector quadrature, 2e-4), `test_constant_environment_reproduces_patch` (L ≡ 1 =
    the patch reference of SPEC §7, a half-vector quadrature with exact spectral R, 3e-5),
    `test_mc_converges_to_reference` (16 VNDF Monte Carlo estimates, a different estimator
    and a nearest-texel lookup, mean within 4 standard errors), and
    `test_rotation_about_z_by_whole_columns` (rotating map, normal and view together by
    whole blocks changes nothing, 1e-10)."""
    n = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.8, 0.6]])
    v = np.array([[0.5, 0.0, np.sqrt(0.75)], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    for alpha in (0.08, 0.3):
        s = None
        base = np.asarray(envmap_radiance(FILM, alpha, n, v, forest, subdivisions=s))
        finer = np.asarray(envmap_radiance(FILM, alpha, n, v, forest, n_cos=2048,
                                           subdivisions=2 * _auto(forest, alpha)))
        scale = np.abs(finer).max(axis=0)
        assert np.all(np.abs(base - finer).max(axis=0) <= 1e-3 * scale), (alpha, base, finer)


def _auto(env, alpha):
    from thinfilm_jax.shading.ibl import auto_subdivisions

    return auto_subdivisions(env.shape[0], alpha)


def test_rotation_about_z_by_whole_columns(forest):
    """Rotating map, normal and view together about z by whole 4 × 4 blocks of the adaptive
    reference's grid changes nothing (1e-10; measured at rounding); by 11 columns, which
    moves the light across the blocks, only by the rule's error (≤ 2e-5 of the band
    maximum; measured 4.7e-6)."""
    n = np.array([0.3, -0.4, np.sqrt(0.75)])
    v = np.array([0.0, 0.6, 0.8])
    a = np.asarray(envmap_radiance(FILM, 0.2, n, v, forest))
    for k, rtol in ((12, 1e-10), (11, 2e-5)):
        rot = 2 * np.pi * k / forest.shape[1]
        rz = np.array([[np.cos(rot), -np.sin(rot), 0], [np.sin(rot), np.cos(rot), 0], [0, 0, 1]])
        rolled = EnvMap(jnp.roll(forest.radiance, k, axis=1))
        b = np.asarray(envmap_radiance(FILM, 0.2, rz @ n, rz @ v, rolled))
        assert np.abs(b - a).max() <= rtol * np.abs(a).max(), (k, np.abs(b - a).max() / np.abs(a).max())


def test_single_bright_texel_is_brdf_times_solid_angle():
    h, w = 128, 256
    i, j = 40, 30
    img = np.zeros((h, w, 3))
    img[i, j] = 1.0
    env = load_envmap(img)
    wi = texel_centers(h, w)[i, j]
    om = texel_solid_angles(h, w)[i, j]
    v = view_at(0.7)
    alpha = 0.5
    got = np.asarray(envmap_radiance(FILM, alpha, Z, v, env, subdivisions=2))
    hv = (wi + v) / np.linalg.norm(wi + v)
    want = (np.asarray(brdf_no_fresnel(wi, v, alpha)) * wi[2] * om
            * np.asarray(rgb_reflectance(FILM, float(hv @ wi))))
    np.testing.assert_allclose(got, want, rtol=2e-3)


def test_white_furnace():
    """A near-perfect mirror base (η₂ = η₁ removes the film, κ₃ = 1e4: R = 1 − 4e-8)
    under L ≡ 1 reflects exactly the prefiltered BRDF A(θ_o, α) ≤ 1 in every band."""
    mirror = Film(300.0, 1.0, 1.0, 1e4)
    const = load_envmap(np.ones((32, 64, 3)))
    theta = np.array([0.2, 0.9, 1.3])
    for alpha in (0.15, 0.5, 1.0):
        got = np.asarray(envmap_radiance(mirror, alpha, Z, view_at(theta), const))
        a = np.asarray(albedo(theta, alpha))
        np.testing.assert_allclose(got, np.repeat(a[:, None], 3, 1), atol=2e-4)
        assert np.all(got <= 1)


def test_below_horizon_is_black(forest):
    v = np.array([[0.6, 0.0, -0.8], [1.0, 0.0, 0.0]])
    for method in ("reference", "filtered"):
        assert np.all(np.asarray(envmap_radiance(FILM, 0.3, Z, v, forest, method=method)) == 0)


def test_mc_converges_to_reference(forest):
    """16 independent MC estimates: their mean is within 4 standard errors of the reference,
    and the spread is that of an unbiased 1/√N estimator (no systematic offset)."""
    n = np.array([0.0, 0.3, np.sqrt(0.91)])
    v = view_at(np.array([0.3, 1.0]), phi=2.0)
    ref = np.asarray(envmap_radiance(FILM, 0.3, n, v, forest))
    est = np.stack([np.asarray(envmap_radiance(FILM, 0.3, n, v, forest, method="mc",
                                               n_samples=4096, key=jax.random.key(k)))
                    for k in range(16)])
    se = est.std(axis=0, ddof=1) / 4
    assert np.all(np.abs(est.mean(axis=0) - ref) <= 4 * se + 1e-12)
    assert np.all(se < 0.02 * np.abs(ref).max())


# ----------------------------------------------------------------------------- real time
def test_prefiltered_constant_map_is_exact_and_moments_match_the_lobe():
    const = prefilter_envmap(np.ones((32, 64, 3)))
    np.testing.assert_allclose(const.radiance, 1.0, atol=1e-12)
    np.testing.assert_allclose(const.albedo[0, 0], 1.0, atol=1e-6)  # A(0, α → 0) = 1
    mean = np.asarray(const.moments[..., :3])
    r = texel_centers(32, 64)
    np.testing.assert_allclose(mean[0], r, atol=1e-12)  # level √α = 0: the mirror
    # |μ| shrinks with roughness, monotonically
    norms = np.linalg.norm(mean[:, 16, 0], axis=-1)
    assert np.all(np.diff(norms) < 0) and norms[-1] > 0.5


@pytest.mark.parametrize("per_channel", [False, True])
def test_prefilter_level_is_the_direct_sum_over_texels(per_channel):
    """`prefilter.filter_level` (FFT correlations along φ) against the defining sums over
    every (output, input) texel pair, written out in NumPy: k_α(ω_r, ω_t) = D(cos θ_h)
    G₂(⟨ω_r, ω_t⟩, 1)/4 (closed forms here), weights k Ω_t. Random positive 16 × 64 map, 8 × 16
    output (4 input columns per output column: the azimuth offset's half-texel shift), a
    narrow and a wide lobe; float64: measured ≤ 2.8e-14 of the largest P and ≤ 4.2e-15 in
    the moments, bound 1e-12 (offsets shifted by one texel or by half a texel fail it)."""
    from thinfilm_jax.shading.prefilter import filter_level

    rng = np.random.default_rng(3)
    big = rng.uniform(0.0, 2.0, (16, 64, 3)) ** 4  # a wide dynamic range
    d_in = texel_centers(16, 64).reshape(-1, 3)
    om = texel_solid_angles(16, 64).reshape(-1)
    d_out = texel_centers(8, 16).reshape(-1, 3)
    c = np.clip(d_out @ d_in.T, -1.0, 1.0)
    lum = np.array([0.2126, 0.7152, 0.0722])
    for alpha in (0.05, 0.6):
        a2 = alpha * alpha
        cs = np.where(c > 0, c, 0.0)
        ch2 = (1 + cs) / 2
        ggx_d = a2 / (np.pi * (ch2 * (a2 - 1) + 1) ** 2)
        with np.errstate(divide="ignore"):  # cs = 0: Λ = ∞, G₂ = 0
            lam = (np.sqrt(1 + a2 * (1 - cs**2) / cs**2) - 1) / 2
        g2 = 1 / (1 + lam)  # height-correlated Smith with the other cosine 1 (Λ = 0)
        wgt = np.where(c > 0, ggx_d * g2 / 4, 0.0) * om
        rad = big.reshape(-1, 3)
        p_ref = wgt @ rad / wgt.sum(1, keepdims=True)
        feats = np.concatenate([d_in, d_in**2, d_in * np.roll(d_in, -1, axis=1)], axis=1)
        y = rad if per_channel else rad @ lum[:, None]
        num = np.einsum("on,nk,nf->okf", wgt, y, feats)
        mom_ref = num / (wgt @ y)[..., None]
        p, mom = filter_level(alpha, big, 8, 16, per_channel)
        scale = np.abs(p_ref).max()
        assert np.abs(p.reshape(-1, 3) - p_ref).max() <= 1e-12 * scale, alpha
        mom_ref = mom_ref if per_channel else mom_ref[:, 0]
        assert np.abs(mom.reshape(mom_ref.shape) - mom_ref).max() <= 1e-12, alpha


def test_prefilter_black_map_has_no_light_direction():
    """Where the lobe sees no light the moments are NaN (prefilter_envmap then falls back to
    the lobe's own moments): a black map, and a map lit only in its top row seen from the
    bottom (no texel there within the lobe's hemisphere)."""
    from thinfilm_jax.shading.prefilter import filter_level

    p, mom = filter_level(0.3, np.zeros((8, 32, 3)), 4, 8)
    assert np.all(p == 0) and np.all(np.isnan(mom))
    top = np.zeros((8, 32, 3))
    top[0] = 1.0
    p, mom = filter_level(0.3, top, 4, 8)
    assert np.all(np.isnan(mom[-1])) and not np.any(np.isnan(mom[0]))
    assert np.all(np.abs(p[-1]) < 1e-15) and np.all(p[0] > 0)


def test_prefiltered_map_reused_and_validated(forest, forest_pref):
    pref = forest_pref
    assert isinstance(pref, PrefilteredEnvMap)
    v = view_at(np.array([0.2, 0.9]))
    a = envmap_radiance(FILM, 0.3, Z, v, pref, method="filtered")
    b = envmap_radiance(FILM, 0.3, Z, v, forest, method="filtered")
    np.testing.assert_allclose(a, b, rtol=1e-12)
    with pytest.raises(ValueError, match="pass an EnvMap"):
        envmap_radiance(FILM, 0.3, Z, v, pref, method="reference")


def test_realtime_methods_track_the_reference(forest, forest_pref):
    """Under a real map the split sum itself errs at grazing views (a grey mirror shows it);
    K 29 adds little to that error, while the ideal-direction film adds much more on a
    rough surface (K §4.2)."""
    pref = forest_pref
    theta = np.linspace(0.1, 1.3, 7)
    v = view_at(theta)

    def rel_err(film, method):
        ref = np.asarray(envmap_radiance(film, 0.5, Z, v, forest))
        got = np.asarray(envmap_radiance(film, 0.5, Z, v, pref, method=method))
        return np.abs(got - ref).mean(axis=1) / ref.mean(axis=1)

    split_sum = rel_err(Film(0.0, 1.0, 1.0, 1e4), "ideal")  # R ≈ 1: the split sum alone
    filtered, ideal = rel_err(FILM, "filtered"), rel_err(FILM, "ideal")
    assert np.all(filtered <= split_sum + 0.05), (filtered, split_sum)
    assert np.any(ideal > split_sum + 0.1), (ideal, split_sum)
    assert filtered[:3].mean() < 0.5 * ideal[:3].mean()
    # `improved` reads the radiance of each bin's part of the lobe (docs/improved.md): the
    # film–light coupling the split sum loses; measured 0.04 against filtered's 0.17 on these
    # views (a loose ordering check; the pin is test_improved_pinned_under_an_environment)
    improved = rel_err(FILM, "improved")
    assert improved.mean() < 0.5 * filtered.mean() and improved.max() < 0.1, (improved,
                                                                               filtered)


def _sphere_points(view, rings=(25.0, 50.0, 70.0, 82.0), per_ring=6):
    """Normals of a sphere seen along `view`: its centre and `per_ring` normals on rings at
    the given angles (degrees) from `view` (25 points by default)."""
    e1 = np.cross(view, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(view, e1)
    ns = [view]
    for g in np.deg2rad(rings):
        for p in np.arange(per_ring) * 2 * np.pi / per_ring + g:
            ns.append(np.cos(g) * view + np.sin(g) * (np.cos(p) * e1 + np.sin(p) * e2))
    return np.array(ns)


def test_improved_pinned_under_an_environment(forest, forest_pref):
    """`improved` against the reference on 25 sphere points (view (0.6, 0.3, 0.5)/|·|, rings
    at 25°–82° from it) under the 32 × 64 forest map, α = 0.25, Figure 7 film; ΔE₀₀ with the
    renders' exposure rule (the reference's brightest luminance → 0.9). Measured (float64):
    filtered mean 6.342 / max 25.87; improved 2.872 / 7.937, ratio of the means 0.4528.
    Bounds: measured × 1.25 (mean 3.59, max 9.92, ratio 0.566).
    Mutations: σ_D,k = 0 gives 4.31 / 17.00, ratio 0.68; every bin at the lobe's mean and
    total spread of c (K = 1) 5.29 / 15.63, 0.83; every bin reading the whole lobe's
    radiance instead of its own part's 8.74 / 34.86, 1.38. Each fails every bound.
    (The reference at 32 × 64, s = 4, is converged: `test_reference_converged_by_refinement`.)"""
    from thinfilm_jax.spectral.colorimetry import bands_to_xyz, delta_e2000

    wo = np.array([0.6, 0.3, 0.5]) / np.linalg.norm([0.6, 0.3, 0.5])
    n = _sphere_points(wo)
    ref = np.asarray(envmap_radiance(FILM, 0.25, n, wo, forest))
    e = 0.9 / bands_to_xyz(ref)[:, 1].max()
    de = {m: np.asarray(delta_e2000(
        e * np.asarray(envmap_radiance(FILM, 0.25, n, wo, forest_pref, method=m)), e * ref))
        for m in ("filtered", "improved")}
    ratio = de["improved"].mean() / de["filtered"].mean()
    assert de["improved"].mean() <= 1.25 * 2.872, de
    assert de["improved"].max() <= 1.25 * 7.937, de
    assert ratio <= 1.25 * 0.4528, (ratio, de)


def test_diagonal_equals_cross_band_under_white_light():
    const = prefilter_envmap(np.ones((16, 32, 3)))
    v = view_at(np.array([0.3, 1.2]))
    for method in ("ideal", "filtered"):
        a = envmap_radiance(FILM, 0.3, Z, v, const, method=method)
        b = envmap_radiance(FILM, 0.3, Z, v, const, method=method, cross_band=False)
        # Σ_k R_jk = R_j exactly; the two paths differ only by the interpolation of their
        # Ŝ tables (cross bands vs plain bands), measured ≈ 1e-8
        np.testing.assert_allclose(a, b, atol=1e-6)


def test_per_channel_moments_option(forest, forest_pref):
    lum = forest_pref
    per = prefilter_envmap(forest, moments="per_channel")
    assert per.moments.shape == lum.moments.shape[:-1] + (3, 9)
    v = view_at(np.array([0.4, 1.1]))
    a = np.asarray(envmap_radiance(FILM, 0.4, Z, v, lum, method="filtered"))
    b = np.asarray(envmap_radiance(FILM, 0.4, Z, v, per, method="filtered"))
    assert np.all(np.isfinite(b)) and np.abs(a - b).max() < 0.05 * np.abs(a).max()


def test_float32_realtime_close_to_float64(forest_pref):
    pref64 = forest_pref
    pref32 = pref64.astype(jnp.float32)
    v = view_at(np.array([0.0, 0.5, 1.2, 1.5]))
    for method in ("ideal", "filtered"):
        a = envmap_radiance(FILM, 0.3, Z, v, pref64, method=method)
        b = envmap_radiance(FILM.astype(jnp.float32), jnp.float32(0.3), Z.astype(np.float32),
                            v.astype(np.float32), pref32, method=method)
        assert b.dtype == jnp.float32
        np.testing.assert_allclose(b, a, atol=2e-5)


# ----------------------------------------------------------------------------- gradients
@pytest.fixture(scope="module")
def sunset8():
    """venice_sunset downsampled by 8 and its prefiltered map, built once for the module."""
    env = load_envmap(downsample(load_envmap("venice_sunset"), 8).radiance)
    return env, prefilter_envmap(env)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize("method", ["reference", "filtered", "improved",
                                    "improved, light_spread"])
def test_gradients_finite(method, dtype, sunset8):
    env, pref = sunset8
    pref = pref if method != "reference" else env
    if dtype == jnp.float32:
        pref = pref.astype(jnp.float32)
    v = view_at(np.array([0.0, 0.8, 1.45]), phi=1.0).astype(dtype)
    z = Z.astype(dtype)
    opts = ModelOptions(light_spread=method.endswith("light_spread"))
    method = method.split(",")[0]

    def loss(d, eta, a):
        f = Film(d, eta, dtype(2.0), dtype(0.5))
        return jnp.sum(envmap_radiance(f, a, z, v, pref, method=method, subdivisions=1,
                                       options=opts))

    args = (dtype(500.0), dtype(1.4), dtype(0.3))
    g = jax.grad(loss, argnums=(0, 1, 2))(*args)
    assert all(np.isfinite(x) for x in g)
    if dtype == jnp.float64 and method == "reference":
        for k, h in ((0, 1e-3), (1, 1e-6), (2, 1e-6)):
            up = list(args)
            dn = list(args)
            up[k] += h
            dn[k] -= h
            fd = (loss(*up) - loss(*dn)) / (2 * h)
            np.testing.assert_allclose(g[k], fd, rtol=1e-5, atol=1e-9)


# ----------------------------------------------------------------------------- float32 on GPU
@pytest.mark.parametrize("method", ["reference", "mc", "ideal", "filtered", "improved"])
def test_contractions_state_their_precision(method):
    """No dot_general of the IBL paths may fall back to the backend default (TF32 on GPUs)."""
    from _precision import assert_contractions_precise, count_contractions

    env = load_envmap(np.ones((8, 16, 3)))
    src = prefilter_envmap(env) if method in ("ideal", "filtered", "improved") else env
    if method in ("ideal", "filtered", "improved"):
        src = src.astype(jnp.float32)
    f32 = FILM.astype(jnp.float32)
    v = view_at(np.array([0.2, 1.0])).astype(np.float32)

    def fn(thickness, alpha):
        return envmap_radiance(f32._replace(thickness=thickness), alpha, Z.astype(np.float32),
                               v, src, method=method, subdivisions=1, n_samples=4)

    args = (jnp.float32(500.0), jnp.float32(0.3))
    if method in ("ideal", "filtered", "improved"):  # elementwise only (the LUT read and the
        # moment projection are explicit products: lut.read_parts): nothing to fall back
        assert count_contractions(fn, *args) == 0
    else:
        assert count_contractions(fn, *args) >= 1
    assert_contractions_precise(fn, *args)
    if method == "filtered":  # the prefilter's one device program: elementwise, no contraction
        # (its sums over texels are float64 FFTs and products on the host, prefilter.filter_level)
        from thinfilm_jax.shading.prefilter import _lobe_rows

        rows = [jnp.linspace(0.1, 3.0, n, dtype=jnp.float32) for n in (4, 8, 16)]
        args = (jnp.float32(0.3), jnp.cos(rows[0]), jnp.sin(rows[0]), jnp.cos(rows[1]),
                jnp.sin(rows[1]), jnp.cos(rows[2]))
        assert count_contractions(_lobe_rows, *args) == 0
        assert_contractions_precise(_lobe_rows, *args)


# ----------------------------------------------------------------------------- stiff inputs
STIFF = [  # (thickness, eta_film, eta_base, kappa_base, alpha, view polar angle)
    (0.0, 1.3, 2.0, 0.5, 0.25, 0.5),         # no film
    (1e5, 1.3, 2.0, 0.5, 0.25, 0.5),         # 100 µm film (beyond the Ŝ table: 0)
    (600.0, 1.0, 2.0, 0.0, 0.25, 0.5),       # η₂ = η₁
    (600.0, 1.3, 2.0, 50.0, 0.25, 0.5),      # strongly absorbing base
    (600.0, 1.3, 2.0, 0.5, 1e-4, 0.5),       # near-mirror
    (600.0, 1.3, 2.0, 0.5, 1.0, 0.5),        # roughest
    (600.0, 1.3, 2.0, 0.5, 0.25, 0.0),       # normal view
    (600.0, 1.3, 2.0, 0.5, 0.25, np.pi / 2 - 1e-6),  # grazing view
]


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_stiff_inputs_finite_and_bounded(dtype):
    """Values and gradients finite; under L ≤ max(L) every band stays ≤ A · max(L) ≤ max(L)
    (up to the documented S&B band overshoot of ≈ 1 %)."""
    env = load_envmap(downsample(load_envmap("forest_slope"), 8).radiance)
    pref = prefilter_envmap(env, levels=5)
    if dtype == jnp.float32:
        pref = pref.astype(jnp.float32)
    lmax = float(env.radiance.max())
    cols = [np.asarray(c, float) for c in zip(*STIFF)]
    film = Film(*(c.astype(dtype) for c in cols[:4]))
    alpha, theta = cols[4].astype(dtype), cols[5]
    v = view_at(theta, phi=0.4).astype(dtype)
    for method, src in (("ideal", pref), ("filtered", pref), ("improved", pref),
                        ("reference", env)):
        if method == "reference" and dtype == jnp.float32:
            continue  # the reference is a float64 path
        def total(f, a, method=method, src=src):
            val = envmap_radiance(f, a, Z.astype(dtype), v, src, method=method,
                                  subdivisions=2)
            return jnp.sum(val), val

        # values and gradients from one trace (a separate value call compiled the forward
        # pass a second time)
        (_, val), g = jax.value_and_grad(total, argnums=(0, 1), has_aux=True)(film, alpha)
        val = np.asarray(val)
        assert val.dtype == dtype, method
        assert np.all(np.isfinite(val)) and np.all(val >= -1e-3 * lmax), method
        assert np.all(val <= 1.02 * lmax), method
        assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(g)), method


def test_to_equirect_finite_gradient_at_the_poles():
    """The lookup coordinates of the zenith/nadir have finite derivatives (they used to be
    NaN: hypot and arctan2 at the origin), and v is continuous through the pole."""
    from thinfilm_jax.shading.envmap import to_equirect

    for w in (jnp.asarray([0.0, 0.0, 1.0]), jnp.asarray([0.0, 0.0, -1.0])):
        g = jax.grad(lambda o: jnp.sum(jnp.stack(to_equirect(o))))(w)
        assert np.all(np.isfinite(np.asarray(g))), g
    u, v = to_equirect(jnp.asarray([[0.0, 0.0, 1.0], [1e-9, 0.0, 1.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(np.asarray(v), [0.0, 1e-9 / np.pi, 1.0], atol=1e-15)


def test_float32_arctangent_of_the_lookups():
    """Below float64 the equirect lookup's arctan2 is an octant-reduced odd polynomial
    (`envmap._atan2`, ≈ 10× cheaper than XLA's on a CPU). Against float64 arctan2 over the
    whole circle, the octant edges and axes included: measured max error 2.4e-7 rad on unit
    vectors and 3.0e-7 on random (y, x), as XLA's float32 arctan2 (2.5e-7); asserted 4e-7
    (a degree-5 fit gives 1.8e-6, a lost quadrant π). The polynomial itself, in float64:
    4.07e-8 (asserted 5e-8). The derivative is the exact one (measured within 1.2e-7 of
    d/dt atan2(sin t, cos t) = 1; asserted 3e-7, also at x = 0 and on |x| = |y|, where the
    reduction's own derivative would be 0), and the poles keep finite gradients."""
    from thinfilm_jax.shading.envmap import _atan2, _atan_coefficients, to_equirect

    a = np.linspace(0.0, 1.0, 100_001)
    c = np.asarray(_atan_coefficients())
    assert np.abs(a * np.polyval(c[::-1], a * a) - np.arctan(a)).max() < 5e-8
    t = np.concatenate([np.linspace(-np.pi, np.pi, 20_001), np.arange(-4, 5) * np.pi / 4])
    t32 = jnp.asarray(t, jnp.float32)
    y, x = jnp.sin(t32), jnp.cos(t32)
    ref = np.arctan2(np.asarray(y, np.float64), np.asarray(x, np.float64))
    got = np.asarray(jax.jit(_atan2)(y, x))
    assert got.dtype == np.float32
    assert np.abs(got - ref).max() < 4e-7
    rng = np.random.default_rng(7)
    yx = rng.normal(size=(2, 100_000)).astype(np.float32)
    yx[:, :4] = [[0.0, 0.0, 1.0, -1.0], [0.0, -2.0, 0.0, 0.0]]  # origin and axes
    got = np.asarray(jax.jit(_atan2)(*jnp.asarray(yx)))
    assert np.abs(got - np.arctan2(*yx.astype(np.float64))).max() < 4e-7
    slope = jax.vmap(jax.grad(lambda s: _atan2(jnp.sin(s), jnp.cos(s))))(t32)
    assert np.abs(np.asarray(slope) - 1.0).max() < 3e-7
    d_dx = jax.grad(lambda x: _atan2(jnp.float32(2.0), x))(jnp.float32(0.0))
    assert abs(float(d_dx) + 0.5) < 1e-7  # −y/(x² + y²)
    for w in ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]):
        g = jax.grad(lambda o: jnp.sum(jnp.stack(to_equirect(o))))(jnp.asarray(w, jnp.float32))
        assert np.all(np.isfinite(np.asarray(g))), g


def test_improved_bins_option(constant):
    """`ModelOptions(bins=K)` is the K of `improved` in both entry points: under L ≡ 1 the map
    path with K = 2 equals the uniform-light patch with K = 2 (to the prefilter's accuracy,
    bound as for K = 3 above; measured 4.1e-5), while K = 2 and K = 3 differ by far more
    (measured 9.5e-3: the bins' film terms move, so a K that failed to travel shows). K = 2
    is the cheaper setting (docs/studies/improved.md, "Choosing K")."""
    theta = np.array([0.0, 0.6, 1.1, 1.4])
    v = view_at(theta, phi=0.3)
    two = ModelOptions(shat="lut", bins=2)
    got = np.asarray(envmap_radiance(FILM, 0.25, Z, v, constant[1], method="improved",
                                     options=two))
    want = np.asarray(patch_radiance(FILM, theta, 0.25, method="improved",
                                     options=ModelOptions(bins=2)))
    three = np.asarray(patch_radiance(FILM, theta, 0.25, method="improved"))
    assert np.abs(got - want).max() < 1.2e-4
    assert np.abs(want - three).max() > 1e-3
    with pytest.raises(ValueError, match="bins"):
        patch_radiance(FILM, theta, 0.25, method="improved", options=ModelOptions(bins=0))
    with pytest.raises(ValueError, match="light_spread"):
        envmap_radiance(FILM, 0.25, Z, v, constant[1], method="improved",
                        options=ModelOptions(shat="lut", light_spread="yes"))
    for bad in (0, 1.5, "2"):
        with pytest.raises(ValueError, match="bin_reads"):
            envmap_radiance(FILM, 0.25, Z, v, constant[1], method="improved",
                            options=ModelOptions(shat="lut", bin_reads=bad))


def test_explicit_options_equal_to_the_default_give_the_default_program(constant, monkeypatch):
    """`ModelOptions(bins=3)` spells the default K: `envmap_radiance(..., options=...)` must
    lower to the same program as no options at all (its Ŝ source "auto" is the map's table
    here, not the exact quadrature that made it 9-14x slower a point), while another K is
    another program whose (θ_o, α) tables are built once, not per call. Without timing: the
    lowered HLO text of the real-time entry, and the bin tables' cache counts."""
    from thinfilm_jax.realtime import improved_table
    from thinfilm_jax.realtime.options import check_options
    from thinfilm_jax.shading import ibl

    assert ModelOptions() == ModelOptions(bins=3)
    assert check_options(ModelOptions(), shat_auto="lut") == ibl.REALTIME_OPTIONS.checked()
    assert check_options(ModelOptions()).shat == "exact"  # uniform light: as before
    real = ibl._realtime_jit
    monkeypatch.setattr(ibl, "_realtime_jit", lambda *a: real.lower(*a).as_text())
    # the views of the tests above (test_constant_environment_reproduces_patch,
    # test_improved_bins_option): `lower` reuses their traces of the same programs
    v = view_at(np.array([0.0, 0.6, 1.1, 1.4]), phi=0.3)

    def hlo(**kw):
        return envmap_radiance(FILM, 0.25, Z, v, constant[1], method="improved", **kw)

    default = hlo()
    assert hlo(options=ModelOptions(bins=3)) == default
    assert hlo(options=ModelOptions()) == default
    assert hlo(options=ModelOptions(shat="exact")) != default  # an explicit choice holds
    hlo(options=ModelOptions(bins=2))
    before = improved_table._bin_table_cached.cache_info()
    assert hlo(options=ModelOptions(bins=2)) != default
    after = improved_table._bin_table_cached.cache_info()
    assert after.misses == before.misses and after.hits > before.hits
