"""`brdf.carpaint`: the AxF-CPA2-style car paint against independent transcriptions (GGX
material, Fresnel equations in angles, Snell's law in angles), reciprocity, the coat's exact
factor T_i T_o/η² (the mirror limit and the white furnace), the lobe albedos against a
brute-force ω_i rule, the pigment tables, gradients (float64 and float32, θ = 0 and grazing),
and the errors at the public boundary."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import thinfilm_jax as tf
from thinfilm_jax.brdf import carpaint as C
from thinfilm_jax.brdf import material as M
from thinfilm_jax.brdf import microfacet
from thinfilm_jax.spectral.reflectance import bare_bands, rgb_reflectance

N = np.array([0.0, 0.0, 1.0])
WHITE = C.plain_colour([1.0, 1.0, 1.0])


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_dirs(rng, k, grazing=False):
    """k unit directions on the upper hemisphere (some at h = n and near grazing)."""
    th = rng.uniform(0, np.pi / 2 * 0.999, k)
    if grazing:
        th[:3] = [0.0, np.pi / 2 - 1e-4, np.pi / 2 - 1e-7]
    ph = rng.uniform(0, 2 * np.pi, k)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


def test_reciprocal_with_and_without_coat():
    rng = np.random.default_rng(0)
    wi, wo = random_dirs(rng, 200, True), random_dirs(rng, 200)
    for name, make in C.PAINTS.items():
        for eta in (1.0, 1.5, 2.2):
            p = make(coat_ior=eta)
            a, b = C.paint_brdf(p, wi, wo, N), C.paint_brdf(p, wo, wi, N)
            np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-300, err_msg=name)
            assert np.all(np.isfinite(a)) and np.all(a >= 0)


def test_no_coat_is_the_ggx_material():
    """One lobe, no coat: the library's `Material` (GGX, height-correlated Smith) with no
    Fresnel (F₀ = 1), with Schlick, and with a Lambert term."""
    rng = np.random.default_rng(1)
    wi, wo = random_dirs(rng, 300, True), random_dirs(rng, 300)
    wi[0] = wo[0] = N  # h = n, θ = 0
    for alpha in (0.05, 0.3, 1.0):
        paint = C.car_paint(0.0, [1.0], [alpha], [1.0], WHITE, 1.0)
        mat = M.Material(M.ggx_lobe(alpha), M.no_fresnel(), M.no_diffuse())
        np.testing.assert_allclose(C.paint_brdf(paint, wi, wo, N), M.brdf_value(mat, wi, wo, N),
                                   rtol=1e-13, atol=0)
    paint = C.car_paint(0.4, [1.0], [0.2], [0.3], WHITE, 1.0)
    mat = M.Material(M.ggx_lobe(0.2), M.schlick_fresnel(0.3), M.lambert_diffuse(0.4))
    np.testing.assert_allclose(C.paint_brightness(paint, wi, wo, N),
                               M.brdf_value(mat, wi, wo, N)[:, 0], rtol=1e-13, atol=0)


# ----------------------------------------------------------------------------- transcription
def fresnel_angles(theta, eta):
    """Unpolarised Fresnel reflectance air | η in angles (Born & Wolf §1.5.2)."""
    tt = np.arcsin(np.sin(theta) / eta)
    if eta == 1.0:
        return np.zeros_like(theta)
    with np.errstate(invalid="ignore"):
        rs = -np.sin(theta - tt) / np.sin(theta + tt)
        rp = np.tan(theta - tt) / np.tan(theta + tt)
    out = 0.5 * (rs**2 + rp**2)
    return np.where(theta == 0, ((eta - 1) / (eta + 1)) ** 2, out)


def refract_angles(w, eta):
    """ω' by Snell's law in angles: same azimuth, sin θ' = sin θ/η."""
    th, ph = np.arccos(np.clip(w[..., 2], -1, 1)), np.arctan2(w[..., 1], w[..., 0])
    tp = np.arcsin(np.sin(th) / eta)
    return np.stack([np.sin(tp) * np.cos(ph), np.sin(tp) * np.sin(ph), np.cos(tp)], -1), th


