r"""Raw spectrometer spectra of soap films (SPEC §14): `fit_spectrum(..., envelope=k)` on
optifik's published spectra against their labels, with optifik's own estimators beside it.

``python -m benchmarks.raw_spectra --out figures`` writes figures/raw_spectra.json
and raw_spectra.md (``--quick``: every fourth spectrum). The spectra are read from
``shared/real/spectra_optifik`` beside the repository (GPL-3.0, Ziapkoff et al., Eur. Phys.
J. E 49:4, 2026; not copied: the outputs hold our numbers and ratios to the labels only).

**manue_sample3** (69 spectra, labels 118–3975 nm, water n = 1.33 as the labels used): a time
series of one draining film under one lamp. The spectra carry instrument structure no
low-degree polynomial follows (a narrow peak near 490 nm, a bump near 905 nm, the fall-off
above 920 nm: the lamp's emission lines and the detector). Over many fringe orders the
reflectance averaged over the films of the series is flat in λ (the fringes average out),
so the *set reference* L(λ), the median over the series of each spectrum divided by its
mean, is the lamp × detector response up to a smooth factor, from the data alone (no label
used). Each spectrum is divided by L and fitted with `envelope=k` on 450–900 nm (k = 1
main; k = 0, 2 and the raw spectrum without L on every fourth spectrum), thickness in
[0, 5000] nm, σ(λ) estimated by the fit (two passes).

**victor2_order0** (10 spectra, labels 110–124 nm, n(λ) = 1.324188 + 3102.060378/λ² as the
labels used) with its ``void.xy`` (no film: stray light and dark): the void spectrum is the
known offset (`background=`) and the gain is linear in λ (k = 1: the lowest degree that
lets the lamp slope, as manue's rises 3× across its band); the flat lamp (k = 0), which
optifik's Scheludko order-0 normalisation assumes, is fitted too and compared by Δχ² in
the linear fit's noise; 400–800 nm main, 450–800 nm (optifik's band) too. A zeroth-order
film has one maximum as broad as the band, so a lamp slope trades with the thickness: the
study reports that trade.

**Per spectrum**: our thickness and standard error, ours/label, Δχ² = (χ²(label) −
χ²(ours))/s² with the envelope re-projected at the label's thickness (how much worse the
data say the label is, in units of the fit's noise), the thickness implied by each pair of
consecutive extrema of the smoothed, reference-divided spectrum, d = 1/(4n(1/λ_a − 1/λ_b))
(its median and spread), the neighbours in time, and optifik's FFT and min-max (RANSAC)
estimates with the settings of its own tests (λ ≥ 450 nm; smoothed by its Savitzky–Golay
filter for min-max, prominence 0.02, distance 10; its RANSAC draws from NumPy's global
RNG, seeded with `OPTIFIK_SEED` for each call), Scheludko order 0 with the void for victor2.

**Timing** (SPEC §14: a raw fit in ≤ 1 s warm): one `fit_spectrum(..., envelope=2)` on a
victor2 spectrum as the spectrometer gave it (no void subtracted), 400–800 nm (1252
wavelengths), its Cauchy index, thickness in [0, 5000] nm, σ estimated (two searches of the
whole box): a first call on T14143 (the compile, from `jax.monitoring`'s backend-compile
events: zero where the persistent cache held the program), then the median of 5 calls on
T14211, with the 1-min load average. ``python -m benchmarks.raw_spectra --timing`` runs and
prints this row alone (no compilation cache, no files written).

Example (the thickness a pair of consecutive extrema implies):
    >>> round(extrema_pair_thickness(600.0, 650.0, 1.33), 1)
    1466.2
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.fit.film_fit import fit_spectrum, spectrum_model
from thinfilm_jax.fit.options import FitOptions
from thinfilm_jax.fit.raw_spectrum import envelope_basis, project
from thinfilm_jax.fit.spectrum_file import read_spectrum
from thinfilm_jax.optics.index import cauchy
from ._timing import environment, fmt, log, write_report

SETS = ("manue_sample3", "victor2_order0")
#: bands (nm) and envelope degrees of the main fits and the variants (module docstring)
MANUE_BAND, MANUE_K, MANUE_VARIANTS = (450.0, 900.0), 1, (0, 2)
VICTOR_BANDS, VICTOR_K = ((400.0, 800.0), (450.0, 800.0)), 1
THICKNESS_BOX = (0.0, 5000.0)
#: victor2's index as its labels used: n(λ) = A + B/λ², B in µm² (3102.06 nm²)
VICTOR_CAUCHY = (1.324188, 3102.060378e-6)
#: the timing row (module docstring): envelope degree, band, spectra (warm-up, timed), calls
TIMING_K, TIMING_BAND, TIMING_FILES, TIMING_REPEATS = 2, (400.0, 800.0), ("T14143.xy",
                                                                          "T14211.xy"), 5
#: NumPy's global seed for each optifik estimator (its min-max RANSAC is random)
OPTIFIK_SEED = 0
#: the `jax.monitoring` event of one XLA compile (its duration in seconds)
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
#: the manue variants run on every this-many-th spectrum (their cost: three fits each)
VARIANT_STEP = 4
TARGET_WITHIN, TARGET_MEDIAN = 0.95, 0.02


def data_dir() -> Path:
    """``shared/real/spectra_optifik`` beside the repository root."""
    return Path(__file__).resolve().parents[1].parent / "shared" / "real" / "spectra_optifik"


def extrema_pair_thickness(lam_a, lam_b, n):
    """d from two consecutive extrema λ_a < λ_b (half an order apart) at normal incidence:
    2 n d (1/λ_a − 1/λ_b) = 1/2."""
    return 1.0 / (4.0 * n * (1.0 / lam_a - 1.0 / lam_b))


def _labels(folder: Path) -> dict:
    import yaml

    with open(folder / "labels.yaml") as f:
        return {k: float(v) for k, v in yaml.safe_load(f)["known_thicknesses"].items()}


def _extrema(lam, s, n_of):
    """Extrema of the smoothed spectrum s (scipy's Savitzky–Golay, 11 points, cubic;
    `scipy.signal.find_peaks`, prominence 2 % of the range) and the thickness each pair of
    consecutive extrema implies: (positions, [d])."""
    from scipy.signal import find_peaks, savgol_filter

    sm = savgol_filter(s, 11, 3)
    prom = 0.02 * float(np.ptp(sm))
    hi, _ = find_peaks(sm, prominence=prom, distance=5)
    lo, _ = find_peaks(-sm, prominence=prom, distance=5)
    idx = np.sort(np.concatenate([hi, lo]))
    pos = lam[idx]
    ds = [extrema_pair_thickness(a, b, n_of(0.5 * (a + b))) for a, b in zip(pos[:-1], pos[1:])]
    return pos, ds


def _optifik(lam, raw, n_lam, void=None):
    """optifik's estimators as its own tests call them (module docstring): {name: d or None}."""
    from optifik.analysis import smooth_intensities
    from optifik.fft import thickness_from_fft
    from optifik.minmax import thickness_from_minmax
    from optifik.scheludko import thickness_from_scheludko

    out = {}
    m = lam >= 450.0
    lam, raw, n = lam[m], raw[m], (n_lam[m] if np.ndim(n_lam) else n_lam)
    calls = {
        "fft": lambda: thickness_from_fft(lam, raw, refractive_index=n).thickness,
        "minmax": lambda: thickness_from_minmax(
            lam, smooth_intensities(raw), refractive_index=n, min_peak_prominence=0.02,
            min_peak_distance=10, method="ransac").thickness,
    }
    if void is not None:
        calls = {"scheludko0": lambda: thickness_from_scheludko(
            lam, smooth_intensities(raw), refractive_index=n, interference_order=0,
            intensities_void=void[m]).thickness}
    for k, fn in calls.items():
        state = np.random.get_state()  # min-max's RANSAC draws from NumPy's global RNG:
        np.random.seed(OPTIFIK_SEED)  # seeded, so that the study is reproducible
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                v = float(fn())
            out[k] = v if math.isfinite(v) else None
        except (RuntimeError, ValueError, TypeError, IndexError):  # optifik's refusals
            out[k] = None
        finally:
            np.random.set_state(state)
    return out


