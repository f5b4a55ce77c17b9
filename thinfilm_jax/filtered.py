r"""Filtered band reflectance for a Gaussian distribution of the optical path (K 19, K 29).

$$ \int p_R R_j \approx C_0^* + \sum_{m=1}^{M} C_m^*\left[e^{im\varphi_2^*}\hat S_j(-m\mu_D, m^2\sigma_D^2)
   + e^{-im\varphi_2^*}\hat S_j(m\mu_D, m^2\sigma_D^2)\right], $$

with C*_m, φ₂* the BB17 terms at the mean light direction (cos θ₁*, K 22) and Ŝ the
Gaussian-filtered sensitivity, either exact (`shat="exact"`, SPEC §5 quadrature) or from
the LUT (`shat="lut"`, `lut.ShatLUT`). Kneiphof et al. use M = 2.

Example (σ_D = 0 is the BB17 Fourier sum K 4; a spread σ_D of many wavelengths averages the
interference out, leaving the same C₀ in every band):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.filtered import filtered_bands
    >>> from thinfilm_jax.opd import OPDMoments, opd_of_cos
    >>> from thinfilm_jax.reflectance import fourier_bands
    >>> film, c, obs = Film(600.0, 1.3, 2.0, 0.5), 0.8, "stiles_burch_1959_10"
    >>> sharp = filtered_bands(film, c, OPDMoments(opd_of_cos(film, c), 0.0), obs)
    >>> bool(np.allclose(sharp, fourier_bands(film, c, obs, terms=2)))
    True
    >>> wide = filtered_bands(film, c, OPDMoments(opd_of_cos(film, c), 1e4), obs)
    >>> bool(np.ptp(np.asarray(wide)) < 1e-9)
    True
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from .film import Film
from .lut import ShatLUT, lookup
from .opd import OPDMoments
from .series import fourier_band_reflectance, series_terms
from .spectra import sensitivity_ft, shat_at_zero

SHAT_SOURCES = ("exact", "lut", "gaussian")


def filtered_bands(film: Film, cos_mean, opd: OPDMoments, observer: str, *, terms: int = 2,
                   shat: str = "exact", lut: ShatLUT | None = None,
                   arithmetic: str = "complex", interpolation: str = "cubic") -> Array:
    """K 29 band reflectance (..., J) for broadcast inputs (no validation; see patch.py).

    `interpolation` is the LUT read (`lut.lookup`) when shat="lut"."""
    st = series_terms(film, cos_mean, arithmetic=arithmetic)
    dtype = jnp.result_type(cos_mean, float)
    mean, std = opd
    if shat == "lut":
        def shat_m(m):
            return lookup(lut, -m * mean, m * std, interpolation=interpolation)
    else:
        def shat_m(m):
            return sensitivity_ft(-m * mean, observer, sigma2=(m * std) ** 2, shat=shat)
    s0 = shat_at_zero(observer, dtype, "gaussian" if shat == "gaussian" else "exact")
    return jnp.mean(fourier_band_reflectance(st, shat_m, terms, s0), axis=0)
