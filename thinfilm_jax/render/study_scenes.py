"""Sphere renders under environment maps (Kneiphof et al. 2019, Figures 3–6): `thinfilm-jax render`.

Scenes (SPEC §9):
* ``fig4`` — Figure 4: α = 0.25, d = 600 nm, η₂ = 1.2, η₃ = 2.0, κ₃ = 0, under every map
  (default: the four shipped maps, `envmap.SHIPPED`);
* ``fig3`` — Figure 3's roughness sweep: η₂ = 1.3, η₃ = 2.0 + 0.5i, d = 650 nm,
  α ∈ `alphas`, under the first map;
* ``varying`` — Figures 5/6-style spatially varying thickness: a smooth thickness field
  d(n) ∈ [250, 850] nm (sum of sines over the normal) on the ``fig4`` material, every map;
* ``carpaint`` (not a default scene) — the example car paints (`carpaint.PAINTS`: metallic,
  pearlescent, plain) under every map, columns `PAINT_METHODS`: the paint's exact reference
  (`carpaint_ibl.paint_envmap_radiance`) and Kneiphof & Klein 2022's colour table
  (`colour_table.prefilter_colour`, rank 1, `PAINT_TABLE` size, the colour-table study's,
  built per paint × map; its build is timed apart and its points/s are warm), in the default bands
  of the paints' colour tables.

Camera: orthographic, looking horizontally-down (15°) at a unit sphere, its azimuth chosen
so that the brightest texel of the map is reflected off-centre (deterministic). Behind the
sphere the map itself is shown (linear RGB). Every method shades the same pixels
(`envmap_methods()`; default columns `DEFAULT_METHODS`): reference (texel-space quadrature,
float64), mc (Monte Carlo), and the real-time ideal, filtered and improved (prefiltered map,
float64 here; the float32 frame timings are in the benchmark). ideal and filtered read the map as it is (the
published methods); improved reads it with its suns split off and shaded apart
(`prefilter_envmap(sources=ibl.DEFAULT_SOURCES)`, `thinfilm_jax.shading.sources`), as
`envmap_radiance(method="improved")` does with a plain map. khr (glTF `KHR_materials_iridescence`,
not a default column) computes linear Rec. 709 RGB and returns it in the bands of the
render's observer like every method (`envmap_radiance`: `colorimetry.rec709_to_bands`), so its ΔE is
`colorimetry.delta_e2000_rec709`'s of its RGB, the convention of every study. Display: exposure ×
radiance, bands → display sRGB (`colorimetry.bands_to_srgb`: linear Rec. 709 with the mirror white
adapted to D65, clipped, sRGB-encoded); the exposure maps the reference's 99th luminance percentile
to 0.9 unless given. Errors: CIEDE2000 per pixel of exposure-scaled values against the reference
(`colorimetry.delta_e2000`, mirror white Y = 1), mean and p95 per panel.

Example (unit normals over the frame; the thickness texture stays in [250, 850] nm):
    >>> import numpy as np
    >>> from thinfilm_jax.render.study_scenes import camera, sphere, thickness_field
    >>> mask, n = sphere(16, *camera(0.3, 15.0))
    >>> mask.shape, n.shape, bool(np.allclose(np.linalg.norm(n, axis=-1), 1.0))
    ((16, 16), (16, 16, 3), True)
    >>> d = thickness_field(n)
    >>> bool(250.0 <= d.min() and d.max() <= 850.0)
    True
"""

from __future__ import annotations

import dataclasses
import functools
import textwrap
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np

from ..core.files import atomic_write, write_json
from ..optics.airy import choose_arithmetic
from ..spectral.colorimetry import bands_to_srgb, bands_to_xyz, delta_e2000
from ..spectral.spectra import DEFAULT_OBSERVER
from ..shading.envmap import SHIPPED, downsample, load_envmap, lookup_bilinear, luminance_weights
from ..core.film import Film
from ..core.image import srgb_encoding
from ..core.methods import implementation
from ..core.methods import names as method_names
from ..shading.ibl import REALTIME_OPTIONS, auto_subdivisions, envmap_radiance
from ..shading.ibl_reference import resample_factor
from ..shading.prefilter import prefilter_envmap
from ..core.sharding import batch_mesh, map_sharded, to_host
from ..brdf.carpaint import PAINTS
from ..shading.carpaint_ibl import paint_envmap_radiance
from ..shading.colour_table import colour_table_radiance, prefilter_colour

