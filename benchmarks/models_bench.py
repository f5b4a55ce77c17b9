r"""`python -m benchmarks.bench --suite models`: classic lobes with a thin film, what an artist's
Schlick tint and the real-time film methods lose against the exact film, and their cost.

Three measurements (`run_models_bench`; the default run writes figures/models.json, .md, .png):

1. *Schlick tint* (uniform light, `material_patch_radiance`): for each lobe family — GGX +
   height-correlated Smith, Cook–Torrance (Beckmann + V-cavity), Blinn–Phong (normalised, its
   V-cavity masking, s = 2/α² − 2, Walter's α ↔ s) over a Lambert term, Ashikhmin–Shirley
   (isotropic n_u = n_v = 2/α² − 2, their masking and their coupled diffuse term) — and each
   film, the CIEDE2000 between the material with the film's exact Fresnel and the same
   material with Schlick's F₀ + (1 − F₀)(1 − c)⁵, F₀ = the film's exact band reflectance at
   normal incidence (what a tint picked at normal view reproduces). Diffuse albedo 0.05.
2. *Film methods* (uniform light, `patch_radiance`, GGX): khr, ideal, filtered, improved
   against the exact reference on the same (θ_o, α) grid for every film, and on the Figure 7
   grids (d = 600 nm over θ_o × √α; α = 0.25 over θ_o × d ∈ [0, 1000] nm).
3. *Every shipped map* at low resolution (each box-filtered to 32 × 64, α = 0.3, 16 × 32
   shading points on the camera-facing hemisphere of a sphere, view +x): the film methods
   of `envmap_radiance` (khr, ideal, filtered, improved; the suns are not split off) and the
   Schlick tint
   (`material_envmap_radiance`, RGB light × tint bands per channel) against the exact film
   (`material_envmap_radiance`, cross bands R_jk = `envmap_radiance(method="reference")`).

ΔE: CIEDE2000 with the perfect mirror as white (`colorimetry.delta_e2000`) between band values, the
convention of every study (SPEC §7); `khr` computes linear Rec. 709 (SPEC §10) and returns it in the
bands like every method (`colorimetry.rec709_to_bands`, CAT02 from D65 to the mirror's white), so
its rows are `colorimetry.delta_e2000_rec709` of its RGB and compare in the same CIELAB as every
other row. Statistics over θ_o ∈ [0°, 85°] and α ∈ {0.1, 0.3, 0.6}: mean and 95th percentile. Cost:
the warm time of one call divided by its shading points (median of `repeats`; wall clock on a shared
machine, noisy).

Example (the configuration of the smoke test; the run itself takes seconds to minutes):
    >>> from benchmarks.models_bench import FAMILIES, ModelsConfig
    >>> cfg = ModelsConfig.quick()
    >>> cfg.families, cfg.alphas, len(FAMILIES)
    (('ggx',), (0.3,), 4)
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax
import numpy as np

from thinfilm_jax.brdf import material as M
from thinfilm_jax.core.film import Film
from thinfilm_jax.shading.envmap import SHIPPED, downsample, load_envmap
from thinfilm_jax.shading.ibl import envmap_radiance
from thinfilm_jax.shading.material_ibl import material_envmap_radiance
from thinfilm_jax.shading.material_patch import material_patch_radiance
from thinfilm_jax.shading.patch import patch_radiance
from thinfilm_jax.shading.prefilter import prefilter_envmap
from thinfilm_jax.spectral.colorimetry import bands_to_srgb, delta_e2000
from thinfilm_jax.spectral.reflectance import rgb_reflectance
from ._timing import environment, jsonable, time_call

FILMS = {  # name: (d nm, η₂, η₃, κ₃)
    "fig7 600 nm": (600.0, 1.3, 2.0, 0.5),  # Kneiphof et al. 2019 Figure 7, metal base
    "soap 1.33 on 1.5": (400.0, 1.33, 1.5, 0.0),  # soap-like film on a dielectric
    "thin 150 nm": (150.0, 1.3, 2.0, 0.5),
    "thick 1200 nm": (1200.0, 1.3, 2.0, 0.5),
}
FAMILIES = ("ggx", "cook_torrance", "blinn_phong", "ashikhmin_shirley")
FAMILY_LABELS = {"ggx": "GGX + Smith", "cook_torrance": "Cook–Torrance (Beckmann + V-cavity)",
                 "blinn_phong": "Blinn–Phong + Lambert", "ashikhmin_shirley":
                 "Ashikhmin–Shirley (+ AS diffuse)"}
FILM_METHODS = ("khr", "ideal", "filtered", "improved")
IBL_METHODS = ("khr", "ideal", "filtered", "improved")
DIFFUSE_ALBEDO = 0.05


@dataclasses.dataclass(frozen=True)
class ModelsConfig:
    """Sizes of one run (`quick()` for the smoke test)."""

    families: tuple = FAMILIES
    films: tuple = tuple(FILMS)
    alphas: tuple = (0.1, 0.3, 0.6)
    n_theta: int = 18  # θ_o ∈ [0°, 85°]
    fig7_theta: int = 24
    fig7_sqrt_alpha: int = 10
    fig7_d: int = 21
    map_names: tuple = tuple(SHIPPED)  # every shipped map (the improved rows without sun split)
    map_height: int = 32
    sphere: tuple = (16, 32)
    ibl_alpha: float = 0.3
    repeats: int = 2
    film_methods: tuple = FILM_METHODS
    ibl_methods: tuple = IBL_METHODS

    @classmethod
    def quick(cls) -> ModelsConfig:
        return cls(families=("ggx",), films=("fig7 600 nm",), alphas=(0.3,),
                   n_theta=4, fig7_theta=0, map_height=8, sphere=(3, 4), repeats=1,
                   film_methods=("khr", "improved"), ibl_methods=("improved",),
                   map_names=("venice_sunset",))


def _film(name):
    d, e2, e3, k3 = FILMS[name]
    return Film(d, e2, e3, k3)


def _exponent(alpha):
    return 2.0 / alpha**2 - 2.0


def material_for(family: str, alpha: float, fresnel: M.Fresnel) -> M.Material:
    """The lobe family at roughness α (module docstring) with the given Fresnel term."""
    if family == "ggx":
        return M.Material(M.ggx_lobe(alpha), fresnel, M.no_diffuse())
    if family == "cook_torrance":
        return M.Material(M.beckmann_lobe(alpha, "v_cavity"), fresnel, M.no_diffuse())
    if family == "blinn_phong":
        return M.Material(M.blinn_phong_lobe(_exponent(alpha)), fresnel,
                          M.lambert_diffuse(DIFFUSE_ALBEDO))
    e = _exponent(alpha)
    return M.Material(M.ashikhmin_shirley_lobe(e, e), fresnel,
                      M.ashikhmin_shirley_diffuse(DIFFUSE_ALBEDO))


def tint_f0(film: Film) -> np.ndarray:
    """F₀ of the Schlick tint: the film's exact band reflectance at normal incidence."""
    return np.clip(np.asarray(rgb_reflectance(film, 1.0)), 0.0, 1.0)


