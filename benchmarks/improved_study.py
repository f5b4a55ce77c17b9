"""`method="improved"` against `filtered` — error by region, IBL renders, cost, Pareto.

``python -m benchmarks.improved_study [--quick] [--out figures]`` writes
``improved.json``, ``improved.md`` (the tables of docs/improved.md and the README),
``improved_pareto.png`` (ΔE against cost per shading point, every kernel option) and
``improved_figure7.png`` (ΔE maps of both methods on the two Figure 7 panel sets);
``--floor`` writes ``improved_ibl_floor.json`` (`ibl_floor`: what any split-sum method can
reach under the shipped maps when its film term is exact); ``--replot`` redraws
``improved_pareto.png`` from ``improved.json``.

Uniform light (SPEC §7), against `patch_radiance(method="reference")`:
* the wide grid: 4 materials (`MATERIALS`: κ₃ ∈ {0, 0, 0.5, 3.99}) × d ∈ {300, 600, 1000} nm ×
  θ_o ∈ {0, 30, 50, 65, 75, 82, 88}° × α ∈ {0.01, 0.06, 0.25, 0.5, 0.9} (three materials
  plus the soap film), reference quadrature 64²;
* the Figure 7 panel sets (`figure7.grids`, cell centres) at `fig7_resolution`², quadrature 32².
Regions: grazing θ_o ≥ 75°, rough α ≥ 0.5, near-mirror α ≤ 0.06 (the rest: "interior").

Image-based lighting (SPEC §9): the sphere renders of `render.study_scenes` (Figures 3–6 setups,
the four shipped maps), reference values read from ``figures/ibl_render.npz`` (written by
``thinfilm-jax render``; the masks are checked against the recomputed geometry), `filtered`
(the published method, the map as it is), `improved` (the map's suns split off and shaded
apart, `prefilter_envmap(sources=ibl.DEFAULT_SOURCES)`, as `envmap_radiance` does) and
`filtered + sources` (K 29 on the same split: an option, not the published method)
recomputed; per render, per map (every pixel of the map's renders pooled, and the worst
render's mean) and over all pixels. Held out (`held_out_maps`, never used to tune the
method): venice_sunset and forest_slope, from which no source is split as shipped, each with
an added 0.53° sun (`add_sun`) at 9° and 43° elevation carrying 70 % of the luminous power;
their references are computed here (fig4 and fig3 α = 0.12, 32 px spheres, a few minutes).
ΔE with the render's exposure rule.

Cost: the per-shading-point kernels (`kernels.filtered_kernel`, `improved.improved_kernel`,
`kernels.ideal_kernel`) on `points` float32 points, jit-compiled, timed interleaved (each
repeat times every row once, so that the load of a shared machine hits all rows alike),
median of `repeats`. The error of each kernel row is that of kernel × A on the wide grid.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.files import atomic_write, write_json
from thinfilm_jax.spectral.colorimetry import delta_e2000
from thinfilm_jax.realtime.improved import bin_table, improved_kernel
from thinfilm_jax.realtime.kernels import filtered_kernel, ideal_kernel
from thinfilm_jax.spectral.lut import build_shat_lut
from thinfilm_jax.brdf.microfacet import albedo, splitsum_light_moments
from thinfilm_jax.realtime.options import ModelOptions
from thinfilm_jax.shading.patch import patch_radiance
from ._common import MATERIALS, material_film, view_vector
from ._timing import environment, jsonable, write_report
from .pareto import render_kernel_pareto

WIDE_THETA_DEG = (0.0, 30.0, 50.0, 65.0, 75.0, 82.0, 88.0)
WIDE_ALPHA = (0.01, 0.06, 0.25, 0.5, 0.9)
WIDE_D = (300.0, 600.0, 1000.0)


@dataclasses.dataclass(frozen=True)
class StudyConfig:
    fig7_resolution: int = 32
    wide_quadrature: int = 64
    points: int = 100_000
    repeats: int = 7
    ibl: bool = True
    held_out: bool = True  # the held-out sun maps (their references: a few minutes)

    @classmethod
    def quick(cls):
        return cls(fig7_resolution=8, wide_quadrature=32, points=5_000, repeats=3,
                   held_out=False)


def regions(theta_o, alpha):
    """Boolean masks of the named regions (grazing, rough, near-mirror, interior).

    Example (interior is what no other region holds):
        >>> import numpy as np
        >>> masks = regions(np.radians([10.0, 80.0, 30.0]), np.array([0.2, 0.2, 0.6]))
        >>> masks["grazing θo ≥ 75°"].tolist(), masks["interior"].tolist()
        ([False, True, False], [True, False, False])
    """
    deg = np.degrees(theta_o)
    g, r, m = deg >= 75.0, alpha >= 0.5, alpha <= 0.06
    return {"all": np.ones_like(g), "grazing θo ≥ 75°": g, "rough α ≥ 0.5": r,
            "near-mirror α ≤ 0.06": m, "interior": ~(g | r | m)}


def _stats(de):
    return {"mean": float(de.mean()), "p95": float(np.percentile(de, 95)),
            "max": float(de.max()), "n": int(de.size)}


def compare(de_f, de_i, theta_o, alpha, labels):
    """Per-region statistics of both methods, ratios and the cases worse than filtered."""
    out = {}
    for name, m in regions(theta_o, alpha).items():
        if not m.any():
            continue
        f, i = _stats(de_f[m]), _stats(de_i[m])
        out[name] = {"filtered": f, "improved": i,
                     "ratio_mean": i["mean"] / f["mean"], "ratio_p95": i["p95"] / f["p95"],
                     "n_worse_by_1": int(np.sum(de_i[m] > de_f[m] + 1.0)),
                     "n_better": int(np.sum(de_i[m] < de_f[m]))}
    excess = de_i - de_f
    order = np.argsort(-excess)[:8]
    out["largest_excess"] = [{"case": str(labels[k]), "filtered": float(de_f[k]),
                              "improved": float(de_i[k])} for k in order if excess[k] > 0]
    return out


def wide_grid():
    names, d, t, a = np.meshgrid(np.array(list(MATERIALS)), WIDE_D, np.deg2rad(WIDE_THETA_DEG),
                                 WIDE_ALPHA, indexing="ij")
    names, d, t, a = (x.ravel() for x in (names, d, t, a))
    labels = np.array([f"{n} d={x:.0f} θo={np.degrees(y):.0f}° α={z:g}"
                       for n, x, y, z in zip(names, d, t, a)])
    return material_film(names, d), t, a, labels


def fig7_grid(row: str, n: int):
    from thinfilm_jax.render.figure7 import Figure7Config, row_inputs

    film, t, a = row_inputs(Figure7Config(resolution=n), row)
    shape = t.shape
    film = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x, float), shape).ravel(), film)
    t, a = t.ravel(), np.broadcast_to(a, shape).ravel()
    labels = np.array([f"fig7 d={x:.0f} θo={np.degrees(y):.1f}° α={z:.3g}"
                       for x, y, z in zip(film.thickness, t, a)])
    return film, t, a, labels, shape


def uniform_light(cfg: StudyConfig, verbose=True):
    """Both methods on the wide grid and the Figure 7 panel sets, every region."""
    res, maps = {}, {}
    opts = {"wide": ModelOptions(quadrature=(cfg.wide_quadrature,) * 2),
            "fig7": ModelOptions(quadrature=(32, 32))}
    grids = [("wide", *wide_grid(), None)]
    for row in ("roughness", "thickness"):
        grids.append((f"figure7 {row}", *fig7_grid(row, cfg.fig7_resolution)))
    for name, film, t, a, labels, shape in grids:
        o = opts["wide" if name == "wide" else "fig7"]
        t0 = time.perf_counter()
        v = {m: np.asarray(patch_radiance(film, t, a, method=m, options=o))
             for m in ("reference", "filtered", "improved")}
        de_f = np.asarray(delta_e2000(v["filtered"], v["reference"]))
        de_i = np.asarray(delta_e2000(v["improved"], v["reference"]))
        res[name] = compare(de_f, de_i, t, a, labels)
        if shape is not None:
            maps[name] = (de_f.reshape(shape), de_i.reshape(shape))
        else:
            res[name]["_values"] = v
        if verbose:
            s = res[name]["all"]
            print(f"{name}: filtered {s['filtered']['mean']:.2f}/{s['filtered']['p95']:.2f}, "
                  f"improved {s['improved']['mean']:.2f}/{s['improved']['p95']:.2f} "
                  f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return res, maps


HELD_OUT_MAPS = ("venice_sunset", "forest_slope")  # no source is split from either as shipped
HELD_OUT_ELEVATIONS_DEG = (9.0, 43.0)
SUN_DIAMETER_DEG = 0.53
SUN_FRACTION = 0.7  # of the luminous power ∫ Y dω of the map with the sun
SUN_RGB = (1.0, 0.93, 0.82)
IBL_METHODS = ("filtered", "improved", "filtered+sources")


def add_sun(envmap, elevation_deg: float, azimuth: float = 2.0, *,
            diameter_deg: float = SUN_DIAMETER_DEG, fraction: float = SUN_FRACTION,
            rgb=SUN_RGB, supersample: int = 32):
    """The map plus a uniform disc sun (a spherical cap of angular `diameter_deg`) at
    (elevation, azimuth φ from +x toward +y), carrying `fraction` of the resulting map's
    luminous power ∫ Y dω; radiance ∝ `rgb`. Each texel within a few texels of the sun gets
    L_sun × the fraction of its solid angle inside the cap (`supersample`² points per texel,
    weighted by sin θ), so the map holds the cap's power up to that coverage estimate.

    Example (the sun carries the asked share of the luminous power):
        >>> import numpy as np
        >>> from thinfilm_jax.shading.envmap import luminance_weights, texel_solid_angles
        >>> base = np.ones((64, 128, 3))
        >>> m = np.asarray(add_sun(base, 30.0).radiance)
        >>> om = texel_solid_angles(64, 128)
        >>> y0, y1 = (((x @ luminance_weights()) * om).sum() for x in (base, m))
        >>> round(float((y1 - y0) / y1), 6)
        0.7
    """
    from thinfilm_jax.shading.envmap import EnvMap, load_envmap, luminance_weights, texel_solid_angles

    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    rad = np.array(env.radiance, np.float64)
    h, w = rad.shape[:2]
    theta_s, phi_s = np.deg2rad(90.0 - elevation_deg), azimuth % (2 * np.pi)
    axis = np.array([np.sin(theta_s) * np.cos(phi_s), np.sin(theta_s) * np.sin(phi_s),
                     np.cos(theta_s)])
    cos_gamma = np.cos(np.deg2rad(diameter_deg) / 2)
    i0, j0 = int(theta_s / np.pi * h), int(phi_s / (2 * np.pi) * w)
    u = (np.arange(supersample) + 0.5) / supersample
    cover = {}
    for i in range(max(i0 - 3, 0), min(i0 + 4, h)):
        th = (i + u) * np.pi / h
        for j in range(j0 - 3, j0 + 4):
            ph = (j + u) * 2 * np.pi / w
            t, p_ = np.meshgrid(th, ph, indexing="ij")
            d = np.stack([np.sin(t) * np.cos(p_), np.sin(t) * np.sin(p_), np.cos(t)], -1)
            wt = np.sin(t)
            f = float((wt * (d @ axis >= cos_gamma)).sum() / wt.sum())
            if f > 0:
                cover[(i, j % w)] = f
    om = texel_solid_angles(h, w)
    lum = luminance_weights()
    sun_rgb = np.asarray(rgb, np.float64)
    omega_eff = sum(f * om[i, j] for (i, j), f in cover.items())
    y_map = float(((rad @ lum) * om).sum())
    scale = fraction / (1 - fraction) * y_map / (omega_eff * float(sun_rgb @ lum))
    for (i, j), f in cover.items():
        rad[i, j] += f * scale * sun_rgb
    return EnvMap(jnp.asarray(rad, env.radiance.dtype))


def _score(setup, cfg, cache, ref, mask=None):
    """ΔE per pixel of every `IBL_METHODS` entry against `ref` on one render setup.
    filtered reads the map as it is, improved and filtered+sources the map with its suns
    split off (`study_scenes.method_map`)."""
    from thinfilm_jax.spectral.colorimetry import bands_to_xyz
    from thinfilm_jax.shading.ibl import envmap_radiance
    from thinfilm_jax.render.study_scenes import view_azimuth, camera, method_map, sphere

    scene, label, name, make_film, alpha = setup
    env = method_map(cache, name, "reference", cfg.observer)
    wo, right, up = camera(view_azimuth(env), cfg.elevation_deg)
    m, n = sphere(cfg.resolution, wo, right, up)
    if mask is not None and not np.array_equal(m, mask):
        raise RuntimeError("the stored references were rendered with another geometry; "
                           "rerun `thinfilm-jax render`")
    pts = n[m]
    film = make_film(pts)
    e = float(0.9 / max(np.percentile(bands_to_xyz(ref, cfg.observer)[:, 1], 99), 1e-12))
    out = {}
    for key in IBL_METHODS:
        method = key.split("+")[0]
        pref = method_map(cache, name, "improved" if "+" in key or method == "improved"
                          else method, cfg.observer)
        v = np.asarray(envmap_radiance(film, alpha, pts, wo, pref, method=method,
                                       observer=cfg.observer))
        out[key] = np.asarray(delta_e2000(v * e, ref * e, cfg.observer))
    return out


def _group(rows, des):
    """Pooled statistics of a group of renders: every pixel's ΔE (mean, p95), the worst
    render's mean, and improved ÷ filtered of the pooled mean and p95."""
    g = {}
    for key in IBL_METHODS:
        s = _stats(np.concatenate([d[key] for d in des]))
        s["worst_render_mean"] = max(r[key]["mean"] for r in rows)
        g[key] = s
    g["renders"] = len(rows)
    g["ratio_mean"] = g["improved"]["mean"] / g["filtered"]["mean"]
    g["ratio_p95"] = g["improved"]["p95"] / g["filtered"]["p95"]
    return g


