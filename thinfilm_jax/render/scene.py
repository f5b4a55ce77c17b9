r"""One's own scene for `thinfilm-jax render`: a film or stack on a sphere, and a soap bubble.

Camera (both scenes). A pinhole at distance `DISTANCE` = 5 from the centre of a unit sphere,
looking at it from `elevation_deg` above the horizon (z-up, SPEC §9) at the azimuth that puts
the map's brightest texel behind the camera, off to one side (`study_scenes.view_azimuth`); the
field of view makes the sphere fill 87 % of the frame. Pixel (i, j) casts the ray
o + t ω (ω unit), hits the sphere at p (outward normal n = p) where ω reaches it, and its view
vector is ω_o = −ω. Pixels that miss the sphere, or graze it (⟨n, ω_o⟩ < 0.02), show the map
itself in the direction ω (bilinear, `envmap.lookup_bilinear`).

Colour. The map's linear RGB c(ω) is the spectrum Σ_k c_k B_k(λ) of the Mallett–Yuksel
basis (SPEC §9, `spectral.uplift`); seen in a perfect mirror its band j is
Σ_k M_jk c_k with M_jk = ∫ S_j B_k dλ (`colorimetry.uplift_to_bands`), so the background and
the sphere are in the same bands (`khr`'s Rec. 709 is taken to them by
`colorimetry.rec709_to_bands` inside `envmap_radiance`). Every image is kept in the observer's
bands (the NPZ) and converted once, by the library's one conversion: bands → linear Rec. 709
= linear sRGB with the mirror white adapted to D65 (CAT02; `colorimetry.bands_to_rec709`, the
EXR, unexposed) and → display sRGB (`colorimetry.bands_to_srgb` at the exposure, IEC
61966-2-1 encoding, clipped: the PNG).

Sphere (`--scene sphere`): `envmap_radiance(material, α, n, ω_o, map, method=m)` per pixel
for each method m; the reference in chunks of `CHUNK` points (a progress bar), on the map
resampled once as `envmap_radiance(max_height=256)` would resample it
(`ibl_reference.resample_factor`: a map taller than 256 rows is box-filtered, solid-angle
exact, by the largest power of two f with texel f·π/H ≤ α/8 and H/f ≥ 128: a 1k map
(512 rows) by 4 to 128 × 256 at α = 0.25); the real-time methods read the map prefiltered
once (`study_scenes.method_map`: `improved` with its suns split off). ΔE₀₀ per pixel against the
reference, exposure-scaled, mirror white Y = 1 (`colorimetry.delta_e2000`, as every study).

Bubble (`--scene bubble`). A free-standing film (air | η₂ | air, default water,
`refractive_index("water")`, Daimon & Masumura 2007) on the unit sphere, smooth (a mirror on
both faces). Its thickness follows a draining film: the vertical-film law of Mysels, Shinoda &
Frankel (1959, *Soap Films: Studies of their Thinning*), h ∝ √x at depth x below the top for
surfaces that do not move, with x the arc length from the top pole and a black film at the
top (`bubble_thickness`):

$$ d(p) = d_{top} + (d_{bottom} - d_{top})\sqrt{\psi/\pi},\qquad \psi = \arccos p_z , $$

default d_top = 30 nm (a common black film), d_bottom = 1200 nm. A thin film between two air
half-spaces does not deviate a ray, and on a sphere every chord meets the surface at the
same angle at both ends, so a pixel ray (direction ω, cos θ = ⟨n, ω_o⟩) that enters at p₁
reaches p₂ = p₁ + 2 cos θ ω, reflects inside into ω' = ω − 2⟨ω, p₂⟩p₂, reaches
p₃ = p₂ + 2 cos θ ω', and so on, all at the one angle θ and in one plane (the plane of
incidence of every event), so s and p polarisation are carried separately along the path:

$$ L(\lambda) = \tfrac12\sum_{\sigma=s,p}\Big[R_\sigma(d_1) L(\omega_r)
   + T_\sigma(d_1) T_\sigma(d_2) L(\omega)
   + \sum_{m=1}^{M} T_\sigma(d_1)\Big(\prod_{i=2}^{m+1} R_\sigma(d_i)\Big)
     T_\sigma(d_{m+2}) L(\omega^{(m)})\Big], $$

ω_r = 2⟨n, ω_o⟩n − ω_o the mirror direction, ω the straight-through one (the map behind the
bubble), ω^{(m)} the direction after m inner reflections. R, T = `stack_reflectance`,
`stack_transmittance` of the one-layer stack, exact and spectral at the observer's
wavelengths; M = `SceneConfig.orders` inner reflections (default 1: the first order, the
far wall's reflection a bubble shows). The orders left out carry ½ Σ_σ T_σ² R_σ^{M+1}/(1 − R_σ)
of a uniform film's light (R + T = 1): at M = 1 and d ∈ [0, 2 µm] at most 0.6 % at normal
incidence (R ≤ 0.083), 4.5 % at 60° (R_s ≤ 0.38), 13 % at cos θ = 0.2, i.e. near the rim,
where the bubble is bright and the truncation darkens it slightly. Band j takes the spectral
factor of each term against the map's spectrum through the cross bands S_j B_k (SPEC §9, the
R_jk of the IBL reference, no per-channel approximation):
L_j = Σ_k Σ_i W_ij B_k(λ_i) F(λ_i) c_k(ω_term). With d → 0, R = 0 and T = 1: the bubble
shows the map straight through (the background's values); for the lossless water film
R + T = 1 at every λ, and with all orders and a uniform thickness the white map's band
values sum to 1 (R + T²/(1 − R) = 1); tests/cli/test_render_scene.py checks the three.

Example (a quarter-degree check of the camera: the sphere's centre pixel looks straight back
along its normal):
    >>> import numpy as np
    >>> eye, dirs = pinhole(9, 0.0, 15.0)
    >>> mask, p, cos = hit_sphere(eye, dirs)
    >>> bool(mask[4, 4]), bool(np.isclose(cos[4, 4], 1.0))
    (True, True)
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.files import atomic_write, write_json
from ..core.film import Film
from ..core.methods import METHODS as METHOD_INFO
from ..optics.materials import MATERIALS
from ..spectral.colorimetry import (bands_to_rec709, bands_to_srgb, bands_to_xyz, delta_e2000,
                                    uplift_to_bands)
from ..spectral.spectra import DEFAULT_OBSERVER, get_observer
from ..spectral.uplift import basis_on
from .bubble import bubble_factors, bubble_paths, bubble_thickness
from .scene_material import (check_methods, describe, index_from_json, index_json,
                             make_material, material_from_json, material_json)
from .study_scenes import PANEL_DPI, fit_title, panel_inches

__all__ = [
    "OWN_SCENES",
    "pinhole",
    "hit_sphere",
    "exposure_of",
    "write_exr",
    "plot_panels",
    "SceneConfig",
    "shade_bubble",
    "default_out_dir",
    "render_scene",
    "throughput_label",
    "format_summary",
    "config_from_dict",
]

OWN_SCENES = ("sphere", "bubble")
DISTANCE = 5.0  # camera distance / sphere radius
FILL = 0.87  # the sphere's diameter / the frame's side
GRAZING = 0.02  # pixels with ⟨n, ω_o⟩ below this show the map
CHUNK = 4096  # reference points per call (one progress step)
MAX_HEIGHT = 256  # the reference's resampling threshold, as envmap_radiance's default


# ----------------------------------------------------------------------------- camera
def pinhole(resolution: int, azimuth: float, elevation_deg: float,
            distance: float = DISTANCE, fill: float = FILL):
    """Eye position (3,) and unit ray directions (R, R, 3) of the pinhole camera (module
    docstring): the unit sphere at the origin fills `fill` of the frame."""
    el = np.deg2rad(elevation_deg)
    toward_eye = np.array([np.cos(el) * np.cos(azimuth), np.cos(el) * np.sin(azimuth),
                           np.sin(el)])
    right = np.cross(-toward_eye, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -toward_eye)
    half = math.tan(math.asin(1.0 / distance)) / fill  # tan of half the field of view
    c = ((np.arange(resolution) + 0.5) / resolution * 2 - 1) * half
    x, y = np.meshgrid(c, -c)
    d = -toward_eye + x[..., None] * right + y[..., None] * up
    return distance * toward_eye, d / np.linalg.norm(d, axis=-1, keepdims=True)


def hit_sphere(eye, dirs):
    """(mask (R, R), hit points = outward normals (R, R, 3), cos θ = ⟨n, ω_o⟩ (R, R)) of rays
    from `eye` along `dirs` on the unit sphere; mask: hit at ⟨n, ω_o⟩ ≥ `GRAZING`."""
    b = dirs @ eye
    disc = b * b - (eye @ eye - 1.0)
    t = -b - np.sqrt(np.clip(disc, 0.0, None))
    p = eye + t[..., None] * dirs
    p /= np.linalg.norm(p, axis=-1, keepdims=True)
    cos = -np.sum(p * dirs, -1)
    return (disc > 0) & (cos >= GRAZING), p, np.clip(cos, 0.0, 1.0)


# ----------------------------------------------------------------------------- colour
def exposure_of(values, observer: str) -> float:
    """The display exposure that maps the 99th luminance percentile to 0.9 (as `render`)."""
    y = bands_to_xyz(np.asarray(values).reshape(-1, np.shape(values)[-1]), observer)[:, 1]
    y = y[np.isfinite(y)]
    return float(0.9 / max(np.percentile(y, 99) if y.size else 1.0, 1e-12))


def write_exr(path, rgb) -> Path:
    """A float32 RGB OpenEXR file (OpenImageIO), written atomically."""
    import OpenImageIO as oiio

    a = np.ascontiguousarray(np.nan_to_num(np.asarray(rgb, np.float32)))

    def w(tmp):
        spec = oiio.ImageSpec(a.shape[1], a.shape[0], 3, "float")
        spec.attribute("oiio:ColorSpace", "lin_rec709_scene")
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise OSError(f"cannot write {path}: {oiio.geterror()}")
        out.write_image(a)
        out.close()

    return atomic_write(path, w, suffix=".exr")


def write_png(path, srgb) -> Path:
    """An 8-bit PNG of display sRGB in [0, 1] (OpenImageIO), written atomically."""
    import OpenImageIO as oiio

    a = np.ascontiguousarray(np.round(np.clip(np.nan_to_num(srgb), 0, 1) * 255).astype(np.uint8))

    def w(tmp):
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), oiio.ImageSpec(a.shape[1], a.shape[0], 3,
                                                                "uint8")):
            raise OSError(f"cannot write {path}: {oiio.geterror()}")
        out.write_image(a)
        out.close()

    return atomic_write(path, w, suffix=".png")


# ----------------------------------------------------------------------------- figures
def plot_panels(path, panels, title: str, resolution: int, *, vmax: float = 20.0) -> tuple:
    """Panels side by side: (label, image) with an (H, W, 3) sRGB image or an (H, W) ΔE₀₀ map
    (magma, 0 … `vmax`, one colour bar); the title is wrapped to the figure's width and shrunk
    until it fits. Returns the PNG's (width, height) in pixels."""
    from . import plot as plt  # the caller's backend untouched

    side = panel_inches(resolution)
    has_bar = any(np.ndim(im) == 2 for _, im in panels)
    width = side * len(panels) + (0.9 if has_bar else 0.2)
    fig, axes = plt.subplots(1, len(panels), figsize=(width, side + 0.9), squeeze=False,
                             layout="constrained")
    im = None
    for ax, (label, img) in zip(axes[0], panels):
        if np.ndim(img) == 2:
            im = ax.imshow(img, cmap="magma", vmin=0, vmax=vmax, interpolation="nearest")
        else:
            ax.imshow(img, interpolation="nearest")
        ax.set_title(label, fontsize=7)
        ax.set_xticks([])
        ax.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="CIEDE2000 ΔE vs reference")
    fit_title(fig, title)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=PANEL_DPI, format="png"))
    out = tuple(int(round(v)) for v in fig.get_size_inches() * PANEL_DPI)
    plt.close(fig)
    return out


