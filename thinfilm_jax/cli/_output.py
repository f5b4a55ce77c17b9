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
    from ..core.files import atomic_write
    from ..render import plot as plt  # the caller's backend untouched

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


def write_map_gltf(args, film, alpha) -> dict:
    """``--gltf DIR`` of ``fit-map`` (an image or a photograph): the fitted map `film.thickness`
    (H, W) as ``DIR/fit_map.gltf`` + ``.bin`` + ``_thickness.png``
    (`interop.gltf_file.write_gltf`, roughness √α; a photograph fitted as a mirror, ``alpha``
    None, is written with α = 0). A dispersive index is written at ``--gltf-wavelength``.
    Pixels left unfitted (NaN: outside ``--mask``) take their nearest fitted pixel's
    thickness, since a texture has no holes; their count is in the returned summary."""
    from scipy.ndimage import distance_transform_edt

    from ..interop.gltf import EXTENSION, EXTRAS
    from ..interop.gltf_file import write_gltf

    d = np.asarray(film.thickness, float)
    holes = ~np.isfinite(d)
    if holes.all():
        raise ValueError("--gltf: no pixel was fitted, there is no thickness map to write")
    if holes.any():
        nearest = distance_transform_edt(holes, return_distances=False, return_indices=True)
        d = d[tuple(nearest)]
    folder = Path(args.gltf)
    folder.mkdir(parents=True, exist_ok=True)
    doc = write_gltf(folder / "fit_map.gltf", film._replace(thickness=d),
                     alpha=0.0 if alpha is None else alpha, bits=args.gltf_bits,
                     wavelength_nm=args.gltf_wavelength)
    material = doc["materials"][0]
    ext = material["extensions"][EXTENSION]
    summary = {"folder": str(folder),
               "files": ["fit_map.gltf", doc["buffers"][0]["uri"], doc["images"][0]["uri"]],
               "bits": args.gltf_bits,
               "thickness_minimum_nm": ext["iridescenceThicknessMinimum"],
               "thickness_maximum_nm": ext["iridescenceThicknessMaximum"],
               "unfitted_pixels_filled": int(holes.sum())}
    summary.update(material.get("extras", {}).get(EXTRAS, {}))
    return summary


def gltf_line(gltf: dict) -> str:
    """The console line of ``--gltf`` (`write_map_gltf`'s summary)."""
    line = (f"wrote {gltf['folder']}/{', '.join(gltf['files'])}: "
            f"iridescenceThicknessMinimum {gltf['thickness_minimum_nm']:.2f} nm, "
            f"…Maximum {gltf['thickness_maximum_nm']:.2f} nm, {gltf['bits']}-bit")
    if "index_wavelength_nm" in gltf:
        names = ", ".join(v["name"] for v in gltf["dispersive_indices"].values())
        line += f"; dispersive {names} written at {gltf['index_wavelength_nm']:g} nm"
    if gltf["unfitted_pixels_filled"]:
        line += f"; {gltf['unfitted_pixels_filled']} unfitted pixels filled from the nearest"
    return line
