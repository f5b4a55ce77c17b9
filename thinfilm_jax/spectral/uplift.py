r"""Spectral uplift of linear sRGB radiance and the cross-band observer of IBL (SPEC §9).

An RGB texel c is read as the spectrum L(λ) = Σ_k c_k B_k(λ) with the Mallett & Yuksel 2019
sRGB basis (`colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019`, 380–780 nm), linearly
interpolated onto the observer's wavelengths and held constant outside its range. The basis
sums to one to within 1.0e-5 (the tabulated basis, largest at 780 nm), Σ_k B_k ≈ 1, so the
white texel is the equal-energy spectrum to that precision.

Band j of light reflected by a film under channel k is

$$ R_{jk}(\cos\theta_1) = \int S_j(\lambda) B_k(\lambda) R(\lambda, \cos\theta_1)\,d\lambda
   = \sum_i W_{ij} B_k(\lambda_i) R(\lambda_i, \cos\theta_1), $$

i.e. an ordinary band integral with the weights W_ij B_k(λ_i). `cross_band_name` names that
observer and `spectra.get_observer` builds it from `cross_band_weights` (J·K bands, band index
j·K + k), so every band-level tool of the library —
the exact spectral bands, the Fourier sum (K 4), the filtered Ŝ (K 18) and its LUT — applies
to R_jk unchanged, with Ŝ_jk(x) = Σ_i W_ij B_k(λ_i) e^{−2πix/λ_i}. Since Σ_k B_k ≈ 1,
Σ_k R_jk = R_j on the shared samples to the basis' 1e-5 (the summed weights differ from
W_ij by ≤ 4.3e-10 after the bands' unit-area normalisation).

Example (9 cross bands of the RGB observer; summed over k they are the plain bands):
    >>> import numpy as np
    >>> from thinfilm_jax.spectral.spectra import get_observer
    >>> from thinfilm_jax.spectral.uplift import cross_band_name
    >>> cross_band_name("stiles_burch_1959_10")
    'stiles_burch_1959_10+mallett2019'
    >>> cross = get_observer(cross_band_name("stiles_burch_1959_10"))
    >>> cross.n_bands, cross.band_names[:3]
    (9, ('R·r', 'R·g', 'R·b'))
    >>> plain = get_observer("stiles_burch_1959_10")
    >>> bool(np.allclose(cross.weights.reshape(-1, 3, 3).sum(-1), plain.weights))
    True
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["BASIS", "SEPARATOR", "cross_band_name", "basis_on", "cross_band_weights"]

BASIS = "mallett2019"
SEPARATOR = "+"


def cross_band_name(observer: str) -> str:
    """The observer name of the cross bands of `observer` (accepted by `get_observer`)."""
    return f"{observer}{SEPARATOR}{BASIS}"


@functools.cache
def basis_on(wavelengths: tuple[float, ...]) -> np.ndarray:
    """B_k(λ_i) (I, 3) on the given wavelengths: linear interpolation, constant outside."""
    import colour

    msds = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    lam0 = np.asarray(msds.wavelengths, float)
    vals = np.asarray(msds.values, float)
    lam = np.asarray(wavelengths, float)
    return np.stack([np.interp(lam, lam0, vals[:, k]) for k in range(vals.shape[1])], axis=-1)


def cross_band_weights(wavelengths: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """W_ij B_k(λ_i) as (I, J·K) with column j·K + k."""
    b = basis_on(tuple(float(x) for x in wavelengths))
    w = weights[:, :, None] * b[:, None, :]
    return w.reshape(weights.shape[0], -1)
