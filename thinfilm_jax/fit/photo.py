r"""Thickness maps from photographs (SPEC §13): camera and light inside the fit.

A pixel p of a photograph of a film of unknown thickness d_p reads, in linear camera units,

$$ o_{pc} = g_c \sum_{j} C_{cj}\, s_j(d_p) + \varepsilon_{pc}, \qquad
   s_j(d) = \sum_k w_{kj}\, \bar R(\lambda_k, d), $$

where R̄ is the template's exact reflectance (SPEC §2, §12: the stack recursion, every index
model evaluated at each λ_k) at the view angle θ_o, or, for a rough surface (α given), its
patch average under uniform light Σ_q ω_q R(λ, cos θ_{h,q}) on the quadrature of SPEC §7
(12 × 12 nodes: 1e-6 of the colour);
w are the camera's weights under the light (`spectral.camera`: a white reflector reads 1);
g = exposure · white balance (3 gains, always free); and C is the identity for a known camera
or a fitted 3 × 3 matrix (rows summing to 1) for ``camera="unknown"``. The noise ε has the
per-pixel standard deviation σ_pc² = σ_image² + (f · o_pc)²: the decoded image's noise
(quantisation and an Immerkær estimate, `core.image`; for a JPEG, the noise at its 2 × 2
block scale and its 4:2:0 chroma's error, `fit.photo_jpeg`) and a relative model floor f
(`model_floor`, the camera and light being known only so well).

The fit, in the order it runs:

1. **Table.** The colour s(d_g) of every thickness on a grid over `thickness_range` (step
   `grid_step_nm`) and its derivative ds/dd (forward mode), exact, once per photograph: at a
   fixed view it does not depend on the pixel. Between grid points s(d) is the cubic Hermite
   interpolant, whose error (h⁴ s⁗/384) is below 1e-9 at 1 nm steps (tested).
2. **Gains** (and C). With `reference` regions of known thickness: least squares of the
   regions' mean colours against s(d_ref) (C too for an unknown camera, which needs three
   regions of distinct colour). Without: alternating minimisation on a subsample of pixels,
   the nearest-colour screen given the gains and the closed-form gains given the
   thicknesses, from a ladder of starting exposures; the lowest total χ² wins.
   With ``illumination="smooth"`` a light field L(x) (the exponential of a degree-3
   polynomial in the pixel coordinates, `fit.photo_light`) is then fitted on a subsample,
   alternating with the pixels' thicknesses, and the photograph divided by it.
3. **Screen.** χ²_p(d_g) for every pixel on a coarse grid (`screen_step_nm`, every basin of
   χ²(d) holds a grid point: fringes are ≳ 100 nm wide) as one matrix product, and the k = 4
   lowest local minima of each pixel. Channels clipped at black or full scale are censored:
   they cost only when the model is on the wrong side of the clip (for a JPEG, the clip
   levels sit a few codes inside, where its DCT rings a clipped channel: `_censoring`; its
   readings are of the colour clipped at black, max(g C s, 0): `fit.photo_jpeg`).
4. **Refine.** Per pixel and candidate, fixed-step Levenberg–Marquardt (`fit.engine`) on the
   Hermite interpolant, the thickness kept in the range. The film is continuous, so the
   order is chosen by continuation (`pixelwise.grow`, as quality-guided phase unwrapping):
   the pixels explained within the noise (χ²_p ≤ (2σ)² · max(1, robust reduced χ²)) whose
   refined minima exclude every other order (none within (2σ)² · max(that, χ²_p), the
   ambiguity margin of step 5) and the pads seed it; the decided region grows by fronts,
   through the well-explained pixels first, each pixel taking, of the orders it does not
   exclude, the one nearest its decided neighbours. With `smoothness_nm` = τ, iterated
   conditional modes over the candidates with the neighbour prior ½((d_p − d_q)/τ)² choose
   instead (Besag 1986). Then the gains (without references, from the readings the model
   puts inside the clip levels; an unknown camera's matrix from every pixel, the pads
   anchoring the orders) alternate with the thicknesses until they settle, and a final
   refine adds the prior's residuals to the neighbours. An unknown camera's sensitivities
   are kept ≥ 0 (a photodiode's response; `photo_screen.matrix_from_pixels`).
5. **Uncertainty.** The reduced χ² = Σ χ²_p / (2P − n_global) (3 residuals, one thickness per
   pixel). Standard errors are the linearised ones σ_d = (J^T J)^{-1/2} times the square root
   of the robust reduced χ² below (the noise scale of the typical pixel; for a JPEG, of
   max(1, it)); a pixel is `ambiguous` where another local minimum at least 15 nm away
   (another fringe order) has a χ² above its own by less than 4 · max(1, robust reduced χ²)
   (two standard deviations), or than 4 χ²_p (the pixel's own misfit), where its neighbours
   disagree by two fringe-order separations, for an unknown camera beyond the pads' span,
   or, for a JPEG, more than 10 nm off the plane of its 5 × 5 neighbourhood (its block
   error, which χ² and σ_d do not see: `fit.photo_flags`). A robust reduced χ² (the median
   pixel's χ² over the median of χ²₂) above `chi2_warn` raises a warning (in the result and
   by `warnings.warn`): the model does not explain the photograph (wrong encoding, camera,
   light, angle or material). It is robust so that a few outlying pixels (an edge, a
   scratch) do not raise it.

Limits. Colours depend on the film's index and thickness mostly through n₂·d: with the wrong
film index the map scales by the ratio of the indices while χ² barely rises (SiO₂ declared
for a soap film: the map 9 % thin, robust χ² 0.8, no warning), so the material must be
known. Where the noise makes two fringe orders equally likely the fit takes the one with the
lower χ², which may be wrong: `ambiguous` flags those pixels, and `alternative` holds the
other order.

Example (an sRGB rendering of an oxide wedge on silicon, exposure and white balance unknown):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, refractive_index
    >>> from thinfilm_jax.fit.photo import fit_photo, render_photo
    >>> film = Film(0.0, refractive_index("SiO2"), refractive_index("Si"))
    >>> d = np.linspace(50.0, 600.0, 64).reshape(8, 8)
    >>> img = render_photo(film, d, camera="srgb", exposure=0.7)
    >>> res = fit_photo(img, film, camera="srgb", encoding="linear", thickness_range=(0, 800))
    >>> bool(np.max(np.abs(res.thickness - d)) < 0.5)
    True
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.image import Photo, read_mask, read_photo, srgb_decoding
from ..spectral.camera import Camera, camera_response, sensitivity_basis
from . import photo_flags as PF
from . import pixelwise as PW
from .photo_flags import fit_notes
from .photo_flags import reasons as flag_reasons
from .photo_jpeg import jpeg_noise
from .photo_light import ILLUMINATIONS, basis, fit_light
from .photo_model import (  # noqa: F401
    _check_na,
    _colours,
    _geometry,
    _host_hermite,
    _layer_stack,
    _refine_all,
    photo_colours,
    render_photo,
)
from .photo_screen import (
    DISTINCT_NM,
    closed_gains,
    features,
    matrix_from_pixels,
    reference_gains,
    residual,
    screen_all,
    search_gains,
)
from .results import MapResult, PhotoResult, chi2_text

__all__ = ["PhotoResult", "fit_photo", "photo_colours", "render_photo"]

_CANDIDATES = 4  # local minima per pixel kept for the neighbour prior
_ICM_SWEEPS = 6  # sweeps of the neighbour prior over the candidates
_MODEL_FLOOR = 0.005  # relative model uncertainty (camera, light, material known so well)
_JPEG_FLOOR = 0.02  # … of a lossy JPEG, in the misfit statistics (quality 75–95: robust χ²
_JPEG_BLACK_CODES = 6  # 0.8–2.4 with it); codes ≤ this of a JPEG channel are black-clipped
_JPEG_CEILING_CODES = 16  # codes ≥ 255 − this: clipped at full scale, rung down (Gibbs)
_JPEG_SUFFIXES = (".jpg", ".jpeg")
_CHI2_2_MEDIAN = 2.0 * np.log(2.0)  # the median of χ² with 2 degrees of freedom
_GAIN_PIXELS = 16384  # pixels of the gain alternation (and every pad pixel)
_GAIN_ROUNDS = 8  # alternations of the gains (an unknown camera's matrix) with the thicknesses
_BASIS_ROUNDS = 3  # an unknown camera's sensitivities alternating with screened thicknesses
_PAD_WEIGHT = 3.0  # × the equal-weight factor: the pads are known, the rest is fitted
_BASIS_SMOOTHING = 1e-2  # second-difference penalty of the sensitivities (`matrix_from_pixels`)


def _describe(photo: Photo, n_clip: int) -> str:
    """`Photo.describe` with the fit's count of pixels with a clipped channel (its censoring,
    a JPEG's black level included) in place of the reader's: one count everywhere."""
    head = photo.describe().rsplit("; ", 1)[0]
    return f"{head}; {n_clip} pixel{'' if n_clip == 1 else 's'} with a clipped channel"


# ----------------------------------------------------------------------------- references
def _read_reference(reference, valid):
    """[(mask (H, W) bool of usable pixels, thickness nm)] from the user's reference list."""
    regions = []
    for i, (mask, d) in enumerate(reference or ()):
        m = read_mask(mask, valid.shape, name=f"reference[{i}] mask") & valid
        if not m.any():
            raise ValueError(f"reference[{i}] has no usable pixel (its mask is empty or all "
                             f"its pixels are clipped)")
        dv = float(d)
        if not np.isfinite(dv) or dv < 0:
            raise ValueError(f"reference[{i}] thickness must be finite and ≥ 0 nm, got {d}")
        regions.append((m, dv))
    return regions