# ----------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class SceneConfig:
    """What `render_scene` renders: scene, material (sphere), map, camera, display."""

    scene: str = "sphere"  # "sphere" | "bubble"
    material: Any = field(default_factory=lambda: Film(600.0, 1.2, 2.0))
    alpha: float = 0.25
    envmap: Any = "venice_sunset"
    resolution: int = 128
    methods: tuple[str, ...] = ("reference", "improved")
    exposure: float | None = None
    observer: str = DEFAULT_OBSERVER
    elevation_deg: float | None = None  # None: 15° (sphere), 30° (bubble: its thin top shows)
    ldr_srgb: bool = False
    # sphere, method "improved" under the map (`ModelOptions.bin_reads`, `.light_spread`,
    # `ModelOptions.preset(quality)`: "fast", "default" or "accurate")
    bin_reads: int = 1
    light_spread: bool = False
    quality: str = "default"
    # bubble
    eta_film: Any = "water"
    thickness_top: float = 30.0
    thickness_bottom: float = 1200.0
    orders: int = 1  # inner reflections kept

    def __post_init__(self):
        if self.scene not in OWN_SCENES:
            raise ValueError(f"scene must be one of {OWN_SCENES}, got {self.scene!r}")
        from .study_scenes import envmap_methods

        bad = [m for m in self.methods if m not in envmap_methods()]
        if bad:
            raise ValueError(f"unknown method(s) {bad}; expected some of {envmap_methods()}")
        object.__setattr__(self, "methods", tuple(dict.fromkeys(self.methods)))
        if self.elevation_deg is None:
            object.__setattr__(self, "elevation_deg", 15.0 if self.scene == "sphere" else 30.0)
        if self.scene == "sphere":
            check_methods(self.material, self.methods)
        from ..realtime.options import ModelOptions

        ModelOptions(bin_reads=self.bin_reads, light_spread=self.light_spread).checked()
        ModelOptions.preset(self.quality)
        if self.quality != "default" and self.bin_reads != 1:
            raise ValueError(f"quality={self.quality!r} sets the reads per bin: give "
                             f"bin_reads={self.bin_reads} or the quality, not both")


