"""`envmap_radiance(method="khr")`: glTF `KHR_materials_iridescence` under an environment map
(SPEC §9, §10; `thinfilm_jax.shading.ibl`).

The method is `ideal`'s split sum with the extension's `F_iridescence` (linear Rec. 709) at h = n in
place of the film's band reflectance, applied per channel to the map's RGB: L = A(θ_o, α) · F(cos
θ_o) ⊙ P(ω_r, α), returned in the observer's bands like every method (`colorimetry.rec709_to_bands`;
`bands_to_rec709` gives the RGB back). Checked against independent quantities: the patch model's
quadrature albedo A = Σ w (`brdf.microfacet.patch_quadrature`, not the map's albedo table),
`khr_bands`, and the exact spectral bands (`rgb_reflectance`, Airy). One 8 × 16 map prefiltered with
the default albedo table (64 × 33) and 3 levels: the films, roughnesses and view angles of a test
are one batch of shading points (one compilation per method).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, ModelOptions, patch_radiance, prefilter_envmap, rgb_reflectance
from thinfilm_jax.brdf.microfacet import patch_quadrature
from thinfilm_jax.shading.ibl import envmap_radiance
from thinfilm_jax.shading.prefilter import lookup_albedo, lookup_radiance
from thinfilm_jax.spectral.colorimetry import bands_to_rec709, rec709_to_bands
from thinfilm_jax.spectral.khr import khr_bands

# a metal-like base (κ₃ > 0: enters through F₀ only), a soap-like film on glass, a high-index
# film on a low-index base (φ₂₃ = π): 3 films × 2 roughnesses × 4 view angles = 24 points
FILMS = [(600.0, 1.3, 2.0, 0.5), (400.0, 1.33, 1.5, 0.0), (250.0, 1.8, 1.2, 0.0)]
ALPHAS = (0.1, 0.6)
THETAS = np.deg2rad([0.0, 30.0, 60.0, 80.0])
COLOUR = np.array([0.8, 1.0, 0.45])  # a coloured constant sky (linear Rec. 709)


def _points():
    f, a, t = np.meshgrid(np.arange(len(FILMS)), np.arange(len(ALPHAS)), np.arange(len(THETAS)),
                          indexing="ij")
    fields = np.asarray(FILMS)[f.ravel()]
    film = Film(*(fields[:, i] for i in range(4)))
    alpha = np.asarray(ALPHAS)[a.ravel()]
    theta = THETAS[t.ravel()]
    view = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    return film, alpha, theta, view


def _sky(h=8, w=16):
    """A non-constant sky: bright zenith, an azimuthal lobe, a bluish floor."""
    rows = np.linspace(2.0, 0.3, h)[:, None, None]
    cols = 1.0 + 0.5 * np.cos(np.linspace(0, 2 * np.pi, w, endpoint=False))[None, :, None]
    return rows * cols * np.array([1.0, 0.8, 0.5]) + np.array([0.05, 0.1, 0.3])


KW = dict(levels=3, resolution=(8, 16))


@pytest.fixture(scope="module")
def maps():
    """Prefiltered white, coloured and non-constant 8 × 16 maps (same albedo table)."""
    return {"white": prefilter_envmap(np.ones((8, 16, 3)), **KW),
            "colour": prefilter_envmap(np.ones((8, 16, 3)) * COLOUR, **KW),
            "sky": prefilter_envmap(_sky(), **KW),
            "sky32": prefilter_envmap(_sky(), dtype=np.float32, **KW)}


@pytest.fixture(scope="module")
def batch():
    film, alpha, theta, view = _points()
    albedo = np.array([float(jnp.sum(patch_quadrature(t, a).weight))
                       for t, a in zip(theta, alpha)])
    return film, alpha, theta, view, albedo


N = np.array([0.0, 0.0, 1.0])


def test_white_map_is_patch_khr(maps, batch):
    """A constant white map is the uniform light of `patch_radiance(method="khr")`, and a
    constant coloured one multiplies it channel by channel (the Rec. 709 F times the map's
    RGB, no band mixing: what glTF engines compute; the outputs are bands, so the product is
    checked on their RGB, `bands_to_rec709`).

    Measured max |envmap − patch| = 1.5e-4 (at α = 0.1, θ_o = 80°; relative 3.0e-4: the
    prefiltered albedo table's interpolation, the same for every film); asserted 2.5e-4.
    The coloured map agrees with white ⊙ colour to 1.4e-16 (asserted 1e-12; the prefilter is
    linear); a cross-band (R_jk) mix is not: `ideal`'s is off by 0.037 on the same map.
    """
    film, alpha, theta, view, albedo = batch
    white = np.asarray(envmap_radiance(film, alpha, N, view, maps["white"], method="khr"))
    patch = np.asarray(patch_radiance(film, theta, alpha, method="khr"))
    assert np.abs(white - patch).max() <= 2.5e-4
    np.testing.assert_allclose(bands_to_rec709(patch), albedo[:, None] * np.asarray(
        khr_bands(film, jnp.asarray(np.cos(theta)))), rtol=0, atol=1e-12)
    colour = np.asarray(envmap_radiance(film, alpha, N, view, maps["colour"], method="khr"))
    np.testing.assert_allclose(bands_to_rec709(colour), bands_to_rec709(white) * COLOUR,
                               rtol=0, atol=1e-12)


def test_khr_minus_ideal_is_reflectance_difference(maps, batch):
    """Under a constant map, envmap khr − envmap ideal = A · (F_khr − R_exact) at h = n, F_khr
    taken to the bands (`rec709_to_bands`),
    R_exact the spectral Airy bands at cos θ_o (`rgb_reflectance`, SPEC §2), with `ideal` run
    with the exact Ŝ and M = 6 (its BB17 sum then converged: M = 2 leaves 2.3e-3).

    Measured max residual 2.9e-5 (the albedo table's 3e-4 relative error of A times the
    difference) against differences of up to 0.097 (in the bands; 0.124 when khr's RGB was
    subtracted from the bands unconverted); asserted 5e-5, and the differences themselves
    ≥ 0.05 (khr is not the exact film).
    """
    film, alpha, theta, view, albedo = batch
    khr = np.asarray(envmap_radiance(film, alpha, N, view, maps["white"], method="khr"))
    ideal = np.asarray(envmap_radiance(film, alpha, N, view, maps["white"], method="ideal",
                                       options=ModelOptions(shat="exact", terms=6)))
    c = np.cos(theta)
    want = albedo[:, None] * (rec709_to_bands(np.asarray(khr_bands(film, jnp.asarray(c))))
                              - np.asarray(rgb_reflectance(film, c)))
    assert np.abs(want).max() > 0.05
    assert np.abs((khr - ideal) - want).max() <= 5e-5


def test_any_map_is_read_at_the_mirror_direction(maps):
    """Under a non-constant map khr reads the prefiltered radiance `ideal` reads (mirror
    direction, level √α): per point and channel, L_khr(map) · L_ideal(white) =
    L_ideal(map) · L_khr(white) = A² F R P with `ideal`'s diagonal (per-channel) form and
    khr's output in RGB (`bands_to_rec709`).
    Tilted normals and views; agreement to 1e-12 relative (measured 4e-16); the sky's
    radiance differs from white's by up to 0.44 there."""
    rng = np.random.default_rng(3)
    normal = rng.normal(size=(32, 3)) * [0.4, 0.4, 1.0] + [0.0, 0.0, 1.0]
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    view = rng.normal(size=(32, 3)) * [0.6, 0.6, 1.0] + [0.0, 0.0, 1.0]
    view /= np.linalg.norm(view, axis=-1, keepdims=True)
    film, alpha = Film(250.0, 1.8, 1.2), 0.3  # its F_khr > 0.018 at every angle (no clamp)
    run = {(m, k): np.asarray(envmap_radiance(film, alpha, normal, view, maps[k], method=m,
                                              cross_band=False))
           for m in ("khr", "ideal") for k in ("sky", "white")}
    run["khr", "sky"], run["khr", "white"] = (bands_to_rec709(run["khr", k]) for k in
                                              ("sky", "white"))
    lhs = run["khr", "sky"] * run["ideal", "white"]
    rhs = run["ideal", "sky"] * run["khr", "white"]
    assert np.all(lhs[np.sum(normal * view, -1) > 0] > 0)  # every visible point lit
    np.testing.assert_allclose(lhs, rhs, rtol=1e-12, atol=0)
    # the map matters: a white map's light is not the sky's
    assert np.abs(run["khr", "sky"] - run["khr", "white"]).max() > 0.1


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_gradients_finite(maps, dtype):
    """Gradients in d, η₂, η₃, κ₃, α and the view are finite in float32 and float64, at
    normal view (cos θ_o = 1), grazing and below the horizon (0 there); in float64 d's
    derivative matches a central difference (step 1e-3 nm; measured relative 1.4e-9,
    asserted 1e-6), float32's follows float64's to 1e-4 relative (measured 4e-6)."""
    th = np.deg2rad([0.0, 40.0, 89.0, 120.0])
    view = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    fields = [np.full(4, v) for v in (420.0, 1.4, 1.9, 0.3)] + [np.full(4, 0.35), view]

    def loss(d, eta2, eta3, kappa3, a, v, pref):
        v = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
        out = envmap_radiance(Film(d, eta2, eta3, kappa3), a, jnp.asarray(N, v.dtype), v,
                              pref, method="khr")
        return jnp.sum(out * jnp.asarray([1.0, 2.0, 3.0], v.dtype))

    grad = jax.grad(loss, argnums=tuple(range(6)))
    pref = maps["sky" if dtype == np.float64 else "sky32"]
    grads = [np.asarray(g) for g in grad(*(x.astype(dtype) for x in fields), pref)]
    for g in grads:
        assert g.dtype == dtype and np.all(np.isfinite(g))
    assert np.all(grads[0][3] == 0) and np.all(grads[5][3] == 0)  # below the horizon
    assert np.all(grads[0][:3] != 0)
    if dtype == np.float64:
        h = 1e-3
        fd = [(loss(fields[0] + h * e, *fields[1:], pref)
               - loss(fields[0] - h * e, *fields[1:], pref)) / (2 * h) for e in np.eye(4)]
        np.testing.assert_allclose(grads[0], np.asarray(fd), rtol=1e-6, atol=1e-12)
    else:
        g64 = np.asarray(grad(*fields, maps["sky"])[0])
        np.testing.assert_allclose(grads[0], g64, rtol=1e-4, atol=1e-9)


def test_below_horizon_black(maps):
    """⟨n, ω_o⟩ ≤ 0 gives 0 (a normal facing away, an exactly grazing view)."""
    film = Film(400.0, 1.33, 1.5)
    normal = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    view = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    out = np.asarray(envmap_radiance(film, 0.3, normal, view, maps["white"], method="khr"))
    assert np.all(out[:2] == 0) and np.all(out[2] > 0)


@pytest.mark.parametrize("observer", ["stiles_burch_1959_10", "cie_1931_2"])
def test_output_is_the_observers_bands(maps, observer):
    """khr returns the observer's bands, as every method of `envmap_radiance`: glTF's linear
    Rec. 709 A · F ⊙ P, built here from the map's own tables (`lookup_albedo`,
    `lookup_radiance` at the mirror direction) and the formula (`khr_bands`), taken to the
    bands by `colorimetry.rec709_to_bands` (host NumPy, the colour-science conversion);
    measured agreement 1e-16, asserted 1e-13. Either observer is accepted (both have three
    bands), and the bands differ from the RGB."""
    rng = np.random.default_rng(5)
    normal = rng.normal(size=(6, 3)) * [0.2, 0.2, 0.3] + [0.0, 0.0, 1.0]
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    film, alpha = Film(np.linspace(250.0, 650.0, 6), 1.4, 1.7), 0.3
    view = np.array([0.3, 0.0, 0.954]) / np.linalg.norm([0.3, 0.0, 0.954])
    got = np.asarray(envmap_radiance(film, alpha, normal, view, maps["sky"], method="khr",
                                     observer=observer))
    co = np.sum(normal * view, -1)
    assert np.all(co > 0.3)  # every point faces the eye
    refl = 2 * co[:, None] * normal - view
    sqa = jnp.full(6, np.sqrt(alpha))
    rgb = (np.asarray(lookup_albedo(maps["sky"], jnp.asarray(co), sqa))[:, None]
           * np.asarray(lookup_radiance(maps["sky"], jnp.asarray(refl), sqa))
           * np.asarray(khr_bands(film, jnp.asarray(co))))
    np.testing.assert_allclose(got, rec709_to_bands(rgb, observer), rtol=0, atol=1e-13)
    assert np.abs(got - rgb).max() > 1e-3


def _sun_map(h=16, w=32):
    """A dim bluish sky with a one-texel sun (0.004 sr at 16 × 32) at the zenith row."""
    sun = np.full((h, w, 3), 0.1) * np.array([1.0, 0.9, 1.2])
    sun[0, 5] = np.array([500.0, 450.0, 380.0])
    return sun


def test_map_with_suns_shades_them(maps):
    """A map prefiltered with suns split off (`prefilter_envmap(sources=...)`, one map for
    every real-time method) is shaded, not refused: the residual map as before plus the suns
    through the GGX lobe times the same F_iridescence(cos θ_o) (`sources.source_light`).
    Independent fact: the split is energy-exact, so under a rough lobe (α = 0.6, where the
    prefiltered sun and the cap see nearly the same lobe) khr on the split map agrees with khr
    on the unsplit map: measured max relative difference 0.030 where the split map gives
    5.5–8.3× the residual alone (which is off by 0.88: what ignoring the suns would give);
    asserted 0.15 and > 2×. The sun's term is one per-channel factor on F: the RGB ratio
    split/residual is the same for two films (to 1e-12). The derivative in α through the suns'
    caps matches a central difference (float64; measured relative 5e-10, asserted 1e-6)."""
    kw = dict(levels=5, resolution=(16, 32))
    split = prefilter_envmap(_sun_map(), sources=1, **kw)
    plain = prefilter_envmap(_sun_map(), **kw)
    assert split.has_sources
    residual = split._replace(sources=None)
    th = np.deg2rad([0.0, 20.0, 40.0])
    view = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    sun_dir = np.asarray(split.sources.direction[0])
    normal = sun_dir + view  # the sun in the mirror direction
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    out = {}
    for name, pref in (("split", split), ("plain", plain), ("residual", residual)):
        for i, film in enumerate((Film(400.0, 1.33, 1.5), Film(650.0, 1.8, 1.2))):
            out[name, i] = bands_to_rec709(np.asarray(envmap_radiance(
                film, 0.6, normal, view, pref, method="khr")))
    for i in (0, 1):
        rel = np.abs(out["split", i] - out["plain", i]) / out["plain", i]
        assert rel.max() <= 0.15, rel.max()
        assert np.all(out["split", i] > 2 * out["residual", i])
    np.testing.assert_allclose(out["split", 0] / out["residual", 0],
                               out["split", 1] / out["residual", 1], rtol=1e-12)

    def loss(a):  # the suns' lobe term is differentiable: α's derivative against a difference
        return jnp.sum(envmap_radiance(Film(400.0, 1.33, 1.5), a, normal, view, split,
                                       method="khr"))

    g, h = float(jax.grad(loss)(0.6)), 1e-5
    assert np.isfinite(g) and g != 0
    np.testing.assert_allclose(g, (loss(0.6 + h) - loss(0.6 - h)) / (2 * h), rtol=1e-6)


def test_render_column_in_the_render_observers_bands(maps, batch):
    """`thinfilm-jax render --method khr` (`render.study_scenes`): the column shades under a
    render observer other than the default and its values are that observer's bands, as
    every method's: the default observer's output taken back to RGB (`bands_to_rec709`) and
    to the render observer's bands (`rec709_to_bands`) is the same; a flat reflectance's RGB
    (R, R, R) maps to bands (R, R, R) in both observers (the map's white, equal-energy light,
    is the bands' white). `render_one` itself is not run here: its sharded compilation and a
    second observer's prefilter cost ~20 s on this machine."""
    from thinfilm_jax.render.study_scenes import shade_block

    for obs in ("stiles_burch_1959_10", "cie_1931_2"):
        np.testing.assert_allclose(rec709_to_bands(np.full((2, 3), 0.3), obs), 0.3, atol=1e-12)
    film, alpha, theta, view, _ = batch
    normal = np.broadcast_to(N, view.shape)
    got = shade_block(film, normal, alpha, view, maps["white"], method="khr",
                 observer="cie_1931_2", options=ModelOptions(), subdivisions=None)
    default = envmap_radiance(film, alpha, N, view, maps["white"], method="khr")
    want = rec709_to_bands(bands_to_rec709(np.asarray(default)), "cie_1931_2")
    np.testing.assert_allclose(np.asarray(got), want, rtol=0, atol=1e-14)