def _check_args(theta_o, alpha, thickness_range, smoothness_nm, model_floor, grid_step_nm,
                chi2_warn):
    if np.ndim(theta_o) != 0:
        raise ValueError(f"theta_o must be a scalar (one view for the photograph), got shape "
                         f"{np.shape(theta_o)}")
    V.check_finite("theta_o", theta_o)
    V.check_range("theta_o", float(theta_o), 0.0, np.pi / 2, hi_open=True, why=" (radians)")
    if alpha is not None:
        V.check_range("alpha", float(alpha), 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    lo, hi = (float(v) for v in thickness_range)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo < hi):
        raise ValueError(f"thickness_range must be (lo, hi) with 0 ≤ lo < hi nm, got "
                         f"{thickness_range}")
    if smoothness_nm is not None and not float(smoothness_nm) > 0:
        raise ValueError(f"smoothness_nm must be > 0 nm or None, got {smoothness_nm}")
    for name, v in (("model_floor", model_floor), ("grid_step_nm", grid_step_nm),
                    ("chi2_warn", chi2_warn)):
        if not (np.isfinite(v) and v > 0 if name != "model_floor" else np.isfinite(v)
                and v >= 0):
            raise ValueError(f"{name} must be a positive number, got {v}")
    return lo, hi


def _check_model(template, camera, illuminant, reference, layer, illumination, view):
    """(camera response, the template's checked `Stack`) of `fit_photo`, or a ValueError
    naming the argument."""
    theta_o, alpha, na = view
    _check_na(na, theta_o, alpha)
    if illumination not in ILLUMINATIONS:
        raise ValueError(f"illumination must be one of {ILLUMINATIONS}, got {illumination!r}")
    cam = camera_response(camera, illuminant)
    if not isinstance(reference, (list, tuple, type(None))):
        raise ValueError("reference must be a list of (mask, thickness_nm) pairs")
    if cam.kind == "unknown" and not reference:
        raise ValueError("camera='unknown' needs reference regions of known thickness (at least "
                         "3 of distinct colour) to fit its 3 × 3 matrix")
    stack = _layer_stack(V.check_material(template, "template", wavelengths=cam.wavelengths),
                         layer)
    return cam, stack


