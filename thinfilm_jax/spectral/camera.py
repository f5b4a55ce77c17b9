r"""Cameras and lights: how a reflectance spectrum becomes three camera numbers (SPEC §13).

A camera channel c under a light of spectral power E(λ) reads a surface of reflectance R(λ) as

$$ s_c = \frac{\int E(\lambda) Q_c(\lambda) R(\lambda)\,d\lambda}
              {\int E(\lambda) Q_c(\lambda)\,d\lambda}
       \approx \sum_k w_{kc} R(\lambda_k), $$

with Q_c the channel's spectral sensitivity and w the trapezoid-rule weights on the camera's
tabulated wavelengths λ_k. The denominator white-balances the camera to the light: a perfect
white reflector reads (1, 1, 1). The photograph is then ``exposure · wb_c · s_c`` (fitted,
`thinfilm_jax.fit.photo`).

Kinds of camera (`camera_response`):

* a **spectral camera**: a name in colour-science's ``MSDS_CAMERA_SENSITIVITIES`` (measured
  at NPL, Darrodi et al. 2015), a CSV with a header ``wavelength_nm, r, g, b``, or arrays
  ``(wavelengths (K,), sensitivities (K, 3))``;
* ``"srgb"``: a colorimetric sRGB image. The channels are CIE 1931 2° tristimulus values under
  the light, adapted to D65 by the Bradford transform (colour-science's von Kries
  implementation), in linear sRGB (IEC 61966-2-1 primaries). A final per-channel factor
  (within 2e-3 of 1) makes the spectral white read exactly (1, 1, 1);
* ``"unknown"``: the channels are this library's observer bands (SPEC §1) under the light,
  and a 3 × 3 matrix from bands to camera RGB is fitted on reference regions. The bands are
  cut to the light's data (CIE tables end at 780 nm; Stiles–Burch has 6e-6 of its R band's
  weight beyond). Real cameras
  violate Luther's condition (their sensitivities are not a linear map of colour-matching
  functions, Luther 1927), so that matrix has an error of its own, measured in the
  photographs study. `fit_photo` then estimates the sensitivities themselves on a basis of
  hat functions (`sensitivity_basis`: piecewise-linear Q_c(λ) through values at knots every
  25 nm, 380–780 nm), which a thin film's spectra, rich in structure across its thicknesses,
  determine (the spectral-sensitivity estimation of Jiang et al. 2013, with the film as the
  target).

Lights (`illuminant_spd`): a CIE illuminant name from ``colour.SDS_ILLUMINANTS`` or a measured
spectrum (a ``colour.SpectralDistribution`` or an (M, 2) array of λ in nm and power). Data
are interpolated linearly onto the camera's wavelengths; a light that does not cover them is
an error, never an extrapolation.

Example (a white reflector reads 1 in every channel, for every kind of camera):
    >>> import numpy as np
    >>> from thinfilm_jax.spectral.camera import camera_response
    >>> for name in ("srgb", "Nikon 5100 (NPL)", "unknown"):
    ...     cam = camera_response(name, "A")
    ...     print(name, np.round(cam.weights.sum(axis=0), 12))
    srgb [ 1.  1.  1.]
    Nikon 5100 (NPL) [ 1.  1.  1.]
    unknown [ 1.  1.  1.]
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from .spectra import DEFAULT_OBSERVER, get_observer

__all__ = ["CAMERAS", "Camera", "camera_response", "illuminant_spd", "known_cameras",
           "known_illuminants", "sensitivity_basis"]

#: the kinds that are not a sensitivity table
CAMERAS = ("srgb", "unknown")
_SRGB_STEP = 5.0  # nm: the CIE 1931 2° observer on 380–780 nm at 5 nm (81 wavelengths)


class Camera(NamedTuple):
    """A camera under a light, host-side: ``s = weights.T @ R(wavelengths)`` (3,).

    Attributes:
        name: the camera's name ("srgb", "unknown", a colour-science name or a file).
        kind: "spectral", "srgb" or "unknown" (then `weights` are the observer's bands and a
            3 × 3 matrix is fitted on top).
        illuminant: the light's name (or "measured").
        wavelengths: λ_k (K,) nm.
        weights: (K, 3), each column summing to 1 (a white reflector reads (1, 1, 1)).
    """

    name: str
    kind: str
    illuminant: str
    wavelengths: np.ndarray
    weights: np.ndarray


def known_cameras() -> list[str]:
    """Every camera name `camera_response` takes (besides arrays and CSV files)."""
    import colour

    return [*CAMERAS, *colour.MSDS_CAMERA_SENSITIVITIES]


def known_illuminants() -> list[str]:
    """Every CIE illuminant name colour-science ships."""
    import colour

    return list(colour.SDS_ILLUMINANTS)


def illuminant_spd(illuminant) -> tuple[str, np.ndarray, np.ndarray]:
    """(name, λ (M,), power (M,)) of a CIE illuminant name or a measured spectrum."""
    import colour

    if isinstance(illuminant, str):
        if illuminant not in colour.SDS_ILLUMINANTS:
            raise ValueError(f"unknown illuminant {illuminant!r}; known: "
                             f"{', '.join(known_illuminants())}, or a measured spectrum")
        sd = colour.SDS_ILLUMINANTS[illuminant]
        return illuminant, np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)
    if isinstance(illuminant, colour.SpectralDistribution):
        lam, power = illuminant.wavelengths, illuminant.values
    else:
        a = np.asarray(illuminant, float)
        if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 2:
            raise ValueError(f"illuminant must be a name or an (M, 2) array of wavelength (nm) "
                             f"and power, got shape {a.shape}")
        lam, power = a[:, 0], a[:, 1]
    lam, power = np.asarray(lam, float), np.asarray(power, float)
    if not (np.all(np.isfinite(power)) and np.all(power >= 0) and np.all(np.diff(lam) > 0)):
        raise ValueError("a measured illuminant needs increasing wavelengths and finite, "
                         "non-negative power")
    return "measured", lam, power


def _resample(lam, values, onto, what):
    """Linear interpolation of tabulated (λ, values) onto `onto`, which they must cover."""
    if onto[0] < lam[0] - 1e-9 or onto[-1] > lam[-1] + 1e-9:
        raise ValueError(f"{what} covers {lam[0]:g}–{lam[-1]:g} nm, the camera needs "
                         f"{onto[0]:g}–{onto[-1]:g} nm")
    values = np.asarray(values, float)
    if values.ndim == 1:
        return np.interp(onto, lam, values)
    return np.stack([np.interp(onto, lam, v) for v in values.T], axis=-1)


def _trapezoid(lam):
    t = np.zeros_like(lam)
    dl = np.diff(lam)
    t[:-1] += dl / 2
    t[1:] += dl / 2
    return t


def _sensitivities(camera):
    """(name, λ (K,), Q (K, 3)) of a spectral camera given by name, CSV path or arrays."""
    import colour

    if isinstance(camera, str) and camera in colour.MSDS_CAMERA_SENSITIVITIES:
        m = colour.MSDS_CAMERA_SENSITIVITIES[camera]
        return camera, np.asarray(m.wavelengths, float), np.asarray(m.values, float)
    if isinstance(camera, (str, Path)):
        path = Path(camera)
        if path.suffix.lower() != ".csv" or not path.is_file():
            raise ValueError(f"unknown camera {str(camera)!r}; known: "
                             f"{', '.join(known_cameras())}, a CSV file of sensitivities "
                             f"(header wavelength_nm,r,g,b) or (wavelengths, sensitivities)")
        table = np.genfromtxt(path, delimiter=",", names=True)
        names = [n.lower() for n in table.dtype.names]
        need = ("wavelength_nm", "r", "g", "b")
        if any(n not in names for n in need):
            raise ValueError(f"{path}: the header must name {', '.join(need)}; got {names}")
        col = {n.lower(): n for n in table.dtype.names}
        lam = np.asarray(table[col["wavelength_nm"]], float)
        q = np.stack([np.asarray(table[col[c]], float) for c in "rgb"], axis=-1)
        return path.name, lam, q
    try:
        lam, q = camera
    except (TypeError, ValueError):
        raise ValueError("camera must be a name, a CSV path or (wavelengths (K,), "
                         "sensitivities (K, 3))") from None
    lam, q = np.asarray(lam, float), np.asarray(q, float)
    if lam.ndim != 1 or q.shape != (lam.size, 3) or lam.size < 2:
        raise ValueError(f"camera sensitivities must be (K,) wavelengths and (K, 3) values, "
                         f"got {lam.shape} and {q.shape}")
    return "sensitivities", lam, q


def sensitivity_basis(illuminant="D65", *, spacing_nm: float = 25.0) -> Camera:
    """A `Camera` of kind "basis" whose B columns are hat functions on knots every
    `spacing_nm` over 380–780 nm under the light (each column summing to 1): a camera with
    piecewise-linear sensitivities reads s = A · (this camera's reading), A (3, B)."""
    light, lam_e, power = illuminant_spd(illuminant)
    lam = np.arange(380.0, 780.0 + _SRGB_STEP / 2, _SRGB_STEP)
    knots = np.linspace(380.0, 780.0, int(round(400.0 / spacing_nm)) + 1)
    hats = np.stack([np.interp(lam, knots, np.eye(knots.size)[b]) for b in range(knots.size)],
                    axis=-1)
    w = _trapezoid(lam)[:, None] * hats * _resample(lam_e, power, lam,
                                                    f"illuminant {light}")[:, None]
    return Camera("basis", "basis", light, lam, w / w.sum(axis=0))


def camera_response(camera, illuminant="D65", *, observer: str = DEFAULT_OBSERVER) -> Camera:
    """The `Camera` (weights w (K, 3), module docstring) of `camera` under `illuminant`.

    Raises:
        ValueError: an unknown camera or illuminant (listing the known ones), sensitivities
            that are negative, non-finite or of the wrong shape, a light that does not cover
            the camera's wavelengths, or a channel that sees no light.
    """
    light, lam_e, power = illuminant_spd(illuminant)
    if isinstance(camera, str) and camera == "srgb":
        import colour

        cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
        lam = np.arange(380.0, 780.0 + _SRGB_STEP / 2, _SRGB_STEP)
        xyz = _resample(np.asarray(cmfs.wavelengths, float), cmfs.values, lam, "CIE 1931 2°")
        w = _trapezoid(lam)[:, None] * xyz * _resample(lam_e, power, lam,
                                                       f"illuminant {light}")[:, None]
        w = w / w[:, 1].sum()  # Y of the white reflector = 1
        d65 = _trapezoid(lam)[:, None] * xyz * _resample(
            *illuminant_spd("D65")[1:], lam, "D65")[:, None]
        white, white_d65 = w.sum(axis=0), d65.sum(axis=0) / d65[:, 1].sum()
        cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(
            white, white_d65, transform="Bradford")
        m = colour.models.RGB_COLOURSPACE_sRGB.matrix_XYZ_to_RGB @ cat
        weights = w @ m.T
        return Camera("srgb", "srgb", light, lam, weights / weights.sum(axis=0))
    if isinstance(camera, str) and camera == "unknown":
        obs = get_observer(observer)
        keep = (obs.wavelengths >= lam_e[0]) & (obs.wavelengths <= lam_e[-1])
        lam = np.asarray(obs.wavelengths, float)[keep]  # the light's data end (CIE: 780 nm)
        w = np.asarray(obs.weights, float)[keep] * _resample(lam_e, power, lam,
                                                             f"illuminant {light}")[:, None]
        return Camera("unknown", "unknown", light, lam, w / w.sum(axis=0))
    name, lam, q = _sensitivities(camera)
    if not (np.all(np.isfinite(q)) and np.all(q >= 0) and np.all(np.diff(lam) > 0)):
        raise ValueError(f"camera {name!r}: sensitivities must be finite and non-negative on "
                         f"increasing wavelengths")
    w = _trapezoid(lam)[:, None] * q * _resample(lam_e, power, lam,
                                                 f"illuminant {light}")[:, None]
    total = w.sum(axis=0)
    if np.any(total <= 0):
        raise ValueError(f"camera {name!r}: a channel sees no light under {light}")
    return Camera(name, "spectral", light, lam, w / total)
