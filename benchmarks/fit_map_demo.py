"""Thickness-map demo: a synthetic draining soap film rendered by the library,
with noise, fitted pixel by pixel with and without the neighbour prior.

The film is free-standing (air | soap η₂ = 1.33 | air: ``Film(d, 1.33, 1.0)``; no total
internal reflection arises, sin θ₃ = sin θ₁ ≤ 1), its thickness a draining wedge
d(x, y) = 100 + 800 s² nm, s = y/(H−1) + 0.06 sin(2π x/(W−1)) clipped to [0, 1] (thin at the
top, thicker and swirled below), seen under uniform light by a camera whose view angle
runs 5°–35° across the columns, GGX α = 0.1. The image is `render_patch_map` (the
filtered map model) plus Gaussian noise of 1 % of the image's RMS, σ known to the fit.

``python -m benchmarks.fit_map_demo [--resolution 64] [--out figures]`` writes
``fit_map_demo.png`` (image, truth, fits, |Δd| maps with colour bars) and
``fit_map_demo.json`` (median / p95 / max |Δd|, fraction > 20 nm, pixels/s warm and the
compilation time, for each fit).

``--envmap`` (also) runs the environment-map case (`fit_map.fit_envmap_map`): a soap bubble
(`render.study_scenes.thickness_field`, d ∈ [250, 850] nm) on a sphere under the shipped
``venice_sunset`` map, rendered with ``envmap_radiance(method="filtered")`` plus 1 % noise,
per-pixel normals and view known; ``fit_map_demo_envmap.png`` / ``.json``.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

ALPHA = 0.1
ETA_FILM = 1.33
NOISE = 0.01  # of the image's RMS
TAU_NM = 50.0


def soap_film(h: int, w: int):
    """(H, W) thickness (nm) of the draining wedge and (H, W) view angles (rad).

    Example (100 nm at the top, 900 nm at the bottom; 5°–35° across the columns):
        >>> import numpy as np
        >>> d, theta = soap_film(8, 5)
        >>> float(d.min()), float(d.max()), [round(float(t), 6) for t in np.degrees(theta[0])]
        (100.0, 900.0, [5.0, 12.5, 20.0, 27.5, 35.0])
    """
    y, x = np.mgrid[0:h, 0:w].astype(float)
    s = np.clip(y / (h - 1) + 0.06 * np.sin(2 * np.pi * x / (w - 1)), 0.0, 1.0)
    d = 100.0 + 800.0 * s**2
    theta = np.deg2rad(5.0 + 30.0 * x / (w - 1))
    return d, theta


def _stats(fit, truth):
    e = np.abs(np.asarray(fit) - truth)
    return {"median_abs_nm": float(np.median(e)), "p95_abs_nm": float(np.percentile(e, 95)),
            "max_abs_nm": float(e.max()), "fraction_over_20nm": float(np.mean(e > 20.0))}


def run(resolution: int = 64, out: str | Path = "figures", seed: int = 0) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from thinfilm_jax.core.files import write_json
    from thinfilm_jax.core.film import Film
    from thinfilm_jax.fit.thickness_map import fit_patch_map, render_patch_map

    h = w = int(resolution)
    d, theta = soap_film(h, w)
    clean = np.asarray(render_patch_map(Film(jnp.asarray(d), ETA_FILM, 1.0),
                                        jnp.asarray(theta), ALPHA))
    sigma = NOISE * float(np.sqrt(np.mean(clean**2)))
    image = clean + np.random.default_rng(seed).normal(0.0, sigma, clean.shape)
    kw = dict(alpha=ALPHA, initial=Film(500.0, ETA_FILM, 1.0), sigma=sigma,
              bounds={"thickness": (0.0, 1500.0)}, grid=151)
    runs = {}
    for name, tau in (("independent", None), (f"prior_tau{TAU_NM:g}nm", TAU_NM)):
        t0 = time.perf_counter()  # the whole fit twice: compile = cold − warm
        fit_patch_map(image, theta, smoothness_nm=tau, **kw)
        first = time.perf_counter() - t0
        res = fit_patch_map(image, theta, smoothness_nm=tau, progress=True, **kw)
        runs[name] = {"result": res, "compile_seconds": max(first - res.seconds, 0.0)}
    summary = {
        "film": f"soap: air | η₂ = {ETA_FILM} | air, d = 100 + 800 s² nm (draining wedge)",
        "resolution": [h, w], "alpha": ALPHA, "theta_o_deg": [5.0, 35.0],
        "noise_sigma": sigma, "noise_fraction_of_rms": NOISE, "seed": seed,
        "model": "render_patch_map / fit_patch_map method='filtered' (same model)",
        "grid": kw["grid"], "bounds_nm": list(kw["bounds"]["thickness"]),
        "machine": {"platform": platform.platform(), "cpu_count": _cpus(),
                    "load_average_1_5_15": _load()},
        "fits": {k: _stats(v["result"].thickness, d)
                 | {"pixels_per_second_warm": float(v["result"].pixels_per_second),
                    "seconds_warm": float(v["result"].seconds),
                    "compile_seconds": v["compile_seconds"]}
                 for k, v in runs.items()},
    }
    out = Path(out)
    write_json(out / "fit_map_demo.json", summary)
    h, w = d.shape
    _figure(out / "fit_map_demo.png", image, d, runs, summary,
            f"Thickness map of a draining soap film (air | η₂={ETA_FILM} | air), {h}×{w}, "
            f"GGX α={ALPHA}, uniform light, noise σ = {NOISE:.0%} of RMS, "
            f"fit_patch_map(method='filtered', grid={summary['grid']})", "x (pixel; θ_o 5°→35°)")
    return summary


def run_envmap(resolution: int = 48, out: str | Path = "figures", seed: int = 0,
               envmap: str = "venice_sunset") -> dict:
    """The sphere under an environment map (module docstring)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from thinfilm_jax.core.files import write_json
    from thinfilm_jax.shading.envmap import load_envmap
    from thinfilm_jax.core.film import Film
    from thinfilm_jax.fit.thickness_map import fit_envmap_map
    from thinfilm_jax.shading.ibl import envmap_radiance
    from thinfilm_jax.shading.prefilter import prefilter_envmap
    from thinfilm_jax.render.study_scenes import view_azimuth, camera, sphere, thickness_field

    env = load_envmap(envmap)
    t0 = time.perf_counter()
    pref = prefilter_envmap(env)
    prefilter_s = time.perf_counter() - t0
    wo, right, up = camera(view_azimuth(env), 20.0)
    mask, normal = sphere(int(resolution), wo, right, up)
    view = np.broadcast_to(wo, normal.shape)
    d = thickness_field(normal)
    clean = np.asarray(envmap_radiance(Film(jnp.asarray(d), ETA_FILM, 1.0), ALPHA, normal,
                                       view, pref, method="filtered"))
    sigma = NOISE * float(np.sqrt(np.mean(clean[mask] ** 2)))
    image = clean + np.random.default_rng(seed).normal(0.0, sigma, clean.shape)
    image = np.where(mask[..., None], image, 0.0)
    nrm = np.where(mask[..., None], normal, np.nan)
    kw = dict(alpha=ALPHA, initial=Film(500.0, ETA_FILM, 1.0), sigma=sigma,
              bounds={"thickness": (0.0, 1500.0)}, grid=151)
    runs = {}
    for name, tau in (("independent", None), (f"prior_tau{TAU_NM:g}nm", TAU_NM)):
        t0 = time.perf_counter()  # the whole fit twice: compile = cold − warm
        fit_envmap_map(image, nrm, view, pref, smoothness_nm=tau, **kw)
        first = time.perf_counter() - t0
        res = fit_envmap_map(image, nrm, view, pref, smoothness_nm=tau, progress=True, **kw)
        runs[name] = {"result": res, "compile_seconds": max(first - res.seconds, 0.0)}
    truth = np.where(mask, d, np.nan)
    summary = {
        "film": f"soap bubble: air | η₂ = {ETA_FILM} | air, d = render.study_scenes.thickness_field",
        "envmap": envmap, "prefilter_seconds": prefilter_s,
        "resolution": [int(resolution)] * 2, "fitted_pixels": int(mask.sum()),
        "alpha": ALPHA, "noise_sigma": sigma, "noise_fraction_of_rms": NOISE, "seed": seed,
        "model": "envmap_radiance(method='filtered') / fit_envmap_map (same model)",
        "grid": kw["grid"], "bounds_nm": list(kw["bounds"]["thickness"]),
        "machine": {"platform": platform.platform(), "cpu_count": _cpus(),
                    "load_average_1_5_15": _load()},
        "fits": {k: _stats(np.asarray(v["result"].thickness)[mask], d[mask])
                 | {"pixels_per_second_warm": float(v["result"].pixels_per_second),
                    "seconds_warm": float(v["result"].seconds),
                    "compile_seconds": v["compile_seconds"]}
                 for k, v in runs.items()},
    }
    out = Path(out)
    write_json(out / "fit_map_demo_envmap.json", summary)
    _figure(out / "fit_map_demo_envmap.png", image, truth, runs, summary,
            f"Thickness map of a soap bubble (air | η₂={ETA_FILM} | air) under {envmap}, "
            f"{resolution}² sphere, GGX α={ALPHA}, noise σ = {NOISE:.0%} of RMS, "
            f"fit_envmap_map(grid={summary['grid']})", "x (pixel)")
    return summary