def _row(label, scene, alpha, envmap, de):
    return {"label": label, "scene": scene, "alpha": alpha, "envmap": envmap,
            **{k: _stats(v) for k, v in de.items()}}


def held_out_maps():
    """{name: EnvMap} of the held-out set: each `HELD_OUT_MAPS` map with an added sun
    (`add_sun`) at each `HELD_OUT_ELEVATIONS_DEG`."""
    from thinfilm_jax.shading.envmap import load_envmap

    return {f"{m} + sun at {el:g}°": add_sun(load_envmap(m), el)
            for m in HELD_OUT_MAPS for el in HELD_OUT_ELEVATIONS_DEG}


def ibl_renders(verbose=True, npz="figures/ibl_render.npz", held_out=True,
                held_out_resolution=32):
    """ΔE of filtered, improved and filtered+sources on the render scenes against the stored
    references (`figures/ibl_render.npz`), per render, per map and pooled; and on the
    held-out set (`held_out_maps`: synthetic suns the method was never tuned on), whose
    references are computed here (fig4 and fig3 α = 0.12 at `held_out_resolution` px)."""
    from thinfilm_jax.render.study_scenes import RenderConfig, map_label, render_one, scene_setups

    cfg = RenderConfig()
    z = np.load(npz)
    cache, rows, des = {}, [], []
    for i, setup in enumerate(scene_setups(cfg)):
        de = _score(setup, cfg, cache, z[f"r{i}_reference"], z[f"r{i}_mask"])
        rows.append(_row(setup[1], setup[0], setup[4], map_label(setup[2]), de))
        des.append(de)
        if verbose:
            print(f"  {setup[1]:40s} " + " ".join(
                f"{k} {rows[-1][k]['mean']:.2f}/{rows[-1][k]['p95']:.2f}" for k in IBL_METHODS),
                  file=sys.stderr)
    per_map = {}
    for m in dict.fromkeys(r["envmap"] for r in rows):
        sel = [k for k, r in enumerate(rows) if r["envmap"] == m]
        per_map[m] = _group([rows[k] for k in sel], [des[k] for k in sel])
    result = {"renders": rows, "per_map": per_map, "all": _group(rows, des)}
    if held_out:
        hrows, hmaps = [], {}
        for name, env in held_out_maps().items():
            hcfg = RenderConfig(envmaps=(name,), scenes=("fig4", "fig3"), alphas=(0.12,),
                                methods=("reference",), resolution=held_out_resolution)
            cache[name] = {"env": env}
            sel, hdes = [], []
            for setup in scene_setups(hcfg):
                t0 = time.perf_counter()
                ref = render_one(setup, hcfg, cache)["values"]["reference"]
                de = _score(setup, hcfg, cache, ref)
                hrows.append(_row(setup[1], setup[0], setup[4], name, de))
                hrows[-1]["reference_seconds"] = time.perf_counter() - t0
                sel.append(hrows[-1])
                hdes.append(de)
                if verbose:
                    print(f"  held out {setup[1]:40s} " + " ".join(
                        f"{k} {hrows[-1][k]['mean']:.2f}/{hrows[-1][k]['p95']:.2f}"
                        for k in IBL_METHODS) + f" ({hrows[-1]['reference_seconds']:.0f} s)",
                          file=sys.stderr)
            hmaps[name] = _group(sel, hdes)
        result["held_out"] = {"renders": hrows, "per_map": hmaps,
                              "resolution": held_out_resolution,
                              "sun": {"diameter_deg": SUN_DIAMETER_DEG,
                                      "fraction": SUN_FRACTION, "rgb": SUN_RGB,
                                      "elevations_deg": HELD_OUT_ELEVATIONS_DEG}}
    return result


