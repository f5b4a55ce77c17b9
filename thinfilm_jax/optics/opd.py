r"""Distribution of the optical path difference D over the light directions (K 5, K 20–28).

D(ω_i) = 2 η₂ d cos θ₂ depends on the light direction only through c = ⟨ω_i, ω_o⟩
(cos θ₁ = ⟨h, ω_i⟩ = √((1 + c)/2), K 22; cos θ₂ by Snell, K 23–24). Kneiphof et al.
approximate the distribution of D by a Gaussian N(μ_D, σ_D²) obtained from the mean μ_ω and
covariance Σ_ω of the light direction by projection onto ω_o (K 20–21) and a first-order
Taylor expansion of cos θ₂ around the mean (K 25–26), then scaling (K 27–28):

$$ \mu_c = \langle\omega_o, \mu_\omega\rangle,\quad \sigma_c^2 = \omega_o^T\Sigma_\omega\omega_o,\quad
   \mu_{\cos\theta_2} = \sqrt{1 + \tfrac{\eta_1^2}{2\eta_2^2}(\mu_c - 1)},\quad
   \sigma_{\cos\theta_2} = \frac{\eta_1^2}{4\eta_2^2}\frac{\sigma_c}{\mu_{\cos\theta_2}}, $$
$$ \mu_D = 2\eta_2 d\,\mu_{\cos\theta_2},\qquad \sigma_D = 2\eta_2 d\,\sigma_{\cos\theta_2}. $$

The ground truth (the true mean and variance of D under p_R) comes from the patch
quadrature: `opd_moments_exact`.

Example (normal incidence without spread: D = 2 η₂ d exactly and σ_D = 0; a spread of
directions gives σ_D > 0):
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.optics.opd import taylor_opd_moments
    >>> m = taylor_opd_moments(Film(500.0, 1.5, 2.0), 1.0, 0.0)
    >>> float(m.mean), float(m.std)
    (1500.0, 0.0)
    >>> bool(taylor_opd_moments(Film(500.0, 1.5, 2.0), 0.9, 0.01).std > 0)
    True
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from .fresnel import safe_div, safe_sqrt

__all__ = [
    "OPDMoments",
    "cos_incidence_from_projection",
    "opd_of_cos",
    "taylor_opd_moments",
    "project_light_moments",
    "opd_moments_exact",
]


class OPDMoments(NamedTuple):
    """Mean μ_D and standard deviation σ_D of the optical path difference (nm)."""

    mean: Array
    std: Array


def cos_incidence_from_projection(mu_c) -> Array:
    """cos θ₁* = √((1 + ⟨ω_o, μ_ω⟩)/2): the microfacet incidence cosine of the mean light
    direction (K 22), used for C*_m and φ₂* in K 29."""
    return safe_sqrt((1.0 + mu_c) / 2.0)


def opd_of_cos(film: Film, cos_theta1) -> Array:
    """D = 2 d √(η₂² − η₁² sin²θ₁) (K 5 with Snell); 0 under TIR in the film."""
    s2 = film.eta_outer**2 * (1.0 - cos_theta1) * (1.0 + cos_theta1)
    return 2.0 * film.thickness * safe_sqrt(film.eta_film**2 - s2)


def taylor_opd_moments(film: Film, mu_c, var_c) -> OPDMoments:
    """μ_D, σ_D from the moments of c = ⟨ω_i, ω_o⟩ by the first-order chain K 25–28.

    Concrete inputs are checked (film domain, μ_c ∈ [−1, 1], σ_c² ≥ 0); traced ones are not.
    """
    if all(V.is_concrete(x) for x in (*film, mu_c, var_c)):
        film = V.check_film(film)
        mu_c = V.check_range("mu_c", mu_c, -1.0, 1.0, ulps=V.ROUNDING_ULPS, why=" (a cosine)")
        var_c = V.check_range("var_c", var_c, 0.0, why=" (a variance)")
    k = film.eta_outer**2 / (2.0 * film.eta_film**2)
    mu_cos2 = safe_sqrt(1.0 + k * (mu_c - 1.0))
    sigma_c = safe_sqrt(var_c)
    sigma_cos2 = safe_div(0.5 * k * sigma_c, mu_cos2)
    scale = 2.0 * film.eta_film * film.thickness
    return OPDMoments(scale * mu_cos2, scale * sigma_cos2)


def project_light_moments(wo, mean, cov):
    """μ_c = ⟨ω_o, μ_ω⟩ and σ_c² = ω_oᵀ Σ_ω ω_o (K 20–21); vectors on the last axis.

    Written as explicit products and sums over the three components (no contraction, no
    reduction): elementwise, so XLA fuses it into the kernel's loop."""
    w = [wo[..., i] for i in range(3)]
    mu_c = w[0] * mean[..., 0] + w[1] * mean[..., 1] + w[2] * mean[..., 2]
    var_c = sum(w[i] * (cov[..., i, 0] * w[0] + cov[..., i, 1] * w[1] + cov[..., i, 2] * w[2])
                for i in range(3))
    return mu_c, jnp.maximum(var_c, 0.0)


def opd_moments_exact(film: Film, cos_hi, weight) -> OPDMoments:
    """True mean and standard deviation of D under p_R ∝ weight at nodes cos θ₁ = `cos_hi`
    (last axis: quadrature nodes)."""
    f = jnp.asarray(film.thickness)[..., None]
    film_n = Film(f, *(jnp.asarray(x)[..., None] for x in film[1:]))
    d = opd_of_cos(film_n, cos_hi)
    wsum = jnp.sum(weight, axis=-1, keepdims=True)
    p = safe_div(weight, wsum)
    mean = jnp.sum(p * d, axis=-1)
    var = jnp.sum(p * (d - mean[..., None]) ** 2, axis=-1)
    return OPDMoments(mean, safe_sqrt(var))