def _frame(cfg: SceneConfig, env):
    from .study_scenes import view_azimuth

    eye, dirs = pinhole(cfg.resolution, view_azimuth(env), cfg.elevation_deg)
    mask, p, cos = hit_sphere(eye, dirs)
    return eye, dirs, mask, p, cos


def _background(env, dirs, observer):
    from ..shading.envmap import lookup_bilinear

    return uplift_to_bands(np.asarray(lookup_bilinear(env.radiance, dirs)), observer)


def shade_sphere(cfg: SceneConfig, env, progress: bool = True):
    """Band images (R, R, J) per method (NaN off the sphere), mask, background, timings, notes.

    Timings per method (`render.json`'s "seconds", "prefilter_seconds", "warm_seconds"): the
    first shading call, compilation included; the map's prefiltering (real-time methods, once
    per kind of map; not in the others); and a second, warm call of the same shading (real-time
    methods; the reference's warm time is its chunks after the first, compiled, scaled to all
    points, when there are two chunks or more, else absent).
    """
    from tqdm.auto import tqdm

    from ..shading.envmap import downsample
    from ..realtime.options import ModelOptions
    from ..shading.ibl import REALTIME_OPTIONS, envmap_radiance
    from ..shading.ibl_reference import GrazingLobeWarning, resample_factor
    from .study_scenes import method_map

    _, dirs, mask, p, _ = _frame(cfg, env)
    n, view = p[mask], -dirs[mask]
    cache: dict = {"map": {"env": env}}
    images, seconds, notes = {}, {}, {}
    prefilter, warm = {}, {}
    for m in cfg.methods:
        t0 = time.perf_counter()
        if METHOD_INFO[m].exact:
            f = resample_factor(env.shape[0], cfg.alpha, MAX_HEIGHT)
            src = downsample(env, f) if f > 1 else env
            if f > 1:
                notes[m] = (f"map resampled by {f} to {src.shape[0]} × {src.shape[1]} "
                            f"(solid-angle-exact box filter, texel ≤ α/8)")
            out = np.zeros((len(n), get_observer(cfg.observer).n_bands))
            chunk = min(CHUNK, len(n))
            steps = range(0, len(n), chunk)
            grazing = 0
            t_first = None
            for s in tqdm(steps, desc=f"render {m}", unit="chunk",
                          disable=not progress or len(steps) < 2):
                if s == chunk:  # the first chunk done: the rest run compiled
                    t_first = time.perf_counter()
                k = min(chunk, len(n) - s)
                # one shape, one compile: pad with the chunk's least oblique point (the pads
                # do not count among the reference's grazing points)
                pad = s + int(np.argmax(np.sum(n[s:s + k] * view[s:s + k], -1)))
                idx = np.where(np.arange(s, s + chunk) < len(n), np.arange(s, s + chunk), pad)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    out[s:s + k] = np.asarray(envmap_radiance(
                        cfg.material, cfg.alpha, n[idx], view[idx], src, method=m,
                        observer=cfg.observer, max_height=None))[:k]
                for w in caught:
                    if isinstance(w.message, GrazingLobeWarning):
                        grazing += w.message.count
                    else:
                        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            if t_first is not None:  # chunks after the first, as if they covered every point
                warm[m] = (time.perf_counter() - t_first) * len(n) / (len(n) - chunk)
            if grazing:
                notes[m] = "; ".join(filter(None, [notes.get(m), (
                    f"{grazing} silhouette points where the view is so oblique that the lobe "
                    "is narrower than two texel nodes: the reference is not converged there "
                    "(ibl_reference, 'Grazing views')")]))
        else:
            pref = method_map(cache, "map", m, cfg.observer)
            prefilter[m] = time.perf_counter() - t0  # 0 when an earlier method built it
            obs = cfg.observer
            q = ModelOptions.preset(cfg.quality)  # bins and reads; bin_reads=g alone is g
            opts = REALTIME_OPTIONS._replace(bins=q.bins, bin_reads=max(q.bin_reads,
                                                                        cfg.bin_reads),
                                             light_spread=cfg.light_spread)

            def shade(pref=pref, obs=obs, opts=opts, m=m):
                return np.asarray(envmap_radiance(cfg.material, cfg.alpha, n, view, pref,
                                                  method=m, observer=obs, options=opts))

            t0 = time.perf_counter()
            out = shade()  # every method in the observer's bands
            seconds[m] = time.perf_counter() - t0
            t1 = time.perf_counter()
            shade()  # the second call: compiled, warm
            warm[m] = time.perf_counter() - t1
        if m not in seconds:
            seconds[m] = time.perf_counter() - t0
        img = np.full(mask.shape + (out.shape[-1],), np.nan)
        img[mask] = out
        images[m] = img
    timing = {"seconds": seconds, "prefilter_seconds": prefilter, "warm_seconds": warm}
    return images, mask, _background(env, dirs, cfg.observer), timing, notes


