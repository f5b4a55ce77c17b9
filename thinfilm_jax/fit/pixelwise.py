r"""The one per-pixel fitting pipeline of the thickness maps (`fit_patch_map`,
`fit_envmap_map`, `fit_photo`).

Each pixel p of an image is a small least-squares problem: its observations o_p (J band
radiances or 3 camera channels) against a *pixel model* m(x, p) of its free parameters x
(the thickness d, optionally η₂; names as `fit.params`: "thickness", "eta_film"), weighted
residuals r_p(x) = (m(x, p) − o_p)/σ_p and χ²_p = Σ r². Colours are periodic in the
optical thickness, so χ²_p(d) has one minimum per fringe order and a local solver alone
lands in the one nearest its start. The pipeline, in its stages (each a pure function of a
leading pixel axis, run in padded chunks: one compilation per map, `jax.vmap` inside):

1. **Screen** (`screen_grid`; `photo_screen.screen` for a photograph's tabulated colours,
   one matrix product): χ²_p at every point of a grid over the box, and from it K candidates
   per pixel: the whole grid (maps), or the K lowest local minima at least
   `photo_screen.DISTINCT_NM` apart, distinct fringe orders (photographs). Every basin of
   χ²(d) holds a grid point when the step is below the fringe width (≳ 100 nm).
2. **Neighbour prior** (`icm`, with `smoothness_nm` = τ): iterated conditional modes
   (Besag 1986, J. R. Stat. Soc. B 48, 259) over the candidates, each pixel in turn
   (checkerboard order) taking $\arg\min_k \tfrac12\chi^2_{pk} + \tfrac12\sum_{q \in N_4(p)}
   ((d_{pk} - d_q)/τ)^2$: the neighbours vote for the fringe order. Without τ, the lowest
   (maps), or (photographs) the continuation `grow`: from the pixels whose data exclude
   every other order, the film's continuity chooses among the orders each pixel does not
   exclude (Herráez et al. 2002, Appl. Opt. 41, 7437).
3. **Refine** (`refine_pixel`): `steps` Levenberg–Marquardt steps (Levenberg 1944, Q. Appl.
   Math. 2, 164; Marquardt 1963, J. SIAM 11, 431; `engine.levenberg_marquardt`, the one
   solver of the fits; fixed steps, so the pixels run as one `jax.vmap` with no
   data-dependent control flow) on [r_p(x), (d − d_q)/τ], the prior's residuals to the
   neighbours' current values (Jacobi sweeps), clipped to the box; the standard error is
   the linearised σ √((JᵀJ)⁻¹)_dd of the pixel's own data (`engine.covariance`).
4. **Score** : χ²_p, the reduced and robust reduced χ² and the misfit test (`options`
   module docstring, `misfit`), and the flags: `ambiguous` where another fringe order
   explains the pixel within its noise, with that order's thickness in `alternative`
   (`alternative`; the rules: `map_quality.order_flags` for maps, `photo_flags` for
   photographs).

`fit_map` runs the four stages for a model-based pixel model ``model(x, pixel inputs,
shared inputs) → (J,)`` (`fit.map_models`: `patch_one` under uniform light, SPEC §7;
`envmap_radiance` under an environment map, SPEC §9) and returns the one result type,
`fit.results.MapResult`. `fit_photo` (SPEC §13) runs the same stages on its pixel model,
g C s(d) with s the cubic Hermite interpolant of the exact colours (`fit.photo_model`) and
censored residuals, with the photometric gains, the smooth light field
(``illumination="smooth"``) and the objective's NA (``na=``) as what the pixel model reads.

Example (a one-parameter toy model with two fringe orders: the prior picks the one that
continues the neighbours):
    >>> import numpy as np
    >>> from thinfilm_jax.fit.pixelwise import icm
    >>> energy = np.zeros((1, 3, 2)); energy[0, 0] = energy[0, 2] = [0.0, 50.0]
    >>> values = np.broadcast_to([100.0, 300.0], (1, 3, 2))
    >>> energy[0, 1] = [0.1, 0.0]  # alone, the middle pixel takes 300 nm
    >>> icm(energy, values, np.ones((1, 3), bool), tau=50.0, sweeps=2)[0].tolist()
    [0, 0, 0]
"""

from __future__ import annotations

import functools
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .engine import covariance, levenberg_marquardt
from .map_quality import neighbours, order_flags
from .options import MISFIT_QUANTILE, MisfitWarning, misfit_warnings, reduced_chi2
from .results import MapResult

