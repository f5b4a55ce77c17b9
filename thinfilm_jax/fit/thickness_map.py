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

Two front ends share these stages (`_fit_map`), differing only in the per-pixel model
``model(x, pixel inputs, shared inputs) → (J,)``: `fit_patch_map` (uniform light, SPEC §7:
`patch_one` at the pixel's θ_o) and `fit_envmap_map` (an environment map, SPEC §9:
`envmap_radiance(method="filtered")` at the pixel's normal and view, background pixels
masked out of the fit and the prior).

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
import functools
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..core.material import batch_shape, needs_stack
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import require
from ..core.stack import Stack
from ..optics.index import index_at
from ..realtime.options import ModelOptions
from ..shading.patch import METHODS, patch_one, stack_patch_one
from ..spectral.reflectance import band_centroids, band_film
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from .engine import covariance, levenberg_marquardt
from .map_quality import estimate_noise, neighbours, order_flags
from .options import (
    MAP_BOUNDS,
    MISFIT_QUANTILE,
    FitOptions,
    MisfitWarning,
    misfit_warnings,
    reduced_chi2,
)

__all__ = ["MapResult", "estimate_noise", "fit_envmap_map", "fit_patch_map", "render_patch_map"]

#: The map model's defaults: the real-time `filtered` path, small quadrature (its moments).
MAP_OPTIONS = ModelOptions(shat="exact", quadrature=(8, 8), arithmetic="complex")


class MapResult(NamedTuple):
    """A fitted map (H, W) per field, plus the run's statistics.

    Attributes:
        thickness, eta_film: the fitted maps (NaN where no pixel was fitted).
        loss: ½ Σ_j ((L_j − o_j)/σ)² of each pixel's data (the prior's terms not included).
        stderr: the linearised standard error of each pixel's thickness from its own data
            (σ absolute; module docstring); inf where the data do not determine it.
        seconds, pixels_per_second: the run's wall time (compilation included on a first
            call).
        reduced_chi2: Σ r² / (P (J − p)) over the P fitted pixels, J bands, p free
            parameters per pixel: ≈ 1 when the map model explains the image within σ.
        warnings: the misfit test of `options` (the 99.9 % point of χ²_ν/ν, ν = P (J − p));
            the map fits also `warnings.warn` it as a `MisfitWarning`; and a count of the
            pixels at the box's bounds where any are.
        sigma: the noise level the fit used (the given one, or the estimate from the image's
            local differences, `estimate_noise`, where ``sigma=None``).
        ambiguous: (H, W) bool: the pixel's thickness is not pinned by its data (`map_quality.order_flags`):
            another fringe order explains it within its noise, or it sits on the box's bound.
        alternative: (H, W) that other order's thickness (nm; NaN where none was found).
        at_bound: (H, W) bool: the thickness sits on a bound of the box (the data pull
            outside the box: a model that does not explain the pixel, or a box too narrow).
    """

    thickness: Array
    eta_film: Array
    loss: Array
    stderr: Array
    seconds: float
    pixels_per_second: float
    reduced_chi2: float = float("nan")
    warnings: tuple = ()
    sigma: float = float("nan")
    ambiguous: Array | None = None
    alternative: Array | None = None
    at_bound: Array | None = None


@functools.lru_cache(maxsize=32)
def _pixel_model(method, observer, options, alpha):
    """model(x = (d, η₂), θ_o, ctx = (η₃, κ₃, η₁)) → (J,) of one pixel (cached: one jit
    compilation per model, not per call)."""
    def model(x, theta, ctx):
        film = Film(x[0], x[1], ctx[0], ctx[1], ctx[2])
        return patch_one(film, theta, alpha, method=method, observer=observer,
                         options=options)
    return model


