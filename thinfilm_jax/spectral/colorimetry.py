r"""Band values ↔ XYZ ↔ linear Rec. 709 ↔ display sRGB, and CIEDE2000 ΔE (host side, NumPy).

The library's one colour convention: every conversion between band values and RGB, and every
ΔE₀₀ of every study, goes through this module.

**White.** Uniform lighting means an equal-energy spectrum, so the white is the perfect mirror
(R ≡ 1, every band 1). For the CIE 1931 observer the bands are x̄, ȳ, z̄ and
XYZ ∝ diag(areas)·R. For Stiles & Burch 1959 10° RGB the CIE 1964 10° XYZ functions are a
linear transform of the RGB functions; the 3×3 matrix is the least-squares solution of
x̄ȳz̄(λ) = M r̄ḡb̄(λ) between colour-science's two tabulations (`colour.colorimetry.
RGB_10_degree_cmfs_to_XYZ_10_degree_cmfs` evaluated at the S&B wavelengths), i.e. derived
from the library's data, not typed in. In both cases XYZ = T 𝐛 (`band_to_xyz_matrix`) is
scaled so that the white has Y = 1.

**Rec. 709 (= linear sRGB).** One matrix: ITU-R BT.709's primaries and its D65 white
(x, y) = (0.3127, 0.3290), the normalised primary matrix P (RGB → XYZ, colour-science's
``RGB_COLOURSPACES["ITU-R BT.709"]``, derived from the chromaticities, so P·(1, 1, 1) is the
white exactly). sRGB (IEC 61966-2-1) has the same primaries and white; its printed
four-decimal matrices, which colour-science's ``XYZ_to_sRGB`` uses, differ from P⁻¹ by
≤ 3.7·10⁻⁴. The whites differ (D65 there, the mirror here), so the map between bands and
Rec. 709 adapts one to the other by von Kries in the cone space of CAT02 (CIE 159:2004;
Moroney et al. 2002, "The CIECAM02 color appearance model", IS&T/SID CIC 10), full adaptation:

$$ \mathbf c = P^{-1} K\, T\,\mathbf b,\qquad
   K = M_{\rm CAT02}^{-1}\operatorname{diag}\!\Big(\frac{M_{\rm CAT02}W_{D65}}
       {M_{\rm CAT02}W_E}\Big) M_{\rm CAT02}, $$

W_E = T·(1, …, 1) the mirror's white and W_D65 = P·(1, 1, 1) (`bands_to_rec709`; K from
colour-science's ``matrix_chromatic_adaptation_VonKries(..., transform="CAT02")``).
`rec709_to_bands` is its matrix inverse (observers with three bands). K W_E = W_D65, so a
flat reflectance R is RGB (R, R, R) and bands (R, R, R), whatever the observer. Display sRGB
(`bands_to_srgb`) is the IEC 61966-2-1 encoding of `bands_to_rec709` clipped to [0, 1]; the
linear EXRs of the studies are `bands_to_rec709` itself. (The 10° observer's XYZ is used as
if it were the 2° one for display: CIE 1964 XYZ goes through the same P.)

**Light, not colour.** A map texel's linear RGB is the *spectrum* Σ_k c_k B_k(λ) of the
Mallett–Yuksel basis (SPEC §9, `spectral.uplift`); seen in a perfect mirror its bands are
M c, M_jk = ∫ S_j B_k dλ (`uplift_to_bands`). That is the physics of the IBL reference, not a
colorimetric conversion: it agrees with `rec709_to_bands` on the white and differs for
coloured light (by ≤ 0.07 per band for the unit primaries, Stiles & Burch bands).

**ΔE₀₀** (SPEC §7, last paragraph: both colours converted the same way, white = the perfect
mirror). `delta_e2000(a, b, observer)`: both band values → XYZ = T𝐛 → CIELAB with the mirror's
white (Y = 1) → CIEDE2000 (Sharma, Wu & Dalal 2005, colour-science). An RGB output (the `khr`
method's linear Rec. 709) is first taken to the observer's bands by `rec709_to_bands`
(`delta_e2000_rec709`), so it is compared in the same space as every band method.

Example (the perfect mirror is the white: Y = 1, sRGB white, ΔE 0 to itself; flat stays flat):
    >>> import numpy as np
    >>> from thinfilm_jax.spectral.colorimetry import (bands_to_rec709, bands_to_srgb,
    ...     bands_to_xyz, delta_e2000, rec709_to_bands)
    >>> bands_to_xyz(np.ones(3)).round(4).tolist()  # Stiles & Burch bands → CIE 1964 XYZ
    [0.9955, 1.0, 0.9836]
    >>> bands_to_srgb(np.ones(3)).round(3).tolist()
    [1.0, 1.0, 1.0]
    >>> float(delta_e2000(np.ones(3), np.ones(3)))
    0.0
    >>> np.round(rec709_to_bands(np.full(3, 0.3), "cie_1931_2"), 12).tolist()
    [0.3, 0.3, 0.3]
    >>> c = np.array([0.3, 0.2, 0.1])
    >>> bool(np.abs(bands_to_rec709(rec709_to_bands(c)) - c).max() < 1e-14)
    True
"""

