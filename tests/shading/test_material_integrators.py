"""The exact integrators of any composed `Material` (thinfilm_jax/shading/material_patch.py,
material_ibl.py): uniform light (SPEC §7 conventions) and environment maps (SPEC §9).

Independent checks: the film's own references (`patch_radiance(method="reference")`, the
exhaustive texel rule of `ibl_reference`), closed forms (Lambert: ρ), two different quadratures
of one integral (the half-vector rule against the ω_i product rule), the white map as the
uniform light, and Monte Carlo within its standard error."""

import jax.numpy as jnp
import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.brdf.microfacet import view_direction
from thinfilm_jax.shading.ibl_reference import exact_radiance
from thinfilm_jax.shading.material_ibl import material_envmap_radiance
from thinfilm_jax.shading.material_patch import (_sphere_part, material_patch_radiance,
                                                 specular_only)

FILM = tf.Film(600.0, 1.3, 2.0, 0.5)  # Kneiphof et al. 2019, Figure 7
THETA = np.array([0.0, 0.3, 0.8, 1.2, 1.45])
Z = np.array([0.0, 0.0, 1.0])


def _film_material(alpha):
    return tf.Material(tf.ggx_lobe(alpha), tf.film_fresnel(FILM), tf.no_diffuse())


def _cook_torrance(alpha=0.3):
    return tf.Material(tf.beckmann_lobe(alpha, "v_cavity"), tf.schlick_fresnel([0.9, 0.6, 0.3]),
                       tf.lambert_diffuse([0.2, 0.3, 0.1]))


def _sphere(material, theta_o, q=(128, 256)):
    """The ω_i product rule alone (what anisotropic lobes and diffuse terms use)."""
    t = jnp.asarray(theta_o)
    return np.asarray(_sphere_part(material, t, jnp.asarray([1.0, 0.0, 0.0]), *q))