def brightness_transcribed(p, wi, wo):
    eta = float(p.coat_ior)
    wi_, ti = refract_angles(wi, eta)
    wo_, to = refract_angles(wo, eta)
    h = unit(wi_ + wo_)
    ci, co, ch, dh = wi_[:, 2], wo_[:, 2], h[:, 2], np.sum(h * wi_, -1)
    out = float(p.diffuse) / np.pi * np.ones_like(ci)
    for s, a, f0 in zip(*(np.asarray(x) for x in (p.lobe_weight, p.lobe_alpha, p.lobe_f0))):
        d = a**2 / (np.pi * (ch**2 * (a**2 - 1) + 1) ** 2)
        lam = lambda c: (np.sqrt(1 + a**2 * (1 - c**2) / c**2) - 1) / 2  # noqa: E731
        g2 = 1 / (1 + lam(ci) + lam(co))
        out = out + s * d * g2 * (f0 + (1 - f0) * (1 - dh) ** 5) / (4 * ci * co)
    t = (1 - fresnel_angles(ti, eta)) * (1 - fresnel_angles(to, eta))
    return t * out / eta**2, np.arccos(np.clip(ch, -1, 1)), np.arccos(np.clip(dh, -1, 1))


@pytest.mark.parametrize("eta", [1.0, 1.5, 1.8])
def test_brightness_and_colour_against_angles(eta):
    """The value in angles: Snell's law, the Fresnel equations, GGX and Smith written out; the
    colour table read at the refracted (θ_h', θ_d') — a table bilinear in them (θ_h, θ_d,
    θ_h θ_d in the three channels) is reproduced exactly by bilinear interpolation."""
    rng = np.random.default_rng(2)
    wi, wo = random_dirs(rng, 200), random_dirs(rng, 200)
    g = np.linspace(0, np.pi / 2, 7)
    th, td = np.meshgrid(g, g, indexing="ij")
    table = np.stack([th, td, th * td], -1)
    p = C.car_paint(0.3, [0.5, 0.7], [0.08, 0.4], [0.9, 0.04], table, eta)
    ref, t_h, t_d = brightness_transcribed(p, wi, wo)
    np.testing.assert_allclose(C.paint_brightness(p, wi, wo, N), ref, rtol=1e-10)
    col = C.paint_colour(p, wi, wo, N)
    np.testing.assert_allclose(col, np.stack([t_h, t_d, t_h * t_d], -1), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(C.paint_brdf(p, wi, wo, N), ref[:, None] * col, rtol=1e-12)


def test_constant_colour_scales_the_brightness():
    rng = np.random.default_rng(3)
    wi, wo = random_dirs(rng, 50), random_dirs(rng, 50)
    c = np.array([0.2, 0.5, 0.9])
    p = C.car_paint(0.1, [0.6, 0.3], [0.1, 0.5], [0.8, 0.1], C.plain_colour(c, 5, 9), 1.5)
    np.testing.assert_allclose(C.paint_brdf(p, wi, wo, N),
                               C.paint_brightness(p, wi, wo, N)[:, None] * c, rtol=1e-14)


def test_coat_reflectance_is_the_fresnel_equations():
    c = np.cos(np.linspace(0, 1.57, 50))
    for eta in (1.0, 1.33, 1.5, 2.4):
        p = C.car_paint(0.0, [1.0], [0.5], [1.0], WHITE, eta)
        exact = bare_bands(tf.Film(0.0, 1.0, eta, 0.0, 1.0), c)[:, 0]
        np.testing.assert_allclose(C.coat_reflectance(p, c), exact, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(C.coat_reflectance(p, c) + C.coat_transmittance(p, c), 1.0,
                                   rtol=1e-15)
    assert float(C.coat_reflectance(p, 0.0)) == 1.0  # grazing: the coat is a mirror
    assert float(C.coat_reflectance(p, -0.1)) == 0.0


# ----------------------------------------------------------------------------- energy
def test_mirror_limit_fixes_the_coat_factor():
    """A near-mirror base under the coat reflects T(θ_o)² of a uniform light (in through the
    coat, mirrored, out again at the same angle): the solid-angle factor is exactly 1/η²
    (η⁰ or 1/η⁴ would be off by η² = 2.25)."""
    eta, alpha = 1.5, 0.002
    p = C.car_paint(0.0, [1.0], [alpha], [1.0], WHITE, eta)
    th = np.array([0.0, 0.6, 1.0])
    t_o = 1 - fresnel_angles(th, eta)
    th_in = np.arcsin(np.sin(th) / eta)
    expect = t_o**2 * microfacet.albedo(th_in, alpha)
    got = C.lobe_albedo(p, np.cos(th))[:, 0]  # measured −2.6e-5, −7.2e-5, −5.1e-4
    np.testing.assert_allclose(got, expect, rtol=1e-3)


def test_white_furnace_at_most_one():
    """coat F + Σ lobe albedos ≤ 1 at every view (grazing included) for a + Σ s ≤ 1, F₀ = 1;
    one lobe, no coat: the GGX albedo of `microfacet.albedo`."""
    th = np.concatenate([np.linspace(0, np.pi / 2, 13), [1.56, np.pi / 2 - 1e-6]])
    c = np.cos(th)
    for eta in (1.0, 1.2, 1.5, 2.5):
        p = C.car_paint(0.2, [0.5, 0.3], [0.04, 0.7], [1.0, 1.0], WHITE, eta)
        total = C.coat_reflectance(p, c) + C.lobe_albedo(p, c).sum(-1)
        assert np.all(total <= 1 + 1e-12), (eta, total.max())
        assert np.all(total >= 0)
    for alpha in (0.02, 0.3, 1.0):
        p = C.car_paint(0.0, [1.0], [alpha], [1.0], WHITE, 1.0)
        np.testing.assert_allclose(C.lobe_albedo(p, c[:-1])[:, 0],
                                   microfacet.albedo(th[:-1], alpha,
                                                     quadrature=C.DEFAULT_PAINT_QUADRATURE),
                                   rtol=1e-12, atol=1e-14)


def _gl(n, a, b, panels):
    x, w = np.polynomial.legendre.leggauss(n)
    e = np.linspace(a, b, panels + 1)
    return (np.concatenate([(x + 1) / 2 * (hi - lo) + lo for lo, hi in zip(e[:-1], e[1:])]),
            np.concatenate([w / 2 * (hi - lo) for lo, hi in zip(e[:-1], e[1:])]))


def brute_albedo(p, th_o):
    """∫ paint_brightness cos θ_i dω_i by a product rule over the *outside* hemisphere
    (θ_i split at θ_o; φ_i ∈ [0, π] doubled, panels ending at the mirror azimuth)."""
    parts = [_gl(16, 0, th_o, 24)] if th_o > 0 else []
    parts.append(_gl(16, th_o, np.pi / 2, 24))
    th = np.concatenate([q[0] for q in parts])
    wt = np.concatenate([q[1] for q in parts]) * np.sin(th) * np.cos(th)
    ph, wp = _gl(16, 0, np.pi, 24)
    d = np.stack([np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph),
                  np.cos(th)[:, None] + 0 * ph], -1).reshape(-1, 3)
    wo = np.array([np.sin(th_o), 0.0, np.cos(th_o)])
    f = np.asarray(C.paint_brightness(p, d, wo, N))
    return 2 * float(np.sum(f * (wt[:, None] * wp[None]).reshape(-1)))


@pytest.mark.parametrize("alpha,eta", [(0.3, 1.5), (0.15, 1.5), (0.3, 1.0)])
def test_lobe_albedo_against_brute_force(alpha, eta):
    """The half-vector rule cut at the refraction cone against a brute-force rule over the
    outside ω_i (measured agreement 1e-15); the Lambert term against scipy's quad of
    a/η² T_o ∫ T(c) 2c dc."""
    p = C.car_paint(0.0, [1.0], [alpha], [0.5], WHITE, eta)
    for th_o in (0.0, 0.7, 1.3):
        a = float(C.lobe_albedo(p, np.cos(th_o))[0])
        assert abs(a - brute_albedo(p, th_o)) < 1e-10
    q = C.car_paint(0.7, [0.0], [0.5], [0.0], WHITE, eta)
    for th_o in (0.0, 0.9, 1.5):
        t_o = 1 - fresnel_angles(np.array(th_o), eta)
        val = 1.0 if eta == 1.0 else integrate.quad(
            lambda c: (1 - fresnel_angles(np.arccos(c), eta)) * 2 * c, 0, 1, epsabs=1e-14,
            epsrel=1e-14)[0]
        assert abs(float(C.lobe_albedo(q, np.cos(th_o))[-1]) - 0.7 / eta**2 * t_o * val) < 1e-12


def test_lobe_albedo_converged():
    """Default orders against 4× the orders: ≤ 1e-10 (measured ≤ 4e-11) for α down to 0.05,
    views to 1.55 rad."""
    c = np.cos(np.array([0.0, 0.5, 1.0, 1.3, 1.5, 1.55]))
    for eta in (1.0, 1.5):
        p = C.car_paint(0.3, [0.3, 0.3, 0.3], [0.05, 0.15, 0.4], [0.5, 0.9, 0.2], WHITE, eta)
        fine = C.lobe_albedo(p, c, quadrature=(256, 256), diffuse_quadrature=(64, 64))
        np.testing.assert_allclose(C.lobe_albedo(p, c), fine, rtol=0, atol=1e-10)
    assert C.lobe_albedo(p, np.zeros((2, 3))).shape == (2, 3, 4)
    assert float(np.abs(C.lobe_albedo(p, -0.5)).max()) == 0.0


# ----------------------------------------------------------------------------- pigments
def test_pearlescent_is_the_film_at_theta_d():
    film = tf.Film(120.0, 2.6, 1.56, 0.0, 1.5)
    tab = C.pearlescent_colour(film, n_h=3, n_d=10)
    assert tab.shape == (3, 10, 3)
    # θ_d = 0 is the film at normal incidence: the same sum, compiled for another shape
    # (measured to differ by 4e-19, one ulp of the smallest channel, on an AVX2 CPU)
    np.testing.assert_allclose(np.asarray(tab[:, 0]),
                               np.broadcast_to(rgb_reflectance(film, 1.0), (3, 3)), rtol=1e-14,
                               atol=0)
    td = np.linspace(0, np.pi / 2, 10)
    np.testing.assert_allclose(tab[1], np.maximum(rgb_reflectance(film, np.cos(td)), 0),
                               rtol=1e-14)
    assert np.all(np.asarray(tab) >= 0)


def test_metallic_is_the_bare_conductor():
    tab = C.metallic_colour(n_d=5)
    eta, kappa, e1 = C.AL_ETA, C.AL_KAPPA, 1.5
    r0 = ((eta - e1) ** 2 + kappa**2) / ((eta + e1) ** 2 + kappa**2)
    np.testing.assert_allclose(tab[0, 0], r0, rtol=1e-12)
    np.testing.assert_allclose(tab[0, -1], 1.0, rtol=1e-7)  # grazing: R → 1 (bare_bands 2e-8)
    td = np.linspace(0, np.pi / 2, 5)[:-1]
    nt = eta + 1j * kappa  # the Fresnel equations with a complex index (Born & Wolf §14.2)
    c = np.cos(td)
    ct = np.sqrt(1 - (e1 * np.sin(td) / nt) ** 2)
    rs = (e1 * c - nt * ct) / (e1 * c + nt * ct)
    rp = (nt * c - e1 * ct) / (nt * c + e1 * ct)
    r = 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)
    np.testing.assert_allclose(tab[1, :-1], np.stack([r] * 3, -1), rtol=1e-12)
    np.testing.assert_allclose(C.plain_colour([0.1, 0.2, 0.3], 4, 5)[3, 4], [0.1, 0.2, 0.3])