def shade_bubble(cfg: SceneConfig, env, progress: bool = True):
    """Band image (R, R, J) of the bubble (NaN off it), mask, background, thickness map."""
    from ..shading.envmap import lookup_bilinear

    _, dirs, mask, p, cos = _frame(cfg, env)
    pts, ds, c = p[mask], dirs[mask], cos[mask]
    points, read = bubble_paths(pts, ds, c, cfg.orders)
    thick = [bubble_thickness(q[..., 2], cfg.thickness_top, cfg.thickness_bottom)
             for q in points]
    factors = bubble_factors(thick, c, cfg.eta_film, cfg.observer)
    obs = get_observer(cfg.observer)
    b = basis_on(tuple(float(x) for x in obs.wavelengths))  # (I, K)
    w = np.asarray(obs.weights, float)  # (I, J)
    out = 0.0
    for f, omega in zip(factors, read):
        rgb = np.asarray(lookup_bilinear(env.radiance, omega))  # (P, K)
        out = out + np.einsum("pi,ij,ik,pk->pj", f, w, b, rgb, optimize=True)
    img = np.full(mask.shape + (w.shape[1],), np.nan)
    img[mask] = out
    dmap = np.full(mask.shape, np.nan)
    dmap[mask] = thick[0]
    return img, mask, _background(env, dirs, cfg.observer), dmap


