r"""Environment maps: loading, texel geometry and lookups (SPEC §9).

An `EnvMap` holds linear Rec. 709 RGB radiance on an equirectangular grid, world frame z-up:
row i covers θ ∈ [iπ/H, (i+1)π/H] from +z (row 0 is the top), column j covers
φ ∈ [2πj/W, 2π(j+1)/W] from +x toward +y, ω = (sin θ cos φ, sin θ sin φ, cos θ). Texels are
piecewise constant; texel (i, j) has solid angle Ω_i = (cos(iπ/H) − cos((i+1)π/H))·2π/W.

Files are read with OpenImageIO (Radiance .hdr, OpenEXR .exr and anything else it reads);
no parser is written here. An integer image file (8-bit PNG or JPEG, 16-bit PNG or TIFF) is
refused: its code values are display-encoded (sRGB, clipped at the display's white), not
radiance; read as radiance, its mid-tones would be too bright (code 0.5 is radiance 0.21) and
its sun no brighter than white. `load_envmap(path, ldr_srgb=True)` reads one knowingly, each
code value normalised to V ∈ [0, 1] and decoded with the sRGB EOTF of IEC 61966-2-1
(colour-science's ``cctf_decoding(V, "sRGB")``): L = V/12.92 for V ≤ 0.04045,
((V + 0.055)/1.055)^2.4 above, relative radiance with the display's white at 1. Four CC0
Poly Haven maps ship with the package (`SHIPPED`), downsampled by `downsample`
(solid-angle-weighted box filter, which preserves the integral ∫ L dω of every channel
exactly).

Example (the texels tile the sphere, 4π sr; `downsample` keeps ∫ L dω of every channel):
    >>> import numpy as np
    >>> from thinfilm_jax.shading.envmap import downsample, load_envmap, texel_solid_angles
    >>> round(float(texel_solid_angles(8, 16).sum() / np.pi), 12)
    4.0
    >>> env = load_envmap(np.random.default_rng(0).uniform(size=(8, 16, 3)))
    >>> env.shape
    (8, 16)
    >>> def integral(e):  # ∫ L dω per channel
    ...     return (np.asarray(e.radiance) * texel_solid_angles(*e.shape)[..., None]).sum((0, 1))
    >>> bool(np.allclose(integral(downsample(env, 2)), integral(env)))
    True
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core.image import srgb_decoding

__all__ = [
    "DATA",
    "SHIPPED",
    "EnvMap",
    "load_envmap",
    "save_envmap",
    "texel_solid_angles",
    "direction",
    "texel_centers",
    "to_equirect",
    "lookup_nearest",
    "lookup_bilinear",
    "bilinear_taps",
    "read_taps",
    "downsample",
    "luminance_weights",
]

DATA = Path(__file__).resolve().parents[1] / "data" / "envmaps"
SHIPPED = {
    "venice_sunset": DATA / "venice_sunset_256.hdr",
    "forest_slope": DATA / "forest_slope_256.hdr",
    "drakensberg": DATA / "drakensberg_solitary_mountain_256.hdr",
    "kloofendal": DATA / "kloofendal_43d_clear_puresky_256.hdr",
}


class EnvMap(NamedTuple):
    """Equirectangular linear-RGB radiance (H, W, 3), W = 2H, z-up (SPEC §9). A pytree."""

    radiance: Array

    @property
    def shape(self) -> tuple[int, int]:
        return self.radiance.shape[:2]

    def astype(self, dtype) -> EnvMap:
        return EnvMap(self.radiance.astype(dtype))


def _fail(what: str, problem: str):
    raise ValueError(f"{what}: {problem}")


def _check_array(a, what: str) -> np.ndarray:
    if isinstance(a, jax.core.Tracer):
        return a
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[-1] != 3:
        _fail(what, f"expected an (H, W, 3) RGB array, got shape {a.shape}")
    h, w = a.shape[:2]
    if h < 2 or w != 2 * h:
        _fail(what, f"not an equirectangular map: width must be 2 × height, got {h} × {w} "
                    "(rows × columns)")
    if not np.issubdtype(a.dtype, np.floating):
        a = a.astype(float)
    if not np.all(np.isfinite(a)):
        _fail(what, f"{int(np.sum(~np.isfinite(a)))} non-finite texel values (NaN or inf)")
    if np.any(a < 0):
        _fail(what, f"{int(np.sum(a < 0))} negative texel values (radiance must be >= 0)")
    return a


def load_envmap(source, *, dtype=None, ldr_srgb: bool = False) -> EnvMap:
    """An `EnvMap` from a file path (.hdr, .exr: OpenImageIO), a shipped name (`SHIPPED`),
    or an (H, W, 3) array of linear RGB laid out as in SPEC §9.

    `ldr_srgb`: read an integer (8- or 16-bit, LDR) image file as sRGB-encoded, decoded to
    relative linear radiance by the sRGB EOTF (module docstring); without it such a file is
    refused. Float files (.hdr, .exr, float TIFF) and arrays are read as they are either way.

    Raises ValueError naming the file and the problem for a missing or unreadable file, an
    integer (LDR) image without `ldr_srgb=True`, a wrong shape, a non-equirectangular aspect
    ratio, or non-finite or negative texels.
    """
    if isinstance(source, EnvMap):
        source = source.radiance
    if isinstance(source, tuple) and hasattr(source, "_fields"):  # a prefiltered map, a table
        raise TypeError(f"expected an environment map (an EnvMap, an (H, W, 3) array, a file "
                        f"or a shipped name), got a {type(source).__name__}: pass the map it "
                        "was made from")
    if isinstance(source, str) and source in SHIPPED:
        source = SHIPPED[source]
    if isinstance(source, (str, Path)):
        path = Path(source)
        what = f"environment map {str(path)!r}"
        if not path.is_file():
            _fail(what, "no such file")
        arr = _read_image(path, what, ldr_srgb=ldr_srgb)
    else:
        what = "environment map array"
        arr = source
    arr = _check_array(arr, what)
    dtype = dtype or jnp.result_type(float)
    return EnvMap(jnp.asarray(arr, dtype))


def _is_integer_format(spec) -> bool:
    """Whether OpenImageIO stores the file's pixels as integers (8-bit PNG, JPEG, 16-bit PNG,
    integer TIFF): display-encoded LDR, not radiance."""
    return np.issubdtype(np.dtype(str(spec.format)), np.integer)


def _read_image(path: Path, what: str, *, ldr_srgb: bool = False) -> np.ndarray:
    """The file's first three channels as float64 radiance. An integer (LDR) file is decoded
    with the sRGB EOTF when `ldr_srgb`, refused otherwise."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        _fail(what, f"unreadable ({buf.geterror().strip() or 'unknown format'})")
    integer = _is_integer_format(buf.spec())
    if integer and not ldr_srgb:
        _fail(what, f"an LDR image ({buf.spec().format} pixels): its values are "
                    "display-encoded (sRGB, clipped at white), not radiance. Pass an HDR file "
                    "(.hdr, .exr) or, to use this one knowingly, ldr_srgb=True (CLI: "
                    "--ldr-srgb) to decode it with the sRGB EOTF into relative radiance "
                    "(white = 1)")
    px = buf.get_pixels(oiio.FLOAT)
    if buf.has_error or px is None:
        _fail(what, f"unreadable ({buf.geterror().strip()})")
    px = np.asarray(px, np.float64)
    if px.ndim != 3 or px.shape[-1] < 3:
        _fail(what, f"expected an RGB image, got {px.shape[-1] if px.ndim == 3 else 1} channel(s)")
    px = px[..., :3]
    if integer and ldr_srgb:  # the sRGB EOTF, IEC 61966-2-1 (module docstring)
        px = srgb_decoding(px)
    return px