def _decode(v: float, encoding: str) -> float:
    """The linear value of the encoded value v (IEC 61966-2-1 for "srgb", colour-science's
    ``cctf_decoding`` through `core.image.srgb_decoding`, as `core.image.read_photo`; else v
    itself)."""
    if encoding != "srgb":
        return v
    return float(srgb_decoding(v))


def _censoring(photo: Photo, lossy: bool) -> tuple[np.ndarray, tuple[float, float]]:
    """((H, W, 3) per channel: 0 a reading, 1 clipped at black, 2 clipped at full scale (for
    integer or sRGB-encoded sources; linear float data have no ceiling); the clip levels
    (b, c)). b = 0 and c = 1, except for a lossy (JPEG) file, whose DCT rings a clipped
    channel away from its clip (the Gibbs overshoot of the 8 × 8 blocks' quantised cosines,
    widened by the chroma subsampling: up to ~25 codes at a saturated colour's edge, ~8 in
    the soap film's over-exposed fringes, docs/studies/photographs.md): b is the linear
    value of `_JPEG_BLACK_CODES` / 255 there and c that of (255 − `_JPEG_CEILING_CODES`) /
    255. A channel beyond a level is a censored observation, the truth beyond the level by
    an unknown amount (`photo_screen.residual`), not a reading."""
    v = photo.linear
    black, ceiling = 0.0, 1.0
    if lossy:
        black, ceiling = (_decode(c / 255.0, photo.encoding)
                          for c in (_JPEG_BLACK_CODES, 255 - _JPEG_CEILING_CODES))
    top = photo.bit_depth is not None or photo.encoding == "srgb"
    cens = np.where(v <= black, 1, np.where(top & (v >= ceiling), 2, 0)).astype(np.int32)
    return cens, (black, ceiling, 0.0) if lossy else (black, ceiling)