from __future__ import annotations

import functools

import numpy as np

from ..core.image import srgb_encoding
from .spectra import DEFAULT_OBSERVER, get_observer
from .uplift import basis_on

__all__ = [
    "CIE_1931",
    "band_to_xyz_matrix",
    "bands_to_xyz",
    "white_xy",
    "rec709_to_band_matrix",
    "bands_to_rec709",
    "rec709_to_bands",
    "xyz_to_srgb",
    "bands_to_srgb",
    "uplift_to_bands",
    "delta_e2000",
    "delta_e2000_rec709",
]

#: The CIE 1931 2° observer: the one glTF's `khr` sensitivity fit approximates.
CIE_1931 = "cie_1931_2"


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


@functools.cache
def rec709_to_xyz_matrix() -> np.ndarray:
    """P (3×3): linear ITU-R BT.709 RGB → XYZ, D65 (0.3127, 0.3290), P·(1, 1, 1) = the white
    with Y = 1 (derived from the chromaticities by colour-science)."""
    import colour

    return np.array(colour.RGB_COLOURSPACES["ITU-R BT.709"].matrix_RGB_to_XYZ, float)


@functools.cache
def _xyz_to_rec709_matrix(observer: str) -> np.ndarray:
    """P⁻¹ K (3×3): XYZ with the mirror's white → linear Rec. 709 (CAT02 von Kries to D65)."""
    import colour

    p = rec709_to_xyz_matrix()
    k = colour.adaptation.matrix_chromatic_adaptation_VonKries(
        band_to_xyz_matrix(observer).sum(axis=1), p.sum(axis=1), transform="CAT02")
    return np.linalg.solve(p, np.asarray(k, float))


