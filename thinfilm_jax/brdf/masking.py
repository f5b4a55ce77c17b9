r"""Masking–shadowing G(ω_i, ω_o) and the visibility V = G / (4⟨n,ω_i⟩⟨n,ω_o⟩) of microfacet BRDFs.

Written once here (`microfacet` and `material` use them), pure and broadcasting. A microfacet
specular BRDF is f = D(h) V F(⟨h,ω_i⟩); every V below is written so that it stays finite, with
finite gradients, where ⟨n,ω_i⟩ or ⟨n,ω_o⟩ → 0 (no 0/0), and every G ≤ 1.

Smith Λ (Walter et al. 2007, Eq. 27, 34; Heitz 2014, "Understanding the masking-shadowing
function", Eq. 72, 86) is carried as L(ω) := cos θ · Λ(ω), finite on the closed hemisphere:

* GGX:       Λ = (−1 + √(1 + α² tan²θ))/2,      L = (√(α² + (1 − α²) cos²θ) − cos θ)/2
* Beckmann:  Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π), a = 1/(α tan θ)
* anisotropic GGX with the projected roughness α_o² = cos²φ α_x² + sin²φ α_y² (Heitz 2014,
  Eq. 80, 86):  L = (√(ω_n² + α_x² ω_t² + α_y² ω_b²) − ω_n)/2  (α_x = α_y: the GGX L).

Masking–shadowing forms (c_i = ⟨n,ω_i⟩, c_o = ⟨n,ω_o⟩, both > 0):

* Smith separable (Walter et al. 2007, Eq. 23): G = G₁(ω_i) G₁(ω_o), G₁ = 1/(1 + Λ) = c/(c + L);
  V = 1 / (4 (c_i + L_i)(c_o + L_o)).
* Smith height-correlated (Heitz 2014, Eq. 99): G = 1/(1 + Λ_i + Λ_o);
  V = 1 / (4 (c_i c_o + c_o L_i + c_i L_o)).
* V-cavity (Cook & Torrance 1982, Eq. for G; Blinn 1977):
  G = min(1, 2⟨n,h⟩c_o/⟨ω_o,h⟩, 2⟨n,h⟩c_i/⟨ω_o,h⟩);  V = min(1/m, 2⟨n,h⟩/⟨ω_o,h⟩)/(4M) with
  m = min(c_i, c_o), M = max(c_i, c_o) (the first entry of the min only where it is the smaller).
* Ashikhmin–Shirley 2000 (the denominator of their specular term, Eq. 4, read as a masking
  term): G = min(c_i, c_o)/⟨ω_o,h⟩ ≤ ⟨n,h⟩ ≤ 1;  V = 1/(4⟨ω_o,h⟩ max(c_i, c_o)).
* implicit (no masking, G = c_i c_o):  V = 1/4.

Example (at normal incidence and view nothing is masked: G = 1 for every form; Smith GGX
G₁ at grazing is 0):
    >>> from thinfilm_jax.brdf import masking
    >>> li = masking.lambda_cos_ggx(1.0, 0.5)
    >>> g2 = masking.smith_correlated(1.0, 1.0, li, li)
    >>> float(g2), float(masking.v_cavity(1.0, 1.0, 1.0, 1.0))
    (1.0, 1.0)
    >>> float(masking.smith_g1(0.0, masking.lambda_cos_ggx(0.0, 0.5)))
    0.0
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc

from .ndf import _float, exp_cut

__all__ = ["MASKINGS", "lambda_cos_ggx", "lambda_cos_beckmann", "lambda_cos",
           "lambda_cos_ggx_aniso",
           "smith_g1", "smith_separable", "smith_correlated", "v_cavity", "ashikhmin_shirley",
           "visibility_smith_separable", "visibility_smith_correlated", "visibility_v_cavity",
           "visibility_ashikhmin_shirley"]

MASKINGS = ("smith_correlated", "smith_separable", "v_cavity", "ashikhmin_shirley", "implicit")
_INV_SQRT_PI = float(1.0 / np.sqrt(np.pi))  # Python float: weakly typed under strict promotion


# ----------------------------------------------------------------------------- Smith L = cos θ Λ
def lambda_cos_ggx(cos, alpha):
    """L = cos θ Λ_GGX(θ) = (√(α² + (1 − α²) cos²θ) − cos θ)/2 for cos θ ∈ [0, 1] (L(0) = α/2)."""
    cos, alpha = _float(cos, alpha)
    a2 = alpha * alpha
    return 0.5 * (jnp.sqrt(a2 + (1 - a2) * cos * cos) - cos)


def lambda_cos_beckmann(cos, alpha):
    """L = cos θ Λ_Beckmann(θ) for cos θ ∈ [0, 1]: −(c/2) erfc(a) + α sin θ e^{−a²}/(2√π),
    a = cot θ/α; L(0) = α/(2√π), 0 where e^{−a²} underflows (Λ = 0 to working precision)."""
    cos, alpha = _float(cos, alpha)
    a2 = alpha * alpha
    sin2 = jnp.clip(1 - cos * cos, 0, 1)
    ok = cos * cos < exp_cut(cos.dtype) * a2 * sin2
    cs = jnp.where(ok, cos, 0)
    ss = jnp.sqrt(jnp.where(ok, sin2, 1))
    a = cs / (alpha * ss)  # a = cot θ / α
    lam = -0.5 * cs * erfc(a) + (0.5 * _INV_SQRT_PI) * alpha * ss * jnp.exp(-a * a)
    return jnp.where(ok, jnp.maximum(lam, 0), 0)


def lambda_cos(cos, alpha, ndf):
    """L = cos θ Λ(θ) of the isotropic `ndf` ("ggx" or "beckmann")."""
    if ndf == "ggx":
        return lambda_cos_ggx(cos, alpha)
    if ndf == "beckmann":
        return lambda_cos_beckmann(cos, alpha)
    raise ValueError(f"no Smith Λ for ndf {ndf!r}; expected 'ggx' or 'beckmann'")


def lambda_cos_ggx_aniso(w_t, w_b, w_n, alpha_x, alpha_y):
    """L = ω_n Λ(ω) = (√(ω_n² + α_x² ω_t² + α_y² ω_b²) − ω_n)/2 of anisotropic GGX (Heitz 2014,
    Eq. 86 with the projected roughness); (ω_t, ω_b, ω_n): the unit direction in the frame
    (t, b, n)."""
    w_t, w_b, w_n, ax, ay = _float(w_t, w_b, w_n, alpha_x, alpha_y)
    x, y = ax * w_t, ay * w_b
    return 0.5 * (jnp.sqrt(w_n * w_n + x * x + y * y) - w_n)


# ----------------------------------------------------------------------------- G
def _pos(x):
    return jnp.where(x > 0, x, 0)


def _safe_inv(den):
    """1/den where den > 0, else 0 (double-where)."""
    ok = den > 0
    return jnp.where(ok, 1 / jnp.where(ok, den, 1), 0)


def smith_g1(cos, lam_cos):
    """Smith masking G₁ = 1/(1 + Λ) = cos θ/(cos θ + L); 0 for cos θ ≤ 0."""
    cos, lam_cos = _float(cos, lam_cos)
    c = _pos(cos)
    return c * _safe_inv(c + lam_cos)


def smith_separable(cos_i, cos_o, lam_cos_i, lam_cos_o):
    """Separable Smith G = G₁(ω_i) G₁(ω_o) (Walter et al. 2007, Eq. 23)."""
    return smith_g1(cos_i, lam_cos_i) * smith_g1(cos_o, lam_cos_o)


def smith_correlated(cos_i, cos_o, lam_cos_i, lam_cos_o):
    """Height-correlated Smith G = 1/(1 + Λ_i + Λ_o) (Heitz 2014, Eq. 99); 0 unless c_i, c_o > 0."""
    ci, co, li, lo = _float(cos_i, cos_o, lam_cos_i, lam_cos_o)
    ci, co = _pos(ci), _pos(co)
    return ci * co * _safe_inv(ci * co + co * li + ci * lo)


def v_cavity(cos_h, cos_i, cos_o, cos_oh):
    """Cook–Torrance V-cavity G = min(1, 2⟨n,h⟩c_o/⟨ω_o,h⟩, 2⟨n,h⟩c_i/⟨ω_o,h⟩); 0 unless c_i,
    c_o > 0. `cos_oh` = ⟨ω_o,h⟩ = ⟨ω_i,h⟩."""
    nh, ci, co, oh = _float(cos_h, cos_i, cos_o, cos_oh)
    ci, co = _pos(ci), _pos(co)
    g = jnp.minimum(1, 2 * nh * jnp.minimum(ci, co) * _safe_inv(oh))
    return jnp.where((ci > 0) & (co > 0), g, 0)


def ashikhmin_shirley(cos_i, cos_o, cos_oh):
    """The masking implied by Ashikhmin–Shirley's specular denominator:
    G = min(c_i, c_o)/⟨ω_o,h⟩."""
    ci, co, oh = _float(cos_i, cos_o, cos_oh)
    ci, co = _pos(ci), _pos(co)
    return jnp.minimum(ci, co) * _safe_inv(oh)


# ----------------------------------------------------------------------------- V = G/(4 c_i c_o)
def visibility_smith_separable(cos_i, cos_o, lam_cos_i, lam_cos_o):
    """V = 1/(4 (c_i + L_i)(c_o + L_o)); 0 unless c_i, c_o > 0."""
    ci, co, li, lo = _float(cos_i, cos_o, lam_cos_i, lam_cos_o)
    up = (ci > 0) & (co > 0)
    return jnp.where(up, 0.25 * _safe_inv((_pos(ci) + li) * (_pos(co) + lo)), 0)


def visibility_smith_correlated(cos_i, cos_o, lam_cos_i, lam_cos_o):
    """V = 1/(4 (c_i c_o + c_o L_i + c_i L_o)); 0 unless c_i, c_o > 0."""
    ci, co, li, lo = _float(cos_i, cos_o, lam_cos_i, lam_cos_o)
    up = (ci > 0) & (co > 0)
    ci, co = _pos(ci), _pos(co)
    return jnp.where(up, 0.25 * _safe_inv(ci * co + co * li + ci * lo), 0)


def visibility_v_cavity(cos_h, cos_i, cos_o, cos_oh):
    """V-cavity V = min(1/m, 2⟨n,h⟩/⟨ω_o,h⟩)/(4M), m = min(c_i, c_o), M = max(c_i, c_o); 0 unless
    c_i, c_o > 0. Finite as m → 0 (then the second entry is the smaller)."""
    nh, ci, co, oh = _float(cos_h, cos_i, cos_o, cos_oh)
    up = (ci > 0) & (co > 0)
    ci, co = _pos(ci), _pos(co)
    m, big = jnp.minimum(ci, co), jnp.maximum(ci, co)
    r = 2 * nh * _safe_inv(oh)  # 2⟨n,h⟩/⟨ω_o,h⟩
    masked = m * r < 1
    v = jnp.where(masked, r, _safe_inv(jnp.where(masked, 1, m)))
    return jnp.where(up, 0.25 * v * _safe_inv(big), 0)


def visibility_ashikhmin_shirley(cos_i, cos_o, cos_oh):
    """Ashikhmin–Shirley V = 1/(4⟨ω_o,h⟩ max(c_i, c_o)); 0 unless c_i, c_o > 0."""
    ci, co, oh = _float(cos_i, cos_o, cos_oh)
    up = (ci > 0) & (co > 0)
    return jnp.where(up, 0.25 * _safe_inv(oh * jnp.maximum(ci, co)), 0)
