r"""From band values to XYZ, sRGB and CIEDE2000 ΔE, through colour-science (host side, NumPy).

Uniform lighting means an equal-energy spectrum, so the white is the perfect mirror
(R ≡ 1, every band 1). For the CIE 1931 observer the bands are x̄, ȳ, z̄ and
XYZ ∝ diag(areas)·R. For Stiles & Burch 1959 10° RGB the CIE 1964 10° XYZ functions are a
linear transform of the RGB functions; the 3×3 matrix is the least-squares solution of
x̄ȳz̄(λ) = M r̄ḡb̄(λ) between colour-science's two tabulations (`colour.colorimetry.
RGB_10_degree_cmfs_to_XYZ_10_degree_cmfs` evaluated at the S&B wavelengths), i.e. derived
from the library's data, not typed in. In both cases XYZ is scaled so the white has Y = 1.

sRGB: colour.XYZ_to_sRGB with chromatic adaptation (CAT02) from the mirror white to D65 and
the sRGB transfer function. (The 10° observer is used as if it were the 2° one for display;
ΔE is computed in the observer's own XYZ with the mirror as white.)

Example (the perfect mirror is the white: Y = 1, sRGB white, ΔE 0 to itself):
    >>> import numpy as np
    >>> from thinfilm_jax.spectral.colorimetry import bands_to_srgb, bands_to_xyz, delta_e2000
    >>> bands_to_xyz(np.ones(3)).round(4).tolist()  # Stiles & Burch bands → CIE 1964 XYZ
    [0.9955, 1.0, 0.9836]
    >>> bands_to_srgb(np.ones(3)).round(3).tolist()
    [1.0, 1.0, 1.0]
    >>> float(delta_e2000(np.ones(3), np.ones(3)))
    0.0
"""

from __future__ import annotations

import functools

import numpy as np

from .spectra import DEFAULT_OBSERVER, get_observer


@functools.cache
def band_to_xyz_matrix(observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """3×J matrix T with XYZ = T @ R_bands and (T @ 1)_Y = 1."""
    import colour

    obs = get_observer(observer)
    if observer == "cie_1931_2":
        m = np.eye(3)
    else:
        cmfs = colour.MSDS_CMFS["Stiles & Burch 1959 10 Degree RGB CMFs"]
        rgb = np.asarray(cmfs.values, float)
        xyz = np.asarray(colour.colorimetry.RGB_10_degree_cmfs_to_XYZ_10_degree_cmfs(
            cmfs.wavelengths), float)
        m = np.linalg.lstsq(rgb, xyz, rcond=None)[0].T
    t = m * obs.areas[None, :]
    return t / t[1].sum()


def bands_to_xyz(values, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """XYZ (…, 3) of band values (…, J); the perfect mirror maps to the white, Y = 1."""
    return np.asarray(values, float) @ band_to_xyz_matrix(observer).T


def white_xy(observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """Chromaticity of the perfect mirror under equal-energy light."""
    w = band_to_xyz_matrix(observer).sum(axis=1)
    return w[:2] / w.sum()


def xyz_to_srgb(xyz, observer: str = DEFAULT_OBSERVER, exposure: float = 1.0) -> np.ndarray:
    """Display sRGB in [0, 1] (clipped) of XYZ·exposure, mirror white adapted to D65."""
    import colour

    rgb = colour.XYZ_to_sRGB(np.asarray(xyz, float) * exposure, illuminant=white_xy(observer),
                             chromatic_adaptation_transform="CAT02")
    return np.clip(rgb, 0.0, 1.0)


def bands_to_srgb(values, observer: str = DEFAULT_OBSERVER, exposure: float = 1.0):
    """sRGB for display of band values (…, J)."""
    return xyz_to_srgb(bands_to_xyz(values, observer), observer, exposure)


def delta_e2000(values_a, values_b, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """CIEDE2000 ΔE between band values a and b (…, J), Lab with the mirror as white."""
    import colour

    wxy = white_xy(observer)
    lab_a = colour.XYZ_to_Lab(bands_to_xyz(values_a, observer), illuminant=wxy)
    lab_b = colour.XYZ_to_Lab(bands_to_xyz(values_b, observer), illuminant=wxy)
    return np.asarray(colour.delta_E(lab_a, lab_b, method="CIE 2000"))
