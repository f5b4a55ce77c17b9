r"""Microfacet normal distributions D(h), each normalised so that ∫ D(h) ⟨n,h⟩ dω_h = 1.

Written once here (`microfacet` and `material` use them), as pure broadcasting functions of the
half vector's components in the local frame (t, b, n): h_t = ⟨h,t⟩, h_b = ⟨h,b⟩, h_n = ⟨h,n⟩ =
cos θ_h; isotropic ones take only cos θ_h. D = 0 for cos θ_h ≤ 0. Values and gradients are
finite on the whole closed upper hemisphere (h = n and grazing h included; double-where guards).

* Beckmann (Walter et al. 2007, Eq. 25):  D = exp(−tan²θ_h / α²) / (π α² cos⁴θ_h)
* GGX / Trowbridge–Reitz (Walter et al. 2007, Eq. 33):
  D = α² / (π cos⁴θ_h (α² + tan²θ_h)²) = α² / (π (sin²θ_h + α² cos²θ_h)²)
* anisotropic GGX (Heitz 2014, "Understanding the masking-shadowing function", Eq. 85;
  Burley 2012, Eq. 13):  D = 1 / (π α_x α_y (h_t²/α_x² + h_b²/α_y² + h_n²)²);
  α_x = α_y = α gives GGX.
* normalised Blinn–Phong (Blinn 1977; normalisation as in Walter et al. 2007, Eq. 30):
  D = (s + 2)/(2π) cosˢθ_h, s ≥ 0 (s = 0: the uniform distribution of cos-weighted h).
* Ashikhmin–Shirley 2000 anisotropic Phong, e(φ_h) = n_u cos²φ_h + n_v sin²φ_h,
  cos²φ_h = h_t²/(h_t² + h_b²), n_u, n_v ≥ 0. Their half-vector density (their Eq. 6 and
  Eq. 4's constant) p(h) = √((n_u + 1)(n_v + 1))/(2π) cos θ_h^{e(φ_h)} is normalised on dω_h,
  ∫ p dω_h = 1 (since ∫₀^{2π} dφ/(A cos²φ + B sin²φ) = 2π/√(AB)); `ashikhmin_shirley_pdf`.
  By the same identity the NDF normalised like the others, ∫ D ⟨n,h⟩ dω_h = 1, is
  D = √((n_u + 2)(n_v + 2))/(2π) cos θ_h^{e(φ_h)} (`ashikhmin_shirley`): p(h) = κ D with
  κ = √((n_u + 1)(n_v + 1)/((n_u + 2)(n_v + 2))) < 1. At n_u = n_v = s, D is Blinn–Phong's and
  p(h) = (s + 1)/(2π) cosˢθ_h. Their specular BRDF (Eq. 4) is p(h) F/(4⟨h,ω⟩ max(c_i, c_o)):
  `material.ashikhmin_shirley_lobe` with its default masking.

The "(s + 8)/(8π) cosˢθ_h" specular lobe of real-time rendering (Akenine-Möller, Haines &
Hoffman, *Real-Time Rendering* 3rd ed., §7.6) is not an NDF but a whole specular BRDF without
Fresnel or masking. With the implicit masking G = ⟨n,ω_i⟩⟨n,ω_o⟩ the microfacet BRDF
D G/(4⟨n,ω_i⟩⟨n,ω_o⟩) of the Blinn–Phong D above is D/4 = (s + 2)/(8π) cosˢθ_h: the same lobe
shape with a smaller factor. The factor that makes the lobe's albedo at normal view exactly 1 is
(s + 2)(s + 4)/(8π(2^{−s/2} + s)) (Sloan & Hoffman; checked by quadrature in
tests/brdf/test_brdf_lobes.py), and (s + 8)/(8π) is its cheap approximation: equal at s = 0 and for
s → ∞, and up to 7.5 % too large in between (normal-view albedo 1.0748 at s = 10), so that
lobe is *not* energy-conserving. `blinn_phong_specular` gives it; the ratio of the two factors,
(s + 8)/(s + 2), tends to 1 for large s.

The anisotropic exponent of Ashikhmin–Shirley is evaluated as cosθ_h^e = exp(g(u) (n_u h_t² +
n_v h_b²)) with u = h_t² + h_b² = sin²θ_h and g(u) = log(cos θ_h)/u = log1p(−u)/(2u) (series
−½(1 + u/2 + u²/3 + …) for small u), which is smooth at h = n where φ_h is undefined.

Example (every D integrates to 1 against ⟨n,h⟩: a 1-D check for GGX, whose integrand in
x = cos²θ_h is α²/(sin²θ_h + α² cos²θ_h)²):
    >>> import numpy as np
    >>> from thinfilm_jax.brdf import ndf
    >>> c = np.linspace(0.0, 1.0, 200001)
    >>> f = 2 * np.pi * np.asarray(ndf.ggx(c, 0.5)) * c
    >>> round(float(np.sum((f[1:] + f[:-1]) / 2) * (c[1] - c[0])), 6)
    1.0
    >>> float(ndf.ggx_aniso(0.0, 0.0, 1.0, 0.5, 0.5)) == float(ndf.ggx(1.0, 0.5))
    True
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

__all__ = ["beckmann", "ggx", "ggx_aniso", "blinn_phong", "blinn_phong_specular",
           "ashikhmin_shirley", "ashikhmin_shirley_pdf", "walter_alpha"]


# ----------------------------------------------------------------------------- helpers
def _float(*xs):
    """`xs` as arrays of one floating dtype (the inputs' precision; ints become float)."""
    dt = jnp.result_type(*xs)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.result_type(float)
    return tuple(jnp.asarray(x, dt) for x in xs)


def clamp01(x):
    """Clamp to [0, 1] keeping the full one-sided gradient at the ends (jnp.clip halves it)."""
    return jnp.where(x >= 0, jnp.where(x <= 1, x, 1), 0)


def dot(a, b):
    """⟨a, b⟩ over the last axis."""
    return jnp.sum(a * b, axis=-1)


def half_vector(a, b, up):
    """h = (a + b)/|a + b| and where it exists (`up` and a + b ≠ 0); elsewhere h is a + b
    (finite, unused: callers mask with the returned flag, the double-where pattern)."""
    hs = a + b
    h2 = dot(hs, hs)
    ok = up & (h2 > 0)
    return hs / jnp.sqrt(jnp.where(ok, h2, 1))[..., None], ok


def exp_cut(dtype):
    """Exponent above which exp(−x) underflows to 0 in `dtype`."""
    return float(-np.log(np.finfo(dtype).tiny)) * 0.99


def log_cos_over_sin2(u):
    """g(u) = log(cos θ)/sin²θ = log1p(−u)/(2u) for u = sin²θ ∈ [0, 1); −½ at u = 0 (smooth).

    Above u = 1e-3 as log(w)/(2(1 − w)), w = 1 − u rounded (Goldberg 1991, Theorem 4: exact
    1 − w makes it accurate to a few ulps).

    Series −½ Σ_k u^k/(k + 1) below u = 1e-3 (truncation after u⁴: relative error ≤ u⁵/6 ≤ 2e-16);
    −inf-free: u = 1 (cos θ = 0) gives a finite large negative value through the guard."""
    small = u < 1e-3
    us = jnp.where(small, 0.5, jnp.minimum(u, 1 - float(np.finfo(u.dtype).eps)))
    w = 1 - us  # log1p(−u)/(2u) = log(w)/(2(1 − w)) with 1 − w exact (Goldberg's log1p): XLA:CPU's
    exact = jnp.log(w) / (2 * (1 - w))  # own float64 log1p is off by up to 3e-14 (measured)
    z = jnp.where(small, u, 0)
    series = -0.5 * (1 + z * (1 / 2 + z * (1 / 3 + z * (1 / 4 + z / 5))))
    return jnp.where(small, series, exact)


# ----------------------------------------------------------------------------- isotropic
def ggx(cos_h, alpha):
    """GGX D(h) = α² / (π (sin²θ_h + α² cos²θ_h)²) of cos θ_h (0 for cos θ_h ≤ 0), α ∈ (0, 1]."""
    cos_h, alpha = _float(cos_h, alpha)
    a2 = alpha * alpha
    c2 = clamp01(cos_h) ** 2
    s2 = 1 - c2
    d = a2 * c2 + s2
    return jnp.where(cos_h > 0, a2 / (np.pi * d * d), 0)


def beckmann(cos_h, alpha):
    """Beckmann D(h) = exp(−tan²θ_h/α²) / (π α² cos⁴θ_h) of cos θ_h (0 for cos θ_h ≤ 0).

    Evaluated as exp(−sin²/(α² cos²) − 2 log cos²) / (π α²), 0 where it underflows."""
    cos_h, alpha = _float(cos_h, alpha)
    a2 = alpha * alpha
    c2 = clamp01(cos_h) ** 2
    s2 = 1 - c2
    ok = (cos_h > 0) & (s2 < exp_cut(cos_h.dtype) * a2 * c2)
    c2s = jnp.where(ok, c2, 1)
    expo = -jnp.where(ok, s2, 0) / (a2 * c2s) - 2 * jnp.log(c2s)
    return jnp.where(ok, jnp.exp(expo) / (np.pi * a2), 0)


def _pow_cos(cos_h, e):
    """cos θ^e for cos θ ∈ (0, 1], e ≥ 0; 0 for cos θ ≤ 0 (exp(e log c), double-where)."""
    pos = cos_h > 0
    lc = jnp.log(jnp.where(pos, clamp01(cos_h), 1))
    return jnp.where(pos, jnp.exp(e * lc), 0)


def blinn_phong(cos_h, s):
    """Normalised Blinn–Phong D(h) = (s + 2)/(2π) cosˢθ_h, exponent s ≥ 0."""
    cos_h, s = _float(cos_h, s)
    return (s + 2) / (2 * np.pi) * _pow_cos(cos_h, s)


def blinn_phong_specular(cos_h, s):
    """The real-time specular lobe (s + 8)/(8π) cosˢθ_h (RTR 3rd ed. §7.6): a whole BRDF
    without Fresnel (implicit masking), not an NDF; see the module docstring."""
    cos_h, s = _float(cos_h, s)
    return (s + 8) / (8 * np.pi) * _pow_cos(cos_h, s)


def walter_alpha(s):
    """The Beckmann α = √(2/(s + 2)) whose D matches Blinn–Phong's for large s (Walter et al.
    2007, §5.2); used for the Smith Λ of a Blinn–Phong lobe (an approximation, documented)."""
    (s,) = _float(s)
    return jnp.sqrt(2 / (s + 2))


# ----------------------------------------------------------------------------- anisotropic
def ggx_aniso(h_t, h_b, h_n, alpha_x, alpha_y):
    """Anisotropic GGX D = 1/(π α_x α_y (h_t²/α_x² + h_b²/α_y² + h_n²)²) (Heitz 2014, Eq. 85).

    h_t, h_b, h_n: components of the unit half vector along the tangent t, the bitangent
    b = n × t and the normal n; α ∈ (0, 1]. 0 for h_n ≤ 0."""
    h_t, h_b, h_n, ax, ay = _float(h_t, h_b, h_n, alpha_x, alpha_y)
    x, y = h_t / ax, h_b / ay
    d = x * x + y * y + h_n * h_n
    return jnp.where(h_n > 0, 1 / (np.pi * ax * ay * d * d), 0)


def _as_power(h_t, h_b, h_n, n_u, n_v, shift):
    h_t, h_b, h_n, nu, nv = _float(h_t, h_b, h_n, n_u, n_v)
    u = clamp01(h_t * h_t + h_b * h_b)
    expo = (nu * h_t * h_t + nv * h_b * h_b) * log_cos_over_sin2(u)
    norm = jnp.sqrt((nu + shift) * (nv + shift)) / (2 * np.pi)
    return jnp.where(h_n > 0, norm * jnp.exp(jnp.where(h_n > 0, expo, 0)), 0)


def ashikhmin_shirley(h_t, h_b, h_n, n_u, n_v):
    """Ashikhmin–Shirley NDF D = √((n_u+2)(n_v+2))/(2π) cos θ_h^{n_u cos²φ_h + n_v sin²φ_h},
    normalised ∫ D ⟨n,h⟩ dω_h = 1 (module docstring).

    The exponent times log cos θ_h is (n_u h_t² + n_v h_b²) g(h_t² + h_b²) (`log_cos_over_sin2`),
    smooth at h = n. n_u, n_v ≥ 0 along t and b. 0 for h_n ≤ 0."""
    return _as_power(h_t, h_b, h_n, n_u, n_v, 2)


def ashikhmin_shirley_pdf(h_t, h_b, h_n, n_u, n_v):
    """Ashikhmin & Shirley's p(h) = √((n_u+1)(n_v+1))/(2π) cos θ_h^{n_u cos²φ_h + n_v sin²φ_h}
    (their Eq. 4 and 6), normalised ∫ p dω_h = 1; = κ `ashikhmin_shirley` (module docstring)."""
    return _as_power(h_t, h_b, h_n, n_u, n_v, 1)
