r"""Photographs read and decoded (SPEC §13): code values → linear signal, clipped pixels, noise.

Sources: an (H, W, 3) array (uint8, uint16, or float; RGBA drops alpha) or a file. PNG, JPEG,
TIFF, EXR and HDR are read with OpenImageIO, camera RAW (by suffix, `RAW_SUFFIXES`) with
rawpy/LibRaw; no parser is written here. Pixels keep their stored order: no EXIF orientation
is applied (RAW: ``user_flip=0``), so masks drawn on the stored image line up.

An integer code c of a b-bit source is the encoded value v = c / (2^b − 1) ∈ [0, 1].
Encodings (`ENCODINGS`):

* ``"srgb"``: the EOTF of IEC 61966-2-1 (colour-science ``cctf_decoding(v, "sRGB")``),
  L = v/12.92 for v ≤ 0.04045, ((v + 0.055)/1.055)^2.4 above; dL/dv = 1/12.92, resp.
  (2.4/1.055)·((v + 0.055)/1.055)^1.4 (`srgb_decoding_derivative`).
* ``"linear"``: L = v. ``"raw"``: L = v for camera RAW decoded by LibRaw to linear,
  demosaiced, camera-space RGB: no tone curve (``gamma=(1, 1)``), no auto-brightening
  (``no_auto_bright``, ``adjust_maximum_thr=0``: LibRaw's default 0.75 would rescale the
  brightest pixel to full scale), unit white balance, no colour matrix (``ColorSpace.raw``),
  16-bit output; black level subtracted and 1.0 = the white level. White balance and the
  camera matrix are fitted later (SPEC §13), so none is applied here.

Clipped pixels (unusable): an integer source with a channel at 2^b − 1 or every channel at 0;
a float sRGB source with a channel ≥ 1. Linear float data (EXR, HDR) are not clipped.

Noise, per pixel and channel, in linear units: σ_L = |dL/dv| · sqrt(σ_e² + σ_q²), where
σ_q² = q²/12 is the quantisation variance of a uniform rounding error of step q = 1/(2^b − 1)
(0 for float data) and σ_e the channel's sensor/compression noise in the encoded domain,
estimated by Immerkær's method (`estimate_noise`). On a smooth image σ_e already includes the
rounding error (a flat area may show none), so σ_v overestimates by at most √2 when
quantisation dominates.

References: IEC 61966-2-1:1999 (sRGB); J. Immerkær, "Fast noise variance estimation",
Computer Vision and Image Understanding 64(2), 300–302 (1996); LibRaw API, "Processing
parameters" (libraw.org/docs/API-datastruct-eng.html).

Example (sRGB code 188 of 255 is half the linear full scale; a flat image has no sensor
noise, so σ is the quantisation floor (1/255)/√12 times dL/dv = 1.523 there):
    >>> import numpy as np
    >>> from thinfilm_jax.core.image import read_photo
    >>> photo = read_photo(np.full((4, 4, 3), 188, np.uint8))
    >>> round(float(photo.linear[0, 0, 0]), 4), round(float(photo.noise[0, 0, 0]), 5)
    (0.5029, 0.00172)
    >>> photo.describe()
    'array: 4×4, 8-bit, sRGB (IEC 61966-2-1) decoded to linear; 0 clipped pixels'
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = [
    "ENCODINGS",
    "RAW_SUFFIXES",
    "Photo",
    "srgb_decoding",
    "srgb_encoding",
    "srgb_decoding_derivative",
    "estimate_noise",
    "read_photo",
    "read_mask",
]

ENCODINGS = ("srgb", "linear", "raw")
RAW_SUFFIXES = frozenset(".3fr .arw .cr2 .cr3 .crw .dcr .dng .erf .iiq .kdc .mef .mos .mrw .nef "
                         ".nrw .orf .pef .raf .rw2 .rwl .sr2 .srf .srw .x3f".split())
_SRGB_KNEE = 0.04045  # = 12.92 × 0.0031308 rounded, colour-science's switch point
_LABELS = {"srgb": "sRGB (IEC 61966-2-1) decoded to linear", "linear": "linear",
           "raw": "camera RAW (LibRaw linear camera RGB)"}


class Photo(NamedTuple):
    """A decoded photograph (module docstring): `linear` (H, W, 3) with 1.0 = full scale,
    `clipped` (H, W) unusable pixels, `noise` (H, W, 3) σ of each linear value."""

    linear: np.ndarray
    encoding: str
    bit_depth: int | None
    clipped: np.ndarray
    noise: np.ndarray
    source: str

    def describe(self) -> str:
        """One line: source, size, bit depth, encoding, clipped pixel count."""
        h, w = self.linear.shape[:2]
        name = Path(self.source).name if self.source != "array" else "array"
        depth = f"{self.bit_depth}-bit" if self.bit_depth else "float"
        n = int(self.clipped.sum())
        return (f"{name}: {w}×{h}, {depth}, {_LABELS[self.encoding]}; "
                f"{n} clipped pixel{'' if n == 1 else 's'}")


def srgb_decoding(v) -> np.ndarray:
    """Linear values L of sRGB-encoded values v (IEC 61966-2-1 EOTF: L = v/12.92 for
    v ≤ 0.04045, ((v + 0.055)/1.055)^2.4 above), float64, by colour-science's
    ``cctf_decoding(v, function="sRGB")``: the package's one sRGB decoder (photographs,
    LDR environment maps, a photo fit's clipping levels).

    Example:
        >>> float(srgb_decoding(0.5)), float(srgb_encoding(srgb_decoding(0.5)))
        (0.21404114048223255, 0.5)
    """
    import colour  # the IEC 61966-2-1 EOTF

    return np.asarray(colour.cctf_decoding(v, function="sRGB"), np.float64)


def srgb_encoding(linear) -> np.ndarray:
    """sRGB-encoded values of linear values (the inverse of `srgb_decoding`: IEC 61966-2-1's
    v = 12.92 L for L ≤ 0.0031308, 1.055 L^(1/2.4) − 0.055 above), float64, by colour-science's
    ``cctf_encoding(L, function="sRGB")``: the package's one sRGB encoder. No clipping: clip
    to [0, 1] first for display."""
    import colour  # the IEC 61966-2-1 inverse EOTF

    return np.asarray(colour.cctf_encoding(linear, function="sRGB"), np.float64)


def srgb_decoding_derivative(v) -> np.ndarray:
    """dL/dv of the IEC 61966-2-1 EOTF at encoded values v (module docstring)."""
    v = np.asarray(v, np.float64)
    return np.where(v <= _SRGB_KNEE, 1 / 12.92,
                    2.4 / 1.055 * ((np.maximum(v, _SRGB_KNEE) + 0.055) / 1.055) ** 1.4)


def estimate_noise(encoded, valid=None) -> np.ndarray:
    """Per-channel noise σ (3,) of an (H, W, 3) image by Immerkær (1996):
    σ = sqrt(π/2) / (6 (W−2)(H−2)) · Σ |I ∗ N|, N = [[1, −2, 1], [−2, 4, −2], [1, −2, 1]].

    N is the difference of two Laplacians, blind to constant and linear trends; on white
    noise E|I ∗ N| = sqrt(2/π)·6σ. Image structure (edges, texture, curvature) leaks
    through, so the estimate is biased upwards on textured images. `valid` (H, W) bool
    optionally drops every 3 × 3 window holding an invalid (e.g. clipped) pixel; the sum is
    then normalised by the count of windows kept. Zeros for images smaller than 3 × 3 or
    without a valid window.
    """
    a = np.asarray(encoded, np.float64)
    if a.ndim != 3 or a.shape[-1] != 3:
        raise ValueError(f"estimate_noise: encoded must be an (H, W, 3) image, got shape "
                         f"{a.shape}")
    h, w = a.shape[:2]
    if h < 3 or w < 3:
        return np.zeros(3)
    weights = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)
    response = sum(weights[i, j] * a[i:h - 2 + i, j:w - 2 + j]
                   for i in range(3) for j in range(3))
    keep = np.ones((h - 2, w - 2), bool)
    if valid is not None:
        valid = np.asarray(valid, bool)
        if valid.shape != (h, w):
            raise ValueError(f"estimate_noise: valid must have shape {(h, w)}, got "
                             f"{valid.shape}")
        for i in range(3):
            for j in range(3):
                keep &= valid[i:h - 2 + i, j:w - 2 + j]
    n = int(keep.sum())
    if n == 0:
        return np.zeros(3)
    return np.sqrt(np.pi / 2) / (6 * n) * np.abs(response[keep]).sum(axis=0)


def read_photo(image, encoding: str | None = "srgb", *, bit_depth: int | None = None) -> Photo:
    """Read and decode a photograph (module docstring) into a `Photo`.

    `image`: a path or an (H, W, 3|4) uint8/uint16/float array. `encoding`: one of
    `ENCODINGS`, or None for the source's own (RAW → "raw", integer → "srgb", float →
    "linear"); a RAW file takes only "raw". `bit_depth`: 8 or 16 to assert the source's.

    Raises ValueError for an unknown encoding or bit depth, an unreadable file (naming the
    path and the reader's message), a declared bit depth or encoding the source contradicts,
    a wrong shape or dtype, NaN/inf or negative values, or float sRGB values above 1.
    """
    if encoding is not None and encoding not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS} (or None), got {encoding!r}")
    if bit_depth not in (None, 8, 16):
        raise ValueError(f"bit_depth must be 8, 16 or None, got {bit_depth!r}")
    if isinstance(image, (str, Path)):
        source, what = str(image), f"image {str(image)!r}"
        if Path(image).suffix.lower() in RAW_SUFFIXES:
            if encoding not in (None, "raw"):
                raise ValueError(f"{what}: a camera RAW file is linear camera RGB; declared "
                                 f"encoding {encoding!r}, pass encoding='raw' (or None)")
            encoding, a = "raw", _read_raw(source, what)
        else:
            a = _read_oiio(source, what)
    else:
        source, what, a = "array", "image array", np.asarray(image)
    if a.ndim != 3 or a.shape[-1] not in (3, 4):
        raise ValueError(f"{what}: expected an (H, W, 3) RGB or (H, W, 4) RGBA image, got "
                         f"shape {a.shape}")
    a = a[..., :3]
    bits = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16}.get(a.dtype)
    if bits is None and not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"{what}: expected uint8, uint16 or float values, got dtype {a.dtype}")
    if bit_depth is not None and bits != bit_depth:
        raise ValueError(f"{what}: {'file' if source != 'array' else 'array'} is "
                         f"{f'{bits}-bit' if bits else 'float'}, declared {bit_depth}-bit")
    if encoding is None:
        encoding = "srgb" if bits else "linear"
    if bits:
        v = a.astype(np.float64) / (2**bits - 1)
        clipped = np.any(a == 2**bits - 1, axis=-1) | np.all(a == 0, axis=-1)
    else:
        v = a.astype(np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{what}: {int(np.sum(~np.isfinite(v)))} NaN or inf values")
        if np.any(v < 0):
            raise ValueError(f"{what}: {int(np.sum(v < 0))} negative values (a signal is ≥ 0)")
        if encoding == "srgb" and np.any(v > 1):
            raise ValueError(f"{what}: values up to {v.max():.4g}: an HDR/float image above 1 "
                             "is not sRGB-encoded; pass encoding='linear'")
        clipped = np.any(v >= 1, axis=-1) if encoding == "srgb" else np.zeros(v.shape[:2], bool)
    sigma_q2 = 1 / (12 * (2**bits - 1) ** 2) if bits else 0.0
    sigma_v = np.sqrt(estimate_noise(v, ~clipped) ** 2 + sigma_q2)
    if encoding == "srgb":
        linear = srgb_decoding(v)
        noise = sigma_v * srgb_decoding_derivative(v)
    else:
        linear, noise = v, np.broadcast_to(sigma_v, v.shape).copy()
    return Photo(linear, encoding, bits, clipped, noise, source)


def _read_oiio(path: str, what: str) -> np.ndarray:
    """The file's pixels in its own integer format (uint8/uint16) or as float32."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(path)
    if buf.has_error:
        raise ValueError(f"{what}: unreadable ({buf.geterror().strip()})")
    fmt = np.dtype(str(buf.spec().format))  # uint8, uint16, half, float, ...
    if fmt.kind in "iub" and fmt not in (np.uint8, np.uint16):
        raise ValueError(f"{what}: {fmt} pixels; expected 8- or 16-bit integer or float")
    px = buf.get_pixels({np.dtype(np.uint8): oiio.UINT8,
                         np.dtype(np.uint16): oiio.UINT16}.get(fmt, oiio.FLOAT))
    if buf.has_error or px is None:  # a truncated file errs only when its pixels are read
        raise ValueError(f"{what}: unreadable ({buf.geterror().strip()})")
    return np.asarray(px)


def _read_raw(path: str, what: str) -> np.ndarray:
    """Linear, demosaiced camera RGB, uint16, from LibRaw (module docstring)."""
    import rawpy

    try:
        with rawpy.imread(path) as raw:
            return raw.postprocess(
                gamma=(1, 1), no_auto_bright=True, adjust_maximum_thr=0.0, output_bps=16,
                use_camera_wb=False, use_auto_wb=False, user_wb=[1.0, 1.0, 1.0, 1.0],
                output_color=rawpy.ColorSpace.raw, user_flip=0)
    except (rawpy.LibRawError, rawpy.NotSupportedError, OSError) as e:
        msg = e.args[0].decode() if e.args and isinstance(e.args[0], bytes) else str(e)
        raise ValueError(f"{what}: unreadable by LibRaw ({msg})") from e


def read_mask(mask, shape: tuple[int, int], name: str = "mask") -> np.ndarray:
    """An (H, W) bool mask, True where nonzero, from an array ((H, W) or (H, W, C)) or an
    image file (OpenImageIO); with colour channels a pixel is True if any of its first three
    (or its only / grey) channel is nonzero, alpha ignored.

    Raises ValueError (naming `name`) for an unreadable file, NaN values, a shape other than
    `shape` (both given), or a mask with no True pixel.
    """
    if isinstance(mask, (str, Path)):
        a = _read_oiio(str(mask), f"{name} {str(mask)!r}")
    else:
        a = np.asarray(mask)
    if a.ndim == 3:
        a = a[..., :3] if a.shape[-1] >= 3 else a[..., :1]
    elif a.ndim != 2:
        raise ValueError(f"{name}: expected an (H, W) mask, got shape {a.shape}")
    if np.issubdtype(a.dtype, np.floating) and np.any(np.isnan(a)):
        raise ValueError(f"{name}: {int(np.isnan(a).sum())} NaN values")
    m = a != 0 if a.ndim == 2 else np.any(a != 0, axis=-1)
    if m.shape != tuple(shape):
        raise ValueError(f"{name}: shape {m.shape} differs from the image's {tuple(shape)} "
                         "(rows, columns)")
    if not m.any():
        raise ValueError(f"{name}: no True (nonzero) pixel")
    return m