# ----------------------------------------------------------------------------- gradients
def _loss(paint, wi, wo):
    return (jnp.sum(C.paint_brdf(paint, wi, wo, N.astype(wi.dtype)))
            + jnp.sum(C.lobe_albedo(paint, wo[:, 2], quadrature=(12, 12),
                                    diffuse_quadrature=(8, 8))))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("eta", [1.0, 1.5])
def test_gradients_finite(dtype, eta):
    """d/d(every leaf) finite at θ = 0 (ω_i = ω_o = n, h = n), near grazing and in between."""
    wi = unit(np.array([[0, 0, 1.0], [np.sin(1.5707), 0, np.cos(1.5707)], [0.3, 0.2, 0.9]]))
    wo = unit(np.array([[0, 0, 1.0], [-np.sin(1.2), 0, np.cos(1.2)],
                        [np.sin(1.5707), 0.0, np.cos(1.5707)]]))
    g_h = np.linspace(0, 1, 4)
    table = 0.2 + 0.5 * np.stack([*np.meshgrid(g_h, g_h, indexing="ij"), np.ones((4, 4))], -1)
    p = C.car_paint(0.2, [0.5, 0.3], [0.1, 0.6], [0.9, 0.1], table.astype(dtype), eta)
    p = C.CarPaint(*(jnp.asarray(x, dtype) for x in p))
    g = jax.grad(_loss)(p, jnp.asarray(wi, dtype), jnp.asarray(wo, dtype))
    for k, v in g._asdict().items():
        assert v.dtype == dtype and np.all(np.isfinite(np.asarray(v))), k
    assert float(jnp.abs(g.coat_ior)) > 0 if eta > 1 else True
    assert float(jnp.abs(g.colour).sum()) > 0