@functools.cache
def band_to_rec709_matrix(observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """3×J matrix P⁻¹ K T (module docstring): bands → linear Rec. 709, mirror → (1, 1, 1)."""
    return _xyz_to_rec709_matrix(observer) @ band_to_xyz_matrix(observer)


@functools.cache
def rec709_to_band_matrix(observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """The inverse (3×3) of `band_to_rec709_matrix` for an observer with three bands."""
    a = band_to_rec709_matrix(observer)
    if a.shape != (3, 3):
        raise ValueError(f"observer {observer!r} has {a.shape[1]} bands: linear Rec. 709 "
                         "maps to the bands of an observer with 3 bands only")
    return np.linalg.inv(a)


def _check_last_axis(name, x, n):
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"{name} must have a last axis of length {n}, got shape {x.shape}")


def bands_to_rec709(values, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    r"""Linear Rec. 709 RGB (…, 3) of band values (…, J), unclipped (host, NumPy):
    𝐜 = P⁻¹ K T 𝐛 (module docstring), the mirror white adapted to D65 by CAT02. The perfect
    mirror (every band 1) is RGB (1, 1, 1); the inverse is `rec709_to_bands` (round trip the
    identity to rounding: measured ≤ 3e-15 on [0, 1.2]³). Also the studies' linear sRGB
    (same primaries and white; the EXRs).

    Example (flat stays flat):
        >>> import numpy as np
        >>> np.round(bands_to_rec709(np.full(3, 0.3), "cie_1931_2"), 12).tolist()
        [0.3, 0.3, 0.3]
    """
    a = band_to_rec709_matrix(observer)
    values = np.asarray(values, float)
    _check_last_axis("values", values, a.shape[1])
    return values @ a.T


def rec709_to_bands(rgb, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    r"""Band values (…, 3) of `observer` of linear Rec. 709 RGB (…, 3) (host, NumPy): the
    inverse of `bands_to_rec709`, 𝐛 = T⁻¹ K⁻¹ P 𝐜 (module docstring), D65 adapted to the
    mirror's equal-energy white by CAT02, so RGB (R, R, R) is bands (R, R, R). How the `khr`
    method's output (SPEC §10) is compared with, and displayed like, every band method.

    Example (flat stays flat; a non-grey colour changes):
        >>> import numpy as np
        >>> np.round(rec709_to_bands(np.full(3, 0.3), "cie_1931_2"), 12).tolist()
        [0.3, 0.3, 0.3]
        >>> bool(np.ptp(rec709_to_bands(np.array([0.3, 0.2, 0.1]), "cie_1931_2")) > 0.05)
        True
    """
    rgb = np.asarray(rgb, float)
    _check_last_axis("rgb", rgb, 3)
    return rgb @ rec709_to_band_matrix(observer).T


def xyz_to_srgb(xyz, observer: str = DEFAULT_OBSERVER, exposure: float = 1.0) -> np.ndarray:
    """Display sRGB in [0, 1] (clipped) of XYZ·exposure, mirror white adapted to D65
    (`bands_to_srgb` for XYZ = T 𝐛)."""
    return _encode(np.asarray(xyz, float) * exposure @ _xyz_to_rec709_matrix(observer).T)


def bands_to_srgb(values, observer: str = DEFAULT_OBSERVER, exposure: float = 1.0):
    """Display sRGB in [0, 1] of band values (…, J)·exposure: `bands_to_rec709` clipped to
    [0, 1] and encoded by IEC 61966-2-1's transfer function."""
    return _encode(bands_to_rec709(np.asarray(values, float) * exposure, observer))


def _encode(rgb):
    return srgb_encoding(np.clip(rgb, 0.0, 1.0))


@functools.cache
def uplift_band_matrix(observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """M (J, 3), M_jk = Σ_i W_ij B_k(λ_i) = ∫ S_j B_k dλ: the bands of uplifted RGB light."""
    obs = get_observer(observer)
    b = basis_on(tuple(float(x) for x in obs.wavelengths))
    return np.asarray(obs.weights, float).T @ b


def uplift_to_bands(rgb, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """Band values (…, J) of linear-RGB *radiance* (…, 3) seen in a perfect mirror: the
    Mallett–Yuksel spectrum of SPEC §9 integrated against the bands (module docstring; not
    the colorimetric `rec709_to_bands`)."""
    rgb = np.asarray(rgb, float)
    _check_last_axis("rgb", rgb, 3)
    return rgb @ uplift_band_matrix(observer).T


def delta_e2000(values_a, values_b, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """CIEDE2000 ΔE between band values a and b (…, J): both → XYZ = T𝐛 → CIELAB with the
    perfect mirror as white (SPEC §7)."""
    import colour

    wxy = white_xy(observer)
    lab_a = colour.XYZ_to_Lab(bands_to_xyz(values_a, observer), illuminant=wxy)
    lab_b = colour.XYZ_to_Lab(bands_to_xyz(values_b, observer), illuminant=wxy)
    return np.asarray(colour.delta_E(lab_a, lab_b, method="CIE 2000"))


def delta_e2000_rec709(rgb, values, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """CIEDE2000 ΔE between linear Rec. 709 RGB (…, 3) (the `khr` method's output) and band
    values (…, 3) of `observer`: ``delta_e2000(rec709_to_bands(rgb, observer), values,
    observer)``, the one convention of every study.

    Example (a flat reflectance in both conventions):
        >>> import numpy as np
        >>> float(delta_e2000_rec709(np.full(3, 0.3), np.full(3, 0.3))) < 1e-9
        True
    """
    return delta_e2000(rec709_to_bands(rgb, observer), values, observer)