def save_envmap(path, envmap) -> Path:
    """Write an `EnvMap` (or array) to `path` with OpenImageIO (format from the suffix), atomically."""
    import OpenImageIO as oiio

    from ..core.files import atomic_write

    arr = np.ascontiguousarray(np.asarray(getattr(envmap, "radiance", envmap), np.float32))

    def write(tmp):
        spec = oiio.ImageSpec(arr.shape[1], arr.shape[0], 3, oiio.FLOAT)
        out = oiio.ImageOutput.create(str(path))
        if out is None or not out.open(tmp, spec):
            raise OSError(f"cannot write {path}: {oiio.geterror()}")
        out.write_image(arr)
        out.close()

    return atomic_write(path, write)


# ----------------------------------------------------------------------------- geometry
@functools.cache
def _row_geometry(h: int, w: int):
    """cos θ at the row edges (h + 1,) and the solid angle of one texel per row (h,)."""
    ct = np.cos(np.arange(h + 1) * np.pi / h)
    return ct, (ct[:-1] - ct[1:]) * 2 * np.pi / w


def texel_solid_angles(h: int, w: int) -> np.ndarray:
    """Ω (h, w) of every texel; sums to 4π."""
    return np.broadcast_to(_row_geometry(h, w)[1][:, None], (h, w))