def _stats(de) -> dict:
    de = np.asarray(de, float).reshape(-1)
    return {"dE2000_mean": float(np.mean(de)), "dE2000_p95": float(np.percentile(de, 95)),
            "dE2000_max": float(np.max(de)), "n": int(de.size)}


def delta_e(method: str, test, ref) -> np.ndarray:
    """ΔE₀₀ of `method`'s values against the reference's bands (module docstring): every
    method returns the bands (`khr` its Rec. 709 taken to them), so `delta_e2000` for all."""
    return delta_e2000(test, ref)


def _timed(fn, args, repeats, points):
    out, t = time_call(fn, args, repeats)
    return np.asarray(out), t.warm_s / max(points, 1), t.compile_s


# ----------------------------------------------------------------------------- 1. Schlick tint
def schlick_tint_rows(cfg: ModelsConfig, log=print):
    theta = np.radians(np.linspace(0.0, 85.0, cfg.n_theta))
    rows, keep = [], {}
    for fam in cfg.families:
        for fname in cfg.films:
            film = _film(fname)
            f_exact = M.film_fresnel(film)
            f_tint = M.schlick_fresnel(tint_f0(film))
            des, cost = [], {"exact": 0.0, "schlick": 0.0}
            for a in cfg.alphas:
                ex, c_ex, _ = _timed(lambda t, m=material_for(fam, a, f_exact):
                                     material_patch_radiance(m, t), (theta,), cfg.repeats,
                                     theta.size)
                ti, c_ti, _ = _timed(lambda t, m=material_for(fam, a, f_tint):
                                     material_patch_radiance(m, t), (theta,), cfg.repeats,
                                     theta.size)
                des.append(delta_e2000(ti, ex))
                cost["exact"] += c_ex / len(cfg.alphas)
                cost["schlick"] += c_ti / len(cfg.alphas)
                keep[(fam, fname, a)] = (ex, ti)
            rows.append({"family": fam, "film": fname, **_stats(des),
                         "warm_s_per_point_exact": cost["exact"],
                         "warm_s_per_point_schlick": cost["schlick"]})
            log(f"tint {fam:18s} {fname:18s} ΔE mean {rows[-1]['dE2000_mean']:.2f}")
    return rows, keep, theta


