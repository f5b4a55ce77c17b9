"""The synthetic photographs of the photographs study (`benchmarks.photo_study`), rendered
independently of `fit_photo`'s model: the samples' thickness maps (an oxide wedge with
terraces, bevel and dome on silicon; a draining soap film with swirls), their spectral
reflectance by the stack recursion on a fine thickness grid, camera responses (colour-
science's measured cameras, or CIE XYZ → sRGB with its own white-balance error), a sensor
(shot and read noise at a full well), 8-bit sRGB encoding and image files.

Example (the scenes are deterministic; the bare terrace is exactly 0 nm):
    >>> from benchmarks.photo_scenes import oxide_thickness, soap_thickness
    >>> d, pads = oxide_thickness(96)
    >>> float(d.min()), float(d.max()) <= 900.0, [t for _, t in pads]
    (0.0, True, [0.0, 120.0, 210.0, 330.0, 520.0, 760.0])
    >>> h = soap_thickness(96)
    >>> round(float(h.min())), round(float(h.max()))
    (80, 1400)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.core.stack import Stack
from thinfilm_jax.optics.materials import refractive_index
from thinfilm_jax.optics.stack import stack_reflectance

FULL_WELL_E = 20_000.0  # electrons at full scale (1.0)
READ_NOISE_E = 5.0  # electrons rms
THICKNESS_STEP_NM = 0.1  # the rendering's thickness grid (1 nm in wavelength)
SOAP_RANGE, OXIDE_RANGE = (80.0, 1400.0), (0.0, 900.0)
#: (cx, cy, radius, turn in radians) of the soap film's swirls (unit square, y down)
SWIRLS = ((0.30, 0.38, 0.13, 2.6), (0.70, 0.55, 0.16, -3.2), (0.45, 0.82, 0.11, 2.2))
TERRACES = (0.0, 120.0, 210.0, 330.0, 520.0, 760.0)  # the oxide terraces (nm)


# ----------------------------------------------------------------------------- scenes
def _unit_grid(n: int):
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    return x, y


def soap_thickness(n: int, lo: float = SOAP_RANGE[0], hi: float = SOAP_RANGE[1]) -> np.ndarray:
    """(n, n) nm: a vertical soap film draining as h ∝ √(depth + 0.03) (the offset: the
    top's meniscus), its coordinates turned by `SWIRLS` (a turn decaying as a Gaussian of
    the distance to each centre), scaled to [lo, hi]."""
    x, y = _unit_grid(n)
    for cx, cy, r, turn in SWIRLS:
        dx, dy = x - cx, y - cy
        a = turn * np.exp(-(dx * dx + dy * dy) / (r * r))
        c, s = np.cos(a), np.sin(a)
        x, y = cx + c * dx - s * dy, cy + s * dx + c * dy
    f = np.sqrt(np.clip(y, 0.0, 1.0) + 0.03)
    return lo + (hi - lo) * (f - f.min()) / (f.max() - f.min())


def oxide_thickness(n: int):
    """((n, n) nm, pads): SiO₂ on Si, top 30 %: the `TERRACES` (uniform), next 30 %: a bevel
    0 → 900 nm across, bottom: a deposited dome 100 + 780·exp(−r²/(2·0.22²)) with a ±4 nm
    ripple. `pads`: [(mask (n, n) bool, thickness)] per terrace, two pixels inside its
    edges (the bare terrace, d = 0, is the bare-substrate reference)."""
    x, y = _unit_grid(n)
    k = np.minimum((x * len(TERRACES)).astype(int), len(TERRACES) - 1)
    dome = 100.0 + 780.0 * np.exp(-((x - 0.5) ** 2 + (y - 0.8) ** 2) / (2 * 0.22**2))
    dome = dome + 4.0 * np.sin(2 * np.pi * 5 * x) * np.sin(2 * np.pi * 3 * y)
    d = np.where(y < 0.3, np.asarray(TERRACES)[k], np.where(y < 0.6, 900.0 * x, dome))
    m = 2.0 / n
    pads = []
    for i, t in enumerate(TERRACES):
        lo, hi = i / len(TERRACES), (i + 1) / len(TERRACES)
        pads.append(((y > m) & (y < 0.3 - m) & (x > lo + m) & (x < hi - m), float(t)))
    return d, pads


def templates():
    """The scenes' materials (`Film`: the unknown thickness is the film's)."""
    return {"soap": Film(0.0, refractive_index("water"), 1.0),
            "oxide": Film(0.0, refractive_index("SiO2"), refractive_index("Si"))}


# ----------------------------------------------------------------------------- rendering
def reflectance_table(template: Film, d_max: float, lam_lo: float, lam_hi: float):
    """(d (G,), λ (L,), R (G, L)): the exact normal-incidence reflectance on a thickness
    grid of `THICKNESS_STEP_NM` up to d_max and on λ = lam_lo … lam_hi at 1 nm."""
    d = np.arange(0.0, d_max + THICKNESS_STEP_NM / 2, THICKNESS_STEP_NM)
    lam = np.arange(lam_lo, lam_hi + 0.5, 1.0)
    stack = Stack([0.0], (template.eta_film,), template.eta_base, template.eta_outer)
    rows = []
    for s in range(0, d.size, 4096):
        st = stack._replace(thickness=d[s:s + 4096, None, None])
        rows.append(np.asarray(stack_reflectance(st, 1.0, lam[None, :])))
    return d, lam, np.concatenate(rows)


def camera_table(r, lam, camera: str, illuminant: str):
    """(raw RGB (G, 3), white (3,)): colour-science's integration of R against a camera's
    sensitivities under a CIE illuminant at 1 nm on λ (the camera's range), normalised so
    that a white reflector reads 1 in green (raw: not white-balanced)."""
    import colour

    shape = colour.SpectralShape(float(lam[0]), float(lam[-1]), 1.0)
    kw = dict(cmfs=colour.MSDS_CAMERA_SENSITIVITIES[camera],
              illuminant=colour.SDS_ILLUMINANTS[illuminant], method="Integration",
              shape=shape)
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):  # "Aligning ..."
        rgb = np.asarray(colour.msds_to_XYZ(r, **kw))
        white = np.asarray(colour.msds_to_XYZ(np.ones((1, lam.size)), **kw))[0]
    return rgb / white[1], white / white[1]


def xyz_table(r, lam, illuminant: str):
    """(XYZ (G, 3), white xy (2,)): CIE 1931 2° tristimulus values of reflectances R under
    the light by colour-science's integration at 1 nm, Y of the white reflector = 1."""
    import colour

    kw = dict(cmfs=colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"],
              illuminant=colour.SDS_ILLUMINANTS[illuminant], method="Integration",
              shape=colour.SpectralShape(float(lam[0]), float(lam[-1]), 1.0))
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):  # "Aligning ..."
        xyz = np.asarray(colour.msds_to_XYZ(r, **kw)) / 100.0
        white = np.asarray(colour.msds_to_XYZ(np.ones((1, lam.size)), **kw))[0] / 100.0
    return xyz, np.asarray(colour.XYZ_to_xy(white))


