r"""`filtered_gt_moments` and `filtered_gt_opd`: `filtered` (K 29) under uniform light fed
with true quantities instead of the split sum's, the ablations of Figure 7 (BB17; SPEC §7).

* ``filtered_gt_moments``: the true light moments μ_ω, Σ_ω of the patch quadrature's lobe
  (`microfacet.light_moments`), then K 20–28 as `filtered` (Figure 7 (b), (f)).
* ``filtered_gt_opd``: the true mean and standard deviation of D under p_R
  (`opd.opd_moments_exact`) at cos θ₁* of K 22 (Figure 7 (c), (g)).

Example:
    >>> from thinfilm_jax import Film, patch_radiance
    >>> patch_radiance(Film(600.0, 1.3, 2.0, 0.5), 0.3, 0.25, method="filtered_gt_opd").shape
    (3,)
"""

from __future__ import annotations

from ...brdf.microfacet import light_moments
from ...optics.opd import (cos_incidence_from_projection, opd_moments_exact,
                           project_light_moments)
from ...realtime.filtered import filtered_bands
from .filtered import Filtered


class FilteredGTMoments(Filtered):
    name = "filtered_gt_moments"
    envmap_kind = ""  # uniform light only

    def light_moments(self, theta_o, alpha, quad, o):
        """The true moments of the patch quadrature's lobe."""
        return light_moments(quad)


class FilteredGTOPD(FilteredGTMoments):
    name = "filtered_gt_opd"

    def film_point(self, film, albedo, quad, mean, cov, wo, observer, o, lut):
        mu_c, _ = project_light_moments(wo, mean, cov)
        opd = opd_moments_exact(film, quad.cos_hi, quad.weight)
        return albedo * filtered_bands(film, cos_incidence_from_projection(mu_c), opd, observer,
                                       terms=o.terms, shat=o.shat, lut=lut,
                                       arithmetic=o.arithmetic)


GT_MOMENTS = FilteredGTMoments()
GT_OPD = FilteredGTOPD()