def ibl_floor(indices=(0, 1, 2, 3, 4, 7), npz="figures/ibl_render.npz", verbose=True):
    """What a split-sum method can reach under an environment: the film term made exact.

    Per shading point, the exact light-weighted film reflectance of each RGB channel,
    R̄_jk = ∫ k c_k R_jk / ∫ k c_k (k = ρ̃⟨n,ω_i⟩, the reference's texel quadrature), times
    the table A and the prefiltered radiance P_k read (a) at (ω_r, √α) as `filtered` and
    `ideal` do, (b) at the lobe's mean direction and α_eff as `improved` does. ΔE against the
    stored reference. Costs a reference render per scene (minutes each). `indices` index
    `render.scene_setups()`: by default fig4 under the four maps and fig3 at α = 0.05, 0.6."""
    from thinfilm_jax.spectral.colorimetry import bands_to_xyz
    from thinfilm_jax.shading.envmap import load_envmap
    from thinfilm_jax.shading.ibl_integrand import (interp_table, lobe_cos_weight,
                                                    reflectance_table, texel_nodes)
    from thinfilm_jax.shading.ibl_reference import auto_subdivisions
    from thinfilm_jax.realtime.improved import lookup_lobe
    from thinfilm_jax.shading.prefilter import lookup_albedo, lookup_prefiltered, prefilter_envmap
    from thinfilm_jax.spectral.uplift import cross_band_name
    from thinfilm_jax.render.study_scenes import RenderConfig, view_azimuth, camera, scene_setups, sphere

    cfg = RenderConfig()
    z = np.load(npz)
    obs = cross_band_name(cfg.observer)
    setups = scene_setups(cfg)
    tab = bin_table(1)  # K = 1: the whole lobe's mean direction and equal-variance level
    rows = []
    for i in indices:
        scene, label, name, make_film, alpha = setups[i]
        env = load_envmap(name)
        pref = prefilter_envmap(env, observer=cfg.observer)
        wo, right, up = camera(view_azimuth(env), cfg.elevation_deg)
        mask, n = sphere(cfg.resolution, wo, right, up)
        pts = n[mask]
        film = make_film(pts)
        if np.ndim(film.thickness):
            raise ValueError("ibl_floor needs one film per scene")
        d, wt, idx = texel_nodes(*env.shape, auto_subdivisions(env.shape[0], alpha))
        dirs = jnp.asarray(d)
        light = jnp.asarray(wt)[:, None] * jnp.asarray(env.radiance).reshape(-1, 3)[idx]
        table = reflectance_table(jax.tree.map(jnp.asarray, film), obs, 1024, "complex", jnp.float64)

        def one(nn, wo=jnp.asarray(wo), dirs=dirs, light=light, table=table, alpha=alpha):
            w, c = lobe_cos_weight(dirs, nn, wo, alpha)
            r = interp_table(table, c).reshape(-1, 3, 3)
            lw = w[:, None] * light
            return jnp.einsum("njk,nk->jk", r, lw, precision=jax.lax.Precision.HIGHEST), \
                lw.sum(0)

        num, den = jax.lax.map(jax.jit(one), jnp.asarray(pts), batch_size=16)
        rbar = np.asarray(num) / np.asarray(den)[:, None, :]
        nrm = jnp.asarray(pts)
        view = jnp.broadcast_to(jnp.asarray(wo), nrm.shape)
        co = jnp.sum(nrm * view, -1)
        sqa = jnp.full(co.shape, np.sqrt(alpha))
        a = np.asarray(lookup_albedo(pref, co, sqa))[:, None]
        ref = z[f"r{i}_reference"]
        e = float(0.9 / max(np.percentile(bands_to_xyz(ref, cfg.observer)[:, 1], 99), 1e-12))
        row = {"label": label}
        dirs, levels = lookup_lobe(tab, nrm, view, co, jnp.full(co.shape, alpha))
        dmu, sqe = dirs[:, 0], levels[:, 0]  # the one bin
        for key, (dirn, lev) in {"P at (ω_r, α)": (2 * co[:, None] * nrm - view, sqa),
                                 "P at (ω_μ, α_eff)": (dmu, sqe)}.items():
            rad = np.asarray(lookup_prefiltered(pref, dirn, lev)[0])
            v = a * np.sum(rbar * rad[:, None, :], -1)
            row[key] = _stats(np.asarray(delta_e2000(v * e, ref * e, cfg.observer)))
        rows.append(row)
        if verbose:
            print(f"  floor {label}: " + ", ".join(f"{k} {row[k]['mean']:.2f}/{row[k]['p95']:.2f}"
                                                   for k in row if k != "label"),
                  file=sys.stderr)
    return rows