__all__ = ["alternative", "choose", "fit_map", "grow", "icm", "misfit", "progress",
           "refine_pixel", "screen_grid"]


# ----------------------------------------------------------------------------- progress
class _NoBar:
    def update(self, k):
        pass

    def close(self):
        pass


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


def progress(on, total, *, desc, pixels=None):
    """A progress bar (tqdm) or a no-op: over `total` chunks, or, with `pixels` = n, over the
    n pixels fed `total` pixel-passes (`_PixelBar`); off: a no-op bar (None for `pixels`)."""
    if not on:
        return None if pixels is not None else _NoBar()
    if pixels is None:
        from tqdm import tqdm

        return tqdm(total=total, unit="chunk", desc=desc)
    from tqdm.auto import tqdm

    return _PixelBar(tqdm(total=pixels, unit="px", desc=desc, leave=False), pixels, total)


# ----------------------------------------------------------------------------- stages
@functools.partial(jax.jit, static_argnames=("model",))
def screen_grid(obs, pix, ctx, grid, sigma, model):
    """Stage 1: (P, G) losses ½ Σ_j ((m_j(x_g) − o_j)/σ)² of every pixel (its per-pixel
    inputs `pix`) at every grid point x_g (G, p)."""

    def pixel(o, p):
        pred = jax.vmap(lambda x: model(x, p, ctx))(grid)
        r = (pred - o) / sigma
        return 0.5 * jnp.sum(r * r, axis=-1)

    return jax.vmap(pixel)(obs, pix)


def icm(energy, values, valid, tau, sweeps):
    """Stage 2: iterated conditional modes (Besag 1986) over K candidates per pixel: energy
    (H, W, K) of each pixel's data (½χ²), candidate thicknesses `values` (H, W, K) (or
    broadcastable, a shared grid (K,)), the pairwise prior ½((v_k − v_q)/τ)² to the current
    values of the fitted 4-neighbours (`valid` (H, W)), checkerboard updates; returns the
    chosen index (H, W)."""
    idx = np.argmin(energy, axis=-1)
    h, w = idx.shape
    values = np.broadcast_to(values, energy.shape)
    colour = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)
    for _ in range(sweeps):
        for c in (False, True):
            cur = np.take_along_axis(values, idx[..., None], -1)[..., 0]
            nb, ok = neighbours(np.where(valid, cur, 0.0), valid)
            pair = np.sum(np.where(ok[..., None, :], ((values[..., :, None] - nb[..., None, :])
                                                       / tau) ** 2, 0.0), axis=-1)
            new = np.argmin(energy + 0.5 * pair, axis=-1)
            idx = np.where(colour == c, new, idx)
    return idx


def choose(cand_d, cand_chi, where, valid, tau, sweeps):
    """Stage 2 on refined candidates: the index (n,) of each fitted pixel's candidate,
    the lowest χ² (τ None) or by `icm` on the image (the n pixels at the flat indices
    `where` of `valid` (H, W)); candidates (n, K), χ² (n, K)."""
    if tau is None:
        return np.argmin(cand_chi, axis=-1)
    h, w = valid.shape
    k = cand_d.shape[-1]
    cd_img = np.zeros((h * w, k))
    cchi_img = np.full((h * w, k), 1e30)
    cd_img[where], cchi_img[where] = cand_d, cand_chi
    return icm(0.5 * cchi_img.reshape(h, w, k), cd_img.reshape(h, w, k), valid, float(tau),
               sweeps).ravel()[where]