def _cpus():
    import os

    return os.cpu_count()


def _load():
    import os

    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def _figure(path, image, d, runs, summary, title, xlabel):
    import matplotlib

    from thinfilm_jax.core.files import atomic_write
    from thinfilm_jax.spectral.colorimetry import bands_to_srgb
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    names = list(runs)
    fig, axes = plt.subplots(2, 3, figsize=(12, 7.6), layout="constrained")
    rgb = np.clip(np.asarray(bands_to_srgb(image, exposure=1.0 / max(
        float(np.percentile(image.sum(-1) / 3, 99)), 1e-9) * 0.6)), 0, 1)
    axes[0, 0].imshow(rgb, interpolation="nearest")
    axes[0, 0].set_title("observed image (sRGB, noise included)")
    vmin, vmax = float(np.nanmin(d)), float(np.nanmax(d))
    panels = [(axes[0, 1], d, "truth d (nm)"),
              (axes[0, 2], np.asarray(runs[names[0]]["result"].thickness),
               "fit, independent pixels (nm)"),
              (axes[1, 0], np.asarray(runs[names[1]]["result"].thickness),
               f"fit, neighbour prior τ = {TAU_NM:g} nm (nm)")]
    for ax, v, t in panels:
        im = ax.imshow(v, cmap="viridis", vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_title(t)
        fig.colorbar(im, ax=ax, label="thickness (nm)")
    errs = {k: np.abs(np.asarray(runs[k]["result"].thickness) - d) for k in names}
    norm = matplotlib.colors.LogNorm(1e-2, max(max(float(np.nanmax(e)) for e in errs.values()),
                                               1.0))
    for ax, k in zip(axes[1, 1:], names):
        im = ax.imshow(np.maximum(errs[k], 1e-3), cmap="magma", norm=norm,
                       interpolation="nearest")
        s = summary["fits"][k]
        ax.set_title(f"|Δd|, {k.replace('_', ' ')}\nmedian {s['median_abs_nm']:.2f} nm, "
                     f"p95 {s['p95_abs_nm']:.1f} nm,\nmax {s['max_abs_nm']:.0f} nm, "
                     f"> 20 nm: {100 * s['fraction_over_20nm']:.2f} %", fontsize=8)
        fig.colorbar(im, ax=ax, label="|fit − truth| (nm)")
    for ax in axes.flat:
        ax.set_xlabel(xlabel)
        ax.set_ylabel("y (pixel)")
    fig.suptitle(title, fontsize=10)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--out", default="figures")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--envmap", action="store_true",
                   help="run the environment-map sphere instead (--resolution default 48)")
    a = p.parse_args(argv)
    if a.envmap:
        s = run_envmap(a.resolution if a.resolution != 64 else 48, a.out, a.seed)
        files = "fit_map_demo_envmap.png, fit_map_demo_envmap.json"
    else:
        s = run(a.resolution, a.out, a.seed)
        files = "fit_map_demo.png, fit_map_demo.json"
    for k, v in s["fits"].items():
        c = v["compile_seconds"]
        print(f"{k:22s} median |Δd| {v['median_abs_nm']:.2f} nm, p95 {v['p95_abs_nm']:.1f}, "
              f"max {v['max_abs_nm']:.1f}, > 20 nm {100 * v['fraction_over_20nm']:.2f} %, "
              f"{v['pixels_per_second_warm']:.0f} px/s warm, compile {c:.1f} s (cold − warm)")
    print(f"wrote {a.out}/{files}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