__all__ = [
    "PAINT_TABLE",
    "PAINT_METHODS",
    "envmap_methods",
    "DEFAULT_METHODS",
    "RenderConfig",
    "camera",
    "sphere",
    "thickness_field",
    "map_label",
    "scene_setups",
    "view_azimuth",
    "shade_block",
    "method_map",
    "render_one",
    "summarise",
    "summary_table",
    "PANEL_DPI",
    "panel_inches",
    "fit_title",
    "run_render",
]

#: the paints' table size: 8 × 16 directions ω_r, 8 views, 4 azimuths (their build evaluates
#: the paint's brightness and colour at every texel node for each configuration); also the
#: colour-table study's (``benchmarks/colour_table_study.py``)
PAINT_TABLE = dict(resolution=(8, 16), n_view=8, n_azimuth=4)

SCENES = ("fig4", "fig3", "varying")  # the default scenes (films)
ALL_SCENES = SCENES + ("carpaint",)
PAINT_METHODS = ("reference", "colour_table")  # the columns of the car-paint scene
DEFAULT_METHODS = ("reference", "ideal", "filtered", "improved")


def envmap_methods() -> tuple[str, ...]:
    """Every `envmap_radiance` method of the registry (core/methods.py) that shades a film
    varying per pixel, as the registry holds them when called (a method registered at run time
    included): those reading a map or its prefiltered form; "colour_table" tabulates one
    homogeneous material (the car-paint scene's column)."""
    return tuple(m for m in method_names("envmap")
                 if implementation(m).envmap_kind in ("realtime", "exact"))


@dataclass(frozen=True)
class RenderConfig:
    envmaps: tuple[str, ...] = tuple(SHIPPED)
    scenes: tuple[str, ...] = SCENES
    methods: tuple[str, ...] = DEFAULT_METHODS
    resolution: int = 64
    alphas: tuple[float, ...] = (0.05, 0.15, 0.3, 0.6)  # fig3
    exposure: float | None = None
    observer: str = "stiles_burch_1959_10"
    elevation_deg: float = 15.0
    ldr_srgb: bool = False  # 8-/16-bit map files: sRGB-decoded, not refused (load_envmap)

    def __post_init__(self):
        bad = [m for m in self.methods if m not in envmap_methods()]
        if bad:
            raise ValueError(f"unknown method(s) {bad}; expected some of {envmap_methods()}")
        # one column per method: a repeated one would be its own reference (no error)
        object.__setattr__(self, "methods", tuple(dict.fromkeys(self.methods)))