def fit_photo(image, template, *, camera, illuminant="D65", encoding: str = "srgb",
              reference=None, theta_o=0.0, alpha=None, thickness_range=(0.0, 2000.0),
              layer: int = 0, smoothness_nm=None, mask=None, bit_depth=None,
              model_floor: float | None = None, grid_step_nm: float = 1.0,
              screen_step_nm: float = 4.0, steps: int = 6,
              chi2_warn: float = 4.0, chunk: int = 4096, progress: bool = False,
              illumination: str = "uniform", na=None) -> MapResult:
    """Fit the thickness map of a photograph of a film (module docstring; SPEC §13).

    Args:
        image: an (H, W, 3) array (uint8, uint16, or float in [0, 1]) or a path (PNG, JPEG,
            TIFF, EXR, HDR; camera RAW through rawpy), read by `core.image.read_photo`.
        template: the `Film` or `Stack` (constant or dispersive indices) whose layer `layer`
            has the unknown thickness (its value in the template is ignored).
        camera: a colour-science camera name, a CSV of sensitivities or
            (wavelengths (K,), sensitivities (K, 3)), "srgb" or "unknown"
            (`spectral.camera.camera_response`).
        illuminant: a CIE illuminant name or a measured spectrum (M, 2).
        encoding: "srgb", "linear" or "raw"; bit_depth: the declared bit depth (8, 16) or
            None (checked against the file).
        reference: regions of known thickness, a list of (mask (H, W) bool or a mask image,
            thickness nm); gains (and C for camera="unknown") come from them.
        theta_o: the view angle (radians) of the whole photograph; alpha: GGX roughness of a
            rough film under uniform light (None: a mirror view of a uniform light).
        na: a microscope image (SPEC §14): the numerical aperture of the Köhler-illuminated
            objective (≤ the ambient's index), the reflectance averaged uniformly over its
            pupil (`objective_reflectance`); θ_o = 0 and α = None with it. A flake's layer
            count is its thickness over the monolayer's (`MONOLAYER_NM`).
        thickness_range: (lo, hi) nm, the screen's range; layer: which layer is unknown.
        smoothness_nm: τ of the neighbour prior that chooses fringe orders (None: per pixel).
        mask: (H, W) bool or a mask image: pixels to fit (default all unclipped pixels).
        model_floor: relative model uncertainty f (None: 0.005; for a JPEG file the misfit
            statistics use 0.02, as its chroma subsampling and DCT quantisation err by about
            that much, while the fit keeps 0.005, since a floor that large would skew the
            channels' relative weights and so the white balance);
        grid_step_nm: the table's step;
        screen_step_nm: the screen grid's step (a multiple of grid_step_nm; every basin of
            χ²(d) must hold a grid point: fringes are ≳ 100 nm wide);
        steps: Levenberg–Marquardt steps; chi2_warn: the robust reduced χ² above which the
            fit warns;
        chunk: pixels per batch; progress: a tqdm progress bar over pixels.
        illumination: "uniform" (one exposure for the frame) or "smooth" (a smooth positive
            light field across the frame, the exponential of a degree-2 polynomial in the
            pixel coordinates, fitted jointly with the map: `fit.photo_light`).

    Returns:
        `MapResult` (also named `PhotoResult`): the (H, W) maps, gains, camera and light.

    Raises:
        ValueError: naming what is wrong: an unreadable or corrupt image, an encoding or bit
            depth that contradicts the file, a mask of another size, a reference without
            usable pixels, an unknown camera or illuminant (listing the known ones),
            camera="unknown" without three distinct references, no pixel to fit, or an
            argument out of range.
    """
    t0 = time.perf_counter()
    jpeg = isinstance(image, (str, Path)) and Path(image).suffix.lower() in _JPEG_SUFFIXES
    report_floor = _JPEG_FLOOR if jpeg and model_floor is None else model_floor
    model_floor = _MODEL_FLOOR if model_floor is None else model_floor
    report_floor = model_floor if report_floor is None else report_floor
    lo, hi = _check_args(theta_o, alpha, thickness_range, smoothness_nm, model_floor,
                         grid_step_nm, chi2_warn)
    cam, stack = _check_model(template, camera, illuminant, reference, layer, illumination,
                              (theta_o, alpha, na))
    photo: Photo = read_photo(image, encoding, bit_depth=bit_depth)
    cens_img, levels = _censoring(photo, jpeg)
    sig_jpeg = jpeg_noise(photo, ~np.any(cens_img > 0, axis=-1)) if jpeg else None
    valid = ~np.all(cens_img > 0, axis=-1)
    if mask is not None:
        valid &= read_mask(mask, valid.shape, name="mask")
    if not valid.any():
        raise ValueError("no pixel to fit: every pixel is clipped or outside the mask")
    run, regions, sig_img = _setup(photo, valid, cens_img, levels, reference, stack, layer, cam,
                                   (lo, hi), (theta_o, alpha, na), grid_step_nm, screen_step_nm,
                                   model_floor, smoothness_nm, steps, chunk, sig_jpeg)
    table = _table(run, cam)
    gains, cmat, cmat_se = _gains(run, photo, sig_img, cens_img, regions, table, cam.kind)
    n = run.obs.shape[0]
    light, ident = np.ones(n), None
    if illumination == "smooth":  # the field, then the photograph divided by it
        h, w = valid.shape
        light, gains, ident = _smooth_light(run.obs, run.sig, run.cens, run.known,
                                            basis(run.where, h, w), gains, cmat, table,
                                            run.grid[run.coarse], chunk, steps)
        run = run._replace(obs=run.obs / light[:, None], sig=run.sig / light[:, None])
    rounds = _BASIS_ROUNDS if cam.kind == "unknown" else 0
    run = run._replace(bar=PW.progress(progress, (1 + _CANDIDATES) * n * (1 + rounds) + 2 * n,
                                       desc="fit_photo", pixels=n))
    try:
        fit = _solve(run, table, gains, cmat, regions, cam.kind, illuminant)
    finally:
        if run.bar is not None:
            run.bar.close()
    sig_rep = (_noise(photo, report_floor, sig_jpeg).reshape(-1, 3)[run.where] / light[:, None]
               if report_floor != model_floor else None)
    score, loud = _score(run, fit, cam, photo, sig_rep, chi2_warn, cens_img, jpeg,
                         ident if illumination == "smooth" else None)
    for note in loud:
        warnings.warn(note, stacklevel=2)

    def full(v, fill=np.nan, dtype=float):
        out = np.full(valid.size, fill, dtype)
        out[run.where] = v
        return out.reshape(valid.shape)

    seconds = time.perf_counter() - t0
    gains = fit.gains
    return MapResult(
        thickness=full(fit.d), stderr=full(fit.se * score["scale"]),
        ambiguous=full(score["amb"], False, bool), alternative=full(fit.d_alt),
        chi2=full(score["chi"]), loss=0.5 * full(score["chi"]), sigma=None,
        exposure=float(gains[1]), white_balance=gains / gains[1], camera_matrix=fit.cmat,
        camera_matrix_stderr=cmat_se, reduced_chi2=score["rchi2"],
        robust_chi2=score["robust"], warnings=score["notes"], encoding=score["described"],
        camera=cam.name, illuminant=cam.illuminant, n_pixels=n, seconds=seconds,
        pixels_per_second=n / seconds if seconds > 0 else float("inf"),
        illumination=illumination, light=full(light), stderr_calibrated=not jpeg)