def grow(cand_d, cand_chi, where, valid, tol, known=None, distinct=15.0, first=None):
    r"""Stage 2 without a prior's τ: the fringe orders by continuation from the pixels whose
    order the data decide (quality-guided path following, as in phase unwrapping: Herráez et
    al. 2002, Appl. Opt. 41, 7437). A pixel's candidates within its tolerance of its lowest
    χ² (χ²_pk − min_k χ²_pk < `tol`_p (n,): orders the pixel does not exclude) are its
    *plausible* ones. Seeds: a pixel with one plausible order (no other ≥ `distinct` nm
    away) among the `first` (n,) bool (the pixels the model explains within the noise; None:
    all), and one of `known` thickness (n,) (NaN elsewhere: a pad; its candidate nearest
    that thickness, the region continuing from the known value). The film is continuous,
    so the decided region grows by fronts, first through the `first` pixels, then into the
    rest (quality-guided: a badly explained pixel does not carry an order to a well
    explained one): each undecided pixel with decided 4-neighbours takes, of its plausible
    candidates, the one nearest their mean thickness. Pixels no front reaches (no seed in
    their connected region) keep their lowest χ². Candidates (n, K), χ² (n, K), the n
    pixels at the flat indices `where` of `valid` (H, W); returns the chosen indices (n,).

    Example (the middle pixel alone prefers 300 nm, but 100 nm is within its tolerance and
    continues its decided neighbours):
        >>> import numpy as np
        >>> d = np.array([[100.0, 300.0]] * 3); chi = np.array([[0.0, 50.0], [0.1, 0.0],
        ...                                                    [0.0, 50.0]])
        >>> grow(d, chi, np.arange(3), np.ones((1, 3), bool), np.full(3, 4.0)).tolist()
        [0, 0, 0]
    """
    rows = np.arange(cand_d.shape[0])
    best = np.argmin(cand_chi, axis=-1)
    d_best = cand_d[rows, best]
    plausible = (cand_chi - cand_chi[rows, best][:, None]) < np.asarray(tol)[:, None]
    plausible[rows, best] = True
    other = plausible & (np.abs(cand_d - d_best[:, None]) >= distinct)
    seed = ~np.any(other, axis=-1) & (True if first is None else first)
    if known is not None:  # a pad: its candidate nearest the known thickness, at that value
        pad = np.isfinite(known)
        seed |= pad
        best = np.where(pad, np.argmin(np.abs(cand_d - np.where(pad, known, 0.0)[:, None]),
                                       axis=-1), best)
        d_best = np.where(pad, known, d_best)
    h, w = valid.shape

    def img(fill, v):  # (H·W, …) filled, v at the fitted pixels
        out = np.full((h * w,) + np.shape(v)[1:], fill, np.result_type(v))
        out[where] = v
        return out

    cand, ok = img(0.0, cand_d), img(False, plausible)
    idx, cur, done = img(0, best), img(0.0, d_best), img(False, seed)
    stages = [valid.ravel()] if first is None else [img(False, first), valid.ravel()]
    for reach in stages:
        while True:
            nb, nb_ok = (a.reshape(h * w, 4) for a in neighbours(cur.reshape(h, w),
                                                                 done.reshape(h, w)))
            front = np.flatnonzero(reach & ~done & nb_ok.any(axis=-1))
            if front.size == 0:
                break
            mean = np.sum(nb[front] * nb_ok[front], -1) / np.sum(nb_ok[front], -1)
            j = np.argmin(np.where(ok[front], np.abs(cand[front] - mean[:, None]), np.inf),
                          -1)
            idx[front], cur[front], done[front] = j, cand[front, j], True
    return idx[where]


def alternative(cand_d, cand_chi, d_best, distinct):
    """Stage 4: each pixel's best other candidate at least `distinct` nm from its thickness
    (another fringe order): (its thickness (n,), whether there is one (n,))."""
    rows = np.arange(cand_d.shape[0])
    other = np.where(np.abs(cand_d - d_best[:, None]) >= distinct, cand_chi, np.inf)
    alt = np.argmin(other, axis=-1)
    has_alt = np.isfinite(other[rows, alt])
    return np.where(has_alt, cand_d[rows, alt], d_best), has_alt


def refine_pixel(data, x0, q, ok, tau, lo, hi, steps, want_se=True):
    """Stage 3 for one pixel: `steps` Levenberg–Marquardt steps on [data(x), (x₀ − d_q)/τ]
    (the prior's residuals where `ok` (4,)) from x0 (p,) in the box [lo, hi]; returns (x,
    Σ data(x)², the standard error of x₀ from the data, σ absolute; 0 unless `want_se`)."""

    def res(x):
        return jnp.concatenate([data(x), jnp.where(ok, (x[0] - q) / tau, 0.0)])

    x = levenberg_marquardt(res, x0, lo, hi, steps)
    r = data(x)
    se = covariance(data, x, absolute_sigma=True).stderr[0] if want_se else x[0] * 0
    return x, jnp.sum(r * r), se


@functools.partial(jax.jit, static_argnames=("model", "steps", "free_eta"))
def _refine_map(obs, pix, x0, nb, nb_ok, ctx, sigma, tau, lo, hi, model, steps, free_eta):
    """`refine_pixel` over a chunk of a map: x = (d, η₂) (η₂ held unless `free_eta`), data
    (m(x) − o)/σ; returns x (P, 2), the data loss ½χ² and the standard error of d."""
    p = 2 if free_eta else 1

    def pixel(o, pp, x, q, ok):
        def full(xf):
            return xf if free_eta else jnp.stack([xf[0], x[1]])

        def data(xf):
            return (model(full(xf), pp, ctx) - o) / sigma

        xf, chi, se = refine_pixel(data, x[:p], q, ok, tau, lo[:p], hi[:p], steps)
        return full(xf), 0.5 * chi, se

    return jax.vmap(pixel)(obs, pix, x0, nb, nb_ok)


