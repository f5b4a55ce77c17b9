"""`fit_spectrum` against optifik on soap-film spectra (the photographs study's last part,
`benchmarks.photo_study`): normal-incidence reflectance of a water film in air on 400–800 nm
(1 nm), at thicknesses from a few hundred nm to several µm, with white noise and a lamp
tilt; per thickness and variant the median and largest error in nm, failures, and the time
of `fit_spectrum` and of each of optifik's estimators and its documented choice among them.

Example (optifik's documented settings used here):
    >>> from benchmarks.photo_spectra import OPTIFIK_DISTANCE, OPTIFIK_PROMINENCE
    >>> OPTIFIK_PROMINENCE, OPTIFIK_DISTANCE
    (0.02, 10)
"""

from __future__ import annotations

import time
import warnings

import jax
import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.core.stack import Stack
from thinfilm_jax.fit.film_fit import fit_spectrum
from thinfilm_jax.fit.options import FitOptions
from thinfilm_jax.optics.materials import refractive_index
from thinfilm_jax.optics.stack import stack_reflectance
from ._timing import fmt, log

#: optifik's documented settings (its notebooks "Choice of method", "FFT", "Peak fitting",
#: "Scheludko renormalisation"): extrema found on the Savitzky–Golay-smoothed spectrum with a
#: prominence of 0.02 and a distance of 10 samples; more than 15 → FFT (zero-padding × 8),
#: 5–15 → min-max (linear regression), at most 4 → Scheludko (order 0, with the void
#: spectrum, when a single maximum is all there is)
OPTIFIK_PROMINENCE, OPTIFIK_DISTANCE, OPTIFIK_PADDING = 0.02, 10, 8


def _optifik(lam, obs, n_lam):
    """optifik on one spectrum (its documented settings, above): {method: (d or NaN,
    seconds)} for its three estimators and for its documented choice among them ("rule",
    with "rule_method"); a refusal is NaN (its message under "<method>_error")."""
    from optifik.analysis import finds_peak, smooth_intensities
    from optifik.fft import thickness_from_fft
    from optifik.minmax import thickness_from_minmax
    from optifik.scheludko import get_default_start_stop_wavelengths, thickness_from_scheludko

    kw = dict(min_peak_prominence=OPTIFIK_PROMINENCE)
    out = {}

    def fft(s):
        return thickness_from_fft(lam, s, refractive_index=n_lam,
                                  N_padding=OPTIFIK_PADDING).thickness

    def minmax(s):
        return thickness_from_minmax(lam, s, refractive_index=n_lam,
                                     min_peak_distance=OPTIFIK_DISTANCE, **kw).thickness

    def scheludko(s):
        start, stop = get_default_start_stop_wavelengths(lam, s, n_lam, **kw)
        return thickness_from_scheludko(lam, s, n_lam, wavelength_start=start,
                                        wavelength_stop=stop).thickness

    def scheludko0(s):  # a free film's void spectrum is dark: zeros
        return thickness_from_scheludko(lam, s, n_lam, interference_order=0,
                                        intensities_void=np.zeros_like(s)).thickness

    def rule(s):
        lo, hi = finds_peak(lam, s, min_peak_distance=OPTIFIK_DISTANCE, **kw)
        k = len(lo) + len(hi)
        if k > 15:
            return "fft", fft(s)
        if k >= 5:
            return "minmax", minmax(s)
        if len(lo) == 0 and len(hi) == 1:
            return "scheludko order 0", scheludko0(s)
        return "scheludko", scheludko(s)

    def timed(name, fn):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = smooth_intensities(obs / np.max(obs))  # inside the timing: its own step
                d = fn(s)
                if name == "rule":
                    out["rule_method"], d = d
                d = float(d)
        except (RuntimeError, ValueError, TypeError) as e:  # optifik's own refusals
            d = float("nan")
            out[name + "_error"] = str(e)
        out[name] = (d, time.perf_counter() - t0)

    for name, fn in (("fft", fft), ("minmax", minmax), ("scheludko", scheludko),
                     ("rule", rule)):
        timed(name, fn)
    return out