def render_patch_map(film: Film, theta_o, alpha, *, method: str = "filtered",
                     observer: str = DEFAULT_OBSERVER,
                     options: ModelOptions = MAP_OPTIONS) -> Array:
    """Band radiances (H, W, J) of a film whose fields (H, W) vary per pixel, seen at the
    per-pixel view angles θ_o (H, W) under uniform light (SPEC §7): the map model. The
    fields and θ_o broadcast together (a scalar θ_o, or a scalar field, is fine)."""
    theta_o = jnp.asarray(theta_o)
    dt = theta_o.dtype if jnp.issubdtype(theta_o.dtype, jnp.floating) else float
    shape = np.broadcast_shapes(theta_o.shape, *(np.shape(v) for v in film))
    f = jax.tree.map(lambda v: jnp.broadcast_to(jnp.asarray(v, dt), shape), film)
    theta_o = jnp.broadcast_to(theta_o.astype(dt), shape)
    model = _pixel_model(method, observer, options, float(alpha))
    out = _render_flat(tuple(v.reshape(-1) for v in (*f, theta_o)), model)
    return out.reshape(*theta_o.shape, -1)


@functools.partial(jax.jit, static_argnames=("model",))
def _render_flat(flat, model):
    def one(d, e, e3, k3, e1, t):
        return model(jnp.stack([d, e]), t, (e3, k3, e1))

    return jax.vmap(one)(*flat)


@functools.partial(jax.jit, static_argnames=("model",))
def _grid_losses(obs, pix, ctx, grid, sigma, model):
    """(P, G) losses of every pixel (its per-pixel inputs `pix`) at every grid point (G, 2)."""

    def pixel(o, p):
        pred = jax.vmap(lambda x: model(x, p, ctx))(grid)
        r = (pred - o) / sigma
        return 0.5 * jnp.sum(r * r, axis=-1)

    return jax.vmap(pixel)(obs, pix)


@functools.partial(jax.jit, static_argnames=("model", "steps", "free_eta"))
def _refine(obs, pix, x0, nb, nb_ok, ctx, sigma, tau, lo, hi, model, steps, free_eta):
    """Per pixel: `steps` Levenberg–Marquardt steps (`engine.levenberg_marquardt`) on
    [(L(x) − o)/σ, (d − d_q)/τ] from x0, clipped to [lo, hi]; the data loss ½Σ((L − o)/σ)²
    and the standard error of d from the pixel's own data (`engine.covariance`, σ absolute)."""
    p = 2 if free_eta else 1

    def pixel(o, pp, x, q, ok):
        def full(xf):
            return xf if free_eta else jnp.stack([xf[0], x[1]])

        def data(xf):
            return (model(full(xf), pp, ctx) - o) / sigma

        def res(xf):
            return jnp.concatenate([data(xf), jnp.where(ok, (xf[0] - q) / tau, 0.0)])

        xf = levenberg_marquardt(res, x[:p], lo[:p], hi[:p], steps)
        r = data(xf)
        se = covariance(data, xf, absolute_sigma=True).stderr[0]
        return full(xf), 0.5 * jnp.sum(r * r), se

    return jax.vmap(pixel)(obs, pix, x0, nb, nb_ok)


def _icm(energy, values, tau, sweeps, valid):
    """Iterated conditional modes on a (H, W, G) energy over grid `values` (G,) with the
    pairwise prior ½((v_g − v_q)/τ)² between 4-neighbours (checkerboard updates)."""
    idx = np.argmin(energy, axis=-1)
    h, w = idx.shape
    colour = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)
    for _ in range(sweeps):
        for c in (False, True):
            nb, ok = neighbours(values[idx], valid)
            pair = 0.5 * np.sum(np.where(ok[..., None], ((values[None, None, None, :]
                                                         - nb[..., None]) / tau) ** 2, 0.0),
                                axis=2)
            new = np.argmin(energy + pair, axis=-1)
            idx = np.where(colour == c, new, idx)
    return idx


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