def kernel_rows(cfg: StudyConfig, ref, verbose=True):
    """Error (wide grid, kernel × A) and interleaved float32 cost of every kernel option."""
    film, t, a, _ = wide_grid()
    co = np.cos(t)
    A = np.asarray(albedo(t, a))[:, None]
    mean, cov = (np.asarray(x) for x in splitsum_light_moments(t, a))
    wo = np.asarray(view_vector(co))
    n = cfg.points
    rep = -(-n // len(t))
    f32 = jnp.float32

    def big(x):
        return jnp.asarray(np.concatenate([x] * rep)[:n], f32)

    lut = {dt: build_shat_lut(dtype=dt) for dt in (jnp.float64, f32)}
    tabs = {k: bin_table(k) for k in (1, 2, 3, 4)}
    filt = {"filtered K29 (shipped: bicubic LUT)": dict(shat="lut"),
            "filtered K29, exact Ŝ": dict(shat="exact"),
            "filtered K29, Gaussian Ŝ": dict(shat="gaussian"),
            "filtered K29, M = 1": dict(shat="lut", terms=1),
            "filtered K29, M = 3": dict(shat="lut", terms=3)}
    imp = {"improved K=3 (default: bilinear LUT)": dict(k=3, shat="lut"),
           "improved K=1": dict(k=1, shat="lut"),
           "improved K=2": dict(k=2, shat="lut"),
           "improved K=4": dict(k=4, shat="lut"),
           "improved K=3, exact Ŝ": dict(k=3, shat="exact"),
           "improved K=3, Gaussian Ŝ": dict(k=3, shat="gaussian"),
           "improved K=3, M = 1": dict(k=3, shat="lut", terms=1),
           "improved K=3, M = 3": dict(k=3, shat="lut", terms=3)}
    ideal = {"ideal (exact Ŝ)": dict(shat="exact"), "ideal (LUT σ = 0)": dict(shat="lut")}
    progs = []
    for name, kw in filt.items():
        def fn(f, w, m, c, lt, kw=kw):
            return filtered_kernel(f, w, m, c, lut=lt, **kw)
        progs.append((name, "filtered", fn, lambda s: (s(film), s(wo), s(mean), s(cov))))
    for name, kw in imp.items():
        kw = dict(kw)
        k = kw.pop("k")

        def fn(f, c, al, tb, lt, kw=kw):
            return improved_kernel(f, c, al, tb, lut=lt, **kw)
        progs.append((name, "improved", fn,
                      lambda s, k=k: (s(film), s(co), s(a), tabs[k])))
    for name, kw in ideal.items():
        def fn(f, c, lt, kw=kw):
            return ideal_kernel(f, c, lut=lt, **kw)
        progs.append((name, "ideal", fn, lambda s: (s(film), s(co))))
    rows, timed = [], []
    for name, group, fn, make in progs:
        jf = jax.jit(fn)
        out = np.asarray(jf(*make(lambda x: x), lut[jnp.float64]))
        de = np.asarray(delta_e2000(A * out, ref))
        row = {"path": name, "group": group, **_stats(de)}
        rows.append(row)
        tf = jax.tree.map(lambda x: big(np.asarray(x)) if np.ndim(x) and np.shape(x)[0] == len(t)
                          else jnp.asarray(x, f32), make(lambda x: x))
        args32 = (*tf, lut[f32])
        jax.block_until_ready(jf(*args32))  # compile
        timed.append((row, jf, args32))
    times = {id(r): [] for r, _, _ in timed}
    for _ in range(cfg.repeats):
        for row, jf, args in timed:
            t0 = time.perf_counter()
            jax.block_until_ready(jf(*args))
            times[id(row)].append(time.perf_counter() - t0)
    base = None
    for row, _, _ in timed:
        row["us_per_point"] = statistics.median(times[id(row)]) / n * 1e6
        if row["path"].startswith("filtered K29 (shipped"):
            base = row["us_per_point"]
    for row in rows:
        row["cost_vs_filtered"] = row["us_per_point"] / base
        if verbose:
            print(f"  {row['path']:42s} ΔE {row['mean']:.2f}/{row['p95']:.2f} "
                  f"{row['us_per_point']:.3f} µs ({row['cost_vs_filtered']:.2f}×)",
                  file=sys.stderr)
    return rows


def plot_fig7(maps, cfg: StudyConfig, path):
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    fig, axes = plt.subplots(2, 2, figsize=(9, 8), constrained_layout=True)
    ext = {"figure7 roughness": ([0, 90, 0, 1], "√α"),
           "figure7 thickness": ([0, 90, 0, 1000], "d (nm)")}
    im = None
    for i, (name, (de_f, de_i)) in enumerate(maps.items()):
        for j, (lab, de) in enumerate((("filtered", de_f), ("improved", de_i))):
            ax = axes[i, j]
            im = ax.imshow(de, origin="lower", extent=ext[name][0], aspect="auto",
                           cmap="magma", vmin=0, vmax=10)
            ax.set_title(f"{name}: {lab}\nΔE mean {de.mean():.2f}, "
                         f"p95 {np.percentile(de, 95):.2f}", fontsize=9)
            ax.set_xlabel("θ_o (°)")
            ax.set_ylabel(ext[name][1])
    fig.colorbar(im, ax=axes, shrink=0.7, label="CIEDE2000 ΔE vs reference")
    fig.suptitle(f"Figure 7 grids ({cfg.fig7_resolution}² patches each; η₂ = 1.3, η₃ = 2.0 + "
                 "0.5i; d = 600 nm (top), α = 0.25 (bottom)); M = 2, exact Ŝ", fontsize=9)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


def markdown(result) -> str:
    lines = ["## Uniform light: ΔE₀₀ against the reference (mean / p95 / max)", "",
             "| grid | region | n | filtered | improved | ratio mean | ratio p95 "
             "| worse by > 1 ΔE |", "|---|---|---|---|---|---|---|---|"]
    for g, res in result["uniform"].items():
        for reg, s in res.items():
            if reg.startswith("_") or reg == "largest_excess":
                continue
            f, i = s["filtered"], s["improved"]
            lines.append(f"| {g} | {reg} | {f['n']} | {f['mean']:.2f} / {f['p95']:.2f} / "
                         f"{f['max']:.2f} | {i['mean']:.2f} / {i['p95']:.2f} / {i['max']:.2f} "
                         f"| {s['ratio_mean']:.2f} | {s['ratio_p95']:.2f} "
                         f"| {s['n_worse_by_1']} |")
    lines += ["", "Largest excess of improved over filtered (ΔE filtered → improved):", ""]
    for g, res in result["uniform"].items():
        ex = ", ".join(f"{e['case']}: {e['filtered']:.2f} → {e['improved']:.2f}"
                       for e in res["largest_excess"][:4])
        lines.append(f"- {g}: {ex or 'none'}")
    if "ibl" in result:
        lines += ibl_markdown(result["ibl"])
    lines += ["", "## Kernels: error on the wide grid (kernel × A) and float32 cost", "",
              "| kernel | ΔE mean | ΔE p95 | ΔE max | µs / point | × filtered |",
              "|---|---|---|---|---|---|"]
    for r in result["kernels"]:
        lines.append(f"| {r['path']} | {r['mean']:.2f} | {r['p95']:.2f} | {r['max']:.2f} "
                     f"| {r['us_per_point']:.3f} | {r['cost_vs_filtered']:.2f} |")
    env = result["environment"]
    lines += ["", f"Machine: {env['devices']}, {env['cpu_count']} CPUs, load average "
              f"{env['load_average']} at start; {result['config']['points']} points, median of "
              f"{result['config']['repeats']} interleaved repeats."]
    return "\n".join(lines) + "\n"


def _triple(s):
    return f"{s['mean']:.2f} / {s['p95']:.2f} / {s['worst_render_mean']:.2f}"


def ibl_markdown(ibl) -> list[str]:
    """The IBL tables: per map (with the held-out set) and per render."""
    names = {"filtered": "filtered", "improved": "improved",
             "filtered+sources": "filtered + sources"}
    lines = ["", "## Image-based lighting: per map (ΔE₀₀ mean / p95 / worst render's mean)", "",
             "Pooled over every pixel of the map's renders. `improved` shades the suns split "
             "from the map apart (`prefilter_envmap(sources=4)`), `filtered` is the published "
             "method on the map as it is, `filtered + sources` is K 29 on the same split (an "
             "option, not the published method). Held out: the map with an added 0.53° sun "
             "carrying 70 % of the luminous power, fig4 and fig3 α = 0.12, "
             f"{ibl.get('held_out', {}).get('resolution', '—')} px spheres.", "",
             "| map | renders | filtered | improved | filtered + sources "
             "| improved ÷ filtered (mean / p95) |", "|---|---|---|---|---|---|"]

    def row(label, g):
        return (f"| {label} | {g['renders']} | " + " | ".join(_triple(g[k]) for k in IBL_METHODS)
                + f" | {g['ratio_mean']:.2f} / {g['ratio_p95']:.2f} |")

    for m, g in ibl["per_map"].items():
        lines.append(row(m, g))
    for m, g in ibl.get("held_out", {}).get("per_map", {}).items():
        lines.append(row(f"held out: {m}", g))
    lines.append(row("**all pixels** (shipped maps)", ibl["all"]))
    lines += ["", "## Image-based lighting: sphere renders (ΔE₀₀ mean / p95)", "",
              "| render | " + " | ".join(names[k] for k in IBL_METHODS) + " |",
              "|---|" + "---|" * len(IBL_METHODS)]
    renders = [(r["label"], r) for r in ibl["renders"]] + [
        (f"held out: {r['envmap']}, {r['label'].split(' | ')[0]}", r)
        for r in ibl.get("held_out", {}).get("renders", [])]
    for label, r in renders:
        lines.append(f"| {label.replace(' | ', ' · ')} | " + " | ".join(
            f"{r[k]['mean']:.2f} / {r[k]['p95']:.2f}" for k in IBL_METHODS) + " |")
    return lines


def run(cfg: StudyConfig = StudyConfig(), out="figures", verbose=True) -> dict:
    if not jax.config.jax_enable_x64:
        raise RuntimeError("the study needs float64: jax.config.update('jax_enable_x64', True)")
    out = Path(out)
    env = environment()
    uni, maps = uniform_light(cfg, verbose)
    ref = uni["wide"].pop("_values")["reference"]
    result = {"environment": env, "config": dataclasses.asdict(cfg), "uniform": uni}
    if cfg.ibl:
        result["ibl"] = ibl_renders(verbose, held_out=cfg.held_out)
    result["kernels"] = kernel_rows(cfg, ref, verbose)
    text = write_report(out, "improved", result, markdown)
    plot_kernel_pareto(result, out)
    plot_fig7(maps, cfg, out / "improved_figure7.png")
    if verbose:
        print(text)
    return result


def plot_kernel_pareto(result, out) -> None:
    """``improved_pareto.png`` of a study's `result` (its "kernels" rows): the uniform-light
    kernels given the lobe's moments, no map; the cost of each method under a map against
    `filtered` is ``method_cost.md`` (`benchmarks.method_cost`), said in the title."""
    env = result["environment"]
    render_kernel_pareto(result["kernels"], Path(out) / "improved_pareto.png",
                "Real-time kernels, uniform light (no map; the lobe's moments given): error "
                "on the wide grid (4 materials × d ≤ 1000 nm × θ_o ≤ 88° × α ∈ [0.01, 0.9]) "
                f"against float32 cost per shading point ({env['cpu_count']} shared CPUs, "
                f"{env['date'][:10]}).\nThese are kernel costs; a method's cost a shading point "
                "under an environment map against filtered: figures/method_cost.md")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures")
    p.add_argument("--quick", action="store_true", help="small grids (smoke test)")
    p.add_argument("--no-ibl", action="store_true", help="skip the IBL renders")
    p.add_argument("--no-held-out", action="store_true",
                   help="skip the held-out sun maps (their references take a few minutes)")
    p.add_argument("--replot", action="store_true",
                   help="only redraw improved_pareto.png from out/improved.json")
    p.add_argument("--floor", action="store_true",
                   help="only the IBL floor of split-sum methods (`ibl_floor`, ≈ 10 min): "
                        "writes improved_ibl_floor.json")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    if args.replot:
        import json

        plot_kernel_pareto(json.loads((Path(args.out) / "improved.json").read_text()),
                           args.out)
        return 0
    if args.floor:
        write_json(Path(args.out) / "improved_ibl_floor.json", jsonable(ibl_floor()))
        return 0
    cfg = StudyConfig.quick() if args.quick else StudyConfig()
    if args.no_ibl:
        cfg = dataclasses.replace(cfg, ibl=False)
    if args.no_held_out:
        cfg = dataclasses.replace(cfg, held_out=False)
    run(cfg, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