def xyz_to_srgb(xyz, white_xy):
    """Linear sRGB of XYZ under a light of white `white_xy`: Bradford to D65 and
    ``colour.XYZ_to_RGB(..., "sRGB")``; not clipped (out-of-gamut values are < 0)."""
    import colour

    return np.asarray(colour.XYZ_to_RGB(xyz, "sRGB", illuminant=white_xy,
                                        chromatic_adaptation_transform="Bradford"))


def srgb_table(r, lam, illuminant: str):
    """Linear sRGB (G, 3) of reflectances R under the light (`xyz_table`, `xyz_to_srgb`)."""
    return xyz_to_srgb(*xyz_table(r, lam, illuminant))


def apply_table(d_grid, table, dmap):
    """The table's colours at the thickness map (linear interpolation): (H, W, 3)."""
    return np.stack([np.interp(dmap, d_grid, table[:, c]) for c in range(3)], axis=-1)


def sensor(v, rng):
    """Photon noise (variance = signal, `FULL_WELL_E` electrons at 1.0) and read noise
    (`READ_NOISE_E`) around v, then the clip to [0, 1]. An out-of-gamut v < 0 (an sRGB
    camera's matrix applied to raw readings) keeps its sign through the noise, so that it is
    clipped to black as a camera clips it."""
    e = np.maximum(v, 0.0) * FULL_WELL_E
    noise = rng.standard_normal(v.shape) * np.sqrt(e + READ_NOISE_E**2) / FULL_WELL_E
    return np.clip(v + noise, 0.0, 1.0)


def encode_srgb8(v):
    """uint8 code values of linear values v ∈ [0, 1] (IEC 61966-2-1 by colour-science)."""
    import colour

    enc = np.asarray(colour.cctf_encoding(np.clip(v, 0.0, 1.0), function="sRGB"))
    return np.round(enc * 255.0).astype(np.uint8)


def write_image(path, codes, quality: int | None = None) -> Path:
    """Write uint8/uint16 (H, W, 3) codes with OpenImageIO (JPEG at `quality`)."""
    import OpenImageIO as oiio

    h, w, _ = codes.shape
    fmt_ = oiio.UINT8 if codes.dtype == np.uint8 else oiio.UINT16
    spec = oiio.ImageSpec(w, h, 3, fmt_)
    if quality is not None:
        spec.attribute("Compression", f"jpeg:{quality}")
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    return Path(path)


def read_codes(path) -> np.ndarray:
    """The file's code values as stored (OpenImageIO)."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    fmt_ = oiio.UINT8 if str(buf.spec().format) == "uint8" else oiio.UINT16
    return np.asarray(buf.get_pixels(fmt_))