# ----------------------------------------------------------------------------- the stages
class _Run(NamedTuple):
    """One photograph's fitted pixels (n, flat indices `where` of `valid`), their readings,
    noise and censoring (n, 3), the pads' known thicknesses (NaN elsewhere), the table's grid
    and the screen's subset of it, and the pipeline's settings."""

    obs: np.ndarray
    sig: np.ndarray
    cens: np.ndarray
    known: np.ndarray
    pads: np.ndarray
    valid: np.ndarray
    where: np.ndarray
    grid: np.ndarray
    coarse: np.ndarray
    lo: float
    hi: float
    step: float
    levels: tuple
    geom: tuple
    smoothness_nm: float | None
    steps: int
    chunk: int
    bar: object = None


def _noise(photo: Photo, floor, sig_jpeg=None):
    """σ (H, W, 3): the decoded image's noise (a JPEG's: `sig_jpeg`, `photo_jpeg`) and the
    relative model floor f (module docstring), with a floor of 1e-6 of the image's largest
    value."""
    noise = photo.noise if sig_jpeg is None else sig_jpeg
    return np.sqrt(noise ** 2 + (floor * photo.linear) ** 2
                   + (1e-6 * max(float(photo.linear.max()), 1e-12)) ** 2)


def _setup(photo, valid, cens_img, levels, reference, stack, layer, cam, box, view,
           grid_step_nm, screen_step_nm, model_floor, smoothness_nm, steps, chunk, sig_jpeg):
    """(`_Run`, reference regions, σ image): the pixels to fit, the table's grid (step
    `grid_step_nm`) and the screen's (every m-th point), the view's cosines and weights."""
    lo, hi = box
    theta_o, alpha, na = view
    h, w = valid.shape
    sig_img = _noise(photo, model_floor, sig_jpeg)
    g_n = int(np.ceil((hi - lo) / grid_step_nm)) + 1
    grid = np.linspace(lo, hi, g_n)
    step = (hi - lo) / (g_n - 1)
    every = max(1, int(round(screen_step_nm / step)))
    coarse = np.unique(np.r_[np.arange(0, g_n, every), g_n - 1])
    cos, qw = _geometry(float(theta_o), alpha, na, stack, layer, cam.wavelengths, hi)
    where = np.flatnonzero(valid.ravel())
    regions = _read_reference(reference, valid)
    known = np.full(h * w, np.nan)
    for m, t in regions:
        known[m.ravel()] = t
    known = known[where]
    run = _Run(photo.linear.reshape(-1, 3)[where], sig_img.reshape(-1, 3)[where],
               cens_img.reshape(-1, 3)[where], known, np.isfinite(known), valid, where, grid,
               coarse, lo, hi, step, levels, (stack, layer, jnp.asarray(cos), jnp.asarray(qw)),
               smoothness_nm, steps, chunk)
    return run, regions, sig_img