def spectra_study(cfg, verbose: bool = True) -> dict:
    """`fit_spectrum` against optifik on soap-film spectra (module docstring); `cfg` gives
    `spectra_thickness`, `spectra_noise` and `spectra_repeats` (`photo_study.PhotoConfig`)."""
    water = refractive_index("water")
    lam = np.arange(400.0, 800.5, 1.0)
    n_lam = np.asarray(water(lam)).real
    stack = Stack([0.0], (water,), 1.0)
    opts = FitOptions(bounds={"thickness": (0.0, 6000.0)})
    initial = Film(1000.0, water, 1.0)
    rng = np.random.default_rng(7)
    variants = [(f"σ = {s:g}", s, 0.0) for s in cfg.spectra_noise]
    variants.append((f"σ = {cfg.spectra_noise[0]:g}, lamp tilt ±5 %",
                     cfg.spectra_noise[0], 0.05))
    rows, compile_s = [], None
    for d in cfg.spectra_thickness:
        r_true = np.asarray(stack_reflectance(stack._replace(thickness=np.array([d])), 1.0,
                                              lam))
        for label, sigma, tilt in variants:
            res = {"fit_spectrum": [], "fft": [], "minmax": [], "scheludko": [], "rule": []}
            times = {k: [] for k in res}
            errors, chosen, flagged = {}, [], 0
            for _ in range(cfg.spectra_repeats):
                lamp = 1.0 + tilt * (lam - 600.0) / 200.0
                obs = r_true * lamp + sigma * rng.standard_normal(lam.size)
                t0 = time.perf_counter()
                fit = fit_spectrum(obs, lam, 1.0, initial=initial, options=opts)
                dt = float(jax.block_until_ready(fit.film.thickness))
                t = time.perf_counter() - t0
                if compile_s is None:  # the first call compiles: time it again
                    t0 = time.perf_counter()
                    jax.block_until_ready(fit_spectrum(obs, lam, 1.0, initial=initial,
                                                       options=opts).film.thickness)
                    compile_s, t = t - (time.perf_counter() - t0), time.perf_counter() - t0
                res["fit_spectrum"].append(dt - d)
                times["fit_spectrum"].append(t)
                flagged += bool(fit.ambiguous)
                for k, v in _optifik(lam, obs, n_lam).items():
                    if k.endswith("_error"):
                        errors[k] = v
                    elif k == "rule_method":
                        chosen.append(v)
                    else:
                        res[k].append(v[0] - d)
                        times[k].append(v[1])
            row = {"thickness_nm": d, "variant": label, "sigma": sigma, "tilt": tilt,
                   "orders": float(2 * n_lam[0] * d / lam[0] - 2 * n_lam[-1] * d / lam[-1])}
            for k in res:
                e = np.abs(res[k])
                row[k] = {"median_abs_nm": float(np.nanmedian(e)) if np.isfinite(e).any()
                          else None, "max_abs_nm": float(np.nanmax(e))
                          if np.isfinite(e).any() else None,
                          "failed": int(np.sum(~np.isfinite(e))),
                          "seconds": float(np.median(times[k]))}
            row["optifik_errors"] = errors
            row["rule_methods"] = sorted(set(chosen))
            row["fit_spectrum"]["ambiguous"] = flagged
            rows.append(row)
        log(f"spectra d = {d:g} nm: fit_spectrum "
             f"{fmt(rows[-len(variants)]['fit_spectrum']['median_abs_nm'], '.2f')} nm", verbose)
    return {"wavelength_nm": [float(lam[0]), float(lam[-1]), 1.0],
            "repeats": cfg.spectra_repeats, "fit_spectrum_compile_s": compile_s,
            "fit_spectrum_box_nm": [0.0, 6000.0], "rows": rows}