def _misfit(loss, n_bands, p):
    """(reduced χ², warnings) of a map: Σ 2·loss over the fitted pixels / (P (J − p))."""
    from scipy.stats import chi2

    loss = np.asarray(loss, float)
    dof = loss.size * (n_bands - p)
    red = float(reduced_chi2(2.0 * np.sum(loss), loss.size * n_bands, loss.size * p, True))
    msg = misfit_warnings(red, dof, "the map model")
    if msg:
        k = int(np.sum(2.0 * loss > chi2.ppf(MISFIT_QUANTILE, n_bands - p)))
        msg = (msg[0] + f" ({k} of {loss.size} pixels beyond their own "
               f"{100 * MISFIT_QUANTILE:g} % point)",)
        for m in msg:
            warnings.warn(m, MisfitWarning, stacklevel=4)
    return red, msg


def _fit_map(obs, pix, ctx, model, valid, *, eta0, free, sigma, smoothness_nm, bounds,
             grid, eta_grid, steps, sweeps, chunk, devices, progress) -> MapResult:
    """The shared engine: `obs` (P, J) and per-pixel model inputs `pix` (a pytree of
    (P, ...) leaves) of the P fitted pixels, the True entries of `valid` (H, W) in row-major
    order; shared inputs `ctx`; ``model(x, pix_p, ctx) → (J,)``. Other pixels are NaN."""
    h, w = valid.shape
    where = np.flatnonzero(valid)
    free_eta = "eta_film" in free
    b = bounds
    lo = jnp.asarray([b["thickness"][0], b["eta_film"][0] if free_eta else 0.0])
    hi = jnp.asarray([b["thickness"][1], b["eta_film"][1] if free_eta else 10.0])
    d_grid = np.linspace(*b["thickness"], grid)
    e_grid = np.linspace(*b["eta_film"], eta_grid) if free_eta else np.asarray([eta0])
    grid_x = jnp.asarray(np.stack(np.meshgrid(d_grid, e_grid, indexing="ij"), -1).reshape(-1, 2))
    n = obs.shape[0]

    grid_fn = functools.partial(_grid_losses, model=model)
    refine_fn = functools.partial(_refine, model=model, steps=steps, free_eta=free_eta)
    if devices is not None:
        from ..core.sharding import map_sharded  # lazily: only a sharded run needs it

        grid_fn = map_sharded(grid_fn, in_axes=(0, 0, None, None, None), devices=devices)
        refine_fn = map_sharded(refine_fn, in_axes=(0, 0, 0, 0, 0) + (None,) * 5,
                                devices=devices)
    size = min(chunk, n)  # every batch has this size (the last one padded): one compile
    n_pad = -(-n // size) * size
    chunks = [slice(i, i + size) for i in range(0, n_pad, size)]

    def pad(a):
        a = np.asarray(a)
        return np.concatenate([a, np.repeat(a[-1:], n_pad - n, axis=0)]) if n_pad > n else a

    obs = pad(obs)
    pix = jax.tree_util.tree_map(pad, pix)
    passes = 1 + (sweeps if smoothness_nm is not None else 1)
    bar = _progress(progress, len(chunks) * passes)

    def take(s):
        return jax.tree_util.tree_map(lambda a: jnp.asarray(a[s]), pix)

    t0 = time.perf_counter()
    try:
        with jax.default_matmul_precision("highest"):
            energy = []
            for s in chunks:
                energy.append(np.asarray(grid_fn(jnp.asarray(obs[s]), take(s), ctx, grid_x,
                                                 sigma)))
                bar.update(1)
            energy_all = np.zeros((h * w, grid * e_grid.size))
            energy_all[where] = np.concatenate(energy)[:n]
            energy = energy_all.reshape(h, w, grid, e_grid.size)
            best_e = np.argmin(energy, axis=-1)  # η₂ index per (pixel, d)
            e_d = np.min(energy, axis=-1)
            tau = float(smoothness_nm) if smoothness_nm is not None else np.inf
            idx = _icm(e_d, d_grid, tau, sweeps, valid) if smoothness_nm is not None \
                else np.argmin(e_d, axis=-1)
            x = np.stack([d_grid[idx], e_grid[np.take_along_axis(best_e, idx[..., None],
                                                                  -1)[..., 0]]], -1)
            loss = np.take_along_axis(e_d, idx[..., None], -1)[..., 0]
            se = np.full((h, w), np.nan)
            for _ in range(passes - 1):
                nb, ok = neighbours(x[..., 0], valid)
                if smoothness_nm is None:
                    ok = np.zeros_like(ok)
                out = []
                xf = pad(x.reshape(-1, 2)[where])
                nbf, okf = pad(nb.reshape(-1, 4)[where]), pad(ok.reshape(-1, 4)[where])
                for s in chunks:
                    out.append(jax.tree_util.tree_map(np.asarray, refine_fn(
                        jnp.asarray(obs[s]), take(s), jnp.asarray(xf[s]),
                        jnp.asarray(nbf[s]), jnp.asarray(okf[s]), ctx, sigma,
                        min(tau, 1e30), lo, hi)))
                    bar.update(1)
                x = x.reshape(-1, 2).copy()
                x[where] = np.concatenate([o[0] for o in out])[:n]
                x = x.reshape(h, w, 2)
                loss = loss.reshape(-1).copy()
                loss[where] = np.concatenate([o[1] for o in out])[:n]
                loss = loss.reshape(h, w)
                se = se.reshape(-1).copy()
                se[where] = np.concatenate([o[2] for o in out])[:n]
                se = se.reshape(h, w)
    finally:
        bar.close()
    dt = time.perf_counter() - t0
    ambiguous, alternative, at_bound, _ = order_flags(e_d, d_grid, x[..., 0], loss, valid,
                                                 b["thickness"], obs.shape[-1],
                                                 2 if free_eta else 1)
    x = np.where(valid[..., None], x, np.nan)
    loss, se = np.where(valid, loss, np.nan), np.where(valid, se, np.nan)
    red, msg = _misfit(loss[valid], obs.shape[-1], 2 if free_eta else 1)
    if np.any(at_bound):
        note = (f"{int(at_bound.sum())} of {n} pixels at a bound of the thickness box "
                f"{tuple(b['thickness'])} nm: the model pulls them outside it (a model that "
                f"does not explain them, or a box too narrow); flagged ambiguous")
        warnings.warn(note, MisfitWarning, stacklevel=3)
        msg = msg + (note,)
    return MapResult(jnp.asarray(x[..., 0]), jnp.asarray(x[..., 1]), jnp.asarray(loss),
                     jnp.asarray(se), dt, n / dt, red, msg, float(sigma),
                     ambiguous, alternative, at_bound)


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
        method: a `patch.METHODS` name for the map model ("filtered": real-time, default).
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
    V.check_choice("method", method, METHODS)
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
    return _fit_map(image.reshape(-1, n_bands), theta.reshape(-1), ctx, model,
                    np.ones((h, w), bool),
                    eta0=eta0, free=free, sigma=float(sigma),
                    smoothness_nm=smoothness_nm, bounds=b, grid=grid, eta_grid=eta_grid,
                    steps=steps, sweeps=sweeps, chunk=chunk, devices=devices,
                    progress=progress)


def _material_pixel_model(initial, free, method, observer, options, alpha):
    """(model, ctx, η₂ reported) of a dispersive single film (SPEC §12): the exact methods and
    `ideal` run the stack code per pixel (`patch.stack_patch_one`, ctx = the one-layer
    stack); the other real-time ones each band with the film at its centroid wavelength
    (`spectral.reflectance.band_film`, ctx = the band films' indices (J,) each)."""
    require(method, dispersive=True, stack=isinstance(initial, Stack))
    if isinstance(initial, Stack) and initial.n_layers > 1:
        raise ValueError("a thickness map fits one film: initial must be a Film (or a "
                         "one-layer Stack); fit a multi-layer stack with fit_film/fit_spectrum")
    if "eta_film" in free:
        raise ValueError("free='eta_film' needs a constant film index: this film's index is a "
                         "model (free its parameters with fit_film)")
    exact = METHOD_INFO[method].exact or method == "ideal"
    stack = V.check_material(initial, "initial", wavelengths=(
        get_observer(observer).wavelengths if exact else band_centroids(observer)))
    if batch_shape(stack) != ():
        raise ValueError("initial must have a scalar thickness (the map's start)")
    eta0 = float(np.real(np.asarray(index_at(stack.eta[0], np.float64(550.0)))))
    if exact:
        return _stack_pixel_model(method, observer, options.quadrature, options.ndf,
                                  alpha), stack, eta0
    bf = band_film(initial if isinstance(initial, Film) else Film(
        0.0, stack.eta[0], stack.eta_base, 0.0, stack.eta_outer), observer)
    n_bands = len(band_centroids(observer))
    ctx = tuple(jnp.broadcast_to(jnp.asarray(v, float), (n_bands,))
                for v in (bf.eta_film, bf.eta_base, bf.kappa_base, bf.eta_outer))
    return _band_pixel_model(method, observer, options, alpha), ctx, eta0


@functools.lru_cache(maxsize=32)
def _stack_pixel_model(method, observer, quadrature, ndf, alpha):
    """model(x = (d, ·), θ_o, ctx = the one-layer stack) → (J,): exact per pixel."""
    def model(x, theta, ctx):
        return stack_patch_one(ctx._replace(thickness=x[:1]), theta, alpha, method=method,
                               observer=observer, quadrature=quadrature, ndf=ndf)
    return model


@functools.lru_cache(maxsize=32)
def _band_pixel_model(method, observer, options, alpha):
    """model(x = (d, ·), θ_o, ctx = (η₂, η₃, κ₃, η₁) of the J band films) → (J,): band j from
    the film at band j's centroid (the real-time methods' approximation of dispersion)."""
    def model(x, theta, ctx):
        def band(e2, e3, k3, e1):
            return patch_one(Film(x[0], e2, e3, k3, e1), theta, alpha, method=method,
                             observer=observer, options=options)
        return jnp.diagonal(jax.vmap(band)(*ctx))
    return model


#: The map models of `fit_envmap_map`: the real-time paths of `envmap_radiance` (one shading
#: point costs them a few hundred ns; the exact ones take a quadrature per point and per
#: grid thickness, 10⁴–10⁶ times that, beyond a per-pixel screen).
ENVMAP_MAP_METHODS = ("filtered", "improved")


@functools.lru_cache(maxsize=32)
def _envmap_model(observer, options, alpha, cross_band, method="filtered"):
    """model(x = (d, η₂), (n, ω_o), ctx = (η₃, κ₃, η₁, prefiltered map)) → (J,): one
    shading point of `envmap_radiance(method=method)` (SPEC §9)."""
    from ..shading.ibl import envmap_radiance  # lazily: the IBL stack only for envmap maps

    def model(x, pix, ctx):
        film = Film(x[0], x[1], ctx[0], ctx[1], ctx[2])
        return envmap_radiance(film, alpha, pix[0], pix[1], ctx[3], method=method,
                               observer=observer, options=options, cross_band=cross_band)
    return model


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
    `alternative` (`map_quality.order_flags`). `method="improved"` is the closer model where the light is
    uneven (bright sources, Figure 3's scenes).

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
    return _fit_map(image[valid], pix, ctx, model, valid, eta0=float(initial.eta_film),
                    free=free, sigma=float(sigma), smoothness_nm=smoothness_nm, bounds=b,
                    grid=grid, eta_grid=eta_grid, steps=steps, sweeps=sweeps, chunk=chunk,
                    devices=devices, progress=progress)


class _NoBar:
    def update(self, k):
        pass

    def close(self):
        pass


def _progress(on, total):
    if not on:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, unit="chunk", desc="fit-map")