def _table(run: _Run, camera: Camera):
    """The table (lo, hi, step, s (G, 3), ds/dd (G, 3), clip levels) of the camera's colours."""
    s_tab, ds_tab = (np.asarray(v) for v in _colours(
        jnp.asarray(run.grid), *run.geom, jnp.asarray(camera.wavelengths),
        jnp.asarray(camera.weights)))
    return (run.lo, run.hi, run.step, s_tab, ds_tab, run.levels)


def _gains(run, photo, sig_img, cens_img, regions, table, kind):
    """(gains (3,), C, its standard errors): from the reference regions, or the search."""
    if regions:
        def s_of(d):
            return _host_hermite(np.asarray([d], float), run.lo, run.step, *table[3:5])[0]

        return reference_gains(photo.linear, sig_img, cens_img, regions, s_of, kind)
    gains = search_gains(run.obs, run.sig, run.cens, table[3][run.coarse],
                         jnp.asarray(run.grid[run.coarse]), run.chunk, run.levels)
    return gains, np.eye(3), np.zeros((3, 3))


def _orders(run: _Run, table, gm):
    """The pipeline's stages 1–3 (`fit.pixelwise`) on the table: screen the k best distinct
    local minima per pixel, refine each, choose (by continuation from the decided pixels and
    the pads, `pixelwise.grow`, or by the neighbour prior); → (d_best, d_alt, has_alt), the
    pads at their known d."""
    k = _CANDIDATES
    n = run.obs.shape[0]
    top, top_chi = screen_all(run.obs, run.sig, run.cens,
                              features(table[3][run.coarse] @ gm.T, run.levels),
                              jnp.asarray(run.grid[run.coarse]), k, run.chunk, run.bar)
    cand0 = run.grid[run.coarse][top]  # (n, k); a missing minimum repeats the pixel's best
    cand0 = np.where(np.isfinite(top_chi), cand0, cand0[:, :1])
    rep = (np.repeat(a, k, axis=0) for a in (run.obs, run.sig, run.cens))
    cd, cchi, _ = (v.reshape(n, k) for v in _refine_all(
        *rep, cand0.ravel(), None, np.inf, gm, table, run.steps, run.chunk, run.bar))
    if run.smoothness_nm is None:  # continuation from the pixels the data decide
        best = np.min(cchi, axis=-1)
        noise = PF.MARGIN_SIGMAS ** 2 * max(np.median(best) / _CHI2_2_MEDIAN, 1.0)
        pick = PW.grow(cd, cchi, run.where, run.valid, np.maximum(noise, PF.MARGIN_SIGMAS ** 2
                                                                   * best),
                       run.known, DISTINCT_NM, first=best <= noise)
    else:
        pick = PW.choose(cd, cchi, run.where, run.valid, run.smoothness_nm, _ICM_SWEEPS)
    d_best = np.where(run.pads, run.known, cd[np.arange(n), pick])
    d_alt, has_alt = PW.alternative(cd, cchi, d_best, DISTINCT_NM)
    return d_best, d_alt, has_alt


