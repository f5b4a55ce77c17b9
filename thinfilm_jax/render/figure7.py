"""Figure 7 of Kneiphof et al. 2019: a patch under uniform light, four methods side by side.

Rows: (a)–(d) view angle θ_o × perceptual roughness √α at d = 600 nm; (e)–(h) θ_o × film
thickness d at α = 0.25. Columns: `ideal` (BB17 real time), `filtered_gt_moments` (K 29 fed
with the true light-direction moments), `filtered_gt_opd` (K 29 fed with the true moments of
D), `reference` (exact spectral integral). Film defaults follow SPEC §7: η₂ = 1.3, η₃ = 2.0,
κ₃ = 0.5. Grids use cell centres in θ_o ∈ [0°, 90°] and √α ∈ [0, 1] (α = 0 is a mirror,
outside the GGX domain) and d ∈ [0, 1000] nm inclusive.

Display: band values → XYZ (mirror white, Y = 1) → sRGB through colour-science, one fixed
exposure for all panels (`exposure`, default 2.0, in the title). Errors: CIEDE2000 ΔE of each
approximation against the reference, per pixel, with mean / 95th percentile / max per method
and per row.

Example (the grids of a 4 × 4 panel: cell centres in θ_o and √α, d with both ends):
    >>> import numpy as np
    >>> from thinfilm_jax.render.figure7 import Figure7Config, grids
    >>> theta, sqrt_alpha, thickness = grids(Figure7Config(resolution=4))
    >>> np.degrees(theta).tolist(), sqrt_alpha.tolist(), thickness[[0, -1]].tolist()
    ([11.25, 33.75, 56.25, 78.75], [0.125, 0.375, 0.625, 0.875], [0.0, 1000.0])
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..core.files import atomic_write, write_json
from ..optics.airy import choose_arithmetic
from ..spectral.colorimetry import bands_to_srgb, delta_e2000
from ..core.film import Film
from ..realtime.options import ModelOptions
from ..shading.patch import patch_radiance
from ..core.sharding import batch_mesh, map_sharded, to_host

__all__ = [
    "METHOD_ORDER",
    "ROWS",
    "Figure7Config",
    "grids",
    "row_inputs",
    "patch_block",
    "compute_figure7",
    "error_summary",
    "render_figure7",
    "render_error",
    "run_figure7",
]

METHOD_ORDER = ("ideal", "filtered_gt_moments", "filtered_gt_opd", "reference")
METHOD_TITLES = {
    "ideal": "ideal direction (BB17)",
    "filtered_gt_moments": "filtered, true ω moments",
    "filtered_gt_opd": "filtered, true D moments",
    "reference": "reference (spectral)",
}
ROWS = ("roughness", "thickness")
#: no "Software" text chunk (matplotlib's version): the PNGs depend on the pixels only
_PNG_METADATA = {"Software": None}


@dataclass(frozen=True)
class Figure7Config:
    """Parameters of the Figure 7 study (SPEC §7 defaults)."""

    resolution: int = 64
    eta_film: float = 1.3
    eta_base: float = 2.0
    kappa_base: float = 0.5
    thickness: float = 600.0  # nm, row (a)–(d)
    alpha: float = 0.25  # row (e)–(h)
    thickness_max: float = 1000.0  # nm, row (e)–(h)
    observer: str = "stiles_burch_1959_10"
    terms: int = 2
    quadrature: tuple[int, int] = (32, 32)  # (n_u, n_φ): reference error ≤ 1e-6 per band
    shat: str = "exact"
    exposure: float = 2.0
    chunk: int = 512  # patches per device per progress step


def grids(cfg: Figure7Config):
    n = cfg.resolution
    centres = (np.arange(n) + 0.5) / n
    theta = centres * np.pi / 2
    sqrt_alpha = centres
    thickness = np.linspace(0.0, cfg.thickness_max, n)
    return theta, sqrt_alpha, thickness


def row_inputs(cfg: Figure7Config, row: str):
    theta, sqrt_alpha, thickness = grids(cfg)
    if row == "roughness":
        y, t = np.meshgrid(sqrt_alpha, theta, indexing="ij")
        d = np.full_like(t, cfg.thickness)
        a = y**2
    else:
        d, t = np.meshgrid(thickness, theta, indexing="ij")
        a = np.full_like(t, cfg.alpha)
    film = Film(d, cfg.eta_film, cfg.eta_base, cfg.kappa_base)
    return film, t, a


def patch_block(film, theta_o, alpha, *, method, observer, options):
    """One block of patches (the function `map_sharded` runs on every device)."""
    return patch_radiance(film, theta_o, alpha, method=method, observer=observer,
                          options=options)


def compute_figure7(cfg: Figure7Config = Figure7Config(), progress: bool = True,
                    devices=None) -> dict:
    """Band radiances of every (row, method) on the (y, θ_o) grid: arrays (n, n, J).

    The patches are split across `devices` (None: every device, an int k: the first k, or a
    sequence; `thinfilm_jax.core.sharding.map_sharded`): each device shades `cfg.chunk` patches
    per progress step. Timing per method (seconds, including compilation of the first
    chunk) is returned under "seconds".
    """
    from tqdm.auto import tqdm

    n = cfg.resolution
    total = len(ROWS) * len(METHOD_ORDER) * n * n
    out: dict = {"values": {r: {} for r in ROWS}, "seconds": {}}
    bar = tqdm(total=total, unit="patch", disable=not progress or jax.process_index() > 0,
               desc="figure7")
    options = ModelOptions(terms=cfg.terms, shat=cfg.shat, quadrature=tuple(cfg.quadrature))
    programs: dict = {}  # one compiled map per (method, options), shared by both rows
    for row in ROWS:
        film, t, a = row_inputs(cfg, row)
        flat = jax.tree.map(lambda x: np.asarray(np.broadcast_to(x, t.shape), float).reshape(-1),
                            (film, t, a))  # (film, θ_o, α) of flat per-point arrays
        # "auto" arithmetic resolved on the concrete film: inside the map it is traced
        opts = options._replace(arithmetic=choose_arithmetic(film, options.arithmetic))
        for method in METHOD_ORDER:
            if (method, opts) not in programs:
                programs[method, opts] = map_sharded(functools.partial(
                    patch_block, method=method, observer=cfg.observer, options=opts),
                    devices=devices)
            shade = programs[method, opts]
            step = cfg.chunk * shade.mesh.size
            t0 = time.perf_counter()
            parts = []
            for s in range(0, n * n, step):
                sl = slice(s, s + step)
                parts.append(to_host(shade(*jax.tree.map(lambda x: x[sl], flat))))
                bar.update(parts[-1].shape[0])
            out["values"][row][method] = np.concatenate(parts).reshape(n, n, -1)
            out["seconds"][f"{row}/{method}"] = time.perf_counter() - t0
    bar.close()
    return out


def error_summary(data: dict, cfg: Figure7Config) -> dict:
    """CIEDE2000 and absolute band errors of every approximation against the reference."""
    summ = {}
    for row in ROWS:
        ref = data["values"][row]["reference"]
        for method in METHOD_ORDER[:-1]:
            v = data["values"][row][method]
            de = delta_e2000(v, ref, cfg.observer)
            summ[f"{row}/{method}"] = {
                "dE2000_mean": float(de.mean()),
                "dE2000_p95": float(np.percentile(de, 95)),
                "dE2000_max": float(de.max()),
                "band_abs_mean": float(np.abs(v - ref).mean()),
                "band_abs_max": float(np.abs(v - ref).max()),
            }
    return summ


def _extent(cfg, row):
    ymax = 1.0 if row == "roughness" else cfg.thickness_max
    return (0.0, 90.0, 0.0, ymax)


def _ylabel(row):
    return "perceptual roughness √α" if row == "roughness" else "film thickness d (nm)"


def _caption(cfg):
    return (f"film η₂={cfg.eta_film}, base η₃={cfg.eta_base}+{cfg.kappa_base}i; "
            f"(a)–(d) d={cfg.thickness:g} nm, (e)–(h) α={cfg.alpha:g}; "
            f"{cfg.observer}, M={cfg.terms}, {cfg.resolution}×{cfg.resolution}, "
            f"uniform light, exposure {cfg.exposure:g}, sRGB (colour-science)")


def render_figure7(data: dict, cfg: Figure7Config, path) -> None:
    """The eight panels (a)–(h) as sRGB images, written atomically to `path`."""
    from . import plot as plt  # the caller's backend untouched

    fig, axes = plt.subplots(2, 4, figsize=(16, 8.6), constrained_layout=True)
    letters = iter("abcdefgh")
    for i, row in enumerate(ROWS):
        for j, method in enumerate(METHOD_ORDER):
            ax = axes[i, j]
            img = bands_to_srgb(data["values"][row][method], cfg.observer, cfg.exposure)
            ax.imshow(img, origin="lower", extent=_extent(cfg, row), aspect="auto",
                      interpolation="nearest")
            ax.set_title(f"({next(letters)}) {METHOD_TITLES[method]}", fontsize=11)
            ax.set_xlabel("view angle θₒ (deg)")
            if j == 0:
                ax.set_ylabel(_ylabel(row))
    fig.suptitle("Kneiphof et al. 2019, Figure 7 — patch under uniform light\n" + _caption(cfg),
                 fontsize=11)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png",
                                                   metadata=_PNG_METADATA))
    plt.close(fig)


def render_error(data: dict, cfg: Figure7Config, path) -> None:
    """CIEDE2000 maps of each approximation against the reference (2 rows × 3 methods)."""
    from . import plot as plt  # the caller's backend untouched

    fig, axes = plt.subplots(2, 3, figsize=(13.5, 8.4), constrained_layout=True)
    des = {(row, m): delta_e2000(data["values"][row][m], data["values"][row]["reference"],
                                 cfg.observer)
           for row in ROWS for m in METHOD_ORDER[:-1]}
    vmax = float(np.percentile(np.concatenate([d.ravel() for d in des.values()]), 99))
    for i, row in enumerate(ROWS):
        for j, method in enumerate(METHOD_ORDER[:-1]):
            ax = axes[i, j]
            de = des[(row, method)]
            im = ax.imshow(de, origin="lower", extent=_extent(cfg, row), aspect="auto",
                           cmap="magma", vmin=0, vmax=vmax, interpolation="nearest")
            ax.set_title(f"{METHOD_TITLES[method]}\nΔE₀₀ mean {de.mean():.2f}, "
                         f"p95 {np.percentile(de, 95):.2f}, max {de.max():.1f}", fontsize=10)
            ax.set_xlabel("view angle θₒ (deg)")
            if j == 0:
                ax.set_ylabel(_ylabel(row))
    fig.colorbar(im, ax=axes, shrink=0.8, label="CIEDE2000 ΔE vs reference")
    fig.suptitle("Error of each method against the spectral reference\n" + _caption(cfg),
                 fontsize=11)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png",
                                                   metadata=_PNG_METADATA))
    plt.close(fig)


def run_figure7(cfg: Figure7Config = Figure7Config(), out_dir="figures",
                progress: bool = True, devices=None, timing_path=None) -> dict:
    """Compute, render and save figure7.png, figure7_error.png, figure7.json, figure7.npz.

    The four files hold the science only (the configuration, x64 and the errors against the
    reference; the band values; the panels), so a rerun on this machine rewrites them byte for
    byte (tests/test_main_job_clean.py). How long the run took depends on the machine and its
    load: it is returned under "timing" (the device, the load average at the start, the
    compute seconds and the seconds per row and method, first compilation included) and
    written to `timing_path` when given (`make bench` writes figures/figure7_timing.json).
    `devices` as in `compute_figure7`; with several processes (`jax.distributed`) every
    process computes its share and process 0 writes the files.
    """
    from pathlib import Path

    out = Path(out_dir)
    load = list(os.getloadavg()) if hasattr(os, "getloadavg") else None  # 1, 5, 15 min
    t0 = time.perf_counter()
    data = compute_figure7(cfg, progress=progress, devices=devices)
    elapsed = time.perf_counter() - t0
    x64 = bool(jnp.zeros(()).dtype == jnp.float64)
    summary = {
        "config": dataclasses.asdict(cfg),
        "x64": x64,
        "errors_vs_reference": error_summary(data, cfg),
    }
    timing = {
        "config": summary["config"],
        "x64": x64,
        "device": str(jax.devices()[0]),
        "devices": batch_mesh(devices).size,
        "processes": jax.process_count(),
        "compute_seconds": elapsed,
        "load_average": load,  # at the start: the times depend on what else ran
        "seconds_per_method": data["seconds"],  # per row and method, first compilation included
    }
    if jax.process_index() > 0:
        return {**summary, "timing": timing}
    arrays = {f"{r}__{m}": v for r in ROWS for m, v in data["values"][r].items()}
    theta, sqrt_alpha, thickness = grids(cfg)
    atomic_write(out / "figure7.npz", lambda tmp: np.savez_compressed(
        tmp, theta_o=theta, sqrt_alpha=sqrt_alpha, thickness=thickness, **arrays))
    render_figure7(data, cfg, out / "figure7.png")
    render_error(data, cfg, out / "figure7_error.png")
    write_json(out / "figure7.json", summary)
    if timing_path is not None:
        write_json(Path(timing_path), timing)
    return {**summary, "timing": timing}