def direction(theta, phi) -> Array:
    """ω = (sin θ cos φ, sin θ sin φ, cos θ) on the last axis."""
    st = jnp.sin(theta)
    return jnp.stack([st * jnp.cos(phi), st * jnp.sin(phi), jnp.cos(theta)], axis=-1)


def texel_centers(h: int, w: int) -> np.ndarray:
    """Unit directions (h, w, 3) at the texel centres (θ, φ midpoints), host float64."""
    th = (np.arange(h) + 0.5) * np.pi / h
    ph = (np.arange(w) + 0.5) * 2 * np.pi / w
    st = np.sin(th)[:, None]
    return np.stack([st * np.cos(ph)[None], st * np.sin(ph)[None],
                     np.broadcast_to(np.cos(th)[:, None], (h, w))], axis=-1)


@functools.cache
def _atan_coefficients(degree: int = 7) -> tuple[float, ...]:
    """c_k (k = 0 … degree) of atan a ≈ a Σ_k c_k a^{2k} on a ∈ [0, 1]: least squares
    on 4,096 Chebyshev nodes, host float64 (max error 4.1e-8 rad at degree 7, below
    float32's half ulp of π/4; tests/shading/test_ibl.py)."""
    a = 0.5 + 0.5 * np.cos(np.pi * (np.arange(4096) + 0.5) / 4096)
    basis = a[:, None] * (a * a)[:, None] ** np.arange(degree + 1)
    return tuple(float(c) for c in np.linalg.lstsq(basis, np.arctan(a), rcond=None)[0])


def _atan2(y, x):
    """arctan2(y, x). float64 is XLA's; below it, `_octant_atan2`: max error 3e-7 rad in
    float32, as XLA's (2.4e-7), at a tenth of the cost on a CPU, where XLA's arctan2 runs
    ≈ 10 ns a value (10 % of an `improved` call under a map: 3 directions a point)."""
    if jnp.result_type(y, x) == jnp.float64:
        return jnp.arctan2(y, x)
    return _octant_atan2(y, x)