def _chi2(obs, lam, film, k, w, background=None):
    """Σ r² of the projected residual of `film` (the envelope re-projected: `project`)."""
    import jax.numpy as jnp

    basis, _, _ = envelope_basis(lam, k)
    o = obs if background is None else obs - background
    refl = spectrum_model(film, jnp.ones(1), jnp.asarray(lam))
    r, _ = project(refl, jnp.asarray(o)[None], jnp.asarray(w)[None], jnp.asarray(basis),
                   background is None)
    return float(jnp.sum(r * r))


def _fit(obs, lam, eta, k, background=None):
    opts = FitOptions(bounds={"thickness": THICKNESS_BOX})
    t0 = time.perf_counter()
    res = fit_spectrum(obs, lam, 1.0, initial=Film(1000.0, eta, 1.0), envelope=k,
                       background=background, options=opts)
    d = float(res.film.thickness)
    return res, d, time.perf_counter() - t0


def _row(fn, label, res, d, seconds, obs, lam, eta, k, background=None):
    w = 1.0 / np.asarray(res.envelope.sigma)[0]
    n, p = obs.size, 1 + res.envelope.n_linear
    chi_ours = _chi2(obs, lam, Film(d, eta, 1.0), k, w, background)
    chi_label = _chi2(obs, lam, Film(label, eta, 1.0), k, w, background)
    s2 = chi_ours / (n - p)
    return {"file": fn, "thickness": d, "stderr": float(res.stderr["thickness"]),
            "ratio": d / label, "dchi2_label": (chi_label - chi_ours) / s2,
            "runner_ups": [round(r["params"]["thickness"], 1) for r in res.runner_ups],
            "seconds": seconds}