def misfit(loss, n_bands, p, what="the map model"):
    """Stage 4's misfit test of a map: (reduced χ², warnings), Σ 2·loss over the fitted
    pixels / (P (J − p)), warned as a `MisfitWarning` past the test of `options`."""
    from scipy.stats import chi2

    loss = np.asarray(loss, float)
    dof = loss.size * (n_bands - p)
    red = float(reduced_chi2(2.0 * np.sum(loss), loss.size * n_bands, loss.size * p, True))
    msg = misfit_warnings(red, dof, what)
    if msg:
        k = int(np.sum(2.0 * loss > chi2.ppf(MISFIT_QUANTILE, n_bands - p)))
        msg = (msg[0] + f" ({k} of {loss.size} pixels beyond their own "
               f"{100 * MISFIT_QUANTILE:g} % point)",)
        for m in msg:
            warnings.warn(m, MisfitWarning, stacklevel=4)
    return red, msg


# ----------------------------------------------------------------------------- the map run
class _Chunks:
    """The P fitted pixels in batches of min(chunk, P), the last one padded by repeating its
    last row: every batch has one shape, so one compilation serves a map."""

    def __init__(self, n, chunk):
        self.n, self.size = n, min(chunk, n)
        self.n_pad = -(-n // self.size) * self.size
        self.slices = [slice(i, i + self.size) for i in range(0, self.n_pad, self.size)]

    def pad(self, a):
        a = np.asarray(a)
        extra = self.n_pad - self.n
        return np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]) if extra else a

    def take(self, tree, s):
        return jax.tree_util.tree_map(lambda a: jnp.asarray(a[s]), tree)


def _stage_fns(model, steps, free_eta, devices):
    grid_fn = functools.partial(screen_grid, model=model)
    refine_fn = functools.partial(_refine_map, model=model, steps=steps, free_eta=free_eta)
    if devices is not None:
        from ..core.sharding import map_sharded  # lazily: only a sharded run needs it

        grid_fn = map_sharded(grid_fn, in_axes=(0, 0, None, None, None), devices=devices)
        refine_fn = map_sharded(refine_fn, in_axes=(0, 0, 0, 0, 0) + (None,) * 5,
                                devices=devices)
    return grid_fn, refine_fn


def _screen_and_prior(grid_fn, ch, obs, pix, ctx, grid_x, sigma, valid, d_grid, e_grid,
                      tau, sweeps, bar):
    """Stages 1–2 of a map: (x (H, W, 2) grid start, its loss (H, W), the loss profile over
    d at each d's best η₂ (H, W, G))."""
    h, w = valid.shape
    where = np.flatnonzero(valid)
    energy = []
    for s in ch.slices:
        energy.append(np.asarray(grid_fn(jnp.asarray(obs[s]), ch.take(pix, s), ctx, grid_x,
                                         sigma)))
        bar.update(1)
    energy_all = np.zeros((h * w, d_grid.size * e_grid.size))
    energy_all[where] = np.concatenate(energy)[:ch.n]
    energy = energy_all.reshape(h, w, d_grid.size, e_grid.size)
    best_e = np.argmin(energy, axis=-1)  # η₂ index per (pixel, d)
    e_d = np.min(energy, axis=-1)
    idx = icm(e_d, d_grid, valid, tau, sweeps) if tau is not None else np.argmin(e_d, -1)
    x = np.stack([d_grid[idx], e_grid[np.take_along_axis(best_e, idx[..., None],
                                                          -1)[..., 0]]], -1)
    loss = np.take_along_axis(e_d, idx[..., None], -1)[..., 0]
    return x, loss, e_d