# ----------------------------------------------------------------------------- 2. film methods
def film_method_rows(cfg: ModelsConfig, log=print):
    theta = np.radians(np.linspace(0.0, 85.0, cfg.n_theta))
    tt, aa = np.meshgrid(theta, np.asarray(cfg.alphas), indexing="ij")
    grids = {}
    for fname in cfg.films:
        grids[fname] = (_film(fname), tt, aa)
    if cfg.fig7_theta:  # the Figure 7 grids (0: skipped, the smoke test)
        t7 = np.radians(np.linspace(0.0, 85.0, cfg.fig7_theta))
        sa = np.linspace(0.1, 1.0, cfg.fig7_sqrt_alpha)
        a, b = np.meshgrid(t7, sa**2, indexing="ij")
        f7 = _film("fig7 600 nm")
        grids["Figure 7 (a–d): d = 600 nm, θ_o × √α"] = (f7, a, b)
        d = np.linspace(0.0, 1000.0, cfg.fig7_d)
        a, dd = np.meshgrid(t7, d, indexing="ij")
        grids["Figure 7 (e–h): α = 0.25, θ_o × d"] = (f7._replace(thickness=dd), a,
                                                       np.full_like(a, 0.25))
    rows, keep = [], {}
    for gname, (film, th, al) in grids.items():
        npts = th.size
        film = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x, float), th.shape), film)
        ref, c_ref, _ = _timed(lambda f, t, x: patch_radiance(f, t, x, method="reference"),
                               (film, th, al), cfg.repeats, npts)
        rows.append({"grid": gname, "method": "reference", "dE2000_mean": 0.0,
                     "dE2000_p95": 0.0, "dE2000_max": 0.0, "n": npts,
                     "warm_s_per_point": c_ref})
        keep[(gname, "reference")] = ref
        for m in cfg.film_methods:
            out, c, _ = _timed(lambda f, t, x, m=m: patch_radiance(f, t, x, method=m),
                               (film, th, al), cfg.repeats, npts)
            keep[(gname, m)] = out
            rows.append({"grid": gname, "method": m, **_stats(delta_e(m, out, ref)),
                         "warm_s_per_point": c})
            log(f"method {gname:40s} {m:9s} ΔE mean {rows[-1]['dE2000_mean']:.2f}")
    return rows, keep


# ----------------------------------------------------------------------------- 3. one map
def sphere_points(n_polar: int, n_azimuth: int):
    """Normals on the camera-facing hemisphere (angle to the view +x in (0°, 85°]) and the
    view, (P, 3) each."""
    g = np.radians(np.linspace(85.0 / n_polar, 85.0, n_polar))
    p = (np.arange(n_azimuth) + 0.5) * 2 * np.pi / n_azimuth
    g, p = np.meshgrid(g, p, indexing="ij")
    n = np.stack([np.cos(g), np.sin(g) * np.cos(p), np.sin(g) * np.sin(p)], -1).reshape(-1, 3)
    return n, np.broadcast_to(np.array([1.0, 0.0, 0.0]), n.shape).copy()


