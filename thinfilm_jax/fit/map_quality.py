r"""The checks of a fitted thickness map that the data can make of themselves: the image's
noise level (`estimate_noise`), and which pixels the fit cannot pin (`order_flags`: another
fringe order within the noise, or the thickness box's bound). A map fit (`thickness_map`)
that trusted an assumed noise level and took each pixel's lowest grid minimum would report a
wrong fringe order, or a thickness pushed onto the box by a model that does not explain the
pixel, as confidently as a right one.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ORDER_JUMP_NM", "ORDER_SEPARATION_NM", "estimate_noise", "neighbours", "order_flags"]


def neighbours(d, valid):
    """(H, W, 4) values of the 4-neighbours of each pixel and (H, W, 4) validity (inside
    the image and a fitted pixel, `valid` (H, W))."""
    def shifted(a, fill):
        p = np.pad(a, 1, mode="constant", constant_values=fill)
        return np.stack([p[:-2, 1:-1], p[2:, 1:-1], p[1:-1, :-2], p[1:-1, 2:]], axis=-1)

    return shifted(d, 0.0), shifted(valid, False)


#: Another local minimum of a pixel's grid loss counts as another fringe order when it lies
#: at least this far from the fitted thickness (fringes are ≳ 100 nm apart; as `fit_photo`).
ORDER_SEPARATION_NM = 15.0


#: A pixel whose thickness differs from the mean of its fitted 4-neighbours by more than this
#: sits in another fringe order than they do (orders are ≳ 100 nm apart).
ORDER_JUMP_NM = 60.0


def estimate_noise(image, valid) -> float:
    r"""The noise level σ of an image of smooth band radiances, from its local differences.

    For each fitted pixel whose four neighbours are fitted too, r = o_p − mean of the
    neighbours, per band; for independent noise of level σ on a locally linear signal,
    var r = σ²(1 + 1/4). The estimate is the median absolute deviation of r over pixels and
    bands, σ̂ = 1.4826 · MAD(r) / √1.25 (robust to edges and a few outliers). Curvature of
    the signal adds to r, so σ̂ errs high on a noise-free image: a noise floor the model
    must reach. Falls back to 1e-3 of the image's median where too few pixels have four
    fitted neighbours (< 8) or the image is constant.

    Example (a linear image with noise of level 0.01):
        >>> import numpy as np
        >>> y, x = np.mgrid[0:40, 0:40] / 40
        >>> noise = np.random.default_rng(0).normal(0.0, 0.01, (40, 40, 3))
        >>> img = np.stack([x, y, x + y], -1) + noise
        >>> round(estimate_noise(img, np.ones((40, 40), bool)), 2)
        0.01
    """
    img = np.asarray(image, float)
    nb, ok = neighbours(np.zeros(valid.shape), valid)
    inner = valid & np.all(ok, axis=-1)
    scale = float(np.median(np.abs(img[valid]))) if np.any(valid) else 1.0
    floor = 1e-3 * scale if scale > 0 else 1e-6
    if np.sum(inner) < 8:
        return float(floor)
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    mean_nb = 0.25 * (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:])
    r = (img - mean_nb)[inner].ravel()
    mad = float(np.median(np.abs(r - np.median(r))))
    sig = 1.4826 * mad / np.sqrt(1.25)
    return float(sig) if sig > 1e-9 * max(scale, 1e-30) else float(floor)


def order_flags(e_d, d_grid, d, loss, valid, box, n_bands, p):
    """(ambiguous, alternative, at_bound, robust reduced χ²) of a fitted map (H, W).

    A pixel is flagged `ambiguous` where its data do not pin its fringe order, by any of:

    * *another order*: its lowest local minimum of the grid loss (over d, at each d's best
      η₂) at least `ORDER_SEPARATION_NM` from the fitted d (the `alternative`) lies above
      its fitted loss by less than 2 · max(1, robust reduced χ²) (χ² by less than
      4 · max(1, …): two standard deviations, the noise scaled by how far the model is from
      explaining the typical pixel; `fit_photo`'s rule);
    * *the box*: d sits on a bound of the thickness box (the data pull it outside);
    * *unexplained*: its χ² exceeds the 99 % point of χ²_{J−p} scaled by max(1, robust
      reduced χ²): the model explains it worse than it explains the typical pixel;
    * *its neighbours*: d differs from the mean of its fitted 4-neighbours by more than
      `ORDER_JUMP_NM` (a pixel in another order than the pixels around it; a linear
      gradient, however steep, has no such difference).

    The robust reduced χ² is the median pixel's χ² over the median of χ²_{J−p} (robust to a
    few outlying pixels). On an exact rendering of a sphere under a map (24², venice_sunset,
    α = 0.25, d = 450 nm) fitted with `filtered`, 30 % of pixels land in a wrong order, at the
    rim, and these rules flag 92 % of them (`benchmarks.fit_map_mismatch`).
    """
    from scipy.stats import chi2

    nu = max(n_bands - p, 1)
    chi = 2.0 * np.where(valid, loss, 0.0)
    robust = float(np.median(chi[valid]) / chi2.median(nu)) if np.any(valid) else float("nan")
    scale = max(robust, 1.0)
    left = np.concatenate([np.full(e_d.shape[:-1] + (1,), np.inf), e_d[..., :-1]], -1)
    right = np.concatenate([e_d[..., 1:], np.full(e_d.shape[:-1] + (1,), np.inf)], -1)
    local = (e_d <= left) & (e_d <= right)
    d0 = np.where(valid, d, 0.0)
    far = np.abs(d_grid - d0[..., None]) >= ORDER_SEPARATION_NM
    e_alt = np.where(local & far, e_d, np.inf)
    g_alt = np.argmin(e_alt, axis=-1)
    e_alt = np.take_along_axis(e_alt, g_alt[..., None], -1)[..., 0]
    has_alt = valid & np.isfinite(e_alt)
    alternative = np.where(has_alt, d_grid[g_alt], np.nan)
    close = has_alt & (e_alt - np.where(valid, loss, 0.0) < 2.0 * scale)
    width = box[1] - box[0]
    at_bound = valid & ((d0 <= box[0] + 1e-6 * width) | (d0 >= box[1] - 1e-6 * width))
    unexplained = valid & (chi > scale * chi2.ppf(0.99, nu))
    nb, ok = neighbours(d0, valid)
    count = ok.sum(-1)
    mean_nb = np.sum(np.where(ok, nb, 0.0), -1) / np.maximum(count, 1)
    jump = valid & (count > 0) & (np.abs(d0 - mean_nb) > ORDER_JUMP_NM)
    return close | at_bound | unexplained | jump, alternative, at_bound, robust