def _model_from_pixels(run: _Run, table, d, kind, cmat, sub=slice(None), gm=None):
    """g C (3, 3) from the pixels `sub` at thicknesses d: an unknown camera's matrix, its
    sensitivities on the hat basis ("basis", the pads weighing as much as the rest), or the
    closed-form gains of a known camera, without the readings that the current model `gm`
    puts beyond a clip level (a clipped channel's JPEG ringing or a colour outside the
    gamut: readings not of the modelled colour, which would pull its gain down)."""
    s_fit = _host_hermite(d, run.lo, run.step, *table[3:5])
    o, sg, cs, pd = run.obs[sub], run.sig[sub], run.cens[sub], run.pads[sub]
    if kind == "unknown":
        return matrix_from_pixels(o, sg, cs, s_fit)
    if kind == "basis":  # the pads, known, weigh as much as all other pixels together
        up = np.sqrt(max((pd.size - pd.sum()) / max(pd.sum(), 1), 1.0)) * _PAD_WEIGHT
        return matrix_from_pixels(o, sg / np.where(pd, up, 1.0)[:, None], cs, s_fit,
                                  smooth=_BASIS_SMOOTHING)
    s_c = s_fit @ cmat.T
    if gm is not None:  # a channel the model puts beyond a clip level is censored there too
        pred = s_fit @ gm.T
        cs = np.where((cs == 0) & ((pred <= run.levels[0]) | (pred >= run.levels[1])), 3, cs)
    return closed_gains(o, sg, cs, s_c)[:, None] * cmat


class _Fit(NamedTuple):
    d: np.ndarray
    chi: np.ndarray
    se: np.ndarray
    d_alt: np.ndarray
    chi_alt: np.ndarray
    gm: np.ndarray
    gains: np.ndarray
    cmat: np.ndarray
    table: tuple