def manue(verbose: bool = True, step: int = 1) -> dict:
    """The manue_sample3 part (module docstring)."""
    folder = data_dir() / "manue_sample3"
    labels = _labels(folder)
    names = sorted(labels)
    lo, hi = MANUE_BAND
    spectra = {}
    for fn in names:
        lam, v = read_spectrum(folder / fn, nonfinite="drop")
        spectra[fn] = (lam, v)
    lam0 = spectra[names[0]][0]
    m = (lam0 >= lo) & (lam0 <= hi)
    if not all(np.array_equal(spectra[f][0], lam0) for f in names):
        raise ValueError("manue_sample3: the spectra do not share one wavelength grid")
    lam = lam0[m]
    stack = np.stack([spectra[f][1][m] for f in names])
    ref = np.median(stack / stack.mean(axis=1, keepdims=True), axis=0)
    chosen = names[::step]
    every = max(1, VARIANT_STEP // step)  # the variants on every fourth spectrum
    rows, variants = [], {f"k={k}": [] for k in MANUE_VARIANTS}
    variants["raw k=2 (no set reference)"] = []
    for fn in chosen:
        obs = stack[names.index(fn)] / ref
        res, d, sec = _fit(obs, lam, 1.33, MANUE_K)
        row = _row(fn, labels[fn], res, d, sec, obs, lam, 1.33, MANUE_K)
        pos, ds = _extrema(lam, obs, lambda _lam: 1.33)
        row["extrema_nm"] = [round(float(x), 1) for x in pos]
        row["extrema_d_median_ratio"] = (float(np.median(ds)) / labels[fn]) if ds else None
        row["extrema_d_spread"] = (float((np.max(ds) - np.min(ds)) / np.median(ds))
                                   if len(ds) > 1 else None)
        full_lam, full_raw = spectra[fn]
        opt = _optifik(full_lam, full_raw, 1.33)
        row["optifik_ratio"] = {k: (v / labels[fn] if v else None) for k, v in opt.items()}
        if len(rows) % every == 0:
            for k in MANUE_VARIANTS:
                variants[f"k={k}"].append(_fit(obs, lam, 1.33, k)[1] / labels[fn])
            variants["raw k=2 (no set reference)"].append(
                _fit(stack[names.index(fn)], lam, 1.33, 2)[1] / labels[fn])
        rows.append(row)
        log(f"manue {fn}: ours/label {row['ratio']:.4f}, Δχ²(label) "
            f"{row['dchi2_label']:.3g}, {sec:.2f} s", verbose)
    # neighbours in time (the file names are times): our fits of the spectra either side
    for i, row in enumerate(rows):
        nb = [rows[j]["thickness"] for j in (i - 1, i + 1) if 0 <= j < len(rows)]
        row["neighbours_thickness"] = nb
    return {"band_nm": [lo, hi], "k": MANUE_K, "n": 1.33, "rows": rows,
            "variants": {k: _summary(v) for k, v in variants.items()},
            "summary": _summary([r["ratio"] for r in rows]),
            "optifik": {k: _summary([r["optifik_ratio"][k] for r in rows])
                        for k in ("fft", "minmax")},
            "warm_seconds": _warm([r["seconds"] for r in rows])}


def victor(verbose: bool = True) -> dict:
    """The victor2_order0 part (module docstring)."""
    folder = data_dir() / "victor2_order0"
    labels = _labels(folder)
    eta = cauchy(*VICTOR_CAUCHY)

    def n_of(lam):
        return 1.324188 + 3102.060378 / np.asarray(lam) ** 2

    lam_v, void = read_spectrum(folder / "void.xy")
    out = {"bands": {}}
    for band in VICTOR_BANDS:
        rows = []
        m = (lam_v >= band[0]) & (lam_v <= band[1])
        lam = lam_v[m]
        for fn in sorted(labels):
            lam_f, raw = read_spectrum(folder / fn)
            if not np.array_equal(lam_f, lam_v):
                raise ValueError(f"victor2_order0: {fn} and void.xy have different grids")
            res, d, sec = _fit(raw[m], lam, eta, VICTOR_K, background=void[m])
            row = _row(fn, labels[fn], res, d, sec, raw[m], lam, eta, VICTOR_K, void[m])
            d0 = _fit(raw[m], lam, eta, 0, background=void[m])[1]
            row["flat_lamp_ratio"] = d0 / labels[fn]
            # the flat lamp (k = 0) against the linear gain, both in the linear fit's noise
            w = 1.0 / np.asarray(res.envelope.sigma)[0]
            c1 = _chi2(raw[m], lam, Film(d, eta, 1.0), 1, w, void[m])
            c0 = _chi2(raw[m], lam, Film(d0, eta, 1.0), 0, w, void[m])
            row["dchi2_flat_lamp"] = (c0 - c1) / (c1 / (lam.size - 1 - res.envelope.n_linear))
            if band == VICTOR_BANDS[0]:
                opt = _optifik(lam_f, raw, n_of(lam_f), void)
                row["optifik_ratio"] = {k: (v / labels[fn] if v else None)
                                        for k, v in opt.items()}
            rows.append(row)
            log(f"victor {band} {fn}: ours/label {row['ratio']:.4f}", verbose)
        out["bands"][f"{band[0]:g}-{band[1]:g}"] = {
            "rows": rows, "summary": _summary([r["ratio"] for r in rows]),
            "flat_lamp": _summary([r["flat_lamp_ratio"] for r in rows]),
            "warm_seconds": _warm([r["seconds"] for r in rows])}
    first = out["bands"][f"{VICTOR_BANDS[0][0]:g}-{VICTOR_BANDS[0][1]:g}"]["rows"]
    out["optifik"] = {"scheludko0": _summary([r["optifik_ratio"]["scheludko0"]
                                              for r in first])}
    return out


def fit_timing(verbose: bool = True, repeats: int = TIMING_REPEATS) -> dict:
    """Warm and compile time of one raw fit (module docstring, "Timing")."""
    import os

    import jax
    import jax.monitoring as monitoring

    folder = data_dir() / "victor2_order0"
    lo, hi = TIMING_BAND
    spectra = []
    for fn in TIMING_FILES:
        lam, raw = read_spectrum(folder / fn)
        m = (lam >= lo) & (lam <= hi)
        spectra.append((lam[m], raw[m]))
    opts = FitOptions(bounds={"thickness": THICKNESS_BOX})
    initial = Film(1000.0, cauchy(*VICTOR_CAUCHY), 1.0)

    def call(lam, obs):
        t0 = time.perf_counter()
        res = jax.block_until_ready(fit_spectrum(obs, lam, 1.0, initial=initial,
                                                 envelope=TIMING_K, options=opts))
        return time.perf_counter() - t0, float(res.film.thickness)

    compiled = []

    def listen(event, seconds, **_):
        if event == COMPILE_EVENT:
            compiled.append(seconds)

    load_before = list(os.getloadavg())
    monitoring.register_event_duration_secs_listener(listen)
    try:
        first, _ = call(*spectra[0])
        n_first = len(compiled)
        warm = [call(*spectra[1]) for _ in range(max(repeats, 1))]
    finally:
        monitoring.unregister_event_duration_listener(listen)
    out = {"files": list(TIMING_FILES), "n_wavelengths": int(spectra[1][0].size),
           "band_nm": [lo, hi], "k": TIMING_K, "first_s": first,
           "compile_s": float(sum(compiled[:n_first])),
           "recompiles_warm": len(compiled) - n_first,
           "warm_s": [t for t, _ in warm],
           "warm_median_s": float(np.median([t for t, _ in warm])),
           "thickness": warm[-1][1], "load_before": load_before,
           "load_after": list(os.getloadavg())}
    log(timing_line(out), verbose)
    return out


def timing_line(t: dict) -> str:
    """The timing row in words."""
    return (f"one raw fit (envelope={t['k']}, {t['files'][1]}, {t['band_nm'][0]:g}–"
            f"{t['band_nm'][1]:g} nm, {t['n_wavelengths']} wavelengths, σ estimated): warm "
            f"median {t['warm_median_s']:.3f} s of {len(t['warm_s'])} (min "
            f"{min(t['warm_s']):.3f}, max {max(t['warm_s']):.3f}); first call "
            f"({t['files'][0]}) {t['first_s']:.1f} s, of which XLA compile "
            f"{t['compile_s']:.1f} s; {t['recompiles_warm']} recompiles when warm; 1-min "
            f"load average {t['load_before'][0]:.2f} before, {t['load_after'][0]:.2f} after")


def _summary(ratios) -> dict:
    r = np.asarray([np.nan if v is None else v for v in ratios], float)
    e = np.abs(r - 1.0)
    ok = np.isfinite(e)
    return {"n": int(r.size), "failed": int((~ok).sum()),
            "within_10pct": int(np.sum(e[ok] < 0.10)),
            "median_abs_rel": float(np.median(e[ok])) if ok.any() else None,
            "max_abs_rel": float(np.max(e[ok])) if ok.any() else None}


def _warm(seconds):
    s = np.asarray(seconds[1:] if len(seconds) > 1 else seconds)
    return {"median": float(np.median(s)), "max": float(np.max(s))}


KNOWN_TO_FAIL = (
    "optifik's `known_to_fail` spectra (not shipped here) are those whose extrema its "
    "estimators cannot find or pair: a zeroth-order film with no extremum in the band, "
    "spectra whose prominence threshold misses fringes, and thick films whose blue fringes "
    "drown in noise. What a model fit needs for them: (1) the instrument's lamp shape, from "
    "a reference (a mirror, or the set reference of a time series as here) or from the "
    "`void`/dark spectrum as `background=`; a zeroth-order film has one maximum as broad as "
    "the band, so the gain must be of low degree (k ≤ 1, chosen by Δχ²) or known, else it trades "
    "with the thickness (victor2's flat-lamp column); (2) the band cut where the "
    "instrument's structure is not smooth (below 450 nm here); (3) the index the labels "
    "used, dispersive where given; (4) a thickness box wide enough and a screen dense "
    "enough for the bluest fringes (`raw_starts`). None of these is an extremum detector, "
    "so no prominence threshold can drop a fringe.")


def run(out="figures", *, quick: bool = False, verbose: bool = True) -> dict:
    """Both sets (module docstring); writes ``out/raw_spectra.json`` and ``.md``."""
    import jax

    from thinfilm_jax.core.compilation_cache import enable_compilation_cache

    jax.config.update("jax_enable_x64", True)
    enable_compilation_cache()
    if not data_dir().is_dir():
        raise SystemExit(f"raw_spectra: {data_dir()} is absent (the optifik spectra)")
    timing = fit_timing(verbose)  # first: its compile is not shared with the fits below
    result = {"environment": environment(), "timing": timing,
              "manue_sample3": manue(verbose, 4 if quick else 1),
              "victor2_order0": victor(verbose), "known_to_fail": KNOWN_TO_FAIL,
              "targets": {"within_10pct": TARGET_WITHIN, "median_abs_rel": TARGET_MEDIAN}}
    ma = result["manue_sample3"]["summary"]
    vi = result["victor2_order0"]["bands"]["400-800"]["summary"]
    n = ma["n"] + vi["n"]
    result["overall"] = {"n": n, "within_10pct": ma["within_10pct"] + vi["within_10pct"],
                         "fraction_within_10pct": (ma["within_10pct"] + vi["within_10pct"]) / n}
    write_report(out, "raw_spectra", result, markdown)
    return result


def _r(v, spec=".4f"):
    return "—" if v is None else fmt(v, spec)


def markdown(res: dict) -> str:
    ma, vi = res["manue_sample3"], res["victor2_order0"]
    lines = ["# Raw spectrometer spectra: fit_spectrum(..., envelope=k) on optifik's spectra",
             "", "Generated by `python -m benchmarks.raw_spectra` (method: module "
             "docstring). Ratios are ours / optifik's published label.", "",
             f"Overall: {res['overall']['within_10pct']} of {res['overall']['n']} within 10 % "
             f"of the label ({100 * res['overall']['fraction_within_10pct']:.1f} %; target "
             f"{100 * TARGET_WITHIN:.0f} %).", "",
             "## Summary", "",
             "| set, fit | n | within 10 % | median abs(ratio − 1) | max |",
             "|---|---|---|---|---|"]

    def srow(name, s):
        return (f"| {name} | {s['n']} | {s['within_10pct']} | {_r(s['median_abs_rel'])} | "
                f"{_r(s['max_abs_rel'])} |")

    lines.append(srow(f"manue, set reference, k = {ma['k']} (main)", ma["summary"]))
    for k, s in ma["variants"].items():
        lines.append(srow(f"manue, {k}", s))
    for k, s in ma["optifik"].items():
        lines.append(srow(f"manue, optifik {k}", s))
    for band, b in vi["bands"].items():
        lines.append(srow(f"victor2, void background, linear gain k = 1, {band} nm "
                          f"(main)", b["summary"]))
        lines.append(srow(f"victor2, void background, flat lamp k = 0, {band} nm",
                          b["flat_lamp"]))
    lines.append(srow("victor2, optifik Scheludko order 0 (void)", vi["optifik"]["scheludko0"]))
    lines += ["", f"Warm time per fit (two passes, σ estimated): manue median "
              f"{ma['warm_seconds']['median']:.3f} s (max {ma['warm_seconds']['max']:.3f} s); "
              f"victor2 median {vi['bands']['400-800']['warm_seconds']['median']:.3f} s.", "",
              "Timing (SPEC §14, ≤ 1 s warm): " + timing_line(res["timing"]) + ".", "",
              "## manue_sample3 per spectrum", "",
              "Δχ²(label): how much worse the label's thickness fits (envelope re-projected), "
              "in units of the fit's noise; extrema d: the thickness implied by consecutive "
              "extrema (median / label, and (max − min)/median).", "",
              "| file | ours nm | ± | ours/label | Δχ²(label) | extrema d/label | spread | "
              "neighbours nm | optifik FFT/label | min-max/label |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in ma["rows"]:
        lines.append(
            f"| {r['file']} | {r['thickness']:.1f} | {r['stderr']:.2g} | {r['ratio']:.4f} | "
            f"{r['dchi2_label']:.3g} | {_r(r['extrema_d_median_ratio'], '.3f')} | "
            f"{_r(r['extrema_d_spread'], '.2f')} | "
            f"{', '.join(f'{v:.0f}' for v in r['neighbours_thickness'])} | "
            f"{_r(r['optifik_ratio']['fft'], '.3f')} | {_r(r['optifik_ratio']['minmax'], '.3f')} |")
    for band, b in vi["bands"].items():
        lines += ["", f"## victor2_order0, {band} nm", "",
                  "Δχ²(flat lamp): how much worse the flat lamp (k = 0) fits than the linear "
                  "gain, in the linear fit's noise.", "",
                  "| file | ours nm | ± | ours/label | Δχ²(label) | flat lamp/label | "
                  "Δχ²(flat lamp) |"
                  + (" optifik Scheludko/label |" if "optifik_ratio" in b["rows"][0] else ""),
                  "|---|---|---|---|---|---|---|" + ("---|" if "optifik_ratio" in b["rows"][0]
                                                 else "")]
        for r in b["rows"]:
            tail = (f" {_r(r['optifik_ratio']['scheludko0'], '.3f')} |"
                    if "optifik_ratio" in r else "")
            lines.append(f"| {r['file']} | {r['thickness']:.1f} | {r['stderr']:.2g} | "
                         f"{r['ratio']:.4f} | {r['dchi2_label']:.3g} | "
                         f"{r['flat_lamp_ratio']:.3f} | {r['dchi2_flat_lamp']:.3g} |" + tail)
    lines += ["", "## What optifik's known_to_fail spectra would need", "", res["known_to_fail"],
              ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.raw_spectra",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="figures")
    p.add_argument("--quick", action="store_true", help="every fourth manue spectrum")
    p.add_argument("--timing", action="store_true",
                   help="only the timing row, printed (no compilation cache, no files)")
    a = p.parse_args(argv)
    if a.timing:
        import jax

        jax.config.update("jax_enable_x64", True)
        if not data_dir().is_dir():
            raise SystemExit(f"raw_spectra: {data_dir()} is absent (the optifik spectra)")
        print(timing_line(fit_timing(verbose=False)))
        return 0
    run(a.out, quick=a.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