def test_gradients_match_finite_differences():
    rng = np.random.default_rng(4)
    wi, wo = jnp.asarray(random_dirs(rng, 20)), jnp.asarray(random_dirs(rng, 20))
    table = rng.uniform(0.1, 1.0, (5, 6, 3))
    p0 = C.car_paint(0.2, [0.5, 0.3], [0.1, 0.6], [0.9, 0.1], table, 1.5)
    g = jax.grad(_loss)(p0, wi, wo)
    for k, idx in (("coat_ior", ()), ("lobe_alpha", (0,)), ("lobe_f0", (1,)),
                   ("lobe_weight", (1,)), ("diffuse", ()), ("colour", (2, 3, 1))):
        eps = 1e-6
        x = np.asarray(getattr(p0, k), float)
        hi, lo = x.copy(), x.copy()
        hi[idx] += eps
        lo[idx] -= eps
        fd = (_loss(p0._replace(**{k: jnp.asarray(hi)}), wi, wo)
              - _loss(p0._replace(**{k: jnp.asarray(lo)}), wi, wo)) / (2 * eps)
        np.testing.assert_allclose(np.asarray(getattr(g, k))[idx], fd, rtol=1e-6, err_msg=k)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_gradient_of_film_thickness(dtype):
    n = N.astype(dtype)
    wi = jnp.asarray(unit([0.3, 0.1, 0.9]), dtype)
    wo = jnp.asarray(unit([-0.5, 0.0, 0.7]), dtype)

    def loss(d):
        film = tf.Film(d, jnp.asarray(2.6, dtype), jnp.asarray(1.56, dtype),
                       jnp.asarray(0.0, dtype), jnp.asarray(1.5, dtype))
        col = C.pearlescent_colour(film, n_d=16)
        p = C.CarPaint(*(jnp.asarray(x, dtype) for x in C.car_paint(
            0.1, [1.0], [0.2], [1.0], WHITE, 1.5)))._replace(colour=col)
        return jnp.sum(C.paint_brdf(p, wi, wo, n))

    d0 = jnp.asarray(120.0, dtype)
    g = jax.grad(loss)(d0)
    assert g.dtype == dtype and np.isfinite(float(g)) and float(g) != 0
    if dtype == np.float64:
        fd = (loss(d0 + 1e-4) - loss(d0 - 1e-4)) / 2e-4
        np.testing.assert_allclose(float(g), float(fd), rtol=1e-6)