def default_out_dir() -> Path:
    """A new folder in the current directory, render-YYYYmmdd-HHMMSS (never `figures/`)."""
    return Path(time.strftime("render-%Y%m%d-%H%M%S"))


def _full(img, background, mask):
    full = np.array(background)
    full[mask] = img[mask]
    return full


def render_scene(cfg: SceneConfig, out_dir=None, progress: bool = True) -> dict:
    """Render `cfg` and write, into `out_dir` (default `default_out_dir()`): per image
    `<name>.exr` (linear sRGB, unexposed, map behind) and `<name>.png` (display sRGB at the
    exposure); per non-reference method `<name>_dE2000.png` (ΔE₀₀ map with its colour bar);
    `composite.png`, `render.npz` ((R, R, J) band images, NaN off the sphere, `mask`,
    `background`) and `render.json` (settings, seconds, ΔE₀₀ mean/p95/max). Returns the
    summary, with the written paths under "files"."""
    from ..shading.envmap import load_envmap
    from .study_scenes import map_label

    out = Path(out_dir) if out_dir is not None else default_out_dir()
    t_all = time.perf_counter()
    env = load_envmap(cfg.envmap, ldr_srgb=cfg.ldr_srgb)
    obs = cfg.observer
    notes: dict = {}
    if cfg.scene == "sphere":
        images, mask, background, timing, notes = shade_sphere(cfg, env, progress)
        what = describe(cfg.material)
        title = f"{what}, GGX α = {cfg.alpha:g} under {map_label(cfg.envmap)}, {cfg.resolution} px"
        extra = {}
    else:
        t0 = time.perf_counter()
        img, mask, background, dmap = shade_bubble(cfg, env, progress)
        timing = {"seconds": {"bubble": time.perf_counter() - t0}, "prefilter_seconds": {},
                  "warm_seconds": {}}
        images = {"bubble": img}
        eta = cfg.eta_film if isinstance(cfg.eta_film, str) else describe(cfg.eta_film)
        what = (f"soap bubble: air | {eta} | air, d = {cfg.thickness_top:g} + "
                f"{cfg.thickness_bottom - cfg.thickness_top:g}·√(ψ/π) nm, mirror, "
                f"{cfg.orders} inner reflection(s)")
        title = f"{what} under {map_label(cfg.envmap)}, {cfg.resolution} px"
        extra = {"thickness": dmap}
    first = "reference" if "reference" in images else next(iter(images))
    exposure = cfg.exposure if cfg.exposure is not None else exposure_of(
        _full(images[first], background, mask) if cfg.scene == "bubble" else images[first][mask],
        obs)
    files, panels, errors = [], [], {}
    for m, img in images.items():
        full = _full(img, background, mask)
        files.append(write_exr(out / f"{m}.exr", bands_to_rec709(full, obs)))
        srgb = bands_to_srgb(full * exposure, obs)
        files.append(write_png(out / f"{m}.png", srgb))
        panels.append((f"{m}\n{throughput_label(timing, m, int(mask.sum()))}", srgb))
    de_maps = {}
    if "reference" in images:
        ref = images["reference"][mask] * exposure
        for m in images:
            if m == "reference":
                continue
            de = np.full(mask.shape, np.nan)
            de[mask] = delta_e2000(images[m][mask] * exposure, ref, obs)
            de_maps[m] = de
            errors[m] = {"mean": float(np.nanmean(de)), "p95": float(np.nanpercentile(de, 95)),
                         "max": float(np.nanmax(de))}
            files.append(out / f"{m}_dE2000.png")
            plot_panels(files[-1], [(f"ΔE₀₀ {m}: mean {errors[m]['mean']:.2f}, "
                                     f"p95 {errors[m]['p95']:.2f}", de)],
                        f"CIEDE2000 of {m} against the reference", cfg.resolution)
    for m, de in de_maps.items():
        panels.append((f"ΔE₀₀ {m}\nmean {errors[m]['mean']:.2f}, p95 {errors[m]['p95']:.2f}",
                       de))
    if cfg.scene == "bubble":
        from .plot import get_cmap

        d = extra["thickness"]
        cmap = get_cmap("viridis")
        lo, hi = np.nanmin(d), np.nanmax(d)
        dimg = np.where(mask[..., None], cmap((d - lo) / max(hi - lo, 1e-9))[..., :3], 1.0)
        panels.append((f"film thickness\n{lo:.0f}–{hi:.0f} nm", dimg))
    files.append(out / "composite.png")
    size = plot_panels(files[-1], panels, title, cfg.resolution)
    arrays = {"mask": mask, "background": background, **images, **extra}
    files.append(atomic_write(out / "render.npz", lambda tmp: np.savez_compressed(tmp, **arrays),
                              suffix=".npz"))
    summary = {
        "scene": cfg.scene, "title": title, "config": config_dict(cfg), "envmap": str(cfg.envmap),
        "envmap_shape": list(env.shape), "resolution": cfg.resolution,
        "observer": obs, "exposure": exposure, "points": int(mask.sum()),
        "alpha": cfg.alpha if cfg.scene == "sphere" else None,
        "material": what, "methods": list(images), **timing,
        "timing": ("seconds: each method's first call, compilation included, prefiltering "
                   "not; prefilter_seconds: the real-time methods' map prefiltering; "
                   "warm_seconds: the same shading called again, compiled (points/s = "
                   "points / warm_seconds)"),
        "points_per_second_warm": {m: int(mask.sum()) / t
                                   for m, t in timing["warm_seconds"].items()},
        "notes": notes,
        "dE2000": errors, "composite_pixels": list(size),
        "bands": "the observer's bands, unit area (a perfect mirror under a white map is 1)",
        "exr": "linear sRGB (Rec. 709, D65), unexposed; png: sRGB at the exposure",
    }
    summary["total_seconds"] = time.perf_counter() - t_all
    files.append(out / "render.json")
    summary["files"] = [str(f) for f in files]
    write_json(out / "render.json", summary)
    return summary


