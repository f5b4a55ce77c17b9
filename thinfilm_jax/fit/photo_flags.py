r"""Which pixels of `fit_photo` to flag `ambiguous` (SPEC §13–§14): those another fringe order
explains within their noise, and those whose order the fit cannot vouch for because it does
not explain them: a pixel put in the wrong order must be flagged whatever the cause (clipped
channels, a light field the fit cannot model, an unknown camera anchored by too few pads).

A pixel p with χ²_p, its best other order's χ²_alt (≥ 15 nm away) and the image's noise
scale s = max(1, robust reduced χ²) (the median pixel's χ² over the median of χ²₂: the
noise as the residuals measure it, not as assumed) is flagged where

1. **another order is within the noise**: χ²_alt − χ²_p < (2σ)² · s (`MARGIN_SIGMAS`);
2. **another order is within the pixel's own misfit**: χ²_alt − χ²_p < (2σ)² · χ²_p. A
   pixel that the model misses by χ²_p carries an error the model does not know (a clipped
   channel, light, a camera): its standard deviation is √χ²_p rather than 1, and an order
   within two of those is not excluded by the pixel;
3. **its neighbours disagree**: |d_p − median of its 8 neighbours| > `NEIGHBOUR_NM` (two
   fringe-order separations; the film is continuous, so an isolated jump is a wrong order
   on one side; at least 3 fitted neighbours);
4. **its thickness is beyond what the pads calibrate** (``camera="unknown"``): more than
   `BEYOND_PADS_NM` outside the span of the reference thicknesses, where the fitted camera
   is extrapolated;
5. **it is off its neighbourhood's plane** (a JPEG only): |d_p − d̂_p| > `LOCAL_NM`, with
   d̂_p the median, over the 12 pairs of opposite neighbours (q, q′) = (p + δ, p − δ) of its
   5 × 5 window, of their midpoints ½(d_q + d_q′) (at least 3 pairs fitted):

   $$ \hat d_p = \operatorname{median}_{\delta}\ \tfrac12\,(d_{p+\delta} + d_{p-\delta}),
      \qquad 0 < \|\delta\|_\infty \le 2 , $$

   exact where the film is a plane over 5 pixels (each midpoint is then d_p) and robust: a
   4:2:0 chroma block (2 × 2 pixels) of bad pixels spoils at most 3 of the 12 pairs. A
   JPEG's compression error (8 × 8 DCT blocks, 4:2:0 chroma) is in the pixel's colour but
   not in its σ (`fit.photo_jpeg` models its mean size, not where the quantiser cut): it
   moves a pixel along the colour curve, within its fringe order, with χ²_p ≈ 1 and a
   standard error that does not see it, so criteria 1–2 cannot find it. The film is
   smooth at the pixel scale and the error is not (a pixel off, its neighbours right), so
   the neighbourhood measures it. `LOCAL_NM` = 10 nm is ⅔ of the 15 nm that separates
   fringe orders (`photo_screen.DISTINCT_NM`, the tolerance of "the right order" in
   docs/studies/photographs.md): a pixel flagged is off the truth by at least 10 nm less
   the plane's own error (a few nm), and a pixel 15 nm off is flagged unless the plane
   errs by 5 nm towards it. The flag means "not placed within an order's separation", a
   wrong order or a right order as far off; on the over-exposed soap JPEG of
   `benchmarks.photo_light` it flags another 1–2 % of the right pixels beyond criteria
   1–4 (0.9–2.3 points on three draws). Lossless input, whose
   noise is per pixel and in σ, is not tested (criteria 1–2 hold there).

Example (a pixel whose alternative is 3 χ² units worse is ambiguous at noise scale 1; one
120 units worse is not, unless its own χ² is 50 (4 · 50 > 120)):
    >>> import numpy as np
    >>> from thinfilm_jax.fit.photo_flags import ambiguous
    >>> chi, alt = np.array([1.0, 1.0, 50.0]), np.array([4.0, 121.0, 170.0])
    >>> ambiguous(chi, alt, 1.0, np.zeros(3), np.arange(3), (1, 3)).tolist()
    [True, False, True]
"""

from __future__ import annotations

import numpy as np

__all__ = ["MARGIN_SIGMAS", "reasons", "ambiguous", "fit_notes"]

MARGIN_SIGMAS = 2.0  # another order within this many standard deviations: ambiguous
NEIGHBOUR_NM = 30.0  # |d − the neighbours' median| above this: a jump between orders
BEYOND_PADS_NM = 100.0  # thickness this far outside the pads' span (unknown camera)
LOCAL_NM = 10.0  # |d − its 5 × 5 neighbourhood's plane| above this: off (a JPEG's block error)


def _window(d, where, shape, r):
    """(n, (2r + 1)² − 1) the thicknesses of each fitted pixel's neighbours within r (NaN:
    unfitted or outside the frame), offsets in lexicographic order, so that the opposite of
    column k is column −1 − k."""
    h, w = shape
    img = np.full(h * w, np.nan)
    img[where] = d
    p = np.pad(img.reshape(h, w), r, constant_values=np.nan)
    rng = range(-r, r + 1)
    return np.stack([p[r + i:h + r + i, r + j:w + r + j] for i in rng for j in rng
                     if i or j], axis=-1).reshape(h * w, -1)[where]