def test_float32_agrees_with_float64():
    rng = np.random.default_rng(5)
    wi, wo = random_dirs(rng, 50), random_dirs(rng, 50)
    p = C.PAINTS["pearlescent"]()
    p32 = C.CarPaint(*(jnp.asarray(x, np.float32) for x in p))
    a = C.paint_brdf(p, wi, wo, N)
    b = C.paint_brdf(p32, wi.astype(np.float32), wo.astype(np.float32), N.astype(np.float32))
    assert b.dtype == np.float32
    np.testing.assert_allclose(b, a, rtol=2e-3, atol=1e-6)


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize("kwargs,match", [
    (dict(diffuse=-0.1), "diffuse"),
    (dict(lobe_weight=[-1.0, 0.5]), "lobe_weight"),
    (dict(lobe_alpha=[0.0, 0.5]), "lobe_alpha"),
    (dict(lobe_alpha=[1.5, 0.5]), "lobe_alpha"),
    (dict(lobe_f0=[np.nan, 0.5]), "lobe_f0"),
    (dict(lobe_f0=[0.5]), "lobe_f0"),
    (dict(colour=np.ones((4, 4))), "colour"),
    (dict(colour=np.ones((1, 4, 3))), "colour"),
    (dict(colour=-np.ones((2, 2, 3))), "colour"),
    (dict(coat_ior=0.9), "coat_ior"),
    (dict(coat_ior=[1.5, 1.5]), "coat_ior"),
    (dict(diffuse=[0.1]), "diffuse"),
])
def test_bad_input(kwargs, match):
    args = dict(diffuse=0.1, lobe_weight=[0.5, 0.5], lobe_alpha=[0.1, 0.5],
                lobe_f0=[0.5, 0.5], colour=np.ones((2, 2, 3)), coat_ior=1.5)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        C.car_paint(**args)