def _solve(run: _Run, table, gains, cmat, regions, kind, illuminant) -> _Fit:
    """The orders, then the gains (no references; an unknown camera's matrix) alternating
    with the thicknesses (the pads fixed) until they settle, an unknown camera's
    sensitivities, and the final refine with the neighbour prior (`fit.pixelwise`)."""
    n = run.obs.shape[0]
    gm = gains[:, None] * cmat
    d_best, d_alt, has_alt = _orders(run, table, gm)
    # on a subsample: a handful of global parameters, then every pixel below
    sub = np.unique(np.r_[np.arange(0, n, max(1, n // _GAIN_PIXELS)), np.flatnonzero(run.pads)])
    d_sub = d_best[sub]
    for _ in range(_GAIN_ROUNDS if not regions or kind == "unknown" else 0):
        gm_new = _model_from_pixels(run, table, d_sub, kind, cmat, sub, gm)
        change = np.max(np.abs(gm_new - gm)) / np.max(np.abs(gm))
        gm = gm_new
        d_sub = np.where(run.pads[sub], run.known[sub], _refine_all(
            run.obs[sub], run.sig[sub], run.cens[sub], d_sub, None, np.inf, gm, table,
            run.steps, run.chunk, None)[0])
        if change < 1e-8:
            break
    d_best[sub] = d_sub
    if kind == "unknown":
        # the 3 × 3 matrix on the observer's bands (reported), then the camera's
        # sensitivities on a basis of hat functions (Luther's condition fails for real
        # cameras: a 3 × 3 matrix cannot match them), from every pixel, re-screened
        cmat3 = gm
        table = _table(run, sensitivity_basis(illuminant))
        for _ in range(_BASIS_ROUNDS):
            gm = _model_from_pixels(run, table, d_best, "basis", cmat)
            d_best, d_alt, has_alt = _orders(run, table, gm)
        gains = gm.sum(axis=1)
        cmat = cmat3 / cmat3.sum(axis=1)[:, None]
    else:
        gains = np.diag(gm).copy()
    tau = float(run.smoothness_nm) if run.smoothness_nm is not None else np.inf
    d, chi, se = _refine_all(run.obs, run.sig, run.cens, d_best,
                             run.valid if np.isfinite(tau) else None, tau, gm, table,
                             run.steps, run.chunk, run.bar, where=run.where, want_se=True)
    _, chi_alt, _ = _refine_all(run.obs, run.sig, run.cens, d_alt, None, np.inf, gm, table,
                                run.steps, run.chunk, run.bar)
    return _Fit(d, chi, se, np.where(has_alt, d_alt, np.nan),
                np.where(has_alt, chi_alt, np.inf), gm, gains, cmat, table)


def _score(run: _Run, fit: _Fit, cam, photo, sig_rep, chi2_warn, cens_img, jpeg, ident):
    """Stage 4 (`fit.pixelwise`): the χ² statistics, the flags (`photo_flags`) and the
    notes. The fit's own χ² scales the standard errors and the ambiguity test; the misfit
    statistics use the reporting floor's σ `sig_rep` where given (a JPEG's 2 %, which,
    applied in the fit, would skew the channels' weights and so the white balance)."""
    n = run.obs.shape[0]
    chi, pads, known = fit.chi, run.pads, run.known
    n_global = 3 + (6 if cam.kind == "unknown" else 0)
    dof = max(2 * n - n_global, 1)
    robust_fit = float(np.median(chi) / _CHI2_2_MEDIAN)
    span = (float(known[pads].min()), float(known[pads].max())) if (
        cam.kind == "unknown" and pads.any()) else None
    why = flag_reasons(chi, fit.chi_alt, robust_fit, fit.d, run.where, run.valid.shape, span,
                       lossy=jpeg)
    amb = np.any(np.stack(list(why.values())), axis=0)
    if sig_rep is not None:
        pred = _host_hermite(fit.d, run.lo, run.step, *fit.table[3:5]) @ fit.gm.T
        chi = np.sum(np.asarray(residual(jnp.asarray(pred), jnp.asarray(run.obs),
                                         jnp.asarray(sig_rep), jnp.asarray(run.cens),
                                         run.levels)) ** 2, axis=-1)
    rchi2 = float(np.sum(chi) / dof)
    robust = float(np.median(chi) / _CHI2_2_MEDIAN)
    misfit = (f"{chi2_text(robust, rchi2)} > {chi2_warn:g}: the model does not explain the "
              f"photograph within its noise (check the encoding ({photo.encoding}), camera "
              f"({cam.name}), light ({cam.illuminant}), view angle and material); "
              f"thicknesses may be wrong") if robust > chi2_warn else None
    notes, loud = fit_notes(misfit, cens_img, run.valid, amb, why, jpeg, ident)
    described = _describe(photo, int(np.sum(np.any(cens_img > 0, axis=-1))))
    # a JPEG's σ (`photo_jpeg`) is not scaled down: its block errors along the colour curve,
    # which move d, do not raise χ² (as the flags, `photo_flags`: s = max(1, robust))
    scale = np.sqrt(max(robust_fit, 1.0) if jpeg else robust_fit)
    return {"scale": scale, "amb": amb, "chi": chi, "rchi2": rchi2,
            "robust": robust, "notes": tuple(notes), "described": described}, loud


def _smooth_light(obs, sig, cens, known, phi, gains, cmat, table, coarse, chunk, steps):
    """`fit.photo_light.fit_light` on the table: (L (n,), gains (3,), identifiability)."""
    lo, _, step, s_tab, ds_tab, levels = table
    feats_grid = jnp.asarray(coarse)
    s_coarse = s_tab[np.rint((coarse - lo) / step).astype(int)]

    def colour(d):
        dd = np.stack([np.interp(d, lo + step * np.arange(len(s_tab)), ds_tab[:, c])
                       for c in range(ds_tab.shape[1])], axis=-1)
        return _host_hermite(d, lo, step, s_tab, ds_tab), dd

    def screen(o, sg, cs, gm):
        top, _ = screen_all(o, sg, cs, features(s_coarse @ gm.T, levels), feats_grid, 1,
                            chunk, None)
        return coarse[top[:, 0]]

    def refine(o, sg, cs, d0, gm):
        return _refine_all(o, sg, cs, d0, None, np.inf, gm, table, steps, chunk, None)[0]

    gm0 = gains[:, None] * cmat
    light, gm, ident = fit_light(obs, sig, cens, known, phi, gm0, colour, screen, refine)
    return light, gains * (gm.sum(axis=1) / gm0.sum(axis=1)), ident
