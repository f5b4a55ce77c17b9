"""The search of `fit_photo` over its colour table's thickness grid (`fit.photo`, module
docstring, steps 2–3): the screen that keeps each pixel's best distinct fringe orders (one
matrix product per chunk), the censored residual it and the refine share, the pixel chunks
padded to a few compiled sizes, and the photometric gains found on that grid: exposure and
white balance from reference regions or by alternation, an unknown camera's 3 × 3 matrix
from its pads, and its sensitivities on a hat basis from every pixel.

Example (one pixel whose colour is the grid's at 300 nm: the screen finds it, and the
closed-form gains of that colour are 1):
    >>> import numpy as np
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax.fit.photo_screen import closed_gains, features, screen
    >>> grid = np.linspace(0.0, 600.0, 61)
    >>> pred = np.stack([0.5 + 0.4 * np.cos(grid / f) for f in (40.0, 55.0, 70.0)], -1)
    >>> obs, sig, cens = pred[30:31], np.full((1, 3), 0.01), np.zeros((1, 3), int)
    >>> idx, chi = screen(jnp.asarray(obs), jnp.asarray(sig), jnp.asarray(cens),
    ...                   features(pred, (0.0, 1.0)), jnp.asarray(grid), 1)
    >>> float(grid[int(idx[0, 0])]), float(chi[0, 0]) < 1e-12
    (300.0, True)
    >>> closed_gains(obs, sig, cens, pred[30:31]).round(6).tolist()
    [1.0, 1.0, 1.0]
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import nnls

__all__ = [
    "DISTINCT_NM",
    "screen",
    "features",
    "residual",
    "bucket",
    "chunks",
    "pad_to",
    "screen_all",
    "closed_gains",
    "search_gains",
    "reference_gains",
    "matrix_from_pixels",
]

_HI = jax.lax.Precision.HIGHEST
_EXPOSURE_LADDER = 2.0 ** np.arange(-2.0, 2.01, 0.5)  # × the brightness-matched exposure
_SUBSAMPLE = 3000  # pixels for the gain search without references
DISTINCT_NM = 15.0  # two local minima this far apart are different fringe orders


@functools.partial(jax.jit, static_argnames=("k",))
def screen(obs, sig, cens, feats, grid, k):
    """The k lowest local minima of χ²_p(d_g) over the screen grid `grid` for each pixel of a
    chunk (P,), each at least `DISTINCT_NM` from the better ones (distinct fringe orders):
    grid indices (P, k) and χ² (P, k) (+inf where a pixel has fewer minima).

    Channels censored at 0 or at full scale (`cens` 1 / 2) cost only on the wrong side
    (`residual`). χ² is one matrix product: pixel terms (P, 12) against the grid's
    `feats` (G, 12) = [pred², pred, relu(pred − b)², relu(c − pred)²] per channel (b the
    black level, c the ceiling, `fit.photo._censoring`), plus Σ w o²."""
    w = 1.0 / (sig * sig)  # (P, 3)
    wu, wl, wh = (w * (cens == c).astype(w.dtype) for c in (0, 1, 2))
    a = jnp.concatenate([wu, -2.0 * obs * wu, wl, wh], axis=-1)  # (P, 12)
    chi = jnp.sum(obs * obs * wu, axis=-1)[:, None] + jnp.matmul(a, feats.T, precision=_HI)
    pad = jnp.full((chi.shape[0], 1), jnp.inf, chi.dtype)
    left = jnp.concatenate([pad, chi[:, :-1]], axis=-1)
    right = jnp.concatenate([chi[:, 1:], pad], axis=-1)
    local = jnp.where((chi <= left) & (chi < right), chi, jnp.inf)
    tops, chis = [], []
    for _ in range(k):  # the best minimum, then the best ≥ DISTINCT_NM from those taken, …
        i = jnp.argmin(local, axis=-1)
        tops.append(i)
        chis.append(jnp.take_along_axis(local, i[:, None], -1)[:, 0])
        local = jnp.where(jnp.abs(grid[None, :] - grid[i][:, None]) < DISTINCT_NM, jnp.inf,
                          local)
    return jnp.stack(tops, -1), jnp.stack(chis, -1)


def features(pred, levels):
    """(G, 12) grid terms of `screen` from the predictions (G, 3) and the clip `levels`
    (black b, ceiling c; `fit.photo._censoring`)."""
    relu = np.maximum
    black, ceiling = levels[0], levels[1]
    if len(levels) > 2:  # a reading is of the colour the camera clipped at its floor
        pred = np.maximum(pred, levels[2])
    return jnp.asarray(np.concatenate([pred * pred, pred, relu(pred - black, 0.0) ** 2,
                                       relu(ceiling - pred, 0.0) ** 2], axis=-1))


def residual(pred, o, sg, cens, levels):
    """(pred − o)/σ per channel; a channel censored at black (1) costs relu(pred − b)/σ, one
    at full scale (2) relu(c − pred)/σ: a clipped reading says only on which side the truth
    is, a one-sided (censored) observation (`levels` = (b, c), the black level and the
    ceiling, `fit.photo._censoring`). With a third level f (a JPEG's: 0), a reading is of
    the colour the camera clipped at f before encoding: max(pred, f) − o."""
    seen = jnp.maximum(pred, levels[2]) if len(levels) > 2 else pred
    return jnp.where(cens == 0, seen - o,
                     jnp.where(cens == 1, jax.nn.relu(pred - levels[0]),
                               jax.nn.relu(levels[1] - pred))) / sg


def bucket(n, chunk):
    """Batch size of n pixels: the next power of two up to `chunk` (padded), so that images of
    many sizes share a few compiled programs."""
    return min(chunk, 1 << max(int(n) - 1, 0).bit_length())


def chunks(n, size):
    return [slice(i, min(i + size, n)) for i in range(0, n, size)]


def pad_to(a, size):
    """Pad the leading axis of a chunk to `size` (repeating its last row): one compilation."""
    n = a.shape[0]
    return a if n == size else np.concatenate([a, np.repeat(a[-1:], size - n, axis=0)])


def screen_all(obs, sig, cens, feats, grid, k, chunk, bar):
    out = []
    size = bucket(obs.shape[0], chunk)
    for s in chunks(obs.shape[0], size):
        n = s.stop - s.start
        r = screen(*(jnp.asarray(pad_to(a[s], size)) for a in (obs, sig, cens)), feats,
                    grid, k)
        out.append([np.asarray(v)[:n] for v in r])
        if bar is not None:
            bar.update(n)
    return [np.concatenate(v) for v in zip(*out)]


# ----------------------------------------------------------------------------- gains
def closed_gains(obs, sig, cens, s_c):
    """Per-channel least squares g_c = Σ o s / σ² / Σ s² / σ² over the uncensored readings
    (s_c = C s, (P, 3))."""
    w = (cens == 0) / (sig * sig)
    return np.sum(obs * s_c * w, axis=0) / np.maximum(np.sum(s_c * s_c * w, axis=0), 1e-300)


def search_gains(obs, sig, cens, s_screen, grid, chunk, levels):
    """Gains without references (`fit.photo`, step 2): alternating minimisation from a
    ladder of exposures around the brightness-matched one, on a subsample, on the screen
    grid's colours `s_screen` (G, 3)."""
    step = max(1, obs.shape[0] // _SUBSAMPLE)
    o, sg, cs = obs[::step], sig[::step], cens[::step]
    e0 = np.median(o[:, 1]) / max(np.median(s_screen[:, 1]), 1e-12)
    best = (np.inf, None)
    for e in e0 * _EXPOSURE_LADDER:
        g = np.full(3, e)
        for _ in range(8):
            idx, chi = screen_all(o, sg, cs, features(s_screen * g, levels), grid, 1, chunk,
                                   None)
            s_at = s_screen[idx[:, 0]]
            keep = cs if len(levels) < 3 else np.where(s_at * g <= levels[0], 3, cs)
            g_new = closed_gains(o, sg, keep, s_at)  # (a colour clipped at f: no reading)
            if np.allclose(g_new, g, rtol=1e-4):
                break
            g = g_new
        total = float(np.sum(np.minimum(chi[:, 0], 1e6)))
        if total < best[0]:
            best = (total, g)
    return best[1]


def reference_gains(obs_img, sig_img, cens_img, regions, s_of, kind):
    """(gains (3,), C (3, 3), C's stderr (3, 3)) from regions of known thickness."""
    rows = [(obs_img[m], np.where(cens_img[m] == 0, sig_img[m], np.inf), s_of(d))
            for m, d in regions]
    if kind != "unknown":
        o = np.concatenate([r[0] for r in rows])
        sg = np.concatenate([r[1] for r in rows])
        s = np.concatenate([np.broadcast_to(r[2], r[0].shape) for r in rows])
        return closed_gains(o, sg, np.zeros(o.shape, int), s), np.eye(3), np.zeros((3, 3))
    thick = sorted({round(d, 6) for _, d in regions})
    s_ref = np.stack([r[2] for r in rows])
    sv = np.linalg.svd(s_ref, compute_uv=False) if len(rows) >= 3 else np.zeros(1)
    if len(thick) < 3 or sv[-1] < 1e-3 * sv[0]:
        raise ValueError(f"camera='unknown' fits a 3 × 3 matrix from reference regions: it needs "
                         f"at least 3 regions whose thicknesses give distinct colours, got "
                         f"{len(rows)} region(s) at {thick} nm")
    # o_pc = Σ_j M_cj s_j: per channel a weighted linear regression over the reference pixels
    m_rows, se_rows = [], []
    for c in range(3):
        a = np.concatenate([np.broadcast_to(r[2], (r[0].shape[0], 3)) / r[1][:, c:c + 1]
                            for r in rows])
        b = np.concatenate([r[0][:, c] / r[1][:, c] for r in rows])
        coef, *_ = np.linalg.lstsq(a, b, rcond=None)
        dof = max(a.shape[0] - 3, 1)
        s2 = max(float(np.sum((a @ coef - b) ** 2)) / dof, 1.0)
        cov = s2 * np.linalg.pinv(a.T @ a)
        m_rows.append(coef)
        se_rows.append(np.sqrt(np.abs(np.diag(cov))))
    m, se = np.stack(m_rows), np.stack(se_rows)
    g = m.sum(axis=1)
    if np.any(g <= 0):
        raise ValueError("the fitted camera matrix maps white to a non-positive colour: the "
                         "reference regions do not determine it (check masks and thicknesses)")
    return g, m / g[:, None], se / g[:, None]


def matrix_from_pixels(obs, sig, cens, s_fit, smooth: float = 0.0):
    """M (3, B) with o_c ≈ Σ_b M_cb s_b over every uncensored reading: per channel a
    weighted linear least-squares fit (the unknown camera's self-calibration), with a
    penalty `smooth` · tr(XᵀWX)/tr(DᵀD) · ‖D m_c‖² on the second differences D of the
    coefficients (smooth sensitivities on a hat basis; 0 for the 3 × 3 matrix). On the hat
    basis (`smooth` > 0) the coefficients are the sensitivities at the knots, which a
    photodiode's physics keeps ≥ 0: the penalised least squares is solved under m ≥ 0
    (Lawson & Hanson 1974, *Solving Least Squares Problems*, ch. 23, scipy's ``nnls``, on
    the Cholesky factor of its normal equations). Unconstrained, the pixels' self-calibration
    from a few pads bends the sensitivities negative to fit wrong orders beyond the pads'
    span (docs/studies/photographs.md)."""
    b = s_fit.shape[1]
    d2 = np.diff(np.eye(b), 2, axis=0)
    rows = []
    for c in range(3):
        w = (cens[:, c] == 0) / sig[:, c]
        x = s_fit * w[:, None]
        a = x.T @ x
        reg = smooth * np.trace(a) / max(np.trace(d2.T @ d2), 1e-300)
        a = a + reg * d2.T @ d2 + 1e-12 * np.trace(a) / b * np.eye(b)
        rhs = x.T @ (obs[:, c] * w)
        if smooth > 0:  # sensitivities: a photodiode's response is ≥ 0 at every wavelength
            r = np.linalg.cholesky(a).T  # mᵀ a m − 2 mᵀ rhs = ‖r m − r⁻ᵀ rhs‖² + const
            rows.append(nnls(r, np.linalg.solve(r.T, rhs))[0])
        else:
            rows.append(np.linalg.solve(a, rhs))
    return np.stack(rows)
