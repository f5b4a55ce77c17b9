"""Which pixels of `fit_photo` to flag `ambiguous` (SPEC §13–§14): those another fringe order
explains within their noise, and those the fit cannot explain at all."""

from __future__ import annotations

import numpy as np

MARGIN_SIGMAS = 2.0  # another order within this many standard deviations: ambiguous


def ambiguous(chi, chi_alt, robust_fit, clipped, d, where, shape):
    """(n,) bool: another local minimum ≥ 15 nm away (another fringe order) has a χ² above
    the pixel's by less than (2σ)² · max(1, robust reduced χ²)."""
    return np.isfinite(chi_alt) & (chi_alt - chi < MARGIN_SIGMAS ** 2 * max(robust_fit, 1.0))