@jax.custom_jvp
def _octant_atan2(y, x):
    """An odd polynomial on the octant a = min(|x|, |y|)/max(|x|, |y|) ∈ [0, 1]
    (`_atan_coefficients`), then π/2 − r where |y| > |x|, π − r where x < 0, −r where
    y < 0; x = y = 0 gives 0. Its derivative is the exact one, (x dy − y dx)/(x² + y²)
    (0 at the origin): the polynomial's own would be 0 on the octant edges, where the
    reduction's abs and selects have no derivative."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    swap = ay > ax
    hi = jnp.where(swap, ay, ax)
    a = jnp.where(hi > 0, jnp.where(swap, ax, ay) / jnp.where(hi > 0, hi, 1.0), 0.0)
    s = a * a
    coef = _atan_coefficients()
    p = jnp.full_like(s, coef[-1])
    for c in coef[-2::-1]:
        p = p * s + c
    r = a * p
    r = jnp.where(swap, 0.5 * np.pi - r, r)
    r = jnp.where(x < 0, np.pi - r, r)
    return jnp.where(y < 0, -r, r)


@_octant_atan2.defjvp
def _octant_atan2_jvp(primals, tangents):
    y, x = primals
    dy, dx = tangents
    r2 = x * x + y * y
    ok = r2 > 0
    return _octant_atan2(y, x), jnp.where(ok, (x * dy - y * dx) / jnp.where(ok, r2, 1.0), 0.0)


def to_equirect(omega):
    """(u, v) ∈ [0, 1)² of unit directions: u = φ/2π (column), v = θ/π (row).

    At the poles (x = y = 0) φ is taken as 0; values and gradients stay finite there
    (double-where: hypot and arctan2 have 0/0 derivatives at the origin)."""
    x, y = omega[..., 0], omega[..., 1]
    z = jnp.clip(omega[..., 2], -1.0, 1.0)
    r2 = x * x + y * y
    pole = r2 == 0
    rho = jnp.where(pole, 0.0, jnp.sqrt(jnp.where(pole, 1.0, r2)))
    theta = _atan2(rho, z)
    phi = jnp.where(pole, 0.0, _atan2(jnp.where(pole, 0.0, y), jnp.where(pole, 1.0, x)))
    return jnp.mod(phi / (2 * jnp.pi), 1.0), theta / jnp.pi


def texel_index(omega, h: int, w: int):
    """(row, column) of the texel containing each direction (piecewise-constant lookup)."""
    u, v = to_equirect(omega)
    i = jnp.clip(jnp.floor(v * h), 0, h - 1).astype(jnp.int32)
    j = jnp.clip(jnp.floor(u * w), 0, w - 1).astype(jnp.int32)
    return i, j


def lookup_nearest(image, omega) -> Array:
    """image[(texel of ω)]: the piecewise-constant value, image (h, w, ...)."""
    i, j = texel_index(omega, image.shape[0], image.shape[1])
    return image[i, j]


def lookup_bilinear(image, omega, layer=None) -> Array:
    """Bilinear interpolation of texel-centre values at ω (wraps in φ, clamps at the poles).

    image: (h, w, ...) or, with `layer` (integer array broadcasting with ω's leading
    axes), a stack (L, h, w, ...) read at image[layer]."""
    if layer is None:
        image, layer = image[None], jnp.zeros(omega.shape[:-1], jnp.int32)
    return read_taps(image, layer, bilinear_taps(omega, image.shape[1], image.shape[2]))


def bilinear_taps(omega, h: int, w: int):
    """The four texels round ω on an h × w map and their weights, for `read_taps`:
    (rows i0, i1, columns j0, j1, fractions fx, fy), φ wrapped, θ clamped at the poles.
    Computed once, they serve every layer and table of that size (`prefilter`)."""
    u, v = to_equirect(omega)
    x = u * w - 0.5
    y = jnp.clip(v * h - 0.5, 0.0, h - 1.0)
    x0, y0 = jnp.floor(x), jnp.minimum(jnp.floor(y), h - 2)
    j0 = jnp.mod(x0.astype(jnp.int32), w)
    i0 = y0.astype(jnp.int32)
    return i0, i0 + 1, j0, jnp.mod(j0 + 1, w), x - x0, y - y0


def read_taps(image, layer, taps, channels=slice(None)) -> Array:
    """image[layer] (a stack (L, h, w, ...)) read bilinearly at `bilinear_taps`;
    `channels` indexes the last axis of each texel as it is gathered (XLA fuses it into the
    loads: no copy of the table, as `image[..., :3]` would make per call)."""
    i0, i1, j0, j1, fx, fy = taps
    n_l, h, w = image.shape[:3]
    flat = image.reshape((n_l * h * w,) + image.shape[3:])  # one index per tap
    r0, r1 = (layer * h + i0) * w, (layer * h + i1) * w
    fx = fx.reshape(fx.shape + (1,) * (image.ndim - 3))
    fy = fy.reshape(fy.shape + (1,) * (image.ndim - 3))

    def tap(rows, cols):
        return flat[rows + cols][..., channels]

    top = tap(r0, j0) * (1 - fx) + tap(r0, j1) * fx
    bot = tap(r1, j0) * (1 - fx) + tap(r1, j1) * fx
    return top * (1 - fy) + bot * fy


def downsample(envmap, factor: int) -> EnvMap:
    """Box-filter by `factor` in both directions, weighting by texel solid angle, so that
    ∫ L dω of each channel is preserved exactly."""
    a = np.asarray(getattr(envmap, "radiance", envmap), np.float64)
    h, w = a.shape[:2]
    if factor < 1 or h % factor or w % factor:
        raise ValueError(f"factor must divide the map size {h} × {w}, got {factor}")
    om = _row_geometry(h, w)[1]
    weighted = a * om[:, None, None]
    s = weighted.reshape(h // factor, factor, w // factor, factor, 3).sum(axis=(1, 3))
    om2 = om.reshape(h // factor, factor).sum(1) * factor
    return EnvMap(jnp.asarray(s / om2[:, None, None]))


def luminance_weights() -> np.ndarray:
    """Y of linear Rec. 709 RGB (the middle row of colour-science's sRGB → XYZ matrix)."""
    import colour

    return np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ[1], float)