def _robust_centre(values):
    """(n,) the median of each row's finite values (NaN where fewer than 3)."""
    enough = np.sum(np.isfinite(values), axis=-1) >= 3
    out = np.full(values.shape[0], np.nan)
    out[enough] = np.nanmedian(values[enough], axis=-1)
    return out


def _neighbour_median(d, where, shape):
    """(n,) the median thickness of each fitted pixel's 8 fitted neighbours (NaN where it
    has fewer than 3)."""
    return _robust_centre(_window(d, where, shape, 1))


def local_plane(d, where, shape):
    """(n,) d̂: the median of the midpoints of the 12 pairs of opposite neighbours in each
    fitted pixel's 5 × 5 window (criterion 5; NaN where fewer than 3 pairs are fitted)."""
    nb = _window(d, where, shape, 2)
    half = nb.shape[1] // 2
    return _robust_centre(0.5 * (nb[:, :half] + nb[:, ::-1][:, :half]))


def reasons(chi, chi_alt, robust_fit, d, where, shape, pads_span=None,
            lossy: bool = False) -> dict:
    """{criterion: (n,) bool} of the module docstring (1 `noise`, 2 `misfit`, 3
    `neighbours`, 4 `beyond_pads` with `pads_span`, 5 `local` for a `lossy` (JPEG) photograph)."""
    margin = chi_alt - chi  # +inf where no other order was found
    out = {"noise": margin < MARGIN_SIGMAS ** 2 * max(robust_fit, 1.0),
           "misfit": margin < MARGIN_SIGMAS ** 2 * chi}
    med = _neighbour_median(d, where, shape)
    with np.errstate(invalid="ignore"):
        out["neighbours"] = np.abs(d - med) > NEIGHBOUR_NM
    if pads_span is not None:
        lo, hi = pads_span
        out["beyond_pads"] = (d < lo - BEYOND_PADS_NM) | (d > hi + BEYOND_PADS_NM)
    if lossy:
        with np.errstate(invalid="ignore"):
            out["local"] = np.abs(d - local_plane(d, where, shape)) > LOCAL_NM
    return out


def ambiguous(chi, chi_alt, robust_fit, d, where, shape, pads_span=None, lossy=False):
    """(n,) bool: any criterion of `reasons`."""
    return np.any(np.stack(list(reasons(chi, chi_alt, robust_fit, d, where, shape,
                                        pads_span, lossy).values())), axis=0)


_WHY = {"noise": "another fringe order within the noise",
        "misfit": "another order within the pixel's own misfit",
        "neighbours": "disagreeing with their neighbours",
        "beyond_pads": "beyond the pads' thicknesses (an extrapolated camera)",
        "local": f"over {LOCAL_NM:g} nm off their 5 × 5 neighbourhood's plane (JPEG block error)"}


def fit_notes(misfit, cens_img, valid, amb, why, jpeg, light_ident=None):
    """(notes, the notes to raise as Python warnings too) of a fit: the misfit (a sentence
    or None), clipped and masked pixels (one count of pixels with a clipped channel, the
    count the photograph's description gives), an undetermined light field
    (`fit.photo_light.identifiability` below `MIN_IDENTIFIABLE`; None: uniform light), many
    ambiguous pixels, a JPEG's uncalibrated standard errors, and why pixels were flagged
    beyond the noise."""
    from .photo_light import MIN_IDENTIFIABLE

    notes, loud = [], []
    if misfit:
        notes.append(misfit)
        loud.append(misfit)
    clip_any, clip_all = np.any(cens_img > 0, axis=-1), np.all(cens_img > 0, axis=-1)
    if clip_any.any():
        notes.append(f"{int(clip_any.sum())} pixel(s) with a clipped channel: "
                     f"{int(np.sum(clip_any & valid))} fitted with the clipped channel(s) "
                     f"censored, {int(clip_all.sum())} with every channel clipped, not fitted")
    n_masked = int(np.sum(~valid & ~clip_all))
    if n_masked:
        notes.append(f"{n_masked} pixel(s) outside the mask, not fitted")
    if light_ident is not None and light_ident < MIN_IDENTIFIABLE:
        notes.append(f"the light field is not determined (identifiability {light_ident:.2g} < "
                     f"{MIN_IDENTIFIABLE:g}: the film's colours cannot tell a change of light "
                     f"from a change of thickness): add reference regions spread over the "
                     f"frame, or use illumination='uniform' under even light")
        loud.append(notes[-1])
    if np.mean(amb) > 0.2:
        notes.append(f"{100 * np.mean(amb):.0f} % of pixels are ambiguous between fringe "
                     f"orders: add reference regions, smoothness_nm, or narrow thickness_range")
    if jpeg:
        notes.append("standard errors are calibrated for raw and linear (lossless) input only: "
                     "a JPEG's compression error (8 × 8 DCT blocks, chroma subsampling) is "
                     "correlated between pixels and not in them; read them as lower bounds")
    if any(v.any() for k, v in why.items() if k != "noise"):  # what the fit cannot explain
        notes.append(f"{int(amb.sum())} pixel(s) flagged ambiguous: " + ", ".join(
            f"{int(v.sum())} {_WHY[k]}" for k, v in why.items() if v.any()))
    return notes, loud