def ibl_rows(cfg: ModelsConfig, log=print):
    rows, keep = [], {}
    for map_name in cfg.map_names:
        env = load_envmap(SHIPPED[map_name])
        env = downsample(env, env.shape[0] // cfg.map_height)
        pref = prefilter_envmap(env, resolution=env.shape)
        n, v = sphere_points(*cfg.sphere)
        a = cfg.ibl_alpha
        for fname in cfg.films:
            film = _film(fname)
            exact_mat = material_for("ggx", a, M.film_fresnel(film))
            tint_mat = material_for("ggx", a, M.schlick_fresnel(tint_f0(film)))
            ref, c_ref, _ = _timed(
                lambda nn, vv: material_envmap_radiance(exact_mat, nn, vv, env), (n, v), 1,
                len(n))
            keep[(map_name, fname, "reference")] = ref
            rows.append({"map": map_name, "film": fname,
                         "method": "reference (material_envmap_radiance)", "dE2000_mean": 0.0,
                         "dE2000_p95": 0.0, "dE2000_max": 0.0, "n": len(n),
                         "warm_s_per_point": c_ref})
            tests = {"schlick tint (material_envmap_radiance)":
                     lambda nn, vv: material_envmap_radiance(tint_mat, nn, vv, env)}
            for m in cfg.ibl_methods:
                tests[m] = (lambda nn, vv, m=m: envmap_radiance(film, a, nn, vv, pref, method=m))
            for name, fn in tests.items():
                out, c, _ = _timed(fn, (n, v), cfg.repeats if "schlick" not in name else 1,
                                   len(n))
                keep[(map_name, fname, name)] = out
                rows.append({"map": map_name, "film": fname, "method": name,
                             **_stats(delta_e(name, out, ref)), "warm_s_per_point": c})
                log(f"ibl {map_name:14s} {fname:18s} {name:40s} "
                    f"ΔE mean {rows[-1]['dE2000_mean']:.2f}")
    return rows, keep, (env.shape, cfg.sphere, a)


# ----------------------------------------------------------------------------- outputs
def _table(rows, keys, heads):
    out = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for r in rows:
        cells = []
        for k in keys:
            x = r[k]
            cells.append(f"{x:.3g}" if isinstance(x, float) else str(x))
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def write_markdown(result: dict, path: Path):
    env = result["environment"]
    lines = [
        "# Classic lobes with a thin film: Schlick tint and real-time methods against the exact "
        "film", "",
        f"Generated by `python -m benchmarks.bench --suite models` ({result['config']['name']}); "
        f"{env['date']}, {env['cpu_count']} CPUs, load average {env['load_average']} "
        "(timings are wall clock on a shared machine: noisy). ΔE: CIEDE2000, mirror white; "
        "statistics over θ_o ∈ [0°, 85°] and the listed α. Cost: warm seconds per shading point.",
        "", "## 1. Schlick tint (F₀ = the film's normal-incidence bands) against the exact film "
        f"Fresnel, uniform light, α ∈ {list(result['config']['alphas'])}", "",
        _table(result["schlick_tint"], ["family", "film", "dE2000_mean", "dE2000_p95",
                                        "dE2000_max", "warm_s_per_point_exact",
                                        "warm_s_per_point_schlick"],
               ["lobe family", "film", "ΔE mean", "ΔE p95", "ΔE max", "s/pt exact",
                "s/pt Schlick"]),
        "", "## 2. Film methods against `patch_radiance(method=\"reference\")` (GGX, uniform "
        "light)", "",
        _table(result["film_methods"], ["grid", "method", "dE2000_mean", "dE2000_p95",
                                        "dE2000_max", "warm_s_per_point"],
               ["grid", "method", "ΔE mean", "ΔE p95", "ΔE max", "s/pt"]),
        "", "`khr` computes linear Rec. 709 (SPEC §10) and returns it in the reference's bands "
        "(`colorimetry.rec709_to_bands`, CAT02 from D65 to the mirror's white): its rows are "
        "`colorimetry.delta_e2000_rec709` of its RGB, compared like every other row.", "",
        f"## 3. Under the shipped maps ({', '.join(result['config']['map_names'])}) at "
        f"{result['ibl']['map_shape']} texels, {result['ibl']['sphere']} sphere points, GGX "
        f"α = {result['ibl']['alpha']} (`improved` without the suns split off)", "",
        _table(result["ibl"]["rows"], ["map", "film", "method", "dE2000_mean", "dE2000_p95",
                                       "dE2000_max", "warm_s_per_point"],
               ["map", "film", "method", "ΔE mean", "ΔE p95", "ΔE max", "s/pt"]),
        "", "The reference is the film's exact texel rule with cross bands R_jk (equal to "
        "`envmap_radiance(method=\"reference\")`, tests/shading/test_material_integrators.py); the "
        "Schlick tint multiplies each RGB channel of the map by its tint band.", ""]
    path.write_text("\n".join(lines), encoding="utf-8")


def write_figure(result, tint_keep, theta, method_keep, path: Path):
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    tint = result["schlick_tint"]
    fams = list(dict.fromkeys(r["family"] for r in tint))
    films = list(dict.fromkeys(r["film"] for r in tint))
    fig = plt.figure(figsize=(13, 8.5), constrained_layout=True)
    gs = fig.add_gridspec(2, 2)
    ax = fig.add_subplot(gs[0, 0])
    w = 0.8 / max(len(films), 1)
    for i, f in enumerate(films):
        vals = [next(r["dE2000_mean"] for r in tint if r["family"] == fa and r["film"] == f)
                for fa in fams]
        p95 = [next(r["dE2000_p95"] for r in tint if r["family"] == fa and r["film"] == f)
               for fa in fams]
        x = np.arange(len(fams)) + (i - (len(films) - 1) / 2) * w
        ax.bar(x, vals, w, label=f)
        ax.scatter(x, p95, marker="_", color="k", s=80, zorder=3)
    short = {"ggx": "GGX + Smith", "cook_torrance": "Cook–Torrance", "blinn_phong":
             "Blinn–Phong\n+ Lambert", "ashikhmin_shirley": "Ashikhmin–Shirley\n+ AS diffuse"}
    ax.set_xticks(np.arange(len(fams)), [short[f] for f in fams], fontsize=9)
    ax.set_ylabel("CIEDE2000 ΔE (bar: mean, tick: p95)")
    ax.set_title("Schlick tint (F₀ = film at normal incidence) vs exact film Fresnel")
    ax.legend(fontsize=8)
    ax = fig.add_subplot(gs[0, 1])
    fm = [r for r in result["film_methods"] if r["method"] != "reference"]
    grids = list(dict.fromkeys(r["grid"] for r in fm))
    meths = list(dict.fromkeys(r["method"] for r in fm))
    w = 0.8 / max(len(grids), 1)
    for i, g in enumerate(grids):
        vals = [next(r["dE2000_mean"] for r in fm if r["grid"] == g and r["method"] == m)
                for m in meths]
        ax.bar(np.arange(len(meths)) + (i - (len(grids) - 1) / 2) * w, vals, w, label=g)
    ax.set_xticks(np.arange(len(meths)), meths)
    ax.set_ylabel("CIEDE2000 ΔE (mean)")
    ax.set_title("Film methods vs exact reference, GGX, uniform light")
    ax.legend(fontsize=7)
    # swatches: exact vs Schlick tint vs khr/improved along θ_o for the Figure 7 film
    ax = fig.add_subplot(gs[1, :])
    fam, fname = fams[0], films[0]
    alphas = sorted({k[2] for k in tint_keep if k[0] == fam and k[1] == fname})
    strips, labels = [], []
    for a in alphas:
        ex, ti = tint_keep[(fam, fname, a)]
        strips += [bands_to_srgb(ex, exposure=1.5), bands_to_srgb(ti, exposure=1.5)]
        labels += [f"exact film, α = {a}", f"Schlick tint, α = {a}"]
    ax.imshow(np.stack(strips), aspect="auto", interpolation="nearest",
              extent=(np.degrees(theta[0]), np.degrees(theta[-1]), len(strips), 0))
    ax.set_yticks(np.arange(len(strips)) + 0.5, labels, fontsize=8)
    ax.set_xlabel("view angle θ_o (degrees)")
    ax.set_title(f"{FAMILY_LABELS[fam]}, film {fname}: sRGB (exposure 1.5) under uniform "
                 "white light")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_models_bench(out="figures", quick: bool = False, cfg: ModelsConfig | None = None,
                     verbose: bool = True) -> dict:
    """Run the three measurements, write models.json / .md / .png under `out`; the result."""
    cfg = cfg or (ModelsConfig.quick() if quick else ModelsConfig())
    log = print if verbose else (lambda *_: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tint, tint_keep, theta = schlick_tint_rows(cfg, log)
    methods, method_keep = film_method_rows(cfg, log)
    ibl, _, (shape, sphere, a) = ibl_rows(cfg, log)
    result = {"config": {"name": "quick" if quick else "full", **dataclasses.asdict(cfg)},
              "environment": environment(), "schlick_tint": tint, "film_methods": methods,
              "ibl": {"map_shape": list(shape), "sphere": list(sphere), "alpha": a,
                      "rows": ibl},
              "total_s": time.perf_counter() - t0}
    (out / "models.json").write_text(json.dumps(jsonable(result), indent=1), encoding="utf-8")
    write_markdown(result, out / "models.md")
    write_figure(result, tint_keep, theta, method_keep, out / "models.png")
    log(f"models bench: {result['total_s']:.0f} s; wrote {out}/models.json, .md, .png")
    return result
