r"""Thickness maps from photographs (SPEC §13): `fit_photo` on synthetic photographs rendered
independently of its model, and `fit_spectrum` against optifik on reflectance spectra.

``python -m benchmarks.photo_study --out figures`` writes figures/photo_study.json,
photo_study.md and photo_study.png (``--quick``: 96 × 96 photographs, the test's sizes).

**The photographs** (`render_scenes`) are made without `fit_photo`'s model (its 5 nm tables,
trapezoid weights and Hermite interpolant): the exact reflectance (`stack_reflectance`, every
index at each wavelength, normal view) at 1 nm steps on a thickness grid of `THICKNESS_STEP_NM`
(0.1 nm; linear interpolation in thickness then moves a colour by < 1e-6), integrated by
colour-science (``msds_to_XYZ(..., method="Integration")`` at 1 nm, its ``align`` interpolating
the 5 nm and 10 nm tables) against

* a camera's measured sensitivities (colour-science's ``MSDS_CAMERA_SENSITIVITIES``, Darrodi
  et al. 2015) on the camera's own range: raw camera RGB, 1 = the green channel's reading of
  a white reflector; the raw channels are not white-balanced, so the truth's gains are the
  exposure times the camera's white (`CameraPhoto.gains`);
* or the CIE 1931 2° observer (360–830 nm) under the light, the light's white adapted to D65
  by the Bradford transform and ``colour.XYZ_to_RGB(..., "sRGB")``: a colorimetric sRGB
  camera; exposure and a white-balance error of the camera are applied in linear sRGB.

Then the sensor: photon noise of `FULL_WELL_E` electrons at full scale (Gaussian, variance =
signal) and a read noise of `READ_NOISE_E` electrons, clipped to [0, 1] as a camera clips (for
the sRGB camera the noise is added to the exposed XYZ, before the matrix to sRGB and the
white balance, as a camera's raw noise goes through its colour matrix; the sRGB values are
then clipped to [0, 1], out-of-gamut colours to black in a channel); then the file: 16-bit
linear TIFF or PNG, or sRGB-encoded (IEC 61966-2-1, colour-science's ``cctf_encoding``)
8-bit JPEG at quality `JPEG_QUALITY` (OpenImageIO's default chroma subsampling, 4:2:0),
written by OpenImageIO and read by `fit_photo` from the file.

**Scenes** (`soap_thickness`, `oxide_thickness`): a free-standing soap film (water in air,
Daimon & Masumura's index) draining as h ∝ √depth below its top (Mysels, Shinoda & Frankel,
*Soap films*, 1959), 80–1400 nm, stirred by three swirls; and thermal SiO₂ on Si (Malitson,
Schinke) with six terraces (bare Si, 120, 210, 330, 520, 760 nm), a 0–900 nm bevel and a
deposited dome (100–880 nm).

**Cases** (`cases`, one row each; statistics over every fitted pixel except the case's own
reference pads): known camera with a bare-substrate reference (a), the 8-bit sRGB JPEG of the
soap film without reference, with and without the neighbour prior (b), the unknown camera
(what `fit_photo` fits for ``camera="unknown"``, on four terraces; photographs by the Nikon
and by the held-out Sigma) and what it costs against the known camera on the same photograph
(c, Luther's condition), the soap film's 16-bit raw photograph by the Nikon, and the traps
(d): a JPEG declared linear, the wrong material, the wrong camera. Per row:
median and p95 of |error|, the share within 15 nm (the right fringe order), the share flagged
ambiguous, the share of wrong-order pixels flagged, the share of right-order pixels within two
standard errors, reduced χ², exposure and white balance against the truth, whether the fit
warned, and the call's time. The first call of each scene is repeated: its compile time is
reported apart (the other rows reuse most programs). A 1-megapixel soap JPEG times one more
call.

**Spectra** (`photo_spectra.spectra_study`): normal-incidence reflectance of a soap film on
400–800 nm at 1 nm, the exact R plus Gaussian noise, optionally divided by a mis-calibrated
lamp (a ±5 % tilt), for films of 120 nm (less than one fringe) to 5 µm (~17 orders): `fit_spectrum`
(exact model, thickness free in [0, 6000] nm) against optifik's three estimators
(Ziapkoff, Boulogne, Salonen & Rio, Eur. Phys. J. E 49, 4 (2026)): the Fourier transform in
n/λ (`thickness_from_fft`, many fringes), the linear regression of the extrema's orders
(`thickness_from_minmax`, a moderate number) and Scheludko's formula on the last monotonic
branch (`thickness_from_scheludko`, few fringes), each on the spectrum normalised to its
maximum and, for the extrema methods, smoothed by optifik's Savitzky–Golay filter.

Example (the study's cases; the scenes and their rendering: `benchmarks.photo_scenes`):
    >>> from benchmarks.photo_study import cases
    >>> [c.key for c in cases(96)][:5]
    ['a', 'a-smooth', 'c-nikon', 'c-sigma-known', 'c-sigma']
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.fit.photo import fit_photo
from thinfilm_jax.optics.materials import refractive_index
from ._timing import environment, fmt, jsonable, write_report
from .photo_scenes import (FULL_WELL_E, OXIDE_RANGE, READ_NOISE_E, SOAP_RANGE, SWIRLS, TERRACES,
                           THICKNESS_STEP_NM, apply_table, camera_table, encode_srgb8,
                           oxide_thickness, read_codes, reflectance_table, sensor,
                           soap_thickness, srgb_table, templates, write_image, xyz_table,
                           xyz_to_srgb)
from .photo_spectra import spectra_study

NIKON, SIGMA = "Nikon 5100 (NPL)", "Sigma SDMerill (NPL)"
JPEG_QUALITY = 90
RIGHT_ORDER_NM = 15.0  # |error| below this: the right fringe order
#: the four oxide terraces (`photo_scenes.TERRACES`) given as references in case (c)
PADS = (0, 1, 3, 4)
#: the fits' thickness_range: what a scientist would know of each sample
FIT_RANGE = {"soap": (0.0, 1600.0), "oxide": (0.0, 1000.0)}
#: truth: exposure of each photograph and, for the sRGB camera, its white-balance error
EXPOSURE = {"oxide": 1.6, "soap_camera": 9.0, "soap_srgb": 7.0}
SRGB_WB = (1.08, 1.0, 0.93)
SOAP_LIGHT = "D50"  # the soap film is photographed under D50, the oxide under D65
SMOOTHNESS_NM_AT_512 = 12.0  # τ of the neighbour prior at 512 px (scaled with 512/size)
_PNG_METADATA = {"Software": None}


class PhotoConfig(NamedTuple):
    """Sizes of one run (`PhotoConfig()` the committed run, `quick()` the test's)."""

    name: str = "full"
    size: int = 512
    timing_size: int | None = 1024  # the 1-megapixel timing (None: skipped)
    spectra_thickness: tuple = (120.0, 300.0, 500.0, 800.0, 1200.0, 2000.0, 3000.0, 5000.0)
    spectra_noise: tuple = (0.0002, 0.001)  # σ of R (the film's peak R is ≈ 0.08)
    spectra_repeats: int = 3  # noise realisations per (thickness, variant)
    figures: bool = True
    extras: bool = False  # one more row: the oxide without its bare-Si reference

    @classmethod
    def quick(cls) -> PhotoConfig:
        return cls(name="quick", size=96, timing_size=None,
                   spectra_thickness=(300.0, 2000.0), spectra_noise=(0.001,),
                   spectra_repeats=1, figures=False)


def _log(msg: str, verbose: bool):
    if verbose:
        print(f"[photo] {msg}", file=sys.stderr, flush=True)


class CameraPhoto(NamedTuple):
    """A rendered photograph: its file, the truth's gains g (3,) (exposure = g[1], white
    balance g / g[1]) and its display sRGB (H, W, 3) in [0, 1] for the figure."""

    path: str
    gains: np.ndarray
    display: np.ndarray
    note: str


def render_scenes(cfg: PhotoConfig, folder, verbose: bool = True) -> dict:
    """Render every photograph of the cases into `folder`; returns {"truth": maps, "pads":
    ..., "photos": {key: CameraPhoto}, "tables_s": seconds}."""
    t0 = time.perf_counter()
    folder = Path(folder)
    n = cfg.size
    tpl = templates()
    soap_d, (oxide_d, pads) = soap_thickness(n), oxide_thickness(n)
    photos = {}
    rng = np.random.default_rng(20240613)

    def camera_photo(key, scene, dmap, camera, light, exposure, suffix, grid):
        d_g, lam, r = grid[camera]
        raw, white = camera_table(r, lam, camera, light)
        v = sensor(exposure * apply_table(d_g, raw, dmap), rng)
        path = write_image(folder / f"{key}{suffix}", np.round(v * 65535).astype(np.uint16))
        photos[key] = CameraPhoto(str(path), exposure * white, None,
                                  f"{camera}, raw (not white-balanced), {light}, 16-bit "
                                  f"linear {suffix[1:].upper()}")

    # the oxide: Nikon (TIFF) and Sigma (PNG) raw photographs, D65; display sRGB at D65
    d_max = OXIDE_RANGE[1] + 1.0
    grid = {NIKON: reflectance_table(tpl["oxide"], d_max, 380.0, 780.0),
            SIGMA: reflectance_table(tpl["oxide"], d_max, 400.0, 680.0),
            "cie": reflectance_table(tpl["oxide"], d_max, 360.0, 830.0)}
    camera_photo("oxide_nikon", "oxide", oxide_d, NIKON, "D65", EXPOSURE["oxide"], ".tif",
                 grid)
    camera_photo("oxide_sigma", "oxide", oxide_d, SIGMA, "D65", EXPOSURE["oxide"], ".png",
                 grid)
    d_g, lam, r = grid["cie"]
    disp = np.clip(EXPOSURE["oxide"] * apply_table(d_g, srgb_table(r, lam, "D65"), oxide_d),
                   0, 1)
    for k in ("oxide_nikon", "oxide_sigma"):
        photos[k] = photos[k]._replace(display=encode_srgb8(disp) / 255.0)
    _log(f"oxide photographs {n}×{n}: {time.perf_counter() - t0:.1f} s", verbose)

    # the soap film: an sRGB JPEG (D50, camera WB off by SRGB_WB) and a Nikon raw TIFF
    d_max = SOAP_RANGE[1] + 1.0
    grid = {NIKON: reflectance_table(tpl["soap"], d_max, 380.0, 780.0),
            "cie": reflectance_table(tpl["soap"], d_max, 360.0, 830.0)}
    d_g, lam, r = grid["cie"]
    soap_xyz, soap_white = xyz_table(r, lam, SOAP_LIGHT)
    gains = EXPOSURE["soap_srgb"] * np.asarray(SRGB_WB)

    def soap_jpeg(key, dmap):  # the noise before the camera's matrix, as a camera's
        xyz = sensor(EXPOSURE["soap_srgb"] * apply_table(d_g, soap_xyz, dmap), rng)
        v = np.clip(np.asarray(SRGB_WB) * xyz_to_srgb(xyz, soap_white), 0.0, 1.0)
        codes = encode_srgb8(v)
        path = write_image(folder / f"{key}.jpg", codes, quality=JPEG_QUALITY)
        photos[key] = CameraPhoto(str(path), gains, read_codes(path) / 255.0,
                                  f"sRGB 8-bit JPEG quality {JPEG_QUALITY}, {SOAP_LIGHT} "
                                  f"adapted to D65 (Bradford), WB error {SRGB_WB}")

    soap_jpeg("soap_srgb", soap_d)
    camera_photo("soap_nikon", "soap", soap_d, NIKON, SOAP_LIGHT, EXPOSURE["soap_camera"],
                 ".tif", grid)
    photos["soap_nikon"] = photos["soap_nikon"]._replace(display=photos["soap_srgb"].display)
    truth = {"soap": soap_d, "oxide": oxide_d}
    if cfg.timing_size:
        truth["soap_1mp"] = soap_thickness(cfg.timing_size)
        soap_jpeg("soap_1mp", truth["soap_1mp"])
    _log(f"all photographs: {time.perf_counter() - t0:.1f} s", verbose)
    return {"truth": truth, "pads": pads, "photos": photos,
            "render_s": time.perf_counter() - t0}


# ----------------------------------------------------------------------------- cases
class Case(NamedTuple):
    key: str
    scene: str
    photo: str
    label: str
    fit: dict  # fit_photo keywords besides image, template, thickness_range
    reference: tuple = ()  # indices into the oxide pads
    target: tuple | None = None  # (median nm ≤, % within 15 nm ≥)
    trap: bool = False
    template: str | None = None  # another material than the scene's (a trap)
    compare: str | None = None  # the known-camera row of the same photograph (Luther)


def cases(size: int, extras: bool = False) -> tuple:
    """The study's rows (module docstring); τ of the prior scales with 512/size; `extras`:
    the oxide without its reference too."""
    tau = SMOOTHNESS_NM_AT_512 * 512.0 / size
    rows = (
        Case("a", "oxide", "oxide_nikon", "(a) Nikon known, 16-bit linear TIFF, bare-Si "
             "reference", dict(camera=NIKON, encoding="linear"), (0,), (1.0, 99.5)),
        Case("a-smooth", "oxide", "oxide_nikon", f"(a) Nikon known, 16-bit linear TIFF, "
             f"bare-Si reference, smoothness τ = {tau:.3g} nm",
             dict(camera=NIKON, encoding="linear", smoothness_nm=tau), (0,), (1.0, 99.5)),
        Case("a-noref", "oxide", "oxide_nikon", "(a) Nikon known, 16-bit linear TIFF, no "
             "reference", dict(camera=NIKON, encoding="linear")),
        Case("c-nikon", "oxide", "oxide_nikon", "(c) camera unknown (Nikon photo), 4 pads",
             dict(camera="unknown", encoding="linear"), PADS, (5.0, 97.0), compare="a"),
        Case("c-sigma-known", "oxide", "oxide_sigma", "Sigma known, 16-bit linear PNG, "
             "bare-Si reference", dict(camera=SIGMA, encoding="linear"), (0,)),
        Case("c-sigma", "oxide", "oxide_sigma", "(c) camera unknown (held-out Sigma photo), "
             "4 pads", dict(camera="unknown", encoding="linear"), PADS, (5.0, 97.0),
             compare="c-sigma-known"),
        Case("d-material", "oxide", "oxide_nikon", "(d) trap: Si3N4 declared for SiO2 "
             "(Nikon, bare-Si reference)", dict(camera=NIKON, encoding="linear"), (0,),
             trap=True, template="Si3N4 on Si"),
        Case("d-camera", "oxide", "oxide_nikon", "(d) trap: Sigma declared for a Nikon "
             "photo (bare-Si reference)", dict(camera=SIGMA, encoding="linear"), (0,),
             trap=True),
        Case("b", "soap", "soap_srgb", "(b) sRGB JPEG q90, camera srgb, no reference",
             dict(camera="srgb", encoding="srgb", illuminant=SOAP_LIGHT), (), (5.0, 95.0)),
        Case("b-smooth", "soap", "soap_srgb", f"(b) sRGB JPEG q90, smoothness τ = "
             f"{tau:.3g} nm", dict(camera="srgb", encoding="srgb", illuminant=SOAP_LIGHT,
                                    smoothness_nm=tau), (), (5.0, 95.0)),
        Case("a-soap", "soap", "soap_nikon", "Nikon known, 16-bit linear TIFF, no reference",
             dict(camera=NIKON, encoding="linear", illuminant=SOAP_LIGHT)),
        Case("d-linear", "soap", "soap_srgb", "(d) trap: the sRGB JPEG declared linear",
             dict(camera="srgb", encoding="linear", illuminant=SOAP_LIGHT), trap=True),
        Case("d-material-soap", "soap", "soap_srgb", "(d) trap: SiO2 film declared for "
             "water (sRGB JPEG)", dict(camera="srgb", encoding="srgb",
                                        illuminant=SOAP_LIGHT), trap=True,
             template="SiO2 film in air"),
    )
    return rows if extras else tuple(r for r in rows if r.key != "a-noref")


def _template(case: Case, tpl: dict):
    if case.template == "Si3N4 on Si":
        return Film(0.0, refractive_index("Si3N4"), refractive_index("Si"))
    if case.template == "SiO2 film in air":
        return Film(0.0, refractive_index("SiO2"), 1.0)
    return tpl[case.scene]


def score(res, truth, exclude) -> dict:
    """Error statistics of a `PhotoResult` against the true map over its fitted pixels
    outside `exclude` (module docstring)."""
    d = np.asarray(res.thickness)
    ok = np.isfinite(d) & ~exclude
    err = (d - truth)[ok]
    a = np.abs(err)
    right = a < RIGHT_ORDER_NM
    amb = np.asarray(res.ambiguous)[ok]
    se = np.asarray(res.stderr)[ok]
    return {
        "pixels_scored": int(ok.sum()),
        "pixels_not_fitted": int(np.sum(~np.isfinite(d) & ~exclude)),
        "median_abs_nm": float(np.median(a)), "p95_abs_nm": float(np.percentile(a, 95)),
        "max_abs_nm": float(a.max()), "median_error_nm": float(np.median(err)),
        "within_15nm_pct": float(100 * right.mean()),
        "ambiguous_pct": float(100 * amb.mean()),
        "wrong_order_flagged_pct": float(100 * amb[~right].mean()) if (~right).any() else None,
        "right_order_flagged_pct": float(100 * amb[right].mean()) if right.any() else None,
        "wrong_alternative_is_truth_pct": float(100 * np.mean(
            np.abs(np.asarray(res.alternative)[ok][~right] - truth[ok][~right])
            < RIGHT_ORDER_NM)) if (~right).any() else None,
        "right_within_2_stderr_pct": float(100 * np.mean(a[right] <= 2 * se[right]))
        if right.any() else None,
        "median_stderr_nm": float(np.median(se)),
    }


def _maybe(x):
    return None if x is None else float(x)


def _fit(case: Case, photo: CameraPhoto, template, reference):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        res = fit_photo(photo.path, template, reference=reference or None,
                        thickness_range=FIT_RANGE[case.scene], **case.fit)
        seconds = time.perf_counter() - t0
    warned = [str(w.message) for w in caught if w.category is UserWarning]
    return res, seconds, warned


def run_cases(cfg: PhotoConfig, scenes: dict, verbose: bool = True):
    """Fit every case; returns (rows, {key: PhotoResult})."""
    tpl = templates()
    rows, fits, first = [], {}, set()
    for case in cases(cfg.size, cfg.extras):
        photo = scenes["photos"][case.photo]
        ref = [scenes["pads"][i] for i in case.reference]
        exclude = np.zeros((cfg.size, cfg.size), bool)
        for m, _ in ref:
            exclude |= m
        template = _template(case, tpl)
        res, seconds, warned = _fit(case, photo, template, ref)
        row = {"key": case.key, "scene": case.scene, "label": case.label,
               "photo": photo.note, "camera": case.fit["camera"],
               "encoding": case.fit["encoding"], "trap": case.trap,
               "template": case.template or case.scene,
               "reference_nm": [t for _, t in ref], "target": case.target}
        if case.scene not in first:  # the scene's first call: repeat it (warm time)
            first.add(case.scene)
            row["first_call_s"] = seconds
            res, seconds, warned = _fit(case, photo, template, ref)
            row["compile_s"] = max(row["first_call_s"] - seconds, 0.0)
        row.update(score(res, scenes["truth"][case.scene], exclude))
        g = np.asarray(photo.gains)
        row.update({
            "seconds": seconds, "pixels_fitted": int(res.n_pixels),
            "pixels_per_s": res.n_pixels / seconds,
            "reduced_chi2": float(res.reduced_chi2),
            "robust_chi2": _maybe(getattr(res, "robust_chi2", None)), "warned": bool(warned),
            "warnings": list(res.warnings),
            "exposure": float(res.exposure), "exposure_true": float(g[1]),
            "white_balance": [float(v) for v in res.white_balance],
            "white_balance_true": [float(v) for v in g / g[1]],
            "camera_matrix": np.asarray(res.camera_matrix).tolist(),
        })
        if case.target:
            row["target_met"] = bool(row["median_abs_nm"] <= case.target[0]
                                     and row["within_15nm_pct"] >= case.target[1])
        if case.compare in fits:  # Luther: the unknown camera's matrix against the known
            known = np.asarray(fits[case.compare].thickness)
            both = np.isfinite(known) & np.isfinite(res.thickness) & ~exclude
            dd = np.abs(np.asarray(res.thickness) - known)[both]
            row["vs_known_camera"] = {"row": case.compare,
                                      "median_abs_nm": float(np.median(dd)),
                                      "p95_abs_nm": float(np.percentile(dd, 95)),
                                      "differ_15nm_pct": float(100 * np.mean(dd >= 15))}
        fits[case.key] = res
        rows.append(row)
        _log(f"{case.key}: median {row['median_abs_nm']:.2f} nm, within 15 nm "
             f"{row['within_15nm_pct']:.2f} %, χ²ᵣ {row['reduced_chi2']:.3g}, "
             f"{seconds:.1f} s", verbose)
    return rows, fits


def timing_1mp(cfg: PhotoConfig, scenes: dict, verbose: bool = True) -> dict | None:
    """One `fit_photo` call on the 1-megapixel soap JPEG (after the 512² soap rows: its
    programs are compiled, except the gain search's subsample shape)."""
    if not cfg.timing_size:
        return None
    photo = scenes["photos"]["soap_1mp"]
    case = next(c for c in cases(cfg.size) if c.key == "b")  # without the prior
    res, seconds, warned = _fit(case, photo, templates()["soap"], [])
    out = {"size": cfg.timing_size, "seconds": seconds, "pixels": int(res.n_pixels),
           "pixels_per_s": res.n_pixels / seconds, "target_pixels_per_s": 10_000,
           "reduced_chi2": float(res.reduced_chi2), "warned": bool(warned)}
    out.update(score(res, scenes["truth"]["soap_1mp"],
                     np.zeros((cfg.timing_size,) * 2, bool)))
    _log(f"1 MP: {seconds:.1f} s, {out['pixels_per_s']:.0f} px/s", verbose)
    return out


# ----------------------------------------------------------------------------- report
def run(out="figures", quick: bool = False, *, config: PhotoConfig | None = None,
        verbose: bool = True) -> dict:
    """Render the photographs, fit every case, compare the spectrum fits and write
    ``out/photo_study.{json,md,png}``; returns the result (JSON-ready)."""
    if not jax.config.jax_enable_x64:
        raise RuntimeError("the photo study needs float64: "
                           "jax.config.update('jax_enable_x64', True)")
    cfg = config or (PhotoConfig.quick() if quick else PhotoConfig())
    t_all, cpu_all = time.perf_counter(), time.process_time()
    env = environment()
    with tempfile.TemporaryDirectory(prefix="photo_study-") as folder:
        scenes = render_scenes(cfg, folder, verbose)
        rows, fits = run_cases(cfg, scenes, verbose)
        big = timing_1mp(cfg, scenes, verbose)
    spectra = spectra_study(cfg, verbose)
    result = {
        "config": cfg._asdict(), "environment": env,
        "sensor": {"full_well_e": FULL_WELL_E, "read_noise_e": READ_NOISE_E,
                   "jpeg_quality": JPEG_QUALITY, "thickness_step_nm": THICKNESS_STEP_NM},
        "scenes": {"soap": {"range_nm": SOAP_RANGE, "light": SOAP_LIGHT,
                            "swirls": SWIRLS, "fit_range_nm": FIT_RANGE["soap"]},
                   "oxide": {"range_nm": OXIDE_RANGE, "light": "D65",
                             "terraces_nm": TERRACES, "pads": [TERRACES[i] for i in PADS],
                             "fit_range_nm": FIT_RANGE["oxide"]}},
        "exposure": EXPOSURE, "srgb_white_balance": SRGB_WB,
        "render_s": scenes["render_s"], "rows": rows, "timing_1mp": big, "spectra": spectra,
        "sources_sha256": _sources(),
    }
    if cfg.figures:
        plot(result, scenes, fits, f"{out}/photo_study.png")
    result["seconds_total"] = time.perf_counter() - t_all
    result["cpu_seconds_total"] = time.process_time() - cpu_all  # every thread, user + sys
    result["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    result = jsonable(result)
    text = write_report(out, "photo_study", result, markdown)
    if verbose:
        print(text)
    return result


def _sources() -> dict:
    """The first 12 hex digits of the SHA-256 of the modules the fits ran (which version of
    fit_photo made the numbers)."""
    import hashlib

    import thinfilm_jax

    root = Path(thinfilm_jax.__file__).resolve().parent
    return {m: hashlib.sha256((root / m).read_bytes()).hexdigest()[:12]
            for m in ("fit/photo.py", "core/image.py", "spectral/camera.py", "fit/film_fit.py")}


def _pct(x):
    return fmt(x, ".1f")


def markdown(res: dict) -> str:
    """The report's tables (figures/photo_study.md)."""
    env, cfg = res["environment"], res["config"]
    out = [f"Run `{cfg['name']}`: {res['seconds_total']:.0f} s wall, "
           f"{res['cpu_seconds_total']:.0f} s CPU on {env['cpu_count']} CPUs (load "
           f"{', '.join(f'{v:.1f}' for v in env['load_average'])} at start); "
           f"photographs {cfg['size']}×{cfg['size']}, sensor: {res['sensor']['full_well_e']:g} "
           f"e⁻ full well, {res['sensor']['read_noise_e']:g} e⁻ read noise.", "",
           "| case | median \\|err\\| nm | p95 nm | within 15 nm % | ambiguous % | wrong order "
           "flagged % | right order within 2σ % | χ²ᵣ (robust) | warned | exposure (true) | "
           "WB R, B (true) | s | px/s | target |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        wb, wt = r["white_balance"], r["white_balance_true"]
        tgt = ("–" if not r["target"] else
               f"≤ {r['target'][0]:g} nm, ≥ {r['target'][1]:g} %: "
               f"{'met' if r['target_met'] else 'missed'}")
        out.append(
            f"| {r['label']} | {r['median_abs_nm']:.2f} | {r['p95_abs_nm']:.1f} | "
            f"{r['within_15nm_pct']:.2f} | {r['ambiguous_pct']:.1f} | "
            f"{_pct(r['wrong_order_flagged_pct'])} | {_pct(r['right_within_2_stderr_pct'])} | "
            f"{r['reduced_chi2']:.3g} ({fmt(r['robust_chi2'], '.3g')}) | "
            f"{'yes' if r['warned'] else 'no'} | "
            f"{r['exposure']:.3f} ({r['exposure_true']:.3f}) | {wb[0]:.3f}, {wb[2]:.3f} "
            f"({wt[0]:.3f}, {wt[2]:.3f}) | {r['seconds']:.1f} | {r['pixels_per_s']:,.0f} | "
            f"{tgt} |")
    firsts = [r for r in res["rows"] if "first_call_s" in r]
    out += ["", "First call of each scene (compilation included; the rows above time a "
            "second call): " + "; ".join(f"{r['key']}: {r['first_call_s']:.1f} s "
                                          f"(compile ≈ {r['compile_s']:.1f} s)"
                                          for r in firsts) + "."]
    lut = [r for r in res["rows"] if "vs_known_camera" in r]
    if lut:
        out += ["", "The unknown camera (fitted on the pads) against the known camera on the "
                "same photograph (Luther's condition):", "",
                "| case | against | median \\|Δd\\| nm | p95 nm | differ by ≥ 15 nm % |",
                "|---|---|---|---|---|"]
        for r in lut:
            v = r["vs_known_camera"]
            out.append(f"| {r['label']} | {v['row']} | {v['median_abs_nm']:.2f} | "
                       f"{v['p95_abs_nm']:.1f} | {v['differ_15nm_pct']:.2f} |")
    big = res["timing_1mp"]
    if big:
        out += ["", f"1-megapixel timing: the {big['size']}×{big['size']} soap JPEG, one call "
                f"(programs compiled, but for the gain search's subsample shape): "
                f"{big['seconds']:.1f} s, {big['pixels_per_s']:,.0f} pixels/s (target ≥ "
                f"{big['target_pixels_per_s']:,}: "
                f"{'met' if big['pixels_per_s'] >= big['target_pixels_per_s'] else 'missed'}); "
                f"median |err| {big['median_abs_nm']:.2f} nm, within 15 nm "
                f"{big['within_15nm_pct']:.2f} %."]
    sp = res["spectra"]
    out += ["", f"Spectra: soap film at normal incidence, {sp['wavelength_nm'][0]:g}–"
            f"{sp['wavelength_nm'][1]:g} nm at 1 nm; median (max) |error| nm over "
            f"{sp['repeats']} noise realisations; time per spectrum (fit_spectrum warm; its "
            f"first call compiled for {fmt(sp['fit_spectrum_compile_s'], '.1f')} s); "
            "failed: the method refused or returned no number.", "",
            "| d nm | fringes | spectrum | fit_spectrum | optifik, its rule (method) | "
            "optifik FFT | optifik min-max | optifik Scheludko | ms: fit / rule |",
            "|---|---|---|---|---|---|---|---|---|"]

    def cell(v):
        s = f"{fmt(v['median_abs_nm'], '.2f')} ({fmt(v['max_abs_nm'], '.2f')})"
        return s + (f", {v['failed']} failed" if v["failed"] else "")

    for r in sp["rows"]:
        ms = " / ".join(f"{1e3 * r[k]['seconds']:.1f}" for k in ("fit_spectrum", "rule"))
        amb = r["fit_spectrum"]["ambiguous"]
        out.append(f"| {r['thickness_nm']:g} | {r['orders']:.1f} | {r['variant']} | "
                   f"{cell(r['fit_spectrum'])}{f', {amb} ambiguous' if amb else ''} | "
                   f"{cell(r['rule'])} ({', '.join(r['rule_methods'])}) | {cell(r['fft'])} | "
                   f"{cell(r['minmax'])} | {cell(r['scheludko'])} | {ms} |")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- figure
def plot(res: dict, scenes: dict, fits: dict, path: str):
    """Per shown case: the photograph, the true and fitted maps, the error map and the
    ambiguity mask; last row: the spectrum fits against optifik."""
    from matplotlib.colors import ListedColormap

    from thinfilm_jax.core.files import atomic_write
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    by = {r["key"]: r for r in res["rows"]}
    shown = [k for k in ("a", "c-sigma", "b", "b-smooth") if k in fits]
    fig, axes = plt.subplots(len(shown) + 1, 5, figsize=(21, 4.1 * (len(shown) + 1)),
                             squeeze=False)
    for i, key in enumerate(shown):
        r, fit = by[key], fits[key]
        case = next(c for c in cases(res["config"]["size"], True) if c.key == key)
        truth = scenes["truth"][r["scene"]]
        photo = scenes["photos"][case.photo]
        lo, hi = FIT_RANGE[r["scene"]][0], np.nanmax(truth) * 1.05
        ax = axes[i]
        ax[0].imshow(photo.display, interpolation="nearest")
        ax[0].set_title(("photograph (sRGB JPEG as fitted)" if photo.path.endswith(".jpg")
                         else "scene in sRGB, D65 (fitted: the camera's raw file)"),
                        fontsize=9)
        ax[0].set_ylabel(f"{r['label']}", fontsize=9)
        for j, (img, title) in enumerate(((truth, "true thickness"),
                                          (fit.thickness, "fitted thickness")), start=1):
            im = ax[j].imshow(img, vmin=lo, vmax=hi, cmap="viridis", interpolation="nearest")
            ax[j].set_title(title + " (nm)", fontsize=9)
            fig.colorbar(im, ax=ax[j], fraction=0.046, pad=0.02, label="nm")
        err = fit.thickness - truth
        im = ax[3].imshow(err, vmin=-15, vmax=15, cmap="RdBu_r", interpolation="nearest")
        fig.colorbar(im, ax=ax[3], fraction=0.046, pad=0.02, label="fitted − true (nm)",
                     extend="both")
        ax[3].set_title(f"error: median |err| {r['median_abs_nm']:.2f} nm, within 15 nm "
                        f"{r['within_15nm_pct']:.1f} %", fontsize=9)
        wrong = np.abs(err) >= RIGHT_ORDER_NM
        amb = np.asarray(fit.ambiguous)
        cls = np.where(np.isnan(err), 4, amb * 1 + wrong * 2)  # 0 ok, 1 amb, 2 wrong, 3 both
        cmap = ListedColormap(["#f2f2f2", "#f4a742", "#c0392b", "#6c3483", "#000000"])
        ax[4].imshow(cls, cmap=cmap, vmin=-0.5, vmax=4.5, interpolation="nearest")
        ax[4].set_title(f"ambiguous (orange, {r['ambiguous_pct']:.1f} %), wrong order "
                        f"unflagged (red),\nwrong order flagged (purple), not fitted (black); "
                        f"χ²ᵣ {r['reduced_chi2']:.2f}", fontsize=8)
        for a in ax:
            a.set_xticks([])
            a.set_yticks([])
    sp = res["spectra"]
    ax = axes[-1]
    styles = {"fit_spectrum": ("k", "o"), "rule": ("C3", "D"), "fft": ("C0", "s"),
              "minmax": ("C1", "^"), "scheludko": ("C2", "v")}
    variants = list(dict.fromkeys(r["variant"] for r in sp["rows"]))
    for j, var in enumerate(variants[:3]):
        a = ax[j]
        rows = [r for r in sp["rows"] if r["variant"] == var]
        d = [r["thickness_nm"] for r in rows]
        for k, (c, m) in styles.items():
            e = [np.nan if r[k]["median_abs_nm"] is None else max(r[k]["median_abs_nm"], 1e-3)
                 for r in rows]
            a.loglog(d, e, color=c, marker=m, label=k if k == "fit_spectrum"
                     else f"optifik {k}")
        a.axhline(RIGHT_ORDER_NM, color="0.6", lw=0.8, ls=":")
        a.set(xlabel="film thickness d (nm)", ylabel="median |error| (nm)",
              title=f"soap spectra 400–800 nm, {var}")
        a.legend(fontsize=7)
    a = ax[3]
    rows = [r for r in sp["rows"] if r["variant"] == variants[0]]
    for k, (c, m) in styles.items():
        a.semilogy([r["thickness_nm"] for r in rows], [1e3 * r[k]["seconds"] for r in rows],
                   color=c, marker=m, label=k)
    a.set(xscale="log", xlabel="film thickness d (nm)", ylabel="ms per spectrum",
          title="time per spectrum (fit_spectrum warm)")
    a.legend(fontsize=7)
    big = res.get("timing_1mp")
    a = ax[4]
    a.axis("off")
    lines = [f"{r['key']}: {r['median_abs_nm']:.2f} nm, {r['within_15nm_pct']:.1f} % ≤ 15 nm,"
             f" χ²ᵣ {r['reduced_chi2']:.2f}{', warned' if r['warned'] else ''}"
             for r in res["rows"]]
    if big:
        lines.append(f"1 MP soap JPEG: {big['pixels_per_s']:,.0f} px/s")
    a.text(0.0, 1.0, "\n".join(lines), va="top", fontsize=8, family="monospace")
    fig.suptitle(f"fit_photo on independently rendered photographs "
                 f"({res['config']['size']}², photon noise {FULL_WELL_E:g} e⁻ full well, "
                 f"read noise {READ_NOISE_E:g} e⁻; soap under {SOAP_LIGHT}, oxide under D65)",
                 fontsize=11)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80, format="png",
                                               metadata=_PNG_METADATA))
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="figures", help="output folder (default: figures)")
    ap.add_argument("--quick", action="store_true", help="96 × 96 photographs, few spectra")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    run(out=args.out, quick=args.quick, verbose=not args.quiet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