def throughput_label(timing: dict, m: str, points: int) -> str:
    """A composite panel's throughput: warm points/s where a warm time was measured, else
    the first call's, labelled as including compilation."""
    warm = timing["warm_seconds"].get(m)
    if warm:
        return f"{points / warm:,.0f} points/s warm"
    return f"{points / timing['seconds'][m]:,.0f} points/s (first call, incl. compile)"


def format_summary(summary: dict) -> str:
    """The command's table per method: the first call's seconds (compilation included), the
    prefiltering's seconds, warm seconds and warm points/s (— where not measured), ΔE₀₀."""
    lines = [f"{'method':10s} {'first s':>8s} {'prefilt s':>9s} {'warm s':>8s} "
             f"{'warm pts/s':>10s} {'ΔE mean':>8s} {'ΔE p95':>8s} {'ΔE max':>8s}"]
    dash = "—"
    for m, t in summary["seconds"].items():
        de = summary["dE2000"].get(m)
        err = (f"{de['mean']:8.2f} {de['p95']:8.2f} {de['max']:8.2f}" if de
               else f"{dash:>8s} {dash:>8s} {dash:>8s}")
        pre = summary.get("prefilter_seconds", {}).get(m)
        warm = summary.get("warm_seconds", {}).get(m)
        pre = f"{pre:9.2f}" if pre is not None else f"{dash:>9s}"
        rate = f"{summary['points'] / warm:10.0f}" if warm else f"{dash:>10s}"
        warm = f"{warm:8.2f}" if warm else f"{dash:>8s}"
        lines.append(f"{m:10s} {t:8.1f} {pre} {warm} {rate} {err}")
    return "\n".join(lines)