def test_bad_directions_and_pigments():
    p = C.PAINTS["plain"]()
    with pytest.raises(ValueError, match="wi"):
        C.paint_brdf(p, [0.0, 0.0, 2.0], N, N)
    with pytest.raises(ValueError, match="wo"):
        C.paint_brdf(p, N, [0.0, 0.0], N)
    with pytest.raises(TypeError, match="paint"):
        C.paint_brdf((1, 2), N, N, N)
    with pytest.raises(ValueError, match="rgb"):
        C.plain_colour([0.1, 0.2])
    with pytest.raises(ValueError, match="n_d"):
        C.metallic_colour(n_d=1)
    with pytest.raises(ValueError, match="thickness"):
        C.pearlescent_colour(tf.Film(-1.0, 2.6, 1.56, 0.0, 1.5))
    with pytest.raises(ValueError, match="quadrature"):
        C.lobe_albedo(p, 0.5, quadrature=(0, 4))


def test_patch_nodes_shapes_and_sums():
    p = C.PAINTS["metallic"]()
    c = np.cos(np.array([[0.2, 1.0]]))
    wl, w_l, wd, w_d = C.paint_patch_nodes(p, c, quadrature=(8, 6), diffuse_quadrature=(4, 4))
    assert wl.shape == (1, 2, 3, 48, 3) and w_l.shape == (1, 2, 3, 48)
    assert wd.shape == (1, 2, 16, 3) and w_d.shape == (1, 2, 16)
    np.testing.assert_allclose(np.linalg.norm(wl, axis=-1), 1.0, atol=1e-12)
    alb = C.lobe_albedo(p, c, quadrature=(8, 6), diffuse_quadrature=(4, 4))
    np.testing.assert_allclose(np.concatenate([w_l.sum(-1), w_d.sum(-1)[..., None]], -1), alb,
                               rtol=1e-13)
