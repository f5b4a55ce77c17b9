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
(quantisation and an Immerkær estimate, `core.image`) and a relative model floor f
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
   they cost only when the model is on the wrong side of the clip.
4. **Refine.** Per pixel and candidate, fixed-step Levenberg–Marquardt (`fit.engine`) on the
   Hermite interpolant, the thickness kept in the range. The pixel's thickness is its best
   refined minimum; with `smoothness_nm` = τ, iterated conditional modes over the candidates
   with the neighbour prior ½((d_p − d_q)/τ)² choose it instead (Besag 1986). Then the gains
   (without references; an unknown camera's matrix from every pixel, the pads anchoring the
   orders) alternate with the thicknesses until they settle, and a final refine adds the
   prior's residuals to the neighbours.
5. **Uncertainty.** The reduced χ² = Σ χ²_p / (2P − n_global) (3 residuals, one thickness per
   pixel). Standard errors are the linearised ones σ_d = (J^T J)^{-1/2} times the square root
   of the robust reduced χ² below (the noise scale of the typical pixel);
   a pixel is `ambiguous` where another local minimum at least 15 nm away (another fringe
   order) has a χ² above its own by less than 4 · max(1, robust reduced χ²) (two standard
   deviations), or than 4 χ²_p (the pixel's own misfit), where its neighbours disagree by
   two fringe-order separations, or, for an unknown camera, beyond the pads' span
   (`fit.photo_flags`). A robust reduced χ² (the median pixel's χ² over the median of χ²₂)
   above `chi2_warn` raises a warning (in the result and by `warnings.warn`): the model does not
   explain the photograph (wrong encoding, camera, light, angle or material). It is robust
   so that a few outlying pixels (an edge, a scratch) do not raise it.

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

import functools
import time
import warnings
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..brdf.microfacet import patch_quadrature
from ..core import _validate as V
from ..core.image import Photo, read_mask, read_photo
from ..core.material import as_stack
from ..core.stack import Stack
from ..optics.stack import stack_reflectance_traced
from ..spectral.camera import Camera, camera_response, sensitivity_basis
from .engine import covariance, levenberg_marquardt
from .photo_flags import fit_notes
from .photo_flags import reasons as flag_reasons
from .photo_light import ILLUMINATIONS, basis, fit_light
from .photo_screen import (DISTINCT_NM, bucket, chunks, closed_gains, features,
                           matrix_from_pixels, pad_to, reference_gains, residual, screen_all,
                           search_gains)

__all__ = ["PhotoResult", "fit_photo", "photo_colours", "render_photo"]

_HI = jax.lax.Precision.HIGHEST
_CANDIDATES = 4  # local minima per pixel kept for the neighbour prior
#: the patch quadrature of a rough film: against (48, 48), 1.3e-6 (oxide on Si) and 9.4e-7
#: (soap) of the largest colour over 0–2000 nm at α = 0.3, θ_o = 0.4 (measured), far below
#: the model floor, at 1/16 of the cost
_QUADRATURE = (12, 12)
_MODEL_FLOOR = 0.005  # relative model uncertainty (camera, light, material known so well)
_JPEG_FLOOR = 0.02  # … of a lossy JPEG, in the misfit statistics (quality 75–95: robust χ²
_JPEG_BLACK_CODES = 6  # 0.8–2.4 with it); codes ≤ this of a JPEG channel are black-clipped
_JPEG_SUFFIXES = (".jpg", ".jpeg")
_CHI2_2_MEDIAN = 2.0 * np.log(2.0)  # the median of χ² with 2 degrees of freedom
_GAIN_PIXELS = 16384  # pixels of the gain alternation (and every pad pixel)
_GAIN_ROUNDS = 8  # alternations of the gains (an unknown camera's matrix) with the thicknesses
_BASIS_ROUNDS = 3  # an unknown camera's sensitivities alternating with screened thicknesses
_PAD_WEIGHT = 3.0  # × the equal-weight factor: the pads are known, the rest is fitted
_BASIS_SMOOTHING = 1e-2  # second-difference penalty of the sensitivities (`matrix_from_pixels`)


class PhotoResult(NamedTuple):
    """A thickness map fitted to a photograph (`fit_photo`). Maps are (H, W) NumPy arrays;
    pixels not fitted (clipped, outside `mask`) are NaN (False in `ambiguous`).

    Attributes:
        thickness, stderr: the fitted thickness of the template's layer and its standard
            error (nm), scaled by √(robust reduced χ²).
        ambiguous: another fringe order explains the pixel within its noise.
        alternative: that other order's thickness (nm; NaN where none was found).
        chi2: the pixel's χ² (3 residuals).
        exposure: the green channel's gain g_G (linear camera units per unit reflectance).
        white_balance: g / g_G (3,).
        camera_matrix: C (3, 3), rows summing to 1 (the identity for a known camera).
        camera_matrix_stderr: standard errors of C's entries (zeros unless fitted).
        reduced_chi2: Σ χ²_p / (2P − n_global).
        robust_chi2: median χ²_p / (the median of χ² with 2 degrees of freedom): as the
            reduced χ² for a model that fits, but blind to a few outlying pixels (edges, a
            wrong order); the misfit warning reads it.
        warnings: what the fit found wrong (a misfit, clipped pixels, ambiguity).
        encoding: how the image was read (`core.image.Photo.describe`).
        camera, illuminant: the camera and light names of the model.
        n_pixels, seconds: pixels fitted and the wall time (compilation included).
        stderr_calibrated: False for a lossy (JPEG) file: the standard errors assume
            independent noise per pixel, calibrated for raw and linear (lossless) input
            only; a JPEG's block-correlated compression error is not in them.
        illumination: "uniform" or "smooth"; light: the fitted light field (H, W), 1 at its
            peak over the fitted pixels (`fit.photo_light`; all ones under uniform light).
    """

    thickness: np.ndarray
    stderr: np.ndarray
    ambiguous: np.ndarray
    alternative: np.ndarray
    chi2: np.ndarray
    exposure: float
    white_balance: np.ndarray
    camera_matrix: np.ndarray
    camera_matrix_stderr: np.ndarray
    reduced_chi2: float
    robust_chi2: float
    warnings: tuple
    encoding: str
    camera: str
    illuminant: str
    n_pixels: int
    seconds: float
    illumination: str = "uniform"
    light: np.ndarray | None = None
    stderr_calibrated: bool = True

    @property
    def chi2_text(self) -> str:
        """The reduced χ² as every output says it (`chi2_text`)."""
        return chi2_text(self.robust_chi2, self.reduced_chi2)

    @property
    def pixels_per_second(self) -> float:
        return self.n_pixels / self.seconds if self.seconds > 0 else float("inf")

    def summary(self) -> dict:
        """The fit's global numbers and residual summary (JSON-ready)."""
        ok = np.isfinite(self.thickness)
        return {
            "encoding": self.encoding, "camera": self.camera, "illuminant": self.illuminant,
            "exposure": float(self.exposure),
            "white_balance": [float(v) for v in self.white_balance],
            "camera_matrix": np.asarray(self.camera_matrix).tolist(),
            "camera_matrix_stderr": np.asarray(self.camera_matrix_stderr).tolist(),
            "reduced_chi2": float(self.reduced_chi2),
            "robust_chi2": float(self.robust_chi2),
            "pixels_fitted": int(self.n_pixels),
            "pixels_ambiguous": int(np.sum(self.ambiguous)),
            "median_stderr_nm": float(np.median(self.stderr[ok])) if ok.any() else None,
            "chi2_p50_p99": [float(np.percentile(self.chi2[ok], q)) for q in (50, 99)]
            if ok.any() else None,
            "stderr_calibrated": bool(self.stderr_calibrated),
            "illumination": self.illumination,
            "light_min_max": [float(np.nanmin(self.light)), float(np.nanmax(self.light))]
            if self.light is not None and ok.any() else None,
            "seconds": float(self.seconds), "pixels_per_second": float(self.pixels_per_second),
            "warnings": list(self.warnings),
        }


def chi2_text(robust: float, mean: float) -> str:
    """"reduced chi2 = R (robust; mean M)": the one way the warning, the console and the
    figure's title say the reduced χ²."""
    return f"reduced chi2 = {robust:.3g} (robust; mean {mean:.3g})"


def _describe(photo: Photo, n_clip: int) -> str:
    """`Photo.describe` with the fit's count of pixels with a clipped channel (its censoring,
    a JPEG's black level included) in place of the reader's: one count everywhere."""
    head = photo.describe().rsplit("; ", 1)[0]
    return f"{head}; {n_clip} pixel{'' if n_clip == 1 else 's'} with a clipped channel"


# ----------------------------------------------------------------------------- the model
def _layer_stack(template, layer: int) -> Stack:
    stack = as_stack(template)
    if not 0 <= layer < stack.n_layers:
        raise ValueError(f"layer must index the template's {stack.n_layers} layer(s), "
                         f"got {layer}")
    return stack


def _geometry(theta_o, alpha, na=None, stack=None, layer=0, wavelengths=None, hi=None):
    """(cosines (N,), weights (N,)) at which the reflectance is averaged: the mirror view,
    the SPEC §7 patch quadrature of a rough surface under uniform light, or a microscope
    objective's cone of numerical aperture `na` (SPEC §14, `optics.objective.cone_nodes`:
    uniform in the pupil, nodes enough for the layer at `hi` nm)."""
    if na is not None:
        from ..optics.objective import cone_nodes

        d = np.array(np.asarray(stack.thickness, float))
        d[..., layer] = float(hi) if hi is not None else d[..., layer]
        return cone_nodes(stack, wavelengths, na, thickness_max=d)
    if alpha is None:
        return np.asarray([np.cos(theta_o)]), np.asarray([1.0])
    quad = patch_quadrature(jnp.float64(theta_o), jnp.float64(alpha), quadrature=_QUADRATURE)
    return np.asarray(quad.cos_hi).ravel(), np.asarray(quad.weight).ravel()


@functools.partial(jax.jit, static_argnames=("layer",))
def _colours(d, stack, layer, cos, qw, lam, weights):
    """(s (G, 3), ds/dd (G, 3)) at thicknesses d (G,) of layer `layer` (module docstring)."""

    def s_of(di):
        st = stack._replace(thickness=jnp.asarray(stack.thickness).at[layer].set(di))
        r = stack_reflectance_traced(st, cos[:, None], lam[None, :])  # (N, K)
        rbar = jnp.matmul(qw, r, precision=_HI)  # (K,)
        return jnp.matmul(rbar, weights, precision=_HI)

    return jax.vmap(lambda di: jax.jvp(s_of, (di,), (jnp.ones_like(di),)))(d)


def photo_colours(template, thickness, *, camera: Camera, theta_o=0.0, alpha=None,
                  layer: int = 0, na=None):
    """The camera colours s(d) (..., 3) of the template with layer `layer` at `thickness`
    (..., nm), white-balanced to the camera's light (a white reflector reads 1); `na`: seen
    through a microscope objective of that numerical aperture (SPEC §14)."""
    stack = _layer_stack(V.check_material(template, "template",
                                          wavelengths=camera.wavelengths), layer)
    d = np.asarray(thickness, float)
    _check_na(na, theta_o, alpha)
    cos, qw = _geometry(float(theta_o), alpha, na, stack, layer, camera.wavelengths,
                        float(np.max(d, initial=0.0)))
    s, _ = _colours(jnp.asarray(d.ravel()), stack, layer, jnp.asarray(cos), jnp.asarray(qw),
                    jnp.asarray(camera.wavelengths), jnp.asarray(camera.weights))
    return np.asarray(s).reshape(*d.shape, -1)


def render_photo(template, thickness, *, camera="srgb", illuminant="D65", theta_o=0.0,
                 alpha=None, layer: int = 0, exposure: float = 1.0,
                 white_balance=(1.0, 1.0, 1.0), na=None) -> np.ndarray:
    """A linear photograph (H, W, 3) of the template with the thickness map `thickness`
    (H, W): exposure · wb_c · s_c(d) of the module docstring (no noise, no encoding). The
    same model `fit_photo` fits: for tests and examples; studies render independently."""
    cam = camera_response(camera, illuminant)
    s = photo_colours(template, thickness, camera=cam, theta_o=theta_o, alpha=alpha,
                      layer=layer, na=na)
    return exposure * np.asarray(white_balance, float) * s


def _hermite(d, lo, h, s, ds):
    """Cubic Hermite interpolant of the table (s, ds) (G, 3) on lo + h·g at d (scalar)."""
    g = s.shape[0]
    u = (d - lo) / h
    fi = jnp.clip(jnp.floor(u), 0, g - 2)
    i = fi.astype(jnp.int32)
    t = u - fi
    t2, t3 = t * t, t * t * t
    h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
    h01, h11 = -2 * t3 + 3 * t2, t3 - t2
    return h00 * s[i] + h10 * h * ds[i] + h01 * s[i + 1] + h11 * h * ds[i + 1]


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


# ----------------------------------------------------------------------------- refine
@functools.partial(jax.jit, static_argnames=("steps", "want_se"))
def _refine(obs, sig, cens, d0, nb, nb_ok, tau, gm, lo_d, hi_d, lo, h, s_tab, ds_tab, black,
            steps,
            want_se):
    """Per pixel: Levenberg–Marquardt on [(g C s(d) − o)/σ, (d − d_q)/τ]; returns d, the
    data χ² and the standard error (absolute σ)."""

    def pixel(o, sg, cs, x0, q, ok):
        def data(x):
            pred = jnp.matmul(gm, _hermite(x[0], lo, h, s_tab, ds_tab), precision=_HI)
            return residual(pred, o, sg, cs, black)

        def res(x):
            return jnp.concatenate([data(x), jnp.where(ok, (x[0] - q) / tau, 0.0)])

        x = levenberg_marquardt(res, x0[None], lo_d[None], hi_d[None], steps)
        r = data(x)
        se = covariance(data, x, absolute_sigma=True).stderr[0] if want_se else x[0] * 0
        return x[0], jnp.sum(r * r), se

    return jax.vmap(pixel)(obs, sig, cens, d0, nb, nb_ok)


def _neighbours(d, valid):
    p = np.pad(d, 1, constant_values=0.0)
    v = np.pad(valid, 1, constant_values=False)

    def four(a):
        return np.stack([a[:-2, 1:-1], a[2:, 1:-1], a[1:-1, :-2], a[1:-1, 2:]], axis=-1)

    return four(p), four(v)


def _icm(cand_d, cand_chi, valid, tau, sweeps=6):
    """Iterated conditional modes over K candidate thicknesses per pixel (H, W, K) with
    energy ½χ² + Σ_q ½((d − d_q)/τ)² (checkerboard updates); returns the chosen index."""
    h, w, _ = cand_d.shape
    idx = np.argmin(cand_chi, axis=-1)
    colour = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)
    for _ in range(sweeps):
        for c in (False, True):
            cur = np.take_along_axis(cand_d, idx[..., None], -1)[..., 0]
            nb, ok = _neighbours(np.where(valid, cur, 0.0), valid)
            pair = np.sum(np.where(ok[..., None, :], ((cand_d[..., :, None] - nb[..., None, :])
                                                       / tau) ** 2, 0.0), axis=-1)
            new = np.argmin(0.5 * cand_chi + 0.5 * pair, axis=-1)
            idx = np.where(colour == c, new, idx)
    return idx


# ----------------------------------------------------------------------------- entry point
def _check_na(na, theta_o, alpha):
    """A microscope objective's NA (SPEC §14): a number ≥ 0 (its upper bound, the ambient's
    index, is checked with the stack), seen along the axis (θ_o = 0) of a mirror (α None)."""
    if na is None:
        return
    if np.ndim(na) != 0 or not np.isfinite(float(na)) or float(na) < 0:
        raise ValueError(f"na must be a number ≥ 0 (the objective's numerical aperture), "
                         f"got {na!r}")
    if float(theta_o) != 0.0 or alpha is not None:
        raise ValueError("na (a microscope objective) views along its axis: give theta_o=0 "
                         "and alpha=None with it")


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


def _censoring(photo: Photo, lossy: bool) -> tuple[np.ndarray, float]:
    """((H, W, 3) per channel: 0 a reading, 1 clipped at black, 2 clipped at full scale (≥ 1,
    for integer or sRGB-encoded sources; linear float data have no ceiling); the black level
    b). b = 0, except for a lossy (JPEG) file, whose DCT rings a clipped channel up to a few
    codes: b is the linear value of `_JPEG_BLACK_CODES` / 255 there."""
    v = photo.linear
    black = 0.0
    if lossy:
        code = _JPEG_BLACK_CODES / 255.0
        black = float(np.asarray(code / 12.92 if photo.encoding == "srgb" else code))
    ceiling = photo.bit_depth is not None or photo.encoding == "srgb"
    cens = np.where(v <= black, 1, np.where(ceiling & (v >= 1.0), 2, 0)).astype(np.int32)
    return cens, black


def fit_photo(image, template, *, camera, illuminant="D65", encoding: str = "srgb",
              reference=None, theta_o=0.0, alpha=None, thickness_range=(0.0, 2000.0),
              layer: int = 0, smoothness_nm=None, mask=None, bit_depth=None,
              model_floor: float | None = None, grid_step_nm: float = 1.0,
              screen_step_nm: float = 4.0, steps: int = 6,
              chi2_warn: float = 4.0, chunk: int = 4096, progress: bool = False,
              illumination: str = "uniform", na=None) -> PhotoResult:
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
        `PhotoResult`.

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
    photo: Photo = read_photo(image, encoding, bit_depth=bit_depth)
    h, w, _ = photo.linear.shape
    cens_img, black = _censoring(photo, jpeg)
    valid = ~np.all(cens_img > 0, axis=-1)
    if mask is not None:
        valid &= read_mask(mask, (h, w), name="mask")
    if not valid.any():
        raise ValueError("no pixel to fit: every pixel is clipped or outside the mask")
    def sigma(floor):
        return np.sqrt(photo.noise ** 2 + (floor * photo.linear) ** 2
                       + (1e-6 * max(float(photo.linear.max()), 1e-12)) ** 2)

    sig_img = sigma(model_floor)

    # 1. the table (fine, for the interpolant) and the screen grid (every m-th point)
    g_n = int(np.ceil((hi - lo) / grid_step_nm)) + 1
    grid = np.linspace(lo, hi, g_n)
    step = (hi - lo) / (g_n - 1)
    every = max(1, int(round(screen_step_nm / step)))
    coarse = np.unique(np.r_[np.arange(0, g_n, every), g_n - 1])
    cos, qw = _geometry(float(theta_o), alpha, na, stack, layer, cam.wavelengths, hi)
    geom = (stack, layer, jnp.asarray(cos), jnp.asarray(qw))

    def table_of(camera_: Camera):
        s_tab, ds_tab = (np.asarray(v) for v in _colours(
            jnp.asarray(grid), *geom, jnp.asarray(camera_.wavelengths),
            jnp.asarray(camera_.weights)))
        return (lo, hi, step, s_tab, ds_tab, black)

    table = table_of(cam)

    def s_of(d):
        return _host_hermite(np.asarray([d], float), lo, step, *table[3:5])[0]

    # 2. gains
    where = np.flatnonzero(valid.ravel())
    obs = photo.linear.reshape(-1, 3)[where]
    sig = sig_img.reshape(-1, 3)[where]
    cens = cens_img.reshape(-1, 3)[where]
    n = obs.shape[0]
    regions = _read_reference(reference, valid)
    known = np.full(h * w, np.nan)
    for m, t in regions:
        known[m.ravel()] = t
    known = known[where]
    pads = np.isfinite(known)
    if regions:
        gains, cmat, cmat_se = reference_gains(photo.linear, sig_img, cens_img, regions,
                                                s_of, cam.kind)
    else:
        cmat, cmat_se = np.eye(3), np.zeros((3, 3))
        gains = search_gains(obs, sig, cens, table[3][coarse], jnp.asarray(grid[coarse]),
                              chunk, black)
    light = np.ones(n)
    if illumination == "smooth":  # the field, then the photograph divided by it
        light, gains, ident = _smooth_light(obs, sig, cens, known, basis(where, h, w),
                                            gains, cmat, table, grid[coarse], chunk, steps)
        obs, sig = obs / light[:, None], sig / light[:, None]
    tau = float(smoothness_nm) if smoothness_nm is not None else np.inf
    k = _CANDIDATES
    rounds = _BASIS_ROUNDS if cam.kind == "unknown" else 0
    bar = _progress(progress, n, (1 + k) * n * (1 + rounds) + 2 * n)

    def orders(table, gm):
        """3. screen: the k best distinct local minima per pixel; 4. refine each; choose
        (best, or by the neighbour prior); → (d_best, d_alt, has_alt), pads at their d."""
        s_tab = table[3]
        top, top_chi = screen_all(obs, sig, cens, features(s_tab[coarse] @ gm.T, black),
                                   jnp.asarray(grid[coarse]), k, chunk, bar)
        cand0 = grid[coarse][top]  # (n, k); a missing minimum repeats the pixel's best
        cand0 = np.where(np.isfinite(top_chi), cand0, cand0[:, :1])
        rep = (np.repeat(a, k, axis=0) for a in (obs, sig, cens))
        cd, cchi, _ = (v.reshape(n, k) for v in _refine_all(
            *rep, cand0.ravel(), None, np.inf, gm, table, steps, chunk, bar))
        if smoothness_nm is None:
            pick = np.argmin(cchi, axis=-1)
        else:
            cd_img = np.zeros((h * w, k))
            cchi_img = np.full((h * w, k), 1e30)
            cd_img[where], cchi_img[where] = cd, cchi
            pick = _icm(cd_img.reshape(h, w, k), cchi_img.reshape(h, w, k), valid,
                        tau).ravel()[where]
        rows = np.arange(n)
        d_best = np.where(pads, known, cd[rows, pick])
        other = np.where(np.abs(cd - d_best[:, None]) >= DISTINCT_NM, cchi, np.inf)
        alt = np.argmin(other, axis=-1)
        has_alt = np.isfinite(other[rows, alt])
        return d_best, np.where(has_alt, cd[rows, alt], d_best), has_alt

    def model_from_pixels(table, gm, d, kind, sub=slice(None)):
        s_fit = _host_hermite(d, lo, step, *table[3:5])
        o, sg, cs, pd = obs[sub], sig[sub], cens[sub], pads[sub]
        if kind == "unknown":
            return matrix_from_pixels(o, sg, cs, s_fit)
        if kind == "basis":  # the pads, known, weigh as much as all other pixels together
            up = np.sqrt(max((pd.size - pd.sum()) / max(pd.sum(), 1), 1.0)) * _PAD_WEIGHT
            return matrix_from_pixels(o, sg / np.where(pd, up, 1.0)[:, None], cs, s_fit,
                                       smooth=_BASIS_SMOOTHING)
        return closed_gains(o, sg, cs, s_fit @ cmat.T)[:, None] * cmat

    try:
        gm = gains[:, None] * cmat
        d_best, d_alt, has_alt = orders(table, gm)
        # 5. gains (no references), an unknown camera's matrix, from every pixel, alternating
        #    with the thicknesses (the pads fixed at theirs) until they settle
        # (on a subsample: a handful of global parameters, then every pixel below)
        sub = np.unique(np.r_[np.arange(0, n, max(1, n // _GAIN_PIXELS)), np.flatnonzero(pads)])
        d_sub = d_best[sub]
        for _ in range(_GAIN_ROUNDS if not regions or cam.kind == "unknown" else 0):
            gm_new = model_from_pixels(table, gm, d_sub, cam.kind, sub)
            change = np.max(np.abs(gm_new - gm)) / np.max(np.abs(gm))
            gm = gm_new
            d_sub = np.where(pads[sub], known[sub], _refine_all(
                obs[sub], sig[sub], cens[sub], d_sub, None, np.inf, gm, table, steps, chunk,
                None)[0])
            if change < 1e-8:
                break
        d_best[sub] = d_sub
        if cam.kind == "unknown":
            # the 3 × 3 matrix on the observer's bands (reported), then the camera's
            # sensitivities on a basis of hat functions (Luther's condition fails for real
            # cameras: a 3 × 3 matrix cannot match them), from every pixel, re-screened
            cmat3 = gm
            if rounds:
                table = table_of(sensitivity_basis(illuminant))
            for _ in range(rounds):
                gm = model_from_pixels(table, None, d_best, "basis")
                d_best, d_alt, has_alt = orders(table, gm)
            gains = gm.sum(axis=1)
            cmat = cmat3 / cmat3.sum(axis=1)[:, None]
        else:
            gains = np.diag(gm).copy()
        # the final refine: the chosen thickness (with the neighbour prior) and the other order
        d, chi, se = _refine_all(obs, sig, cens, d_best, valid if np.isfinite(tau) else None,
                                 tau, gm, table, steps, chunk, bar, where=where, want_se=True)
        _, chi_alt, _ = _refine_all(obs, sig, cens, d_alt, None, np.inf, gm, table, steps,
                                    chunk, bar)
        chi_alt = np.where(has_alt, chi_alt, np.inf)
        d_alt = np.where(has_alt, d_alt, np.nan)
    finally:
        if bar is not None:
            bar.close()

    # 5. uncertainty, ambiguity, warnings. The fit's own χ² scales the standard errors and
    #    the ambiguity test; the misfit statistics use the reporting floor (a JPEG's 2 %,
    #    which, applied in the fit, would skew the channels' weights and so the white balance)
    n_global = 3 + (6 if cam.kind == "unknown" else 0)
    dof = max(2 * n - n_global, 1)
    robust_fit = float(np.median(chi) / _CHI2_2_MEDIAN)
    scale = np.sqrt(robust_fit)
    span = (float(known[pads].min()), float(known[pads].max())) if (
        cam.kind == "unknown" and pads.any()) else None
    why = flag_reasons(chi, chi_alt, robust_fit, d, where, (h, w), span)
    amb = np.any(np.stack(list(why.values())), axis=0)
    if report_floor != model_floor:
        pred = _host_hermite(d, lo, step, *table[3:5]) @ gm.T
        sig_rep = sigma(report_floor).reshape(-1, 3)[where] / light[:, None]
        chi = np.sum(np.asarray(residual(jnp.asarray(pred), jnp.asarray(obs), jnp.asarray(sig_rep),
                                          jnp.asarray(cens), black)) ** 2, axis=-1)
    rchi2 = float(np.sum(chi) / dof)
    robust = float(np.median(chi) / _CHI2_2_MEDIAN)
    misfit = (f"{chi2_text(robust, rchi2)} > {chi2_warn:g}: the model does not explain the "
              f"photograph within its noise (check the encoding ({photo.encoding}), camera "
              f"({cam.name}), light ({cam.illuminant}), view angle and material); "
              f"thicknesses may be wrong") if robust > chi2_warn else None
    notes, loud = fit_notes(misfit, cens_img, valid, amb, why, jpeg,
                            ident if illumination == "smooth" else None)
    for note in loud:
        warnings.warn(note, stacklevel=2)
    described = _describe(photo, int(np.sum(np.any(cens_img > 0, axis=-1))))

    def full(v, fill=np.nan, dtype=float):
        out = np.full(h * w, fill, dtype)
        out[where] = v
        return out.reshape(h, w)

    return PhotoResult(
        thickness=full(d), stderr=full(se * scale), ambiguous=full(amb, False, bool),
        alternative=full(d_alt), chi2=full(chi),
        exposure=float(gains[1]), white_balance=gains / gains[1], camera_matrix=cmat,
        camera_matrix_stderr=cmat_se, reduced_chi2=rchi2, robust_chi2=robust,
        warnings=tuple(notes),
        encoding=described, camera=cam.name, illuminant=cam.illuminant, n_pixels=n,
        seconds=time.perf_counter() - t0, illumination=illumination, light=full(light),
        stderr_calibrated=not jpeg)


def _smooth_light(obs, sig, cens, known, phi, gains, cmat, table, coarse, chunk, steps):
    """`fit.photo_light.fit_light` on the table: (L (n,), gains (3,), identifiability)."""
    lo, _, step, s_tab, ds_tab, black = table
    feats_grid = jnp.asarray(coarse)
    s_coarse = s_tab[np.rint((coarse - lo) / step).astype(int)]

    def colour(d):
        dd = np.stack([np.interp(d, lo + step * np.arange(len(s_tab)), ds_tab[:, c])
                       for c in range(ds_tab.shape[1])], axis=-1)
        return _host_hermite(d, lo, step, s_tab, ds_tab), dd

    def screen(o, sg, cs, gm):
        top, _ = screen_all(o, sg, cs, features(s_coarse @ gm.T, black), feats_grid, 1,
                            chunk, None)
        return coarse[top[:, 0]]

    def refine(o, sg, cs, d0, gm):
        return _refine_all(o, sg, cs, d0, None, np.inf, gm, table, steps, chunk, None)[0]

    gm0 = gains[:, None] * cmat
    light, gm, ident = fit_light(obs, sig, cens, known, phi, gm0, colour, screen, refine)
    return light, gains * (gm.sum(axis=1) / gm0.sum(axis=1)), ident


def _host_hermite(d, lo, h, s, ds):
    """`_hermite` on the host for a vector d (P,) → (P, 3)."""
    g = s.shape[0]
    u = (d - lo) / h
    i = np.clip(np.floor(u), 0, g - 2).astype(int)
    t = (u - i)[:, None]
    t2, t3 = t * t, t * t * t
    return ((2 * t3 - 3 * t2 + 1) * s[i] + (t3 - 2 * t2 + t) * h * ds[i]
            + (-2 * t3 + 3 * t2) * s[i + 1] + (t3 - t2) * h * ds[i + 1])


def _refine_all(obs, sig, cens, d0, valid, tau, gm, table, steps, chunk, bar, where=None,
                want_se=False):
    """`_refine` over every pixel in chunks: the neighbour prior (τ finite) needs `valid`
    (H, W) and the fitted pixels' flat indices `where` (their neighbours' current d0)."""
    lo, hi, step, s_tab, ds_tab, black = table
    n = obs.shape[0]
    if valid is not None:
        h, w = valid.shape
        img = np.zeros(h * w)
        img[where] = d0
        nb, ok = _neighbours(img.reshape(h, w), valid)
        nb, ok = nb.reshape(-1, 4)[where], ok.reshape(-1, 4)[where]
    else:
        nb, ok = np.zeros((n, 4)), np.zeros((n, 4), bool)
    consts = (jnp.asarray(min(tau, 1e30)), jnp.asarray(gm), jnp.asarray(lo), jnp.asarray(hi),
              jnp.asarray(lo), jnp.asarray(step), jnp.asarray(s_tab), jnp.asarray(ds_tab),
              jnp.asarray(black))
    out = []
    size = bucket(n, chunk)
    for s in chunks(n, size):
        m = s.stop - s.start
        r = _refine(*(jnp.asarray(pad_to(a[s], size)) for a in (obs, sig, cens, d0, nb, ok)),
                    *consts, steps=steps, want_se=want_se)
        out.append([np.asarray(v)[:m] for v in r])
        if bar is not None:
            bar.update(m)
    return [np.concatenate(v) for v in zip(*out)]


class _PixelBar:
    """A tqdm bar over the image's n pixels fed the fit's passes (`work` pixel-passes in
    all): it advances n / work per pixel-pass, so it counts pixels, not passes."""

    def __init__(self, bar, n, work):
        self.bar, self.scale, self.acc, self.done = bar, n / max(work, 1), 0.0, 0

    def update(self, m):
        self.acc += m * self.scale
        step = min(int(self.acc), self.bar.total) - self.done
        if step > 0:
            self.bar.update(step)
            self.done += step

    def close(self):
        if self.done < self.bar.total:
            self.bar.update(self.bar.total - self.done)
        self.bar.close()


def _progress(on, n, work):
    if not on:
        return None
    from tqdm.auto import tqdm

    return _PixelBar(tqdm(total=n, unit="px", desc="fit_photo", leave=False), n, work)
