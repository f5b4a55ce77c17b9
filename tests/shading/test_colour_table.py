"""Prefiltered colour tables (Kneiphof & Klein 2022; SPEC §11; `shading.colour_table`).

Independent quantities: the exact IBL reference of `envmap_radiance(method="reference")`
(its own texel rule and R_jk table), the GGX albedo of `brdf.microfacet.albedo` through the
patch reference, the Eckart–Young property of the truncated SVD, and refinement of the
table's own quadrature. Maps are 16 × 32 so that a table builds in about a second.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, envmap_radiance
from thinfilm_jax.shading.colour_table import (ColourTable, check_colour_table,
                                               colour_table_radiance, decompose,
                                               decomposition_error, exact_colour_radiance,
                                               prefilter_colour, view_nodes)

FILM = Film(600.0, 1.3, 2.0, 0.5)  # Figure 3/7's film on a metal-like base
ALPHA = 0.3
COLOUR = np.array([0.8, 1.0, 0.45])  # a coloured constant sky: R_jk must couple k to j
SMALL = dict(resolution=(4, 8), n_view=4, n_azimuth=2, brightness_resolution=(8, 16))


def _sky(h=16, w=32):
    """A smooth non-constant map: a bright blob, a blue gradient, a dim ground."""
    th = (np.arange(h) + 0.5) * np.pi / h
    ph = (np.arange(w) + 0.5) * 2 * np.pi / w
    t, p = np.meshgrid(th, ph, indexing="ij")
    blob = 6 * np.exp(-((t - 0.7) ** 2 + (p - 2.0) ** 2) / 0.15)
    sky = np.stack([0.3 + blob, 0.5 + 0.8 * blob, 1.0 + 0.2 * np.cos(p) + 0.5 * blob], -1)
    return np.where((t < np.pi / 2)[..., None], sky, 0.1)


@pytest.fixture(scope="module")
def constant_table():
    return prefilter_colour(np.broadcast_to(COLOUR, (16, 32, 3)), FILM, ALPHA, **SMALL)


@pytest.fixture(scope="module")
def sky_table():
    return prefilter_colour(_sky(), FILM, ALPHA, resolution=(8, 16), n_view=6, n_azimuth=4,
                            rank=2, brightness_resolution=(8, 16))


def _views(thetas):
    return np.stack([np.sin(thetas), np.zeros_like(thetas), np.cos(thetas)], -1)


def test_constant_map_gives_the_albedo_weighted_colour(constant_table):
    """Under a constant map C_jk = ∫ρ̃⟨n,ω_i⟩R_jk / ∫ρ̃⟨n,ω_i⟩ and P = the map's colour, so
    A Σ_k C_jk P_k is the exact reference under that map (up to the tables' quadrature).
    Measured at the view nodes up to 74°: 3.3e-5 of radiances ≈ 0.06; bound 2e-4. Reading
    the diagonal C_jj only (no cross bands) misses by 1.4e-2."""
    thetas = np.arccos(view_nodes(4)[1:] ** 2)  # 74°, 67°... the nodes above grazing
    n = np.array([0.0, 0.0, 1.0])
    v = _views(thetas)
    got = np.asarray(colour_table_radiance(constant_table, n, v, rank=None))
    env = np.broadcast_to(COLOUR, (16, 32, 3))
    ref = np.asarray(envmap_radiance(FILM, ALPHA, np.broadcast_to(n, v.shape), v, env))
    assert np.abs(got - ref).max() < 2e-4
    c = np.asarray(constant_table.full).reshape(*constant_table.full.shape[:-1], 3, 3)
    assert np.abs(np.einsum("hwvjj->hwvj", c) - c.sum(-1)).max() > 1e-3  # R_jk is not diagonal


def test_full_rank_reproduces_the_3d_table(sky_table):
    """rank = n_view: the decomposition is the table (to rounding), and trilinear reads of the
    3D table equal the factor reads at any direction (both are linear interpolations)."""
    us, vs = decompose(sky_table.full, None)
    assert np.abs(np.einsum("hwrc,vrc->hwvc", us, vs) - np.asarray(sky_table.full)).max() < 1e-12
    full = ColourTable(jnp.asarray(us), jnp.asarray(vs), sky_table.full, sky_table.brightness,
                       sky_table.albedo, material=sky_table.material, envmap=sky_table.envmap)
    from _geometry import front_facing

    n, v = front_facing(np.random.default_rng(0), 32)
    a = colour_table_radiance(full, n, v, rank=0)
    b = colour_table_radiance(full, n, v, rank=None)
    assert np.abs(np.asarray(a - b)).max() < 1e-12


def test_decomposition_error_falls_with_rank(sky_table):
    """Eckart–Young: the best rank-r error is non-increasing in r and 0 at full rank; the
    rank-1 form (K&K 2022's) carries a real error on a non-constant map."""
    errs = []
    for r in (1, 2, 3, 6):
        us, vs = decompose(sky_table.full, r)
        errs.append(float(np.abs(np.einsum("hwrc,vrc->hwvc", us, vs)
                                 - np.asarray(sky_table.full)).max()))
    assert all(b <= a + 1e-15 for a, b in zip(errs, errs[1:]))
    assert errs[0] > 1e-4 and errs[-1] < 1e-12
    assert decomposition_error(sky_table) == pytest.approx(errs[1], rel=1e-9)


def test_table_converges_under_refinement():
    """Azimuth nodes 2 → 4 → 8 → 16 (periodic trapezoid rule in ψ, geometric: measured
    1.6e-2, 3.0e-3, 4.3e-4 of C ≈ 0.1–0.25) and sub-texel nodes s = 2 → 4 → 8 on the
    16 × 32 map (texels 0.2 rad, wider than α: measured 3.7e-3, 5.9e-5). Bounds: the last
    step < 1e-3 and at most a fifth of the step before."""
    kw = dict(resolution=(4, 8), n_view=3, brightness_resolution=(8, 16), rank=None)
    tabs = [np.asarray(prefilter_colour(_sky(), FILM, ALPHA, n_azimuth=a, **kw).full)
            for a in (2, 4, 8, 16)]
    steps = [np.abs(b - a).max() for a, b in zip(tabs, tabs[1:])]
    assert steps[-1] < 1e-3 and steps[-1] < steps[-2] / 5 and steps[-2] < steps[-3] / 3
    subs = [np.asarray(prefilter_colour(_sky(), FILM, ALPHA, n_azimuth=4, subdivisions=s,
                                        **kw).full) for s in (2, 4, 8)]
    s1, s2 = (np.abs(b - a).max() for a, b in zip(subs, subs[1:]))
    assert s2 < 1e-3 and s2 < s1 / 5


def test_ceiling_equals_the_reference_under_a_constant_map(constant_table):
    """The exact-colour ceiling with the table's brightness: under a constant map its colour is
    the albedo-weighted colour at every point (no table), so it equals the reference."""
    thetas = np.deg2rad([0.0, 35.0, 60.0])
    n = np.broadcast_to([0.0, 0.0, 1.0], (3, 3))
    env = np.broadcast_to(COLOUR, (16, 32, 3))
    got = np.asarray(exact_colour_radiance(FILM, ALPHA, n, _views(thetas), env,
                                           constant_table))
    ref = np.asarray(envmap_radiance(FILM, ALPHA, n, _views(thetas), env))
    assert np.abs(got - ref).max() < 2e-4


def test_method_in_envmap_radiance_and_checks(sky_table):
    """`envmap_radiance(..., table, method="colour_table")` reads the table; the film, α,
    observer, map and table contents are checked (SPEC §11)."""
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    v = np.array([0.0, 0.0, 1.0])
    out = envmap_radiance(FILM, ALPHA, n, v, sky_table, method="colour_table")
    assert out.shape == (2, 3) and np.all(np.asarray(out[0]) > 0) and np.all(out[1] == 0)
    with pytest.raises(ValueError, match="another material.*thickness"):
        envmap_radiance(Film(601.0, 1.3, 2.0, 0.5), ALPHA, n, v, sky_table,
                        method="colour_table")
    with pytest.raises(ValueError, match="another material.*alpha"):
        envmap_radiance(FILM, 0.31, n, v, sky_table, method="colour_table")
    with pytest.raises(ValueError, match="observer"):
        envmap_radiance(FILM, ALPHA, n, v, sky_table, method="colour_table",
                        observer="cie1964_10")
    with pytest.raises(ValueError, match="ColourTable"):
        envmap_radiance(FILM, ALPHA, n, v, _sky(), method="colour_table")
    with pytest.raises(ValueError, match="method='colour_table'"):
        envmap_radiance(FILM, ALPHA, n, v, sky_table, method="filtered")
    bad = ColourTable(sky_table.colour.at[0, 0, 0, 0].set(jnp.nan), sky_table.view,
                      sky_table.full, sky_table.brightness, sky_table.albedo,
                      material=sky_table.material, envmap=sky_table.envmap)
    with pytest.raises(ValueError, match="NaN"):
        envmap_radiance(FILM, ALPHA, n, v, bad, method="colour_table")
    with pytest.raises(ValueError, match="another environment map"):
        check_colour_table(sky_table, FILM, ALPHA, envmap=_sky() * 1.01)
    check_colour_table(sky_table, FILM, ALPHA, envmap=_sky())
    with pytest.raises(ValueError, match="one homogeneous material"):
        prefilter_colour(_sky(), Film([600.0, 700.0], 1.3, 2.0, 0.5), ALPHA, **SMALL)
    with pytest.raises(ValueError, match="alpha"):
        prefilter_colour(_sky(), FILM, 1.5, **SMALL)
    with pytest.raises(ValueError, match="resolution"):
        prefilter_colour(_sky(), FILM, ALPHA, resolution=(4, 4))


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_gradients_are_finite_at_the_singular_points(sky_table, dtype):
    """d L / d(view, table) finite at normal view (ω_r at the equirect pole), grazing and
    below the horizon; float32 values within 1e-5 of float64.

    The four views in one call (one backward pass instead of four): the points are
    independent, so row i of d/d(view) is point i's own gradient, and d/d(table) is the sum
    of the four points' gradients, which is finite only if each of them is (a NaN or an
    infinite term makes the sum NaN or infinite)."""
    tab = jax.tree.map(lambda x: x.astype(dtype), sky_table)
    n = jnp.asarray([0.0, 0.0, 1.0], dtype)

    def f(view, table):
        return jnp.sum(colour_table_radiance(table, n, view))

    theta = np.array([0.0, 0.7, np.pi / 2 - 1e-4, np.pi / 2 + 0.1])
    v = jnp.asarray(np.stack([np.sin(theta), np.zeros(4), np.cos(theta)], -1), dtype)
    gv, gt = jax.grad(f, argnums=(0, 1))(v, tab)
    assert gv.shape == (4, 3)
    assert all(np.all(np.isfinite(np.asarray(g))) for g in [gv, *jax.tree.leaves(gt)])
    v = _views(np.deg2rad([0.0, 20.0, 50.0, 80.0]))
    lo = np.asarray(colour_table_radiance(tab, n, jnp.asarray(v, dtype)))
    hi = np.asarray(colour_table_radiance(sky_table, np.array([0.0, 0.0, 1.0]), v))
    assert np.abs(lo - hi).max() < 1e-5


# ----------------------------------------------------------------------------- car paints
def _paint(colour):
    from thinfilm_jax.brdf.carpaint import car_paint

    return car_paint(0.1, [0.5, 0.3], [0.2, 0.45], [0.9, 0.5], colour, 1.5)


@pytest.fixture(scope="module")
def pearl_table():
    from thinfilm_jax.brdf.carpaint import pearlescent_colour

    paint = _paint(pearlescent_colour(Film(120.0, 2.6, 1.56, 0.0, 1.5), n_d=31))
    return paint, prefilter_colour(np.broadcast_to(COLOUR, (16, 32, 3)), paint, **SMALL)


def test_paint_constant_colour_is_the_brightness_split_sum():
    """χ ≡ c: the table is c exactly (the brightness cancels in the ratio) and the shading is
    c ⊙ Σ_b A_b P_b plus the uncoloured coat: the brightness-only split sum."""
    from thinfilm_jax.brdf.carpaint import coat_reflectance, plain_colour
    from thinfilm_jax.shading.envmap import lookup_bilinear

    c = np.array([0.7, 0.3, 0.2])
    paint = _paint(plain_colour(c))
    table = prefilter_colour(_sky(), paint, **SMALL)
    assert np.abs(np.asarray(table.full) - c).max() < 1e-12
    assert table.terms == ("specular", "specular", "diffuse", "coat")
    n, v = np.array([0.0, 0.0, 1.0]), _views(np.deg2rad([0.0, 40.0, 70.0]))
    got = np.asarray(colour_table_radiance(table, n, v))
    white = prefilter_colour(_sky(), _paint(plain_colour([1.0, 1.0, 1.0])), **SMALL)
    b = np.asarray(colour_table_radiance(white, n, v))  # the brightness alone (χ = 1)
    # the coat's share: its albedo row (F(θ_o) on the √cos grid) times the mirror map
    coat = np.asarray(white.albedo)[:, -1]
    f = np.interp(np.sqrt(v[:, 2]), np.linspace(0, 1, coat.size), coat)[:, None]
    assert np.abs(f[:, 0] - np.asarray(coat_reflectance(paint, v[:, 2]))).max() < 1e-3
    refl = 2 * v[:, 2:3] * n - v
    mirror = np.asarray(lookup_bilinear(white.brightness[-1], refl))
    assert np.abs(got - (c * (b - f * mirror) + f * mirror)).max() < 1e-12
    assert np.abs(got - c * b).max() > 1e-3  # the coat is not coloured


def test_paint_constant_map_gives_the_patch_radiance(pearl_table):
    """Under a constant map a paint's table gives its exact patch radiance (`carpaint_ibl.
    paint_patch_radiance`: coat F plus ∫ f cos) per channel: C_j = ∫ f_b χ_j cos / ∫ f_b cos
    and Σ_b A_b = ∫ f_b cos (the lobe albedos). Measured at the view nodes up to 74°:
    ≤ 2e-4 (the 16 × 32 map's texel rule); a table without the coat (or with χ at θ_d = 0
    only) misses by more than 1e-2."""
    from thinfilm_jax.shading.carpaint_ibl import paint_patch_radiance

    paint, table = pearl_table
    thetas = np.arccos(view_nodes(4)[1:] ** 2)
    got = np.asarray(colour_table_radiance(table, np.array([0.0, 0.0, 1.0]), _views(thetas)))
    exact = np.asarray(paint_patch_radiance(paint, thetas)) * COLOUR
    assert np.abs(got - exact).max() < 5e-4


def test_paint_table_checks(pearl_table, sky_table):
    paint, table = pearl_table
    check_colour_table(table, paint)
    other = paint._replace(coat_ior=jnp.asarray(1.6, paint.coat_ior.dtype))
    with pytest.raises(ValueError, match="another material"):
        check_colour_table(table, other)
    with pytest.raises(ValueError, match="for a film, not a car paint"):
        check_colour_table(sky_table, paint)
    with pytest.raises(ValueError, match="car paint, not a film"):
        envmap_radiance(FILM, ALPHA, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]),
                        table, method="colour_table")
    with pytest.raises(ValueError, match="alpha=None"):
        prefilter_colour(_sky(), paint, 0.3, **SMALL)
    with pytest.raises(ValueError, match="films only|film's table"):
        colour_table_radiance(table, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]),
                              brightness=object())