@pytest.fixture(scope="module")
def points():
    """6 random shading points, one grazing view (85°)."""
    rng = np.random.default_rng(3)
    n = rng.normal(size=(6, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    t = rng.normal(size=(6, 3))
    t -= np.sum(t * n, -1, keepdims=True) * n
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    th = np.array([1.48, 0.2, 0.5, 0.8, 1.0, 1.2])[:, None]
    return n, np.cos(th) * n + np.sin(th) * t


@pytest.fixture(scope="module")
def small_map():
    return np.random.default_rng(7).uniform(0.0, 2.0, (16, 32, 3))


@pytest.mark.parametrize("alpha", [0.1, 0.4])
def test_ggx_film_patch_is_the_film_reference(alpha):
    """GGX + thin film (height-correlated Smith) through the material path equals
    `patch_radiance(film, θ_o, α, method="reference")` (measured ≤ 5e-16; bound 1e-10)."""
    got = material_patch_radiance(_film_material(alpha), THETA)
    ref = tf.patch_radiance(FILM, THETA, alpha, method="reference")
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10)


def test_lambert_under_uniform_light_is_its_albedo():
    """∫ ρ/π ⟨n,ω_i⟩ dω_i = ρ for every view (measured ≤ 6e-14 by the ω_i rule)."""
    rho = np.array([0.2, 0.5, 0.8])
    mat = tf.Material(tf.no_specular(), tf.no_fresnel(), tf.lambert_diffuse(rho))
    got = material_patch_radiance(mat, THETA)
    np.testing.assert_allclose(got, np.broadcast_to(rho, got.shape), rtol=0, atol=1e-13)


def test_anisotropic_rule_matches_half_vector_rule_at_equal_alphas():
    """Anisotropic GGX at α_x = α_y = 0.3 by the ω_i product rule against isotropic GGX by
    the half-vector rule, film Fresnel. Convergence of the ω_i rule in (n_θ, n_φ) measured at
    θ_o = 1.45 (the worst view): 1.5e-5, 4.1e-7, 2.2e-9 at (64, 128), (128, 256), (256, 512);
    ≤ 4e-11 at every θ_o ≤ 1.2 from (128, 256) on. Bounds: 1e-9 (θ_o ≤ 1.2), 2e-6 (1.45)."""
    ref = np.asarray(material_patch_radiance(_film_material(0.3), THETA))
    aniso = tf.Material(tf.ggx_aniso_lobe(0.3, 0.3), tf.film_fresnel(FILM), tf.no_diffuse())
    got = np.asarray(material_patch_radiance(aniso, THETA))
    err = np.abs(got - ref).max(axis=-1)
    assert np.all(err[:4] < 1e-9) and err[4] < 2e-6, err


@pytest.mark.parametrize("which", ["cook_torrance", "blinn_phong"])
def test_half_vector_reweighting_matches_the_sphere_rule(which):
    """Lobes whose masking is not the proxy's (Beckmann + V-cavity, Blinn–Phong + V-cavity at
    s = 20, integrated on the Smith-Beckmann proxy's nodes reweighted by f/ρ̃_p) against the ω_i
    product rule on the same specular lobe. The V-cavity's min(1, ·) kinks make both rules
    converge slowly: at θ_o = 0 the half-vector rule moves 2.0e-5, 5.0e-6 from (48, 48) to
    (96, 96) to (192, 192), the ω_i rule 6.5e-6, 1.5e-6 from (128, 256) to (256, 512) to
    (512, 1024). Compared here at (192, 192) against (256, 512): measured ≤ 2.4e-7
    (Blinn–Phong, θ_o = 0), bound 1e-6 (2e-6 of the values)."""
    mat = _cook_torrance() if which == "cook_torrance" else tf.Material(
        tf.blinn_phong_lobe(20.0), tf.schlick_fresnel(0.5), tf.no_diffuse())
    spec = specular_only(mat)
    got = np.asarray(material_patch_radiance(spec, THETA[:4], quadrature=(192, 192)))
    ref = np.stack([_sphere(spec, t, (256, 512)) for t in THETA[:4]])
    assert np.abs(got - ref).max() < 1e-6, np.abs(got - ref).max()


def test_ggx_film_envmap_is_the_exhaustive_reference(points, small_map):
    """GGX + film (cross bands R_jk, SPEC §9) through `material_envmap_radiance` equals the
    exhaustive texel rule of `envmap_radiance`'s reference (same nodes, same R_jk table) on a
    random 16 × 32 map, a grazing view included: measured 5.6e-17 against values up to 0.19;
    bound 1e-12. The diagonal approximation (cross_band=False) differs by 2.6e-2 here
    (asserted > 1e-3), so the bound sees the cross bands."""
    n, v = points
    mat = _film_material(0.3)
    k = len(n)
    film = tf.Film(*(jnp.full(k, float(x)) for x in FILM))
    ref = exact_radiance(film, jnp.full(k, 0.3), jnp.asarray(n), jnp.asarray(v),
                         tf.load_envmap(small_map), method="reference",
                         observer="stiles_burch_1959_10", cross_band=True,
                         arithmetic="complex", one_film=True, exhaustive=True)
    got = material_envmap_radiance(mat, n, v, small_map)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    diag = material_envmap_radiance(mat, n, v, small_map, cross_band=False)
    assert np.abs(np.asarray(diag) - np.asarray(ref)).max() > 1e-3


def test_white_map_is_the_uniform_light():
    """A white map is the uniform unit light: Lambert gives ρ (to 1e-12; the texel rule
    integrates ρ/π⟨n,ω⟩ over the hemisphere's texels: measured 2e-15) and Cook–Torrance +
    Lambert equals `material_patch_radiance` at (192, 192) to the texel rule's error at the
    V-cavity's kinks (16 × 32, s = 6: measured 5.8e-6, 6.5e-6, 2.3e-5, 1.5e-4 at θ_o = 0,
    0.3, 0.8, 1.2; bound 3e-4, i.e. 3e-4 of the values)."""
    white = np.ones((16, 32, 3))
    lam = tf.Material(tf.no_specular(), tf.no_fresnel(), tf.lambert_diffuse(0.6))
    th = THETA[:4]
    views = view_direction(th)
    got = material_envmap_radiance(lam, Z, views, white)
    np.testing.assert_allclose(got, 0.6, rtol=0, atol=1e-12)
    ct = _cook_torrance()
    got = np.asarray(material_envmap_radiance(ct, Z, views, white))
    ref = np.asarray(material_patch_radiance(ct, th, quadrature=(192, 192)))
    assert np.abs(got - ref).max() < 3e-4, np.abs(got - ref).max()


def test_mc_within_four_standard_errors(points, small_map):
    """Cook–Torrance (Beckmann + V-cavity + Schlick) over Lambert: cosine-weighted MC
    (2¹⁶ samples, fixed key) against the texel reference, every band of 6 points within
    4 standard errors (measured |z| ≤ 2.03)."""
    n, v = points
    ct = _cook_torrance()
    ref = np.asarray(material_envmap_radiance(ct, n, v, small_map))
    mc, se = material_envmap_radiance(ct, n, v, small_map, method="mc", return_stderr=True)
    z = (np.asarray(mc) - ref) / np.asarray(se)
    assert np.all(np.asarray(se) > 0) and np.all(np.abs(z) < 4), z


def test_gradient_through_the_material_is_finite_differences():
    """∂L/∂d of a GGX + film + Lambert patch (jax.grad through the `Material` pytree) against
    a central difference, step 1e-3 nm: measured relative difference 1e-9; bound 1e-6."""
    import jax

    def total(d):
        mat = tf.Material(tf.ggx_lobe(0.3), tf.film_fresnel(tf.Film(d, 1.3, 2.0, 0.5)),
                          tf.lambert_diffuse(0.1))
        return jnp.sum(material_patch_radiance(mat, jnp.array([0.3, 1.0])))

    g = float(jax.grad(total)(600.0))
    fd = float((total(600.001) - total(599.999)) / 0.002)
    assert np.isfinite(g) and abs(g - fd) <= 1e-6 * abs(fd), (g, fd)
