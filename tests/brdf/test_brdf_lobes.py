"""The classic lobes term by term (thinfilm_jax.brdf.ndf, .masking, .diffuse).

References are independent transcriptions of the published formulas in NumPy, written in
angles (θ, φ, tan θ, cos(φ_i − φ_o)) where the library works with dot products and local
components; normalisation by quadrature; the published limits (Oren–Nayar σ = 0 is Lambert,
Ashikhmin–Shirley n_u = n_v is Phong, anisotropic GGX α_x = α_y is GGX); gradients against
central finite differences and finite at the singular points (h = n, grazing, α_x ≠ α_y).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from thinfilm_jax.brdf import diffuse, masking, ndf

TOL = 1e-12  # float64 agreement with the transcriptions (relative); measured ≤ 3e-14
RNG_SEED = 20240601


# ------------------------------------------------------------------------- transcriptions (angles)
def ref_ggx(th, a):  # Walter et al. 2007, Eq. 33
    return a**2 / (np.pi * np.cos(th) ** 4 * (a**2 + np.tan(th) ** 2) ** 2)


def ref_beckmann(th, a):  # Walter et al. 2007, Eq. 25
    return np.exp(-np.tan(th) ** 2 / a**2) / (np.pi * a**2 * np.cos(th) ** 4)


def ref_ggx_aniso(th, ph, ax, ay):  # Heitz 2014, Eq. 85 in slopes: tan θ (cos φ/α_x, sin φ/α_y)
    t2 = np.tan(th) ** 2 * (np.cos(ph) ** 2 / ax**2 + np.sin(ph) ** 2 / ay**2)
    return 1 / (np.pi * ax * ay * np.cos(th) ** 4 * (1 + t2) ** 2)


def ref_blinn_phong(th, s):
    return (s + 2) / (2 * np.pi) * np.cos(th) ** s


def ref_as(th, ph, nu, nv, k):  # Ashikhmin & Shirley 2000, Eq. 4/6 (k = 1), projected (k = 2)
    return np.sqrt((nu + k) * (nv + k)) / (2 * np.pi) * np.cos(th) ** (
        nu * np.cos(ph) ** 2 + nv * np.sin(ph) ** 2)


def ref_lambda(th, a, kind, ph=0.0, ay=None):
    """Smith Λ (Walter 2007 Eq. 27/34; Heitz 2014 Eq. 80/86 with the projected roughness)."""
    tan = np.tan(th)
    if kind == "beckmann":
        x = 1 / (a * tan)
        return (special.erf(x) - 1) / 2 + np.exp(-x * x) / (2 * x * np.sqrt(np.pi))
    if ay is not None:
        a = np.sqrt(np.cos(ph) ** 2 * a**2 + np.sin(ph) ** 2 * ay**2)
    return (-1 + np.sqrt(1 + a**2 * tan**2)) / 2


def vec(th, ph):
    th, ph = np.broadcast_arrays(th, ph)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


@pytest.fixture(scope="module")
def pairs():
    """Seeded directions above the horizon (θ ∈ (0, 88°)), n = z, t = x; their half vectors."""
    rng = np.random.default_rng(RNG_SEED)
    k = 300
    ti, to = rng.uniform(0.01, 1.53, k), rng.uniform(0.01, 1.53, k)
    pi_, po = rng.uniform(0, 2 * np.pi, k), rng.uniform(0, 2 * np.pi, k)
    wi, wo = vec(ti, pi_), vec(to, po)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    th, ph = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2]), np.arctan2(h[:, 1], h[:, 0])
    return dict(ti=ti, to=to, pi=pi_, po=po, wi=wi, wo=wo, h=h, th=th, ph=ph, rng=rng,
                a=rng.uniform(0.05, 1.0, k), ay=rng.uniform(0.05, 1.0, k),
                nu=rng.uniform(0, 300, k), nv=rng.uniform(0, 300, k))


def close(got, ref, tol=TOL):
    got, ref = np.asarray(got), np.asarray(ref)
    err = np.abs(got - ref) / np.maximum(np.abs(ref), 1e-300)
    assert np.all(err <= tol), (err.max(), np.max(err / tol))


# ------------------------------------------------------------------------- NDFs
def test_isotropic_ndfs_match_transcriptions(pairs):
    th, a = pairs["th"], pairs["a"]
    c = np.cos(th)
    close(ndf.ggx(c, a), ref_ggx(th, a))
    close(ndf.beckmann(c, a), ref_beckmann(th, a))
    close(ndf.blinn_phong(c, pairs["nu"]), ref_blinn_phong(th, pairs["nu"]))
    s = pairs["nu"]
    close(ndf.blinn_phong_specular(c, s), (s + 8) / (8 * np.pi) * np.cos(th) ** s)


def test_anisotropic_ndfs_match_transcriptions(pairs):
    h, th, ph = pairs["h"], pairs["th"], pairs["ph"]
    ax, ay, nu, nv = pairs["a"], pairs["ay"], pairs["nu"], pairs["nv"]
    close(ndf.ggx_aniso(h[:, 0], h[:, 1], h[:, 2], ax, ay), ref_ggx_aniso(th, ph, ax, ay))
    # cos θ^e = exp(e log cos θ) amplifies rounding by |e log cos θ| (up to 426 here): measured
    # 4.4e-13 (1.2e-12 with XLA:CPU's own float64 log1p, which ndf.log_cos_over_sin2 avoids)
    close(ndf.ashikhmin_shirley(h[:, 0], h[:, 1], h[:, 2], nu, nv), ref_as(th, ph, nu, nv, 2))
    close(ndf.ashikhmin_shirley_pdf(h[:, 0], h[:, 1], h[:, 2], nu, nv), ref_as(th, ph, nu, nv, 1))


def test_ndf_limits(pairs):
    """α_x = α_y: anisotropic GGX is GGX (≤ 1e-14); n_u = n_v = s: the Ashikhmin–Shirley NDF is
    Blinn–Phong, and their p(h) is (s + 1)/(2π) cosˢ, to ≤ 1e-14 (1 + s) relative: cosˢ
    amplifies the rounding of the unit h (one reads h_n, the other h_t² + h_b²) by s."""
    h, a, s = pairs["h"], pairs["a"], pairs["nu"]
    close(ndf.ggx_aniso(h[:, 0], h[:, 1], h[:, 2], a, a), ndf.ggx(h[:, 2], a), 1e-14)
    close(ndf.ashikhmin_shirley(h[:, 0], h[:, 1], h[:, 2], s, s), ndf.blinn_phong(h[:, 2], s),
          1e-14 * (1 + s))
    close(ndf.ashikhmin_shirley_pdf(h[:, 0], h[:, 1], h[:, 2], s, s),
          (s + 1) / (2 * np.pi) * h[:, 2] ** s, 1e-14 * (1 + s))
    # at h = n, where φ_h is undefined, the exponent's limit is taken: D = √((n_u+2)(n_v+2))/2π
    assert float(ndf.ashikhmin_shirley(0.0, 0.0, 1.0, 3.0, 6.0)) == np.sqrt(5 * 8) / (2 * np.pi)


@functools.lru_cache(maxsize=None)
def _sphere_rule(n_b, n_p):
    """Gauss–Legendre in β ∈ [0, π/2] and the (spectral) trapezoid rule in φ ∈ [0, 2π)."""
    x, w = np.polynomial.legendre.leggauss(n_b)
    beta, wb = np.pi / 4 * (x + 1), np.pi / 4 * w
    phi = 2 * np.pi * (np.arange(n_p) + 0.5) / n_p
    return beta[:, None], wb[:, None], phi[None, :], 2 * np.pi / n_p


def projected_integral(d_of, a, n_b=400, n_p=512, weight_cos=True):
    """∫ D(h) ⟨n,h⟩ dω_h with θ_h = atan(a tan β) (a: the lobe's width, so that the peak and the
    heavy tail are both resolved): dθ/dβ = a/(cos²β + a² sin²β)."""
    beta, wb, phi, wp = _sphere_rule(n_b, n_p)
    th = np.arctan2(a * np.sin(beta), np.cos(beta))
    jac = a / (np.cos(beta) ** 2 + a**2 * np.sin(beta) ** 2)
    h = vec(th, phi)
    dv = np.asarray(d_of(h[..., 0], h[..., 1], h[..., 2]))
    f = dv * (h[..., 2] if weight_cos else 1) * np.sin(th) * jac
    return float(np.sum(f * wb) * wp)


NORMALISED = {  # name: (D of the local half vector, the lobe width for the substitution)
    "ggx 0.05": (lambda t, b, c: ndf.ggx(c, 0.05), 0.05),
    "ggx 1": (lambda t, b, c: ndf.ggx(c, 1.0), 1.0),
    "beckmann 0.1": (lambda t, b, c: ndf.beckmann(c, 0.1), 0.1),
    "beckmann 1": (lambda t, b, c: ndf.beckmann(c, 1.0), 1.0),
    "blinn_phong 0": (lambda t, b, c: ndf.blinn_phong(c, 0.0), 1.0),
    "blinn_phong 500": (lambda t, b, c: ndf.blinn_phong(c, 500.0), 0.06),
    "ggx_aniso 0.05, 0.6": (lambda t, b, c: ndf.ggx_aniso(t, b, c, 0.05, 0.6), 0.17),
    "ggx_aniso 1, 0.3": (lambda t, b, c: ndf.ggx_aniso(t, b, c, 1.0, 0.3), 0.55),
    "ashikhmin_shirley 10, 1000": (lambda t, b, c: ndf.ashikhmin_shirley(t, b, c, 10.0, 1000.0),
                                   0.1),
    "ashikhmin_shirley 0, 50": (lambda t, b, c: ndf.ashikhmin_shirley(t, b, c, 0.0, 50.0), 1.0),
}


@pytest.mark.parametrize("name", sorted(NORMALISED))
def test_ndf_normalisation(name):
    """∫ D ⟨n,h⟩ dω_h = 1 for every NDF, isotropic and anisotropic (400 × 512 nodes; measured
    |error| ≤ 6e-15 for all but Ashikhmin–Shirley (n_u, n_v) = (0, 50), 2e-13: cos θ^e(φ) with
    e(φ) → 0 near φ = 0 is not smooth at the horizon, so the β rule converges algebraically there
    (5e-12 at 200 nodes); the trapezoid rule in φ converges geometrically, slowest for the
    anisotropic GGX at α_x/α_y = 12: 1e-9 at 256 nodes). Pinned at 1e-12."""
    d_of, width = NORMALISED[name]
    assert abs(projected_integral(d_of, width) - 1) < 1e-12


def test_ashikhmin_shirley_pdf_normalised_on_solid_angle():
    """Their p(h) integrates to 1 over dω_h (not ⟨n,h⟩ dω_h), and p = κ D (module docstring)."""
    nu, nv = 10.0, 1000.0
    p = lambda t, b, c: ndf.ashikhmin_shirley_pdf(t, b, c, nu, nv)  # noqa: E731
    assert abs(projected_integral(p, 0.1, weight_cos=False) - 1) < 1e-12
    kappa = np.sqrt((nu + 1) * (nv + 1) / ((nu + 2) * (nv + 2)))
    assert abs(projected_integral(p, 0.1) - kappa) < 1e-12


def test_blinn_phong_specular_normalisation():
    """(s + 8)/(8π) approximates the exact normal-view normalisation (s + 2)(s + 4)/(8π(2^(−s/2) +
    s)) of the lobe cosˢθ_h: the exact factor gives albedo 1 (≤ 1e-13), the approximation
    0.9999999 at s = 0, 1.0748 at s = 10 (measured 1.07478; pinned ±1e-4), 1.0020 at s = 1000."""
    x, w = np.polynomial.legendre.leggauss(400)
    th, w = np.pi / 4 * (x + 1), np.pi / 4 * w  # ω_i polar angle at ω_o = n: θ_h = θ_i / 2
    for s, expect in ((0.0, 1.0), (10.0, 1.07478), (1000.0, 1.00198)):
        lobe = np.asarray(ndf.blinn_phong_specular(np.cos(th / 2), s))
        alb = 2 * np.pi * np.sum(w * lobe * np.cos(th) * np.sin(th))
        assert abs(alb - expect) < 1e-4, (s, alb)
        exact = (s + 2) * (s + 4) / (8 * np.pi * (2 ** (-s / 2) + s))
        alb_exact = 2 * np.pi * np.sum(w * exact * np.cos(th / 2) ** s * np.cos(th) * np.sin(th))
        assert abs(alb_exact - 1) < 1e-13


# ------------------------------------------------------------------------- masking
def test_smith_lambda_matches_transcriptions(pairs):
    """Λ enters G only as 1 + Λ (+ Λ'), so it is compared on that scale: |ΔΛ|/(1 + Λ) ≤ 1e-12
    (the textbook forms −1 + √(1 + x) and erf(a) − 1 cancel where Λ ≪ 1)."""
    th, ph, a, ay = pairs["ti"], pairs["pi"], pairs["a"], pairs["ay"]
    c, w = np.cos(th), pairs["wi"]

    def close1(got, ref):
        assert np.max(np.abs(np.asarray(got) / c - ref) / (1 + ref)) <= TOL

    close1(masking.lambda_cos_ggx(c, a), ref_lambda(th, a, "ggx"))
    close1(masking.lambda_cos_beckmann(c, a), ref_lambda(th, a, "beckmann"))
    close1(masking.lambda_cos_ggx_aniso(w[:, 0], w[:, 1], w[:, 2], a, ay),
           ref_lambda(th, a, "ggx", ph, ay))
    # α_x = α_y: the anisotropic L is the GGX one (≤ 1e-14 of L + cos θ, the scale it enters G)
    la = np.asarray(masking.lambda_cos_ggx_aniso(w[:, 0], w[:, 1], w[:, 2], a, a))
    assert np.max(np.abs(la - np.asarray(masking.lambda_cos_ggx(c, a))) / (la + c)) < 1e-14


def test_masking_forms_match_transcriptions(pairs):
    """G of every form against the published expressions (Λ from the transcriptions)."""
    ti, to, a = pairs["ti"], pairs["to"], pairs["a"]
    wi, wo, h = pairs["wi"], pairs["wo"], pairs["h"]
    ci, co, nh, vh = wi[:, 2], wo[:, 2], h[:, 2], np.sum(wo * h, -1)
    lam_i, lam_o = ref_lambda(ti, a, "ggx"), ref_lambda(to, a, "ggx")
    li, lo = masking.lambda_cos_ggx(ci, a), masking.lambda_cos_ggx(co, a)
    close(masking.smith_separable(ci, co, li, lo), 1 / ((1 + lam_i) * (1 + lam_o)))
    close(masking.smith_correlated(ci, co, li, lo), 1 / (1 + lam_i + lam_o))
    ref_v = np.minimum(1, np.minimum(2 * nh * co / vh, 2 * nh * ci / vh))  # Cook–Torrance 1982
    close(masking.v_cavity(nh, ci, co, vh), ref_v)
    ref_as = ci * co / (vh * np.maximum(ci, co))  # from A–S 2000 Eq. 4's denominator
    close(masking.ashikhmin_shirley(ci, co, vh), ref_as)
    assert np.all(ref_as <= nh + 1e-15)  # the implied G ≤ ⟨n,h⟩ ≤ 1
    # the visibility forms V = G/(4 c_i c_o)
    q = 4 * ci * co
    close(masking.visibility_smith_separable(ci, co, li, lo), 1 / ((1 + lam_i) * (1 + lam_o)) / q)
    close(masking.visibility_smith_correlated(ci, co, li, lo), 1 / (1 + lam_i + lam_o) / q)
    close(masking.visibility_v_cavity(nh, ci, co, vh), ref_v / q)
    close(masking.visibility_ashikhmin_shirley(ci, co, vh), ref_as / q)


def test_visibility_finite_and_continuous_at_grazing():
    """V stays finite as c_i → 0 and is continuous there (V(1e-9) vs V(1e-12): ≤ 1e-8 relative)."""
    nh, co, oh = 0.9, 0.4, 0.7
    for fn in (lambda c: masking.visibility_v_cavity(nh, c, co, oh),
               lambda c: masking.visibility_ashikhmin_shirley(c, co, oh),
               lambda c: masking.visibility_smith_correlated(
                   c, co, masking.lambda_cos_ggx(c, 0.3), masking.lambda_cos_ggx(co, 0.3)),
               lambda c: masking.visibility_smith_separable(
                   c, co, masking.lambda_cos_beckmann(c, 0.3),
                   masking.lambda_cos_beckmann(co, 0.3))):
        a, b = float(fn(1e-9)), float(fn(1e-12))
        assert np.isfinite(a) and 0 < a and abs(a - b) <= 1e-8 * a


# ------------------------------------------------------------------------- diffuse
def test_diffuse_terms_match_transcriptions(pairs):
    ti, to, dphi = pairs["ti"], pairs["to"], pairs["pi"] - pairs["po"]
    wi, wo, n = pairs["wi"], pairs["wo"], np.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(RNG_SEED + 1)
    rho, sigma, rs = rng.uniform(0, 1, ti.size), rng.uniform(0, 1.2, ti.size), rng.uniform(
        0, 1, ti.size)
    close(diffuse.lambert(rho, wi, wo, n), rho / np.pi)
    # Oren & Nayar 1994, Eq. 30 in angles
    s2 = sigma**2
    big_a, big_b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    alpha, beta = np.maximum(ti, to), np.minimum(ti, to)
    ref = rho / np.pi * (big_a + big_b * np.maximum(0, np.cos(dphi)) * np.sin(alpha) * np.tan(beta))
    close(diffuse.oren_nayar(rho, sigma, wi, wo, n), ref)
    # Ashikhmin & Shirley 2000, Eq. 5
    ref = (28 * rho / (23 * np.pi) * (1 - rs) * (1 - (1 - np.cos(ti) / 2) ** 5)
           * (1 - (1 - np.cos(to) / 2) ** 5))
    close(diffuse.ashikhmin_shirley(rho, rs, wi, wo, n), ref)


def test_oren_nayar_is_lambert_at_zero_sigma(pairs):
    wi, wo, n = pairs["wi"], pairs["wo"], np.array([0.0, 0.0, 1.0])
    np.testing.assert_array_equal(diffuse.oren_nayar(0.7, 0.0, wi, wo, n),
                                  diffuse.lambert(0.7, wi, wo, n))


def test_diffuse_zero_below_horizon():
    n = np.array([0.0, 0.0, 1.0])
    up, down = np.array([0.0, 0.6, 0.8]), np.array([0.0, 0.6, -0.8])
    for f in (diffuse.lambert(1.0, up, down, n), diffuse.oren_nayar(1.0, 0.3, down, up, n),
              diffuse.ashikhmin_shirley(1.0, 0.0, up, down, n)):
        assert float(f) == 0.0


# ------------------------------------------------------------------------- gradients
def _terms():
    """(name, f of scalars, singular points, interior points) for every term."""
    n = jnp.array([0.0, 0.0, 1.0])

    def w(th, ph):
        return jnp.stack([jnp.sin(th) * jnp.cos(ph), jnp.sin(th) * jnp.sin(ph), jnp.cos(th)])

    def hv(th, ph):  # a unit half vector's components
        return jnp.sin(th) * jnp.cos(ph), jnp.sin(th) * jnp.sin(ph), jnp.cos(th)

    half = np.pi / 2
    return [
        ("ggx", lambda c, a: ndf.ggx(c, a), [(1.0, 0.3), (0.0, 0.3), (1.0, 1.0), (1e-4, 0.05)],
         [(0.8, 0.3), (0.3, 0.9)]),
        ("beckmann", lambda c, a: ndf.beckmann(c, a), [(1.0, 0.3), (0.0, 0.3), (1e-4, 0.05)],
         [(0.8, 0.3), (0.5, 0.9)]),
        ("blinn_phong", lambda c, s: ndf.blinn_phong(c, s), [(1.0, 20.0), (0.0, 20.0), (1.0, 0.0)],
         [(0.9, 20.0), (0.5, 2.0)]),
        ("blinn_phong_specular", lambda c, s: ndf.blinn_phong_specular(c, s),
         [(1.0, 20.0), (0.0, 3.0)], [(0.9, 20.0)]),
        ("ggx_aniso", lambda th, ph, ax, ay: ndf.ggx_aniso(*hv(th, ph), ax, ay),
         [(0.0, 0.0, 0.1, 0.7), (half, 0.3, 0.1, 0.7), (1e-9, 1.0, 0.5, 0.5)],
         [(0.4, 0.7, 0.1, 0.7), (1.0, 2.0, 0.9, 0.4)]),
        ("ashikhmin_shirley", lambda th, ph, nu, nv: ndf.ashikhmin_shirley(*hv(th, ph), nu, nv),
         [(0.0, 0.0, 10.0, 100.0), (half, 0.3, 10.0, 100.0), (1e-9, 1.0, 0.0, 5.0)],
         [(0.2, 0.7, 10.0, 100.0), (0.03, 2.0, 1e3, 10.0)]),
        ("lambda_ggx", lambda c, a: masking.lambda_cos_ggx(c, a), [(0.0, 0.3), (1.0, 0.3)],
         [(0.4, 0.3)]),
        ("lambda_beckmann", lambda c, a: masking.lambda_cos_beckmann(c, a),
         [(0.0, 0.3), (1.0, 0.3), (0.999999, 0.05)], [(0.4, 0.3), (0.2, 0.9)]),
        ("lambda_ggx_aniso", lambda th, ph, ax, ay: masking.lambda_cos_ggx_aniso(
            *hv(th, ph), ax, ay), [(0.0, 0.0, 0.1, 0.7), (half, 0.3, 0.1, 0.7)],
         [(1.0, 0.7, 0.1, 0.7)]),
        ("v_cavity", lambda nh, ci, co, oh: masking.visibility_v_cavity(nh, ci, co, oh),
         [(1.0, 0.0, 0.5, 0.7), (1.0, 1.0, 1.0, 1.0), (0.9, 0.0, 0.0, 0.5)],
         [(0.9, 0.2, 0.5, 0.7), (0.95, 0.8, 0.9, 0.9)]),
        ("ashikhmin_shirley_g", lambda ci, co, oh: masking.visibility_ashikhmin_shirley(ci, co, oh),
         [(0.0, 0.5, 0.7), (1.0, 1.0, 1.0)], [(0.3, 0.5, 0.7)]),
        ("smith_correlated", lambda ci, co, a: masking.visibility_smith_correlated(
            ci, co, masking.lambda_cos_ggx(ci, a), masking.lambda_cos_ggx(co, a)),
         [(0.0, 0.5, 0.3), (1.0, 1.0, 0.3), (0.0, 0.0, 0.3)], [(0.3, 0.5, 0.3)]),
        ("smith_separable", lambda ci, co, a: masking.visibility_smith_separable(
            ci, co, masking.lambda_cos_beckmann(ci, a), masking.lambda_cos_beckmann(co, a)),
         [(0.0, 0.5, 0.3), (1.0, 1.0, 0.3)], [(0.3, 0.5, 0.3)]),
        ("oren_nayar", lambda ti, to, dp, s: diffuse.oren_nayar(0.8, s, w(ti, 0.0), w(to, dp),
                                                                  n.astype(ti.dtype)),
         [(0.0, 0.0, 0.0, 0.3), (half, 0.5, 0.0, 0.3), (0.5, 0.5, 0.0, 0.0)],
         [(0.4, 0.9, 0.5, 0.3), (1.0, 0.3, 2.0, 0.6)]),
        ("ashikhmin_shirley_diffuse", lambda ti, to, rs: diffuse.ashikhmin_shirley(
            0.8, rs, w(ti, 0.0), w(to, 1.0), n.astype(ti.dtype)),
         [(0.0, 0.0, 0.04), (half, 0.3, 0.04)],
         [(0.4, 0.9, 0.5)]),
    ]


TERMS = _terms()


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_gradients_finite_at_singular_points(dtype):
    """Every argument's derivative is finite at h = n, at grazing and with α_x ≠ α_y, float32 and
    float64."""
    for name, fn, singular, interior in TERMS:
        g = jax.grad(fn, argnums=tuple(range(len(singular[0]))))
        for p in singular + interior:
            grads = g(*(jnp.asarray(x, dtype) for x in p))
            assert all(bool(jnp.isfinite(x)) and jnp.asarray(x).dtype == dtype for x in grads), \
                (name, p, grads)


def test_gradients_match_finite_differences():
    """jax.grad against central differences (step 1e-6 · max(1, |x|)) at interior points, float64:
    relative agreement ≤ 1e-6 (passes at 1e-8)."""
    for name, fn, _, interior in TERMS:
        for p in interior:
            p = [float(x) for x in p]
            f64 = lambda q: [jnp.asarray(x, jnp.float64) for x in q]  # noqa: E731
            grads = jax.grad(fn, argnums=tuple(range(len(p))))(*f64(p))
            for k in range(len(p)):
                e = 1e-6 * max(1.0, abs(p[k]))
                up, dn = list(p), list(p)
                up[k] += e
                dn[k] -= e
                fd = (float(fn(*f64(up))) - float(fn(*f64(dn)))) / (2 * e)
                scale = max(abs(fd), abs(float(fn(*f64(p)))), 1e-12)
                assert abs(float(grads[k]) - fd) <= 1e-6 * scale, (name, p, k, grads[k], fd)
