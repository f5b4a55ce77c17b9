r"""Thickness maps: per-pixel fits of film thickness (optionally η₂) to an image.

An image of a film under known light is, pixel by pixel, one `fit_film` problem with a
single view: the band radiances L_j (J = 3 numbers) of pixel p at its known view angle
θ_o,p. Three numbers cannot pin the fringe order of a thick film on their own, so the map
is fitted in three batched stages, each a pure function of a leading pixel axis (so it
can be `jax.vmap`ped, chunked and sharded across devices, `thinfilm_jax.core.sharding`):

1. *grid*: the loss $E_p(d_g) = \tfrac12\sum_j ((L_j(d_g) - o_{pj})/\sigma)^2$ at `grid`
   thicknesses spanning the box (with η₂ free: the minimum over `eta_grid` film indices);
2. *smoothness prior* (optional, `smoothness_nm` = τ): iterated conditional modes on the
   grid, each pixel in turn (checkerboard order) taking
   $\arg\min_g E_p(d_g) + \tfrac12\sum_{q \in N_4(p)} ((d_g - d_q)/τ)^2$: neighbours
   vote for the fringe order (a warm start from the neighbours);
3. *refine*: Levenberg–Marquardt per pixel from the grid value (`engine.levenberg_marquardt`,
   the one solver of the fits; a fixed number of `steps`, so the pixels run as one
   `jax.vmap` with no data-dependent control flow), with the prior's residuals
   (d − d_q)/τ to the neighbours' current values (Jacobi sweeps), clipped to the box.

The boxes are the fits' table (`options.MAP_BOUNDS`: thickness as `fit_film`, η₂ the map's
screen); `options=` is the fits' one options type, `FitOptions` (its `bounds`), and the map
model's settings are `model_options=` (`ModelOptions`). Standard errors are the linearised
ones of the pixel's own data, σ √((JᵀJ)⁻¹)_dd (`engine.covariance`), with σ the given noise
level (`sigma`, absolute); the map's reduced χ² and misfit warning are those of `FitResult`
(`options` module docstring) over all fitted pixels.

Two front ends over the one per-pixel pipeline (`fit.pixelwise.fit_map`: its stages, the
neighbour prior and the flags), differing only in the per-pixel model
``model(x, pixel inputs, shared inputs) → (J,)`` (`fit.map_models`): `fit_patch_map`
(uniform light, SPEC §7: `patch_one` at the pixel's θ_o) and `fit_envmap_map` (an
environment map, SPEC §9: `envmap_radiance(method="filtered")` at the pixel's normal and
view, background pixels masked out of the fit and the prior).

Example:
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.fit.thickness_map import fit_patch_map, render_patch_map
    >>> d = jnp.linspace(300.0, 420.0, 6).reshape(2, 3)
    >>> theta = jnp.full((2, 3), 0.3)
    >>> img = render_patch_map(Film(d, 1.33, 1.0), theta, 0.2)
    >>> res = fit_patch_map(img, theta, alpha=0.2, initial=Film(350.0, 1.33, 1.0),
    ...                     sigma=1e-3, smoothness_nm=50.0)
    >>> bool(jnp.max(jnp.abs(res.thickness - d)) < 0.5)
    True
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.film import Film
from ..core.material import needs_stack
from ..realtime.options import ModelOptions
from ..core.methods import names as method_names
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from .map_models import (  # noqa: F401  (the map models, read by tests and studies here)
    ENVMAP_MAP_METHODS,
    MAP_OPTIONS,
    _envmap_model,
    _material_pixel_model,
    _pixel_model,
    render_patch_map,
)
from .map_quality import estimate_noise
from .options import MAP_BOUNDS, FitOptions
from .pixelwise import fit_map
from .pixelwise import screen_grid as _grid_losses  # noqa: F401  (stage 1, read by tests)
from .results import MapResult

__all__ = ["MapResult", "estimate_noise", "fit_envmap_map", "fit_patch_map", "render_patch_map"]

def _check_image(image, observer, sigma):
    """(H, W, J) finite radiances as float64 NumPy, else a ValueError naming `image`.

    Band radiances are Σ_k W_kj L(λ_k) with the observer's weights W (columns summing to 1):
    bands whose weights have negative lobes (Stiles–Burch RGB) may be negative, down to
    Σ_k min(W_kj, 0) × the image's largest value; noise adds 5σ. Anything lower is not a
    radiance of this observer (a wrong observer, an sRGB image, an offset) and is rejected.
    """
    obs = get_observer(observer)
    n_bands = obs.n_bands
    a = np.asarray(image)
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)) \
            or a.dtype == bool:
        raise ValueError(f"image must be a real array of band radiances, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if a.ndim != 3 or a.shape[-1] != n_bands or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"image must have shape (H, W, {n_bands}), got {a.shape}")
    bad = ~np.isfinite(a)
    if np.any(bad):
        p = np.argwhere(bad)[0]
        raise ValueError(f"image must be finite: {int(bad.any(-1).sum())} pixel(s) hold "
                         f"NaN/inf, first at (row {p[0]}, col {p[1]})")
    floor = np.minimum(obs.weights, 0.0).sum(axis=0) * max(float(a.max()), 0.0) - 5 * sigma
    low = a < floor
    if np.any(low):
        p = np.argwhere(low)[0]
        raise ValueError(f"image must hold non-negative radiances ({observer} bands reach "
                         f"at most {floor[p[2]]:.3g} below zero with noise σ={sigma:g}): "
                         f"{a[tuple(p)]:.4g} at (row {p[0]}, col {p[1]}, band {p[2]})")
    return a


def _check_options(free, sigma, smoothness_nm, bounds, grid, eta_grid, steps, sweeps, chunk,
                   options):
    """(free, boxes) of a map fit: `MAP_BOUNDS`, then `options.bounds`, then `bounds`."""
    free = (free,) if isinstance(free, str) else tuple(free)
    unknown = [f for f in free if f not in ("thickness", "eta_film")]
    if unknown or "thickness" not in free or len(set(free)) != len(free):
        raise ValueError(f"free must be ('thickness',) or ('thickness', 'eta_film'), got "
                         f"{free}" + (f" (unknown: {unknown})" if unknown else ""))
    if sigma is not None and not (isinstance(sigma, (int, float)) and np.isfinite(sigma)
                                  and sigma > 0):
        raise ValueError(f"sigma must be a finite number > 0 or None (estimated from the "
                         f"image), got {sigma!r}")
    if smoothness_nm is not None and not (np.isfinite(smoothness_nm) and smoothness_nm > 0):
        raise ValueError(f"smoothness_nm must be > 0 or None, got {smoothness_nm!r}")
    for name, v, lo in (("grid", grid, 2), ("eta_grid", eta_grid, 1), ("steps", steps, 0),
                        ("sweeps", sweeps, 0), ("chunk", chunk, 1)):
        V.check_int(name, v, lo)
    b = dict(MAP_BOUNDS)
    for k, v in {**_fit_options(options), **dict(bounds or {})}.items():
        if k not in b:
            raise ValueError(f"bounds: unknown parameter {k!r}; expected thickness, eta_film")
        v = tuple(float(t) for t in v)
        if len(v) != 2 or not (np.all(np.isfinite(v)) and v[0] < v[1]):
            raise ValueError(f"bounds[{k!r}] must be (lo, hi) with lo < hi, got {v}")
        if k == "thickness" and v[0] < 0:
            raise ValueError(f"bounds['thickness'] must be >= 0 nm, got {v}")
        b[k] = v
    return free, b


def _fit_options(options) -> dict:
    """The bounds of `options` (a `FitOptions`, the one options type of the fits; None:
    none); its other fields set the search of `fit_film` and must keep their defaults."""
    if options is None:
        return {}
    if isinstance(options, ModelOptions):
        raise ValueError("options takes a FitOptions (the fit's settings: bounds); the map "
                         "model's ModelOptions is model_options=")
    if not isinstance(options, FitOptions):
        raise ValueError(f"options must be a thinfilm_jax.FitOptions or None, got "
                         f"{type(options).__name__}")
    default = FitOptions()
    changed = [f.name for f in dataclasses.fields(FitOptions)
               if f.name != "bounds" and getattr(options, f.name) != getattr(default, f.name)]
    if changed:
        raise ValueError(f"options: FitOptions field(s) {changed} do not apply to a thickness "
                         f"map (only bounds; its search is grid, eta_grid, sweeps and steps, "
                         f"its model model_options)")
    return dict(options.bounds or ())


def _model_options(model_options, shat_auto: str = "exact") -> ModelOptions:
    if not isinstance(model_options, ModelOptions):
        raise ValueError(f"model_options must be a thinfilm_jax.ModelOptions, got "
                         f"{type(model_options).__name__}")
    return model_options.checked(shat_auto)


def fit_patch_map(image, theta_o, *, alpha, initial: Film, free=("thickness",),
                  method: str = "filtered", sigma: float = 0.01, smoothness_nm=None,
                  bounds=None, grid: int = 201, eta_grid: int = 7, steps: int = 8,
                  sweeps: int = 3, chunk: int = 2048, observer: str = DEFAULT_OBSERVER,
                  model_options: ModelOptions = MAP_OPTIONS, options: FitOptions | None = None,
                  devices=None, progress: bool = False) -> MapResult:
    """Fit a thickness map (optionally η₂) to an image of band radiances (module docstring).

    Args:
        image: (H, W, J) band radiances (as `render_patch_map` / `patch_radiance` give):
            finite, non-negative up to the observer's negative lobes and noise
            (`_check_image`); any real dtype (read as float64).
        theta_o: (H, W) view angle of each pixel (radians, [0, π/2]), or a scalar.
        alpha: GGX roughness α ∈ (0, 1] (known).
        initial: `Film` with scalar fields: η₂ (initial / fixed), η₃, κ₃, η₁ (known).
        free: ("thickness",) or ("thickness", "eta_film").
        method: a `core.methods.names("patch")` name for the map model ("filtered": real-time, default).
        sigma: noise standard deviation of the image (absolute; weights and errors); None:
            estimated from the image's local differences (`estimate_noise`).
        smoothness_nm: τ of the neighbour prior (None: independent pixels).
        bounds: {"thickness": (lo, hi), "eta_film": (lo, hi)} overriding the boxes of
            `options` and the default table `fit.options.MAP_BOUNDS` ((0, 2000) nm, as
            `fit_film`; η₂ (1.2, 1.8), the map's η₂ screen, when η₂ is free).
        grid, eta_grid: grid sizes of stage 1; steps: Levenberg–Marquardt steps per sweep
            (`fit.engine.levenberg_marquardt`, the one solver of the fits);
        sweeps: ICM / Jacobi sweeps of the prior.
        chunk: pixels per batch (memory; progress granularity); every batch has
            min(chunk, H·W) pixels (the last one padded), so one compilation serves a map.
        observer, model_options: the map model's observer and `ModelOptions` (renamed from
            ``options``).
        options: a `FitOptions`, the one options type of the fits, or None: its `bounds`
            apply (under `bounds`); its other fields set `fit_film`'s search and must keep
            their defaults (a map's search is `grid`, `eta_grid`, `sweeps` and `steps`).
        devices: None (one device), or as `thinfilm_jax.core.sharding.map_sharded` takes it
            (an int k, devices, or a `Mesh`): each stage's chunks are split across them.
        progress: show a tqdm progress bar over the chunks.

    Returns:
        `MapResult` with (H, W) maps, the run's pixels per second (the wall time
        includes compilation on a first call) and the misfit test (`reduced_chi2`,
        `warnings`; also warned as a `MisfitWarning`).

    Raises:
        ValueError: naming the argument: an image not (H, W, J), NaN/inf or negative
            radiances, a theta_o that is not a scalar or (H, W), α ∉ (0, 1], unknown `free`
            names, `options` not a `FitOptions` (a `ModelOptions` is `model_options`).
    """
    V.check_choice("method", method, method_names("patch"))
    V.check_choice("observer", observer, OBSERVERS)
    free, b = _check_options(free, sigma, smoothness_nm, bounds, grid, eta_grid, steps,
                             sweeps, chunk, options)
    model_options = _model_options(model_options)
    if sigma is None:
        img = np.asarray(image, float)
        sigma = estimate_noise(img, np.ones(img.shape[:2], bool)) if img.ndim == 3 else 1.0
    image = _check_image(image, observer, float(sigma))
    h, w, n_bands = image.shape
    theta_in = np.asarray(theta_o, float)
    if theta_in.shape not in ((), (h, w)):
        raise ValueError(f"theta_o must be a scalar or have the image's shape ({h}, {w}), "
                         f"got {theta_in.shape}")
    theta = np.broadcast_to(theta_in, (h, w))
    V.check_finite("theta_o", theta)
    V.check_angle("theta_o", theta)
    if np.ndim(alpha) != 0:
        raise ValueError(f"alpha must be a scalar, got shape {np.shape(alpha)}")
    V.check_range("alpha", float(alpha), 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    if needs_stack(initial):
        model, ctx, eta0 = _material_pixel_model(initial, free, method, observer,
                                                 model_options, float(alpha))
    else:
        initial = V.check_film(initial, "initial")
        if np.shape(initial.thickness) != () or any(np.ndim(v) for v in initial):
            raise ValueError("initial must be a Film with scalar fields")
        model = _pixel_model(method, observer, model_options, float(alpha))
        ctx = tuple(jnp.asarray(float(v)) for v in (initial.eta_base, initial.kappa_base,
                                                    initial.eta_outer))
        eta0 = float(initial.eta_film)
    return fit_map(image.reshape(-1, n_bands), theta.reshape(-1), ctx, model,
                   np.ones((h, w), bool), eta0=eta0, free=free, sigma=float(sigma),
                   smoothness_nm=smoothness_nm, bounds=b, grid=grid, eta_grid=eta_grid,
                   steps=steps, sweeps=sweeps, chunk=chunk, devices=devices,
                   progress_bar=progress)


def fit_envmap_map(image, normal, view, prefiltered, *, alpha, initial: Film,
                   free=("thickness",), sigma: float | None = None, smoothness_nm=None,
                   bounds=None, grid: int = 201, eta_grid: int = 7, steps: int = 8,
                   sweeps: int = 3, chunk: int = 2048, observer: str = DEFAULT_OBSERVER,
                   model_options: ModelOptions | None = None, options: FitOptions | None = None,
                   cross_band: bool = True, method: str = "filtered", devices=None,
                   progress: bool = False) -> MapResult:
    """Fit a thickness map (optionally η₂) to an image of a film under an environment map.

    The per-pixel model is `envmap_radiance(film, α, n_p, ω_o,p, prefiltered,
    method=method)` (SPEC §9, a real-time path) with the pixel's known unit normal
    n_p and view direction ω_o,p; the stages (grid, prior, Levenberg–Marquardt) are those of
    `fit_patch_map` (module docstring). Pixels whose normal is NaN (background) or faces
    away from the view (⟨n, ω_o⟩ ≤ 0: no signal) are not fitted and come back NaN; they
    do not take part in the prior.

    An image the model does not explain (a photograph, an exact rendering fitted with
    `filtered`) is caught three ways: the noise is estimated from the image (``sigma=None``)
    rather than assumed, so the reduced χ² measures the model's error against the image's
    own noise and warns past the misfit test; pixels pushed onto the thickness box's bounds
    are counted in a warning; and both these and the pixels that another fringe order fits
    within their (χ²-scaled) noise are flagged `ambiguous`, with that order's thickness in
    `alternative` (`map_quality.order_flags`). `method="improved"` is the closer model where
    the light is uneven (bright sources, Figure 3's scenes).

    Args:
        image: (H, W, J) band radiances; background pixels may hold anything finite.
        normal, view: (H, W, 3) unit world vectors (view points toward the eye); a
            normal of NaN marks a background pixel.
        prefiltered: `PrefilteredEnvMap` (`prefilter_envmap`, built for `observer`).
        alpha: GGX roughness α ∈ (0, 1] (known).
        model_options: `ModelOptions` of the real-time path (default
            `ibl.REALTIME_OPTIONS`; renamed from ``options``).
        options: a `FitOptions` or None, as `fit_patch_map` (its `bounds` apply).
        cross_band: as `envmap_radiance`.
        method: the map model, one of `ENVMAP_MAP_METHODS`: "filtered" (K 29, the default)
            or "improved" (≈ 2.3× its cost a point, closer to the exact reference).
        sigma: the image's noise level (absolute), or None (default): estimated from the
            image's local differences (`estimate_noise`), reported as `MapResult.sigma`.
        the rest: as `fit_patch_map`.

    Example:
        >>> import jax.numpy as jnp, numpy as np
        >>> from thinfilm_jax import Film, prefilter_envmap
        >>> from thinfilm_jax.shading.ibl import envmap_radiance
        >>> from thinfilm_jax.fit.thickness_map import fit_envmap_map
        >>> pref = prefilter_envmap(np.ones((8, 16, 3)), levels=3, resolution=(8, 16),
        ...                         albedo_shape=(8, 5))
        >>> n = np.array([[[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]])
        >>> v = np.broadcast_to([0.0, 0.0, 1.0], n.shape)
        >>> d = jnp.asarray([[300.0, 420.0]])
        >>> img = envmap_radiance(Film(d, 1.33, 1.0), 0.2, n, v, pref, method="filtered")
        >>> res = fit_envmap_map(img, n, v, pref, alpha=0.2, initial=Film(350.0, 1.33, 1.0),
        ...                      sigma=1e-3, bounds={"thickness": (0.0, 1000.0)}, grid=101)
        >>> bool(jnp.max(jnp.abs(res.thickness - d)) < 0.5)
        True
    """
    from ..shading.ibl import REALTIME_OPTIONS
    from ..shading.prefilter import PrefilteredEnvMap

    V.check_choice("observer", observer, OBSERVERS)
    V.check_choice("method", method, ENVMAP_MAP_METHODS)
    free, b = _check_options(free, sigma, smoothness_nm, bounds, grid, eta_grid, steps,
                             sweeps, chunk, options)
    model_options = _model_options(REALTIME_OPTIONS if model_options is None
                                   else model_options, shat_auto="lut")  # the map's table
    if not isinstance(prefiltered, PrefilteredEnvMap):
        raise ValueError(f"prefiltered must be a PrefilteredEnvMap (prefilter_envmap), got "
                         f"{type(prefiltered).__name__}")
    n_bands = get_observer(observer).n_bands
    nrm = np.asarray(normal, float)
    h, w = nrm.shape[:2] if nrm.ndim == 3 else (0, 0)
    if nrm.ndim != 3 or nrm.shape[-1] != 3:
        raise ValueError(f"normal must have shape (H, W, 3), got {nrm.shape}")
    vw = np.asarray(view, float)
    if vw.shape != nrm.shape:
        raise ValueError(f"view must have the normal's shape {nrm.shape}, got {vw.shape}")
    img = np.asarray(image)
    if img.shape != (h, w, n_bands):
        raise ValueError(f"image must have shape ({h}, {w}, {n_bands}) like normal, got "
                         f"{img.shape}")
    bg = np.any(np.isnan(nrm), axis=-1)
    cos_o = np.where(bg, 0.0, np.sum(np.where(bg[..., None], 0.0, nrm) * vw, axis=-1))
    valid = ~bg & (cos_o > 1e-6)
    if not np.any(valid):
        raise ValueError("no pixel to fit: every normal is NaN or faces away from its view")
    for name, a in (("normal", nrm[valid]), ("view", vw[valid])):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite on the fitted pixels")
        if np.any(np.abs(np.linalg.norm(a, axis=-1) - 1) > 1e-3):
            raise ValueError(f"{name} must be unit vectors")
    if sigma is None:
        sigma = estimate_noise(np.where(valid[..., None], img, 0.0), valid)
    image = _check_image(np.where(valid[..., None], img, 0.0), observer, float(sigma))
    if np.ndim(alpha) != 0:
        raise ValueError(f"alpha must be a scalar, got shape {np.shape(alpha)}")
    V.check_range("alpha", float(alpha), 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    initial = V.check_film(initial, "initial")
    if any(np.ndim(v) for v in initial):
        raise ValueError("initial must be a Film with scalar fields")
    model = _envmap_model(observer, model_options, float(alpha), bool(cross_band), method)
    ctx = tuple(jnp.asarray(float(v)) for v in (initial.eta_base, initial.kappa_base,
                                                initial.eta_outer)) + (prefiltered,)
    pix = (nrm[valid], vw[valid])
    return fit_map(image[valid], pix, ctx, model, valid, eta0=float(initial.eta_film),
                   free=free, sigma=float(sigma), smoothness_nm=smoothness_nm, bounds=b,
                   grid=grid, eta_grid=eta_grid, steps=steps, sweeps=sweeps, chunk=chunk,
                   devices=devices, progress_bar=progress)
