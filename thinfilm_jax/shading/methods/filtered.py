r"""`method="filtered"`: K 29 with split-sum / prefiltered light moments (Kneiphof 2019;
SPEC §7, §9).

Uniform light: L_j = A(θ_o, α) R̄_j, R̄ = K 29 (`kernels.filtered_kernel`) with the light
moments μ_ω, Σ_ω of the split-sum prefiltered uniform environment
(`microfacet.splitsum_light_moments`); a bare layer (d = 0) the exact R₁₃ Ŝ_j(0) at cos θ₁*
of K 22. Under a map: A(θ_o, α) Σ_k R̄_jk P_k(ω_r, α) with the prefiltered moments (Ŝ read
with 8 taps, linear in |μ| and cubic in σ: `MAP_SHAT_READ`). `filtered_gt` holds its two
Figure 7 variants with true moments.

Example:
    >>> from thinfilm_jax import Film, patch_radiance
    >>> patch_radiance(Film(600.0, 1.3, 2.0, 0.5), 0.3, 0.25, method="filtered").shape
    (3,)
"""

from __future__ import annotations

import jax.numpy as jnp

from ...brdf.microfacet import splitsum_light_moments, view_direction
from ...core.material import expand_batch
from ...optics.opd import cos_incidence_from_projection, project_light_moments
from ...realtime.kernels import filtered_kernel
from ...spectral.reflectance import bare_bands
from ..prefilter import moments_to_mean_cov
from . import SplitSum

# `filtered`'s Ŝ read under a map: linear in |μ|, Catmull–Rom in σ (8 taps, within 4.7e-5 of
# the exact cross bands against the bicubic read's 2.8e-5, `lut.lookup`), 1.2× faster a point
# at frame size (docs/studies/performance.md, "Real-time IBL at frame size")
MAP_SHAT_READ = "linear_mu"


class Filtered(SplitSum):
    name = "filtered"

    def light_moments(self, theta_o, alpha, quad, o):
        """(μ_ω, Σ_ω) of the light lobe under uniform light: the split sum's."""
        return splitsum_light_moments(theta_o, alpha, quadrature=o.quadrature, ndf=o.ndf)

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        o = options
        albedo = jnp.sum(quad.weight)
        mean, cov = self.light_moments(theta_o, alpha, quad, o)
        wo = view_direction(theta_o)
        if o.layer == "bare":
            mu_c, _ = project_light_moments(wo, mean, cov)
            return albedo * bare_bands(film, cos_incidence_from_projection(mu_c), observer,
                                       shat=o.shat, arithmetic=o.arithmetic)
        return self.film_point(film, albedo, quad, mean, cov, wo, observer, o, lut)

    def film_point(self, film, albedo, quad, mean, cov, wo, observer, o, lut):
        return albedo * filtered_kernel(film, wo, mean, cov, observer=observer, terms=o.terms,
                                        shat=o.shat, lut=lut, arithmetic=o.arithmetic)

    def bands_per_light(self, film, co, view, mom, kw):
        return filtered_kernel(film, view, *moments_to_mean_cov(mom), **kw,
                               interpolation=MAP_SHAT_READ)

    def bands(self, film, co, view, mom, pref, kw):
        mean, cov = moments_to_mean_cov(mom)
        if pref.per_channel:  # moments of channel k drive R_jk (..., 3[k], 9)
            return filtered_kernel(expand_batch(film), view[..., None, :], mean, cov, **kw,
                                   interpolation=MAP_SHAT_READ)
        return filtered_kernel(film, view, mean, cov, **kw, interpolation=MAP_SHAT_READ)

    def bare_cos(self, co, view, mom):  # cos θ₁* of the read's mean light (K 22)
        mean, cov = moments_to_mean_cov(mom)
        wo = view[..., None, :] if mom.ndim > view.ndim else view
        return cos_incidence_from_projection(project_light_moments(wo, mean, cov)[0])


FILTERED = Filtered()