def camera(view_azimuth: float, elevation_deg: float):
    """(ω_o toward the eye, right, up) of the orthographic camera."""
    el = np.deg2rad(elevation_deg)
    wo = np.array([np.cos(el) * np.cos(view_azimuth), np.cos(el) * np.sin(view_azimuth),
                   np.sin(el)])
    right = np.cross(-wo, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return wo, right, np.cross(right, -wo)


def sphere(resolution: int, wo, right, up):
    """Pixel mask (R, R) and unit normals (R, R, 3) of a unit sphere filling the frame."""
    c = (np.arange(resolution) + 0.5) / resolution * 2 - 1
    x, y = np.meshgrid(c, -c)
    r2 = x * x + y * y
    mask = r2 < 0.98
    z = np.sqrt(np.clip(1 - r2, 0, 1))
    n = x[..., None] * right + y[..., None] * up + z[..., None] * wo
    return mask, n / np.linalg.norm(n, axis=-1, keepdims=True)


def thickness_field(n):
    """A smooth thickness texture on the sphere, d ∈ [250, 850] nm (soap-film-like swirls)."""
    s = (np.sin(3.1 * n[..., 0] + 1.3 * n[..., 2] + 0.4) * np.cos(2.3 * n[..., 1] - 0.7)
         + 0.5 * np.sin(5.0 * n[..., 2] + 2.0 * n[..., 0]))
    return 550.0 + 200.0 * s  # |s| ≤ 1.5


def map_label(name) -> str:
    """A map's name for labels: a shipped name as is, a file by its stem (not its path)."""
    name = str(name)
    return name if name in SHIPPED else Path(name).stem


def scene_setups(cfg: RenderConfig):
    """[(scene, label, envmap name, Film-maker(normals), α)]."""
    fig4 = (1.2, 2.0, 0.0)
    out = []
    for scene in cfg.scenes:
        if scene == "fig4":
            out += [(scene, f"α=0.25, d=600 nm | {map_label(m)}", m,
                     lambda n: Film(600.0, *fig4), 0.25) for m in cfg.envmaps]
        elif scene == "fig3":
            out += [(scene, f"α={a:g} | {map_label(cfg.envmaps[0])}", cfg.envmaps[0],
                     lambda n: Film(650.0, 1.3, 2.0, 0.5), a) for a in cfg.alphas]
        elif scene == "varying":
            out += [(scene, f"d(x) ∈ [250, 850] nm | {map_label(m)}", m,
                     lambda n: Film(thickness_field(n), *fig4), 0.25) for m in cfg.envmaps]
        elif scene == "carpaint":
            out += [(scene, f"{p} paint | {map_label(m)}", m, p, None)
                    for m in cfg.envmaps for p in PAINTS]
        else:
            raise ValueError(f"unknown scene {scene!r}; expected one of {ALL_SCENES}")
    return out


def view_azimuth(env) -> float:
    lum = np.asarray(env.radiance) @ luminance_weights()
    _, j = np.unravel_index(np.argmax(lum), lum.shape)
    phi_sun = (j + 0.5) / lum.shape[1] * 2 * np.pi
    return float(phi_sun + np.deg2rad(150.0))  # the sun behind the camera, off to one side


def shade_block(film, normal, alpha, view, envmap, *, method, observer, options, subdivisions):
    """One block of shading points (the function `map_sharded` runs on every device)."""
    return envmap_radiance(film, alpha, normal, view, envmap, method=method, observer=observer,
                           options=options, subdivisions=subdivisions)


def _shader(cache: dict, devices, method: str, observer: str, film, alpha, env):
    """The sharded shading program of `method`, compiled once per static configuration.

    Film and normals are split across the devices; α, the view and the (prefiltered) map
    are replicated. What `envmap_radiance` decides from concrete values is decided here,
    before tracing: the arithmetic of the film and the reference's subdivisions.
    """
    options = REALTIME_OPTIONS._replace(arithmetic=choose_arithmetic(film, "auto"))
    subdivisions = auto_subdivisions(env.shape[0], alpha) if method == "reference" else None
    mesh = batch_mesh(devices)
    key = ("program", mesh, method, observer, options, subdivisions)
    if key not in cache:
        cache[key] = map_sharded(functools.partial(
            shade_block, method=method, observer=observer, options=options,
            subdivisions=subdivisions), in_axes=(0, 0, None, None, None), devices=mesh)
    return cache[key]


def _reference_map(cache: dict, name, env, alpha):
    """The map the reference integrates: a map taller than 256 rows resampled by
    `ibl_reference.resample_factor` for this α (solid-angle-exact `downsample`), with a
    warning, as `envmap_radiance` does for a concrete α."""
    f = resample_factor(env.shape[0], float(np.min(alpha)), 256)
    if f == 1:
        return env
    key = ("reference map", name, f)
    if key not in cache:
        warnings.warn(f"render: the reference integrates {map_label(name)} resampled by {f} "
                      f"to {env.shape[0] // f} × {env.shape[1] // f} (texel ≤ α/8)",
                      stacklevel=2)
        cache[key] = downsample(env, f)
    return cache[key]


def method_map(cache: dict, name, method: str, observer: str):
    """What `method` reads for the map `name`, built once per map and kept in `cache`: the
    `EnvMap` (reference, mc), the prefiltered map as it is (ideal, filtered), or prefiltered
    with up to `ibl.DEFAULT_SOURCES` suns split off and shaded apart (improved)."""
    films = envmap_methods()
    if method not in films:
        raise ValueError(f"unknown method {method!r}; expected one of {films}")
    if name not in cache:
        cache[name] = {"env": load_envmap(name)}
    maps = cache[name]
    impl = implementation(method)  # the registry's object: what its map path reads
    kind = ("env" if impl.envmap_kind == "exact" else
            f"sources={impl.default_sources}" if impl.default_sources else "plain")
    if kind not in maps:
        maps[kind] = prefilter_envmap(maps["env"], observer=observer,
                                      sources=impl.default_sources)
    return maps[kind]


def render_paint(setup, cfg: RenderConfig, cache: dict):
    """One sphere of car paint: the exact reference and the colour table (`PAINT_METHODS`)."""
    scene, label, name, paint_name, _ = setup
    env = method_map(cache, name, "reference", cfg.observer)
    wo, right, up = camera(view_azimuth(env), cfg.elevation_deg)
    mask, n = sphere(cfg.resolution, wo, right, up)
    pts = n[mask]
    paint = PAINTS[paint_name]()
    out = {"label": label, "scene": scene, "envmap": map_label(name), "alpha": None,
           "mask": mask, "times": {}, "values": {}}
    t0 = time.perf_counter()
    out["values"]["reference"] = np.asarray(paint_envmap_radiance(paint, pts, wo, env))
    out["times"]["reference"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    table = prefilter_colour(env, paint, **PAINT_TABLE)
    out["prefilter_times"] = {"colour_table": time.perf_counter() - t0}  # the build, apart
    for _ in range(2):  # the second call is the warm one, like the real-time methods'
        t0 = time.perf_counter()
        out["values"]["colour_table"] = np.asarray(colour_table_radiance(table, pts, wo))
        out["times"]["colour_table"] = time.perf_counter() - t0
    d = (np.arange(cfg.resolution) + 0.5) / cfg.resolution * 2 - 1
    bx, by = np.meshgrid(d, -d)
    bg_dir = -wo + 0.6 * (bx[..., None] * right + by[..., None] * up)
    bg_dir /= np.linalg.norm(bg_dir, axis=-1, keepdims=True)
    out["background"] = np.asarray(lookup_bilinear(env.radiance, bg_dir))
    out["film_thickness"] = np.zeros(int(mask.sum()))
    return out


def render_one(setup, cfg: RenderConfig, cache: dict, devices=None):
    """Shade one sphere with every method; the shading points are split across `devices`
    (`thinfilm_jax.core.sharding.map_sharded`: None = every device, an int k = the first k)."""
    scene, label, name, make_film, alpha = setup
    if scene == "carpaint":
        return render_paint(setup, cfg, cache)
    env = method_map(cache, name, "reference", cfg.observer)
    wo, right, up = camera(view_azimuth(env), cfg.elevation_deg)
    mask, n = sphere(cfg.resolution, wo, right, up)
    pts = n[mask]
    film = make_film(pts)
    out = {"label": label, "scene": scene, "envmap": map_label(name), "alpha": alpha,
           "mask": mask,
           "times": {}, "values": {}}
    for method in cfg.methods:
        src = method_map(cache, name, method, cfg.observer)
        exact = implementation(method).envmap_kind == "exact"
        if method == "reference":  # α is traced inside the sharded program: resample here
            src = _reference_map(cache, name, env, alpha)
        shade = _shader(cache, devices, method, cfg.observer, film, alpha, src)
        for _ in range(1 if exact else 2):  # real time: the second call is the warm one
            t0 = time.perf_counter()
            vals = to_host(shade(film, pts, alpha, wo, src))
            out["times"][method] = time.perf_counter() - t0
        out["values"][method] = np.asarray(vals)  # every method in the observer's bands
    d = (np.arange(cfg.resolution) + 0.5) / cfg.resolution * 2 - 1
    bx, by = np.meshgrid(d, -d)
    bg_dir = -wo + 0.6 * (bx[..., None] * right + by[..., None] * up)
    bg_dir /= np.linalg.norm(bg_dir, axis=-1, keepdims=True)
    out["background"] = np.asarray(lookup_bilinear(env.radiance, bg_dir))
    out["film_thickness"] = np.asarray(np.broadcast_to(film.thickness, mask[mask].shape))
    return out


def _exposure(r, cfg):
    if cfg.exposure is not None:
        return cfg.exposure
    y = bands_to_xyz(r["values"]["reference" if "reference" in r["values"] else
                              next(iter(r["values"]))], _observer(r, cfg))[:, 1]
    return float(0.9 / max(np.percentile(y, 99), 1e-12))


def _observer(r, cfg) -> str:
    """The bands of a render's values: the car paints' colour tables are in the default
    bands, the films are rendered in `cfg.observer`."""
    return DEFAULT_OBSERVER if r["scene"] == "carpaint" else cfg.observer


def _methods(r, cfg) -> tuple:
    return PAINT_METHODS if r["scene"] == "carpaint" else cfg.methods


def _image(r, vals, exposure, observer):
    img = np.clip(srgb_encoding(np.clip(r["background"] * exposure * 0.5, 0, 1)), 0, 1)
    img[r["mask"]] = bands_to_srgb(vals * exposure, observer)
    return img


def summarise(results, cfg: RenderConfig) -> dict:
    rows = []
    for r in results:
        e = _exposure(r, cfg)
        row = {"label": r["label"], "scene": r["scene"], "envmap": r["envmap"],
               "alpha": r["alpha"], "exposure": e, "points": int(r["mask"].sum()),
               "seconds": r["times"], "prefilter_seconds": r.get("prefilter_times", {}),
               "dE2000": {}}
        if "reference" in r["values"]:
            for m in _methods(r, cfg):
                if m == "reference":
                    continue
                de = delta_e2000(r["values"][m] * e, r["values"]["reference"] * e,
                                 _observer(r, cfg))
                row["dE2000"][m] = {"mean": float(de.mean()), "p95": float(np.percentile(de, 95)),
                                    "max": float(de.max())}
        rows.append(row)
    return {"config": dataclasses.asdict(cfg), "renders": rows}


def summary_table(summary) -> str:
    """The command's table: throughput and ΔE₀₀ against the reference per render and method;
    "—" where there is no error (the reference itself, or no reference rendered).

    Example (a map given by its path is labelled by its stem):
        >>> row = {"label": f"α=0.25 | {map_label('/maps/sky_1k.hdr')}", "points": 100,
        ...        "seconds": {"reference": 10.0, "improved": 0.01},
        ...        "dE2000": {"improved": {"mean": 0.96, "p95": 1.85}}}
        >>> print(summary_table({"renders": [row]}))  # doctest: +NORMALIZE_WHITESPACE
        render                                       method        pts/s  ΔE mean   ΔE p95
        α=0.25 | sky_1k                              reference        10        —        —
        α=0.25 | sky_1k                              improved      10000     0.96     1.85
    """
    w = max([44] + [len(r["label"]) for r in summary["renders"]])
    lines = [f"{'render':{w}s} {'method':9s} {'pts/s':>9s} {'ΔE mean':>8s} {'ΔE p95':>8s}"]
    for r in summary["renders"]:
        for m, t in r["seconds"].items():
            de = r["dE2000"].get(m) if m != "reference" else None
            ok = de is not None and np.isfinite([de["mean"], de["p95"]]).all()
            err = f"{de['mean']:8.2f} {de['p95']:8.2f}" if ok else f"{'—':>8s} {'—':>8s}"
            lines.append(f"{r['label']:{w}s} {m:9s} {r['points'] / t:9.0f} {err}")
    return "\n".join(lines)


PANEL_DPI = 100


def panel_inches(resolution: int) -> float:
    """Side of one composite panel (inches): grows with the resolution (one image pixel per
    figure pixel at `PANEL_DPI`, above a fixed margin for titles)."""
    return 1.3 + resolution / PANEL_DPI


def fit_title(fig, title: str, size: float = 8.5):
    """`fig.suptitle(title)` wrapped to the figure's width (lines kept where the title has
    them), its font shrunk until it lies inside the figure."""
    width = fig.get_size_inches()[0]
    while True:
        chars = max(20, int(width * 72 / (0.55 * size)))
        text = "\n".join(w for line in title.split("\n") for w in textwrap.wrap(line, chars))
        sup = fig.suptitle(text, fontsize=size)
        fig.canvas.draw()
        box = sup.get_window_extent()
        if (box.x0 >= 0 and box.x1 <= fig.bbox.x1) or size <= 5:
            return sup
        size -= 0.5


def plot_scene(results, cfg: RenderConfig, path, title: str) -> None:
    from . import plot as plt  # the caller's backend untouched

    methods = _methods(results[0], cfg)
    others = [m for m in methods if m != "reference"]
    ncol = len(methods) + (len(others) if "reference" in methods else 0)
    side = panel_inches(cfg.resolution)  # grows with the resolution
    size = (side * ncol + 1.2, (side + 0.2) * len(results) + 0.9)
    fig, axes = plt.subplots(len(results), ncol, figsize=size, squeeze=False,
                             layout="constrained")
    im = None
    for i, r in enumerate(results):
        e = _exposure(r, cfg)
        obs = _observer(r, cfg)
        for j, m in enumerate(methods):
            ax = axes[i, j]
            ax.imshow(_image(r, r["values"][m], e, obs))
            pts = r["mask"].sum() / r["times"][m]
            kind = "incl. compile" if m in ("reference", "mc") else "warm"
            build = r.get("prefilter_times", {}).get(m)
            if build is not None:
                kind += f"; table built in {build:.1f} s apart"
            ax.set_title(f"{m}\n{pts:,.0f} points/s ({kind})", fontsize=7)
            if j == 0:
                ax.set_ylabel(r["label"].replace(" | ", "\n"), fontsize=7)
        for j, m in enumerate(others if "reference" in methods else []):
            ax = axes[i, len(methods) + j]
            de = np.full(r["mask"].shape, np.nan)
            de[r["mask"]] = delta_e2000(r["values"][m] * e, r["values"]["reference"] * e, obs)
            im = ax.imshow(de, cmap="magma", vmin=0, vmax=20)
            ax.set_title(f"ΔE₀₀ {m}\nmean {np.nanmean(de):.2f}, "
                         f"p95 {np.nanpercentile(de, 95):.2f}", fontsize=8)
        for ax in axes[i]:
            ax.set_xticks([])
            ax.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.6, label="CIEDE2000 ΔE vs reference")
    fit_title(fig, title, 9.0)  # wrapped to the width, never clipped
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


TITLES = {
    "fig4": "Figure 4 setup: η₂ = 1.2 on η₃ = 2.0 (κ₃ = 0), d = 600 nm, GGX α = 0.25; "
            "Stiles & Burch bands, M = 2, LUT Ŝ, cross-band R_jk; exposure per row",
    "fig3": "Figure 3 roughness sweep: η₂ = 1.3 on η₃ = 2.0 + 0.5i, d = 650 nm; exposure per row",
    "varying": "Spatially varying thickness d ∈ [250, 850] nm (Figures 5/6 style), η₂ = 1.2 "
               "on η₃ = 2.0, α = 0.25; exposure per row",
    "carpaint": "Car paints (brdf/carpaint.py PAINTS: GGX lobes × colour table,\nclear coat "
                "η_c = 1.5): exact reference vs Kneiphof & Klein 2022's colour table\n(rank 1, "
                "8 × 16 × 8 views); Stiles & Burch 10° bands; exposure per row",
}


def run_render(cfg: RenderConfig = RenderConfig(), out_dir="figures", progress: bool = True,
               devices=None):
    """Render every scene, write ibl_<scene>.png, ibl_render.npz and ibl_render.json.

    The shading points of every frame are split across `devices` (None: every device);
    with several processes (`jax.distributed`) process 0 writes the files.
    """
    from pathlib import Path

    from tqdm.auto import tqdm

    out = Path(out_dir)
    setups = scene_setups(cfg)
    # every map read (and checked) before the first frame; `method_map` finds them here
    cache: dict = {name: {"env": load_envmap(name, ldr_srgb=cfg.ldr_srgb)}
                   for name in dict.fromkeys(s[2] for s in setups)}
    results = []
    for s in tqdm(setups, desc="render", disable=not progress or jax.process_index() > 0):
        results.append(render_one(s, cfg, cache, devices))
    if jax.process_index() > 0:
        return summarise(results, cfg)
    for scene in cfg.scenes:
        rs = [r for r in results if r["scene"] == scene]
        plot_scene(rs, cfg, out / f"ibl_{scene}.png", TITLES[scene])
    summary = summarise(results, cfg)
    summary["devices"] = batch_mesh(devices).size
    arrays = {}
    for i, r in enumerate(results):
        arrays[f"r{i}_mask"] = r["mask"]
        for m, v in r["values"].items():
            arrays[f"r{i}_{m}"] = v
    atomic_write(out / "ibl_render.npz", lambda tmp: np.savez_compressed(tmp, **arrays),
                 suffix=".npz")
    write_json(out / "ibl_render.json", summary)
    return summary