#: the settings each scene uses (besides `COMMON_FIELDS`): `render.json` records these alone
SCENE_FIELDS = {"sphere": ("material", "alpha", "methods", "bin_reads", "light_spread"),
                "bubble": ("eta_film", "thickness_top", "thickness_bottom", "orders")}
COMMON_FIELDS = ("scene", "envmap", "resolution", "exposure", "observer", "elevation_deg",
                 "ldr_srgb")


def config_dict(cfg: SceneConfig) -> dict:
    """The settings as JSON-able values: those common to both scenes and those of the scene
    rendered (`SCENE_FIELDS`), each as it was rendered; `config_from_dict` reads it back.

    Example (a bubble records its film, not the sphere's default material):
        >>> d = config_dict(SceneConfig(scene="bubble"))
        >>> "material" in d, d["eta_film"], d["thickness_top"]
        (False, 'water', 30.0)
    """
    d = {k: getattr(cfg, k) for k in COMMON_FIELDS + SCENE_FIELDS[cfg.scene]}
    d["envmap"] = str(cfg.envmap)
    if "material" in d:
        d["material"] = material_json(cfg.material)
        d["methods"] = list(cfg.methods)
    if "eta_film" in d:
        d["eta_film"] = index_json(cfg.eta_film)
    return d


def config_from_dict(d: dict) -> SceneConfig:
    """The `SceneConfig` of a ``render.json``'s ``"config"`` (`config_dict`): rendering it
    again gives the same images."""
    kw = dict(d)
    if "material" in kw:
        kw["material"] = material_from_json(kw["material"])
    if "methods" in kw:
        kw["methods"] = tuple(kw["methods"])
    if "eta_film" in kw and not (isinstance(kw["eta_film"], str) and kw["eta_film"] in MATERIALS):
        kw["eta_film"] = index_from_json(kw["eta_film"])  # a bundled name stays a name
    return SceneConfig(**kw)
