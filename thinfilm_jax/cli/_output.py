"""Files the fit commands write: the thickness map as a figure (`fit-map` of an image, of a
photograph).

Example (a 4 × 6 map with one pixel flagged, written as a PNG):
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from thinfilm_jax.cli._output import save_thickness_png
    >>> path = Path(tempfile.mkdtemp()) / "thickness.png"
    >>> flagged = np.zeros((4, 6), bool)
    >>> flagged[1, 2] = True
    >>> save_thickness_png(path, np.linspace(100, 600, 24).reshape(4, 6), "demo", flagged)
    >>> path.read_bytes()[:4]
    b'\x89PNG'
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def save_thickness_png(path: Path, d: np.ndarray, title: str, ambiguous=None) -> None:
    """The thickness map `d` (nm) as a PNG with a colour bar, pixels flagged in `ambiguous`
    hatched (`fit-map` of an image and of a photograph), written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..core._io import atomic_write

    h, w = d.shape
    fig, ax = plt.subplots(figsize=(5.4, 4.4 * h / max(w, 1) + 0.7))
    im = ax.imshow(d, cmap="viridis", interpolation="nearest")
    if ambiguous is not None and np.any(ambiguous):
        ax.contourf(np.asarray(ambiguous, float), levels=[0.5, 1.5], colors="none",
                    hatches=["////"])
    ax.set_xlabel("x (pixel)")
    ax.set_ylabel("y (pixel)")
    ax.set_title(title, fontsize=7)
    fig.colorbar(im, ax=ax, label="thickness (nm)")
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
