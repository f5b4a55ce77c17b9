r"""The one result type of the per-pixel fits (`fit.pixelwise`): `MapResult`.

`fit_patch_map`, `fit_envmap_map` (band radiances under known light, SPEC §7, §9) and
`fit_photo` (a photograph, SPEC §13) return the same type: (H, W) maps of the thickness, its
standard error, the pixel's χ², the ambiguity flag and the other fringe order, and the run's
statistics (reduced χ², robust reduced χ², warnings, timing). The fields a front end has no
value for are None: η₂ and σ for a photograph (one template index; a per-pixel noise model),
the camera and light fields for a map of band radiances. `PhotoResult` is the same type under
the name `fit_photo` documented first.

Example:
    >>> from thinfilm_jax.fit.results import MapResult, PhotoResult, chi2_text
    >>> PhotoResult is MapResult
    True
    >>> chi2_text(1.04, 1.2)
    'reduced chi2 = 1.04 (robust; mean 1.2)'
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["MapResult", "PhotoResult", "chi2_text"]


def chi2_text(robust: float, mean: float) -> str:
    """"reduced chi2 = R (robust; mean M)": the one way the warning, the console and the
    figure's title say the reduced χ²."""
    return f"reduced chi2 = {robust:.3g} (robust; mean {mean:.3g})"


class MapResult(NamedTuple):
    """A fitted map (H, W) per field, plus the run's statistics. Pixels not fitted (a
    background, clipped or masked pixel) are NaN (False in the flags).

    Attributes:
        thickness: the fitted thickness (nm) of the film (of the template's layer `layer`
            for a photograph).
        eta_film: the fitted (or fixed) η₂ map of a map of band radiances; None for a
            photograph.
        loss: ½ χ² of each pixel's data (the prior's terms not included).
        stderr: the linearised standard error of each pixel's thickness from its own data
            (`engine.covariance`): σ absolute for maps; for a photograph scaled by
            √(robust reduced χ²). inf where the data do not determine it.
        seconds, pixels_per_second: the run's wall time (compilation included on a first
            call) and fitted pixels per second.
        reduced_chi2: Σ χ²_p over the fitted pixels / their degrees of freedom (P (J − p) for
            a map; 2P − n_global for a photograph): ≈ 1 when the model explains the image
            within its noise.
        warnings: what the fit found wrong (the misfit test, pixels at the box's bound,
            clipped pixels, ambiguity); the fits also `warnings.warn` them.
        sigma: the noise level a map fit used (given, or `map_quality.estimate_noise`);
            None for a photograph (per-pixel noise, `core.image`).
        ambiguous: (H, W) bool: the pixel's thickness is not pinned by its data (another
            fringe order explains it within its noise, its neighbours disagree, a JPEG's
            pixel is off its neighbourhood's plane by 10 nm, or, for a map, it sits on the
            box's bound; `map_quality.order_flags`, `photo_flags`).
        alternative: (H, W) that other order's thickness (nm; NaN where none was found).
        at_bound: (H, W) bool: a map's thickness sits on a bound of the box; None for a
            photograph.
        chi2: (H, W) the pixel's χ² (= 2 · loss).
        robust_chi2: the median pixel's χ² over the median of χ² with its degrees of freedom
            (blind to a few outlying pixels; a photograph's misfit warning reads it).
        n_pixels: pixels fitted.
        exposure, white_balance, camera_matrix, camera_matrix_stderr: a photograph's gains:
            the green channel's gain g_G, g / g_G (3,), C (3, 3) (rows summing to 1) and its
            standard errors (`fit.photo`); None for a map.
        encoding, camera, illuminant: how the photograph was read and the camera and light
            names of the model; None for a map.
        illumination: "uniform" or "smooth"; light: a photograph's fitted light field (H, W),
            1 at its peak (`fit.photo_light`); None for a map.
        stderr_calibrated: False for a lossy (JPEG) photograph, whose block-correlated
            compression error is not in the standard errors.
    """

    thickness: np.ndarray
    eta_film: np.ndarray | None = None
    loss: np.ndarray | None = None
    stderr: np.ndarray | None = None
    seconds: float = 0.0
    pixels_per_second: float = float("nan")
    reduced_chi2: float = float("nan")
    warnings: tuple = ()
    sigma: float | None = float("nan")
    ambiguous: np.ndarray | None = None
    alternative: np.ndarray | None = None
    at_bound: np.ndarray | None = None
    chi2: np.ndarray | None = None
    robust_chi2: float = float("nan")
    n_pixels: int = 0
    exposure: float | None = None
    white_balance: np.ndarray | None = None
    camera_matrix: np.ndarray | None = None
    camera_matrix_stderr: np.ndarray | None = None
    encoding: str | None = None
    camera: str | None = None
    illuminant: str | None = None
    illumination: str = "uniform"
    light: np.ndarray | None = None
    stderr_calibrated: bool = True

    @property
    def chi2_text(self) -> str:
        """The reduced χ² as every output says it (`chi2_text`)."""
        return chi2_text(self.robust_chi2, self.reduced_chi2)

    def summary(self) -> dict:
        """The fit's global numbers and residual summary (JSON-ready); a photograph's gains,
        encoding and light where the fit has them."""
        thick = np.asarray(self.thickness)
        ok = np.isfinite(thick)
        se, chi = np.asarray(self.stderr), np.asarray(self.chi2)
        out = {}
        if self.exposure is not None:
            out.update({
                "encoding": self.encoding, "camera": self.camera,
                "illuminant": self.illuminant, "exposure": float(self.exposure),
                "white_balance": [float(v) for v in self.white_balance],
                "camera_matrix": np.asarray(self.camera_matrix).tolist(),
                "camera_matrix_stderr": np.asarray(self.camera_matrix_stderr).tolist()})
        out.update({
            "reduced_chi2": float(self.reduced_chi2),
            "robust_chi2": float(self.robust_chi2),
            "pixels_fitted": int(self.n_pixels),
            "pixels_ambiguous": int(np.sum(self.ambiguous)),
            "median_stderr_nm": float(np.median(se[ok])) if ok.any() else None,
            "chi2_p50_p99": [float(np.percentile(chi[ok], q)) for q in (50, 99)]
            if ok.any() else None,
            "stderr_calibrated": bool(self.stderr_calibrated),
            "illumination": self.illumination,
            "light_min_max": [float(np.nanmin(self.light)), float(np.nanmax(self.light))]
            if self.light is not None and ok.any() else None,
            "seconds": float(self.seconds), "pixels_per_second": float(self.pixels_per_second),
            "warnings": list(self.warnings)})
        return out


#: `fit_photo`'s name for the one map result (the photographs' pages and the API index use it).
PhotoResult = MapResult