def _refine_sweeps(refine_fn, ch, obs, pix, ctx, x, loss, sigma, valid, tau, lo, hi, sweeps,
                   bar):
    """Stage 3 of a map: Jacobi sweeps of `refine_pixel` (one sweep without the prior)."""
    h, w = valid.shape
    where = np.flatnonzero(valid)
    se = np.full((h, w), np.nan)
    for _ in range(sweeps if tau is not None else 1):
        nb, ok = neighbours(x[..., 0], valid)
        if tau is None:
            ok = np.zeros_like(ok)
        out = []
        xf = ch.pad(x.reshape(-1, 2)[where])
        nbf, okf = ch.pad(nb.reshape(-1, 4)[where]), ch.pad(ok.reshape(-1, 4)[where])
        for s in ch.slices:
            out.append(jax.tree_util.tree_map(np.asarray, refine_fn(
                jnp.asarray(obs[s]), ch.take(pix, s), jnp.asarray(xf[s]),
                jnp.asarray(nbf[s]), jnp.asarray(okf[s]), ctx, sigma,
                min(tau if tau is not None else np.inf, 1e30), lo, hi)))
            bar.update(1)
        x = x.reshape(-1, 2).copy()
        x[where] = np.concatenate([o[0] for o in out])[:ch.n]
        x = x.reshape(h, w, 2)
        loss = loss.reshape(-1).copy()
        loss[where] = np.concatenate([o[1] for o in out])[:ch.n]
        loss = loss.reshape(h, w)
        se = se.reshape(-1).copy()
        se[where] = np.concatenate([o[2] for o in out])[:ch.n]
        se = se.reshape(h, w)
    return x, loss, se


def fit_map(obs, pix, ctx, model, valid, *, eta0, free, sigma, smoothness_nm, bounds,
            grid, eta_grid, steps, sweeps, chunk, devices, progress_bar) -> MapResult:
    """The pipeline on a model-based map: `obs` (P, J) and per-pixel model inputs `pix` (a
    pytree of (P, ...) leaves) of the P fitted pixels, the True entries of `valid` (H, W)
    in row-major order; shared inputs `ctx`; ``model(x = (d, η₂), pix_p, ctx) → (J,)``.
    Other pixels are NaN. Stages: module docstring."""
    h, w = valid.shape
    free_eta = "eta_film" in free
    b = bounds
    lo = jnp.asarray([b["thickness"][0], b["eta_film"][0] if free_eta else 0.0])
    hi = jnp.asarray([b["thickness"][1], b["eta_film"][1] if free_eta else 10.0])
    d_grid = np.linspace(*b["thickness"], grid)
    e_grid = np.linspace(*b["eta_film"], eta_grid) if free_eta else np.asarray([eta0])
    grid_x = jnp.asarray(np.stack(np.meshgrid(d_grid, e_grid, indexing="ij"), -1).reshape(-1, 2))
    n = obs.shape[0]
    grid_fn, refine_fn = _stage_fns(model, steps, free_eta, devices)
    ch = _Chunks(n, chunk)
    obs = ch.pad(obs)
    pix = jax.tree_util.tree_map(ch.pad, pix)
    tau = float(smoothness_nm) if smoothness_nm is not None else None
    bar = progress(progress_bar, len(ch.slices) * (1 + (sweeps if tau is not None else 1)),
                   desc="fit-map")
    t0 = time.perf_counter()
    try:
        with jax.default_matmul_precision("highest"):
            x, loss, e_d = _screen_and_prior(grid_fn, ch, obs, pix, ctx, grid_x, sigma, valid,
                                             d_grid, e_grid, tau, sweeps, bar)
            x, loss, se = _refine_sweeps(refine_fn, ch, obs, pix, ctx, x, loss, sigma, valid,
                                         tau, lo, hi, sweeps, bar)
    finally:
        bar.close()
    dt = time.perf_counter() - t0
    p = 2 if free_eta else 1
    ambiguous, alt, at_bound, robust = order_flags(e_d, d_grid, x[..., 0], loss, valid,
                                                   b["thickness"], obs.shape[-1], p)
    x = np.where(valid[..., None], x, np.nan)
    loss, se = np.where(valid, loss, np.nan), np.where(valid, se, np.nan)
    red, msg = misfit(loss[valid], obs.shape[-1], p)
    if np.any(at_bound):
        note = (f"{int(at_bound.sum())} of {n} pixels at a bound of the thickness box "
                f"{tuple(b['thickness'])} nm: the model pulls them outside it (a model that "
                f"does not explain them, or a box too narrow); flagged ambiguous")
        warnings.warn(note, MisfitWarning, stacklevel=3)
        msg = msg + (note,)
    return MapResult(jnp.asarray(x[..., 0]), jnp.asarray(x[..., 1]), jnp.asarray(loss),
                     jnp.asarray(se), dt, n / dt, red, msg, float(sigma),
                     ambiguous, alt, at_bound, chi2=2.0 * loss, robust_chi2=robust, n_pixels=n)
