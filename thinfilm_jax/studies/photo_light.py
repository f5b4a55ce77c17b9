r"""Uneven light, over-exposure and too few pads (SPEC §14): `fit_photo`'s smooth light field
and its flags of what it cannot explain, on photographs rendered independently of its model
(`studies.photo_scenes`).

``python -m thinfilm_jax.studies.photo_light --out figures`` writes figures/photo_light.json
and photo_light.md (``--size``: the photographs' side, default 160).

**Scenarios** (fixed seed):

* *uneven light*: the oxide wafer of `photo_scenes.oxide_thickness` (SiO₂ on Si), a 16-bit
  linear TIFF by the Nikon (known camera, D65), lit by a lamp off to one side (inverse-square
  falloff with the cosine of incidence, from a point at (−0.6, 0.3) of the frame's width, 1.2
  widths above the wafer) through a lens vignetting as cos⁴ of the field angle (a 35° half
  diagonal), the product scaled to 1 at its peak and 0.55 in the darkest corner (`light_field`;
  not in the fit's family). Bare-Si terrace as reference. Fitted with
  ``illumination="uniform"`` and ``"smooth"``; the same wafer evenly lit as the baseline.
* *over-exposed JPEG*: the soap film of `photo_scenes.soap_thickness` as an 8-bit sRGB JPEG
  (quality 90, D50) exposed 1.6 × the study's exposure, so that bright fringes clip.
* *pads*: the oxide wafer by the Nikon, ``camera="unknown"``, anchored by four terraces
  against all six.

Per row: median |error|, the share within 15 nm (the right fringe order), the share wrong, the
share of the wrong flagged `ambiguous`, the share of the right flagged, reduced χ² (mean and
robust), the fit's time and pixels per second.

Example (the light field's range):
    >>> from thinfilm_jax.studies.photo_light import light_field
    >>> f = light_field(64)
    >>> round(float(f.max()), 6), round(float(f.min()), 6)
    (1.0, 0.55)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from .photo_scenes import (SOAP_RANGE, apply_table, camera_table, encode_srgb8, oxide_thickness,
                           reflectance_table, sensor, soap_thickness, templates, write_image,
                           xyz_table, xyz_to_srgb)

NIKON = "Nikon 5100 (NPL)"
SEED = 20261206
CORNER = 0.55  # the darkest corner's light / the peak's
OXIDE_EXPOSURE = 1.6  # as photo_study's oxide photographs
SOAP_EXPOSURE, SOAP_LIGHT, SOAP_WB = 7.0 * 1.6, "D50", (1.08, 1.0, 0.93)
FOUR_PADS = (0, 1, 3, 4)
RIGHT_NM = 15.0


def light_field(n: int, corner: float = CORNER) -> np.ndarray:
    """(n, n) the light reaching the sensor relative to its peak: a lamp at (−0.6, 0.3, 1.2)
    (frame widths; the frame is the unit square, y down), E ∝ cos θ / r², times cos⁴ of the
    lens's field angle (35° at the corners), mapped affinely in log so that the peak is 1
    and the darkest pixel `corner`."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    dx, dy, dz = x + 0.6, y - 0.3, 1.2
    r2 = dx * dx + dy * dy + dz * dz
    lamp = dz / r2 ** 1.5
    rr = np.hypot(x - 0.5, y - 0.5) / np.hypot(0.5, 0.5)
    vig = np.cos(np.arctan(rr * np.tan(np.deg2rad(35.0)))) ** 4
    f = np.log(lamp * vig)
    f = (f - f.max()) / (f.max() - f.min()) * -np.log(corner)
    return np.exp(f)


def render(n: int, folder) -> dict:
    """The scenarios' photographs in `folder`: {key: path}, the truth maps and the pads."""
    rng = np.random.default_rng(SEED)
    folder = Path(folder)
    tpl = templates()
    oxide, pads = oxide_thickness(n)
    d_g, lam, r = reflectance_table(tpl["oxide"], 901.0, 380.0, 780.0)
    raw, _ = camera_table(r, lam, NIKON, "D65")
    colours = OXIDE_EXPOSURE * apply_table(d_g, raw, oxide)
    paths = {}
    for key, field in (("even", 1.0), ("uneven", light_field(n)[..., None])):
        v = sensor(colours * field, rng)
        paths[key] = write_image(folder / f"oxide_{key}.tif",
                                 np.round(v * 65535).astype(np.uint16))
    soap = soap_thickness(n)
    d_g, lam, r = reflectance_table(tpl["soap"], SOAP_RANGE[1] + 1.0, 360.0, 830.0)
    xyz_t, white = xyz_table(r, lam, SOAP_LIGHT)
    xyz = sensor(SOAP_EXPOSURE * apply_table(d_g, xyz_t, soap), rng)
    v = np.clip(np.asarray(SOAP_WB) * xyz_to_srgb(xyz, white), 0.0, 1.0)
    paths["soap_over"] = write_image(folder / "soap_over.jpg", encode_srgb8(v), quality=90)
    return {"paths": paths, "oxide": oxide, "soap": soap, "pads": pads}
