r"""Error against run time of every evaluation path, speed against peers (issue 4).

`run_bench` (``thinfilm-jax bench``, ``benchmarks/run_bench.py``) measures, for every path
and knob, the error against a converged reference and the warm run time per evaluation,
and writes ``bench.json``, ``error_vs_runtime.png`` (error against time, log axes, Pareto
front) and ``error_vs_runtime.md`` (the table, also printed). The last section of this module
runs every public function at stiff and extreme inputs (`stability_check`, asserted by
tests/test_stability.py) and `write_stability_report` writes ``stability_report.md``.

Two families of paths, each against its own converged float64 reference:

(a) **per shading point** — band reflectance R_j(cos θ) of one film at one angle:
    `rgb_reflectance(method="spectral")` (the reference), the same quadrature on every
    2nd / 4th observer sample, the Fourier path (K 4) with M terms and tabulated or
    Gaussian-fit Ŝ, float32, the CIE 1931 observer, and the real dielectric arithmetic.
    Grid `shading_grid`: 4 materials (`MATERIALS`) × d ∈ [0, 1000] nm × θ ∈ [0°, 89°].
(b) **per patch** — L_j(θ_o, α) under uniform light (SPEC §7): the half-vector quadrature
    of `patch_radiance(method="reference")` at several orders, Monte Carlo
    (`patch_radiance_mc`), `ideal`, `filtered`, `filtered_gt_moments`, `filtered_gt_opd`,
    the LUT against the exact filtered Ŝ, float32; reference:
    `patch_radiance(method="reference", quadrature=(96, 96))` (its own error is checked
    against order 64 and against Monte Carlo, `bench.json["reference_check"]`).
    Grid `patch_grid`: 4 materials × d ∈ {200, 600, 1000} nm × θ_o ∈ {0, 45, 70, 85, 89}° ×
    α ∈ {0.01, 0.1, 0.4}. Also in (b), the **real-time kernels** (`ideal_point_kernel`,
    `filtered_point_kernel`: one shading point given its light-lobe moments, as a renderer
    with a prefiltered table would run it), timed on 10⁶ points and scored on the patch grid
    (kernel output × A against the reference).

Errors: CIEDE2000 ΔE (`colorimetry.delta_e2000`, mirror white) mean / 95th percentile / max
over the grid, and the absolute band error. Times: every path is a `jax.jit`-compiled
function of array inputs (the public functions are called inside `jax.jit`, so their
host-side argument validation is not timed); the first call's time minus the warm time is
reported as compile time; the warm time is the median of `repeats` (≥ 5) calls, each
ended by `jax.block_until_ready`, divided by the number of evaluations in the call.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import platform
import statistics
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._io import atomic_write, write_json
from .airy import airy_reflectance
from .colorimetry import delta_e2000
from .film import Film
from .filtered import filtered_bands
from .fresnel import as_complex
from .lut import build_shat_lut, lut_max_error
from .microfacet import albedo, light_moments, patch_quadrature
from .opd import cos_incidence_from_projection, project_light_moments, taylor_opd_moments
from .patch import patch_radiance, patch_radiance_mc
from .reflectance import fourier_bands, rgb_reflectance
from .series import series_terms
from .spectra import get_observer, sensitivity_ft, shat_at_zero, trapezoid_weights

# name: (eta_film, eta_base, kappa_base, eta_outer)
MATERIALS = {
    "fig7": (1.3, 2.0, 0.5, 1.0),  # Kneiphof et al. 2019 Fig. 2/7 film on an absorbing base
    "soap": (1.33, 1.0, 0.0, 1.0),  # soap film in air (dielectric, η₃ = η₁)
    "tio2_glass": (2.4, 1.5, 0.0, 1.0),  # high-index coating on glass (dielectric)
    "sio2_silver": (1.46, 0.13, 3.99, 1.0),  # oxide on a silver-like metal (Ag near 550 nm)
}
DIELECTRIC_MATERIALS = ("soap", "tio2_glass")
SB = "stiles_burch_1959_10"
CIE = "cie_1931_2"
OFF_GRID_GROUPS = ("dielectric subset", "observer")  # other grid or other reference
ERROR_FLOOR = 1e-6  # ΔE below this (the references: 0) is drawn on the floor of the log plot


@dataclass(frozen=True)
class BenchConfig:
    """Sizes and knobs of one benchmark run (`full()`, `quick()`, `tiny()`)."""

    name: str = "full"
    repeats: int = 5
    # (a) shading points: per material, n_thickness × n_angle points
    n_thickness: int = 48
    n_angle: int = 48
    lambda_steps: tuple[int, ...] = (1, 2, 4)
    fourier_terms: tuple[int, ...] = (1, 2, 3, 4, 8)
    gaussian_terms: tuple[int, ...] = (2, 8)
    m_sweep_max: int = 24
    # (b) patches
    patch_thickness: tuple[float, ...] = (200.0, 600.0, 1000.0)
    patch_theta_deg: tuple[float, ...] = (0.0, 45.0, 70.0, 85.0, 89.0)
    patch_alpha: tuple[float, ...] = (0.01, 0.1, 0.4)
    reference_quadrature: int = 96
    check_quadrature: int = 64
    quadrature_orders: tuple[int, ...] = (8, 16, 24, 32, 48, 64)
    patch_methods: tuple[str, ...] = ("ideal", "filtered", "filtered_gt_moments",
                                      "filtered_gt_opd")
    patch_chunk: int = 12  # patches per timed call (the error pass runs all chunks)
    mc_samples: tuple[int, ...] = (1_000, 10_000, 100_000)
    mc_patches: int = 12
    mc_chunk: int = 4
    lut_resolutions: tuple[tuple[float, int], ...] = ((12.5, 256), (25.0, 128), (50.0, 64),
                                                      (100.0, 32))
    kernel_points: int = 1_000_000
    # peers
    peer_sides: tuple[int, ...] = (100, 1000)  # (angle × wavelength) grids of side² pairs
    tmm_calls: int = 300
    # specialisation rows (float32, CIE 1931, dielectric arithmetic, Gaussian-Ŝ patch and
    # kernel variants) and the dielectric peer film; off only in the smoke test
    extras: bool = True
    stability: bool = True

    @classmethod
    def full(cls) -> BenchConfig:
        return cls()

    @classmethod
    def quick(cls) -> BenchConfig:
        """≤ 1 min smoke version: every family present, small grids, few knobs."""
        return cls(name="quick", n_thickness=12, n_angle=12, lambda_steps=(1, 4),
                   fourier_terms=(1, 2, 4), gaussian_terms=(2,), m_sweep_max=12,
                   patch_thickness=(600.0,), patch_theta_deg=(0.0, 70.0, 89.0),
                   patch_alpha=(0.05, 0.4), reference_quadrature=48, check_quadrature=32,
                   quadrature_orders=(8, 16, 32), patch_methods=("ideal", "filtered_gt_moments"),
                   patch_chunk=8, mc_samples=(1_000,), mc_patches=4, mc_chunk=4,
                   lut_resolutions=((25.0, 128),), kernel_points=10_000, peer_sides=(100,),
                   tmm_calls=40, stability=False)

    @classmethod
    def tiny(cls) -> BenchConfig:
        """The smallest configuration that runs every code path (the smoke test)."""
        return cls(name="tiny", repeats=1, n_thickness=3, n_angle=3, lambda_steps=(1, 2),
                   fourier_terms=(2,), gaussian_terms=(), m_sweep_max=3,
                   patch_thickness=(600.0,), patch_theta_deg=(30.0,), patch_alpha=(0.2,),
                   reference_quadrature=12, check_quadrature=8, quadrature_orders=(8,),
                   patch_methods=("ideal", "filtered_gt_moments"), patch_chunk=2,
                   mc_samples=(64,), mc_patches=1, mc_chunk=1, lut_resolutions=((50.0, 32),),
                   kernel_points=64, peer_sides=(4,), tmm_calls=2, extras=False,
                   stability=False)


# ======================================================================================
# timing and error measurement
# ======================================================================================


class Timing(NamedTuple):
    first_s: float  # first call: compile + run
    warm_s: float  # median warm call
    min_s: float
    max_s: float
    repeats: int

    @property
    def compile_s(self) -> float:
        return max(self.first_s - self.warm_s, 0.0)


def time_call(fn, args, repeats: int):
    """(output, Timing) of ``fn(*args)``: first call, then the median of `repeats` calls."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    ts = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        ts.append(time.perf_counter() - t0)
    return out, Timing(first, statistics.median(ts), min(ts), max(ts), len(ts))


def time_host(fn, repeats: int) -> Timing:
    """Timing of a host (NumPy / Python) callable: first call and median of `repeats`."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    ts = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return Timing(first, statistics.median(ts), min(ts), max(ts), len(ts))


def error_stats(values, ref, observer: str = SB, labels=None) -> dict:
    """CIEDE2000 mean / p95 / max and absolute band error of `values` against `ref` (…, J);
    with `labels` (one per case), also the case of the largest ΔE."""
    v = np.asarray(values, np.float64)
    r = np.asarray(ref, np.float64)
    finite = bool(np.all(np.isfinite(v)))
    if not finite:
        return {"dE_mean": math.nan, "dE_p95": math.nan, "dE_max": math.nan,
                "band_abs_mean": math.nan, "band_abs_max": math.nan, "finite": False}
    de = np.asarray(delta_e2000(v, r, observer)).ravel()
    diff = np.abs(v - r)
    out = {"dE_mean": float(de.mean()), "dE_p95": float(np.percentile(de, 95)),
           "dE_max": float(de.max()), "band_abs_mean": float(diff.mean()),
           "band_abs_max": float(diff.max()), "finite": True}
    if labels is not None and de.size:
        out["worst_case"] = str(np.asarray(labels).ravel()[int(np.argmax(de))])
    return out


def case_labels(names, film: Film, cos_theta=None, theta_o=None, alpha=None) -> np.ndarray:
    """Human-readable grid points ("fig7 d=600 nm θ=85.0°", …) for the worst-case column."""
    d = np.asarray(film.thickness)
    if cos_theta is not None:
        deg = np.degrees(np.arccos(np.clip(cos_theta, -1, 1)))
        return np.array([f"{n} d={x:.0f} nm θ={t:.1f}°" for n, x, t in zip(names, d, deg)])
    return np.array([f"{n} d={x:.0f} nm θo={np.degrees(t):.0f}° α={a:g}"
                     for n, x, t, a in zip(names, d, theta_o, alpha)])


def make_row(family: str, path: str, group: str, knobs: dict, dtype, n_eval: int,
             timing: Timing | None, err: dict | None, error_vs: str, **extra) -> dict:
    """One table row; times are per evaluation (shading point or patch)."""
    row = {"family": family, "path": path, "group": group, "knobs": knobs,
           "dtype": np.dtype(dtype).name, "n_eval": int(n_eval), "error_vs": error_vs,
           # on the family's full grid against its reference (else: not on the Pareto front)
           "comparable": group not in OFF_GRID_GROUPS and "dielectric films" not in path}
    row.update(err or {"dE_mean": math.nan, "dE_p95": math.nan, "dE_max": math.nan,
                       "band_abs_mean": math.nan, "band_abs_max": math.nan})
    if timing is not None:
        per = timing.warm_s / max(n_eval, 1)
        row.update({"warm_s_per_eval": per, "evals_per_s": 1.0 / per if per > 0 else math.inf,
                    "warm_s_call": timing.warm_s, "warm_s_min": timing.min_s,
                    "warm_s_max": timing.max_s, "compile_s": timing.compile_s,
                    "repeats": timing.repeats})
    row.update(extra)
    return row


def _log(msg: str, verbose: bool):
    if verbose:
        print(f"[bench] {msg}", file=sys.stderr, flush=True)


def _as(tree, dtype):
    return jax.tree.map(lambda x: jnp.asarray(x, dtype), tree)


# ======================================================================================
# grids
# ======================================================================================


def material_film(names, thickness) -> Film:
    """A `Film` per (material name, thickness) pair (flat arrays, float64)."""
    p = np.array([MATERIALS[n] for n in names], np.float64).reshape(-1, 4)
    d = np.asarray(thickness, np.float64)
    return Film(d, p[:, 0], p[:, 1], p[:, 2], p[:, 3])


def shading_grid(cfg: BenchConfig, materials=tuple(MATERIALS)):
    """Family (a) grid: materials × d ∈ linspace(0, 1000) nm × θ ∈ linspace(0°, 89°).

    Returns (film, cos_theta, material name per point), flat float64 arrays.
    """
    d = np.linspace(0.0, 1000.0, cfg.n_thickness)
    th = np.deg2rad(np.linspace(0.0, 89.0, cfg.n_angle))
    m, dd, tt = np.meshgrid(np.arange(len(materials)), d, th, indexing="ij")
    names = np.asarray(materials)[m.ravel()]
    return material_film(names, dd.ravel()), np.cos(tt.ravel()), names


def patch_grid(cfg: BenchConfig, materials=tuple(MATERIALS)):
    """Family (b) grid: materials × d × θ_o × α (`BenchConfig` lists); flat float64."""
    m, d, t, a = np.meshgrid(np.arange(len(materials)), cfg.patch_thickness,
                             np.deg2rad(cfg.patch_theta_deg), cfg.patch_alpha, indexing="ij")
    names = np.asarray(materials)[m.ravel()]
    return material_film(names, d.ravel()), t.ravel(), a.ravel(), names


@functools.cache
def jitted_rgb(**kw):
    """`rgb_reflectance` with fixed options under one `jax.jit` (cached: one compile per
    option set and input shape; the host-side validation is skipped on tracers)."""
    return jax.jit(lambda film, cos_theta: rgb_reflectance(film, cos_theta, **kw))


@functools.cache
def jitted_patch(**kw):
    """`patch_radiance` with fixed options under one `jax.jit` (cached like `jitted_rgb`)."""
    return jax.jit(lambda film, theta_o, alpha, lut=None: patch_radiance(film, theta_o, alpha,
                                                                         lut=lut, **kw))


def _take(tree, idx):
    return jax.tree.map(lambda x: np.asarray(x)[idx], tree)


def _chunked(fn, args, chunk: int, repeats: int):
    """Evaluate ``fn`` over the leading axis of `args` in chunks of one shape (one compile);
    time the first chunk. Returns (outputs (P, …) as NumPy, Timing of one chunk call)."""
    n = len(jax.tree.leaves(args)[0])
    chunk = max(1, min(chunk, n))
    pad = (-n) % chunk
    idx = np.concatenate([np.arange(n), np.full(pad, n - 1, int)])
    out0, timing = time_call(fn, _take(args, idx[:chunk]), repeats)
    outs = [np.asarray(out0)]
    for s in range(chunk, n + pad, chunk):
        outs.append(np.asarray(fn(*_take(args, idx[s:s + chunk]))))
    return np.concatenate(outs)[:n], timing, chunk


# ======================================================================================
# family (a): per shading point
# ======================================================================================


def subsampled_observer(observer: str, step: int):
    """(λ, W) of `observer` on every `step`-th tabulated sample, trapezoid weights on the
    kept nodes, each band renormalised to unit area (step 1 is the library's quadrature)."""
    obs = get_observer(observer)
    s = obs.weights / trapezoid_weights(obs.wavelengths)[:, None]  # ∝ S_j(λ_k)
    lam = obs.wavelengths[::step]
    w = trapezoid_weights(lam)[:, None] * s[::step]
    return lam, w / w.sum(axis=0)


def spectral_subsampled(film: Film, cos_theta, lam, weights, base: str = "general"):
    """Σ_k W_kj R(θ, λ_k) with `airy_reflectance` on the given nodes (broadcast inputs)."""
    film_k = Film(*(jnp.asarray(x)[..., None] for x in film))
    dtype = jnp.result_type(cos_theta, float)
    r = airy_reflectance(film_k, jnp.asarray(cos_theta)[..., None], jnp.asarray(lam, dtype),
                         base=base)
    return r @ jnp.asarray(weights, dtype)


def fourier_partial_sums(film: Film, cos_theta, observer: str, m_max: int,
                         shat: str = "tabulated", base: str = "general"):
    """R_j of the Fourier path for every M = 0 … m_max at once, shape (m_max + 1, …, J).

    The same sum as `reflectance.fourier_bands` (K 4), accumulated term by term so that one
    compiled call gives the whole M sweep; `run_bench` checks it against `rgb_reflectance`.
    """
    st = series_terms(film, cos_theta, base=base)
    dtype = jnp.result_type(cos_theta, float)
    s0 = shat_at_zero(observer, dtype, shat)
    z = as_complex(st.z[..., None])
    zm = jnp.ones_like(z)
    acc = st.c0[..., None] * s0
    sums = [jnp.mean(acc, axis=0)]
    for m in range(1, m_max + 1):
        zm = zm * z
        acc = acc + 2.0 * st.amp[..., None] * jnp.real(
            zm * sensitivity_ft(-m * st.opd, observer, method=shat))
        sums.append(jnp.mean(acc, axis=0))
    return jnp.stack(sums)


def _smallest_m(errs: list[dict], key: str, tol: float):
    for m, e in enumerate(errs):
        if e[key] < tol:
            return m
    return None


def _shading_extras(cfg, run, rgb, film, c, film32, c32, names, ref, m32):
    """Family (a) specialisation rows: float32, CIE 1931, dielectric arithmetic."""
    run(rgb(method="spectral", base="general"), (film32, c32), "spectral f32", "float32",
        {"lambda_step": 1}, np.float32, ref)
    run(rgb(method="fourier", terms=m32, base="general"), (film32, c32), f"Fourier M={m32} f32",
        "float32", {"terms": m32, "shat": "tabulated"}, np.float32, ref)
    run(rgb(method="fourier", terms=m32, shat="gaussian", base="general"), (film32, c32),
        f"Fourier M={m32}, Gaussian Ŝ f32", "float32", {"terms": m32, "shat": "gaussian"},
        np.float32, ref)
    # one observer: the cost scales with its number of samples (CIE 1931 at 1 nm: 471)
    ref_cie = run(rgb(method="spectral", observer=CIE, base="general"), (film, c),
                  "spectral CIE 1931 (reference)", "observer",
                  {"observer": CIE, "n_lambda": len(get_observer(CIE).wavelengths)},
                  np.float64, None, observer=CIE, error_vs="spectral CIE 1931 f64")
    run(rgb(method="fourier", terms=m32, observer=CIE, base="general"), (film, c),
        f"Fourier M={m32} CIE 1931", "observer", {"observer": CIE, "terms": m32}, np.float64,
        ref_cie, observer=CIE, error_vs="spectral CIE 1931 f64")
    # dielectric specialisation (real arithmetic) on the dielectric materials only
    diel = np.isin(names, DIELECTRIC_MATERIALS)
    fd, cd = _take(film, diel), c[diel]
    ref_d = ref[diel]
    for base in ("general", "dielectric"):
        run(rgb(method="spectral", base=base), (fd, cd), f"spectral, {base} arithmetic",
            "dielectric subset", {"base": base, "grid": "dielectric materials"}, np.float64,
            ref_d, n_eval=int(diel.sum()), sel=diel)
        run(rgb(method="fourier", terms=m32, base=base), (fd, cd),
            f"Fourier M={m32}, {base} arithmetic", "dielectric subset",
            {"base": base, "terms": m32, "grid": "dielectric materials"}, np.float64, ref_d,
            n_eval=int(diel.sum()), sel=diel)


def bench_shading(cfg: BenchConfig, verbose: bool = True):
    """Rows of family (a) and the M-per-tolerance sweep."""
    rows, fam = [], "a: shading point"
    film, c, names = shading_grid(cfg)
    n = len(c)
    film32, c32 = film.astype(jnp.float32), jnp.asarray(c, jnp.float32)
    labels = case_labels(names, film, cos_theta=c)

    rgb = jitted_rgb

    def run(fn, args, path, group, knobs, dtype, ref, observer=SB, error_vs="spectral f64",
            n_eval=n, sel=None):
        _log(f"(a) {path}", verbose)
        out, t = time_call(fn, args, cfg.repeats)
        out = np.asarray(out)
        lab = labels if sel is None else labels[sel]
        rows.append(make_row(fam, path, group, knobs, dtype, n_eval, t,
                             error_stats(out, out if ref is None else ref, observer, lab),
                             error_vs))
        return out

    ref = run(rgb(method="spectral", base="general"), (film, c), "spectral (reference)",
              "spectral", {"lambda_step": 1, "n_lambda": len(get_observer(SB).wavelengths)},
              np.float64, None)
    for step in cfg.lambda_steps:
        if step == 1:
            continue
        lam, w = subsampled_observer(SB, step)
        fn = jax.jit(functools.partial(spectral_subsampled, lam=lam, weights=w))
        run(fn, (film, c), f"spectral λ every {step}", "spectral",
            {"lambda_step": step, "n_lambda": len(lam)}, np.float64, ref)
    fourier_out = {}
    for m in cfg.fourier_terms:
        fourier_out[m] = run(rgb(method="fourier", terms=m, base="general"), (film, c),
                             f"Fourier M={m}", "Fourier (tabulated Ŝ)",
                             {"terms": m, "shat": "tabulated"}, np.float64, ref)
    for m in cfg.gaussian_terms:
        run(rgb(method="fourier", terms=m, shat="gaussian", base="general"), (film, c),
            f"Fourier M={m}, Gaussian Ŝ", "Fourier (Gaussian Ŝ)",
            {"terms": m, "shat": "gaussian"}, np.float64, ref)
    m32 = 2 if 2 in cfg.fourier_terms else cfg.fourier_terms[0]
    if cfg.extras:
        _shading_extras(cfg, run, rgb, film, c, film32, c32, names, ref, m32)

    # M per tolerance: every M at once, checked against the timed rgb_reflectance values
    sweep = {}
    for shat in ("tabulated", "gaussian") if cfg.gaussian_terms else ("tabulated",):
        _log(f"(a) M sweep 0…{cfg.m_sweep_max}, {shat} Ŝ", verbose)
        fn = jax.jit(functools.partial(fourier_partial_sums, observer=SB, m_max=cfg.m_sweep_max,
                                       shat=shat))
        sums = np.asarray(fn(film, c))
        errs = [error_stats(s, ref) for s in sums]
        mild = c >= np.cos(np.deg2rad(80.0))
        errs80 = [error_stats(s[mild], ref[mild]) for s in sums]
        entry = {"M": list(range(cfg.m_sweep_max + 1)),
                 "dE_max": [e["dE_max"] for e in errs], "dE_p95": [e["dE_p95"] for e in errs],
                 "dE_mean": [e["dE_mean"] for e in errs],
                 "band_abs_max": [e["band_abs_max"] for e in errs]}
        entry["dE_max_theta_le_80deg"] = [e["dE_max"] for e in errs80]
        for key in ("dE_max", "dE_p95"):
            for tol in (1.0, 0.1):
                entry[f"smallest_M_{key}_below_{tol:g}"] = _smallest_m(errs, key, tol)
                entry[f"smallest_M_{key}_below_{tol:g}_theta_le_80deg"] = _smallest_m(
                    errs80, key, tol)
        if shat == "tabulated":
            entry["max_diff_vs_rgb_reflectance"] = float(max(
                np.abs(sums[m] - fourier_out[m]).max() for m in fourier_out
                if m <= cfg.m_sweep_max))
        sweep[shat] = entry
    return rows, sweep


# ======================================================================================
# family (b): per patch, and the real-time per-point kernels
# ======================================================================================


def ideal_point_kernel(film: Film, cos_o, *, observer: str = SB, terms: int = 2,
                       shat: str = "tabulated", base: str = "general"):
    """BB17 real time at one shading point: R_j(cos θ_o) by K 4 (the `ideal` method / A),
    with the tabulated Ŝ (as `patch_radiance(method="ideal")`) or BB17's Gaussian fit."""
    return fourier_bands(film, cos_o, observer, terms=terms, shat=shat, base=base)


def filtered_point_kernel(film: Film, cos_o, mean, cov, lut=None, *, observer: str = SB,
                          terms: int = 2, shat: str = "lut", base: str = "general"):
    """K 29 at one shading point from the light-lobe moments μ_ω (…, 3), Σ_ω (…, 3, 3).

    ω_o = (sin θ_o, 0, cos θ_o); μ_c, σ_c² by K 20–21; μ_D, σ_D by K 25–28; C*, φ₂* at
    cos θ₁* (K 22); Ŝ(μ, σ²) from the LUT, the exact quadrature or the Gaussian fit.
    Multiplying by A(θ_o, α) gives `patch_radiance(method="filtered_gt_moments")`.
    """
    sin_o = jnp.sqrt(jnp.maximum((1.0 - cos_o) * (1.0 + cos_o), 0.0))
    wo = jnp.stack([sin_o, jnp.zeros_like(cos_o), cos_o], axis=-1)
    mu_c, var_c = project_light_moments(wo, mean, cov)
    opd = taylor_opd_moments(film, mu_c, var_c)
    cos_star = cos_incidence_from_projection(mu_c)
    return filtered_bands(film, cos_star, opd, observer, terms=terms, shat=shat, lut=lut,
                          base=base)


def lobe_moments(theta_o, alpha, order: int = 48):
    """(A, μ_ω, Σ_ω) of p_R per patch from the half-vector quadrature (host arrays)."""
    def one(t, a):
        q = patch_quadrature(t, a, n_u=order, n_phi=order)
        mean, cov = light_moments(q)
        return jnp.sum(q.weight), mean, cov

    a, mean, cov = jax.jit(jax.vmap(one))(jnp.asarray(theta_o), jnp.asarray(alpha))
    return np.asarray(a), np.asarray(mean), np.asarray(cov)


def bench_patches(cfg: BenchConfig, verbose: bool = True):
    """Rows of family (b), the reference checks and the LUT accuracy table."""
    rows, fam = [], "b: patch"
    film, theta, alpha, names = patch_grid(cfg)
    p = len(theta)
    labels = case_labels(names, film, theta_o=theta, alpha=alpha)
    args64 = (film, theta, alpha)
    args32 = _as(args64, jnp.float32)
    q_ref = cfg.reference_quadrature

    patch_fn = jitted_patch

    def run(fn, args, path, group, knobs, dtype, ref, error_vs, chunk=cfg.patch_chunk,
            **extra):
        _log(f"(b) {path}", verbose)
        out, t, ch = _chunked(fn, args, chunk, cfg.repeats)
        rows.append(make_row(fam, path, group, knobs, dtype, ch, t,
                             error_stats(out, ref, SB, labels), error_vs, **extra))
        return out

    ref_name = f"reference quadrature {q_ref}² f64"
    _log(f"(b) reference {q_ref}²", verbose)
    ref, t_ref, ch = _chunked(patch_fn(method="reference", quadrature=(q_ref, q_ref)), args64,
                              cfg.patch_chunk, cfg.repeats)
    rows.append(make_row(fam, f"reference quadrature {q_ref}²", "reference quadrature",
                         {"quadrature": q_ref}, np.float64, ch, t_ref,
                         error_stats(ref, ref), ref_name))
    quad_out = {}
    for order in cfg.quadrature_orders:
        if order == q_ref:
            continue
        quad_out[order] = run(patch_fn(method="reference", quadrature=(order, order)), args64,
                              f"reference quadrature {order}²", "reference quadrature",
                              {"quadrature": order}, np.float64, ref, ref_name)

    # Monte Carlo on a spread subset of patches (fixed key)
    sub = np.unique(np.linspace(0, p - 1, min(cfg.mc_patches, p)).round().astype(int))
    mc_args = (*_take(args64, sub), jax.random.split(jax.random.PRNGKey(20190707), len(sub)))
    mc_check = {}
    for n in cfg.mc_samples:
        def mc(f, t, a, keys, n=n):
            def one(x):
                return patch_radiance_mc(Film(*x[:5]), x[5], x[6], x[7], n_samples=n)
            return jax.lax.map(one, (*f, t, a, keys))

        _log(f"(b) Monte Carlo {n}", verbose)
        (mean, se), t, ch = _chunked_mc(jax.jit(mc), mc_args, cfg.mc_chunk, cfg.repeats)
        rows.append(make_row(fam, f"Monte Carlo {n:.0e}", "Monte Carlo", {"samples": n},
                             np.float64, ch, t, error_stats(mean, ref[sub], SB, labels[sub]),
                             ref_name + " (MC subset)", n_patches=int(len(sub))))
        z = np.abs(mean - ref[sub]) / np.maximum(se, 1e-300)
        mc_check[str(n)] = {"max_abs_diff": float(np.abs(mean - ref[sub]).max()),
                            "max_standard_error": float(se.max()),
                            "max_z": float(z.max()), "patches": int(len(sub))}

    method_out = {}
    for method in cfg.patch_methods:
        method_out[method] = run(patch_fn(method=method), args64, method, "patch method",
                                 {"method": method, "terms": 2, "shat": "exact"}, np.float64,
                                 ref, ref_name)
    for method in ("ideal", "filtered_gt_moments"):
        if cfg.extras and method in cfg.patch_methods:
            run(patch_fn(method=method), args32, f"{method} f32", "float32",
                {"method": method, "terms": 2, "shat": "exact"}, np.float32, ref, ref_name)

    # LUT resolution against the exact filtered quadrature (K 29 with true ω moments)
    exact_k29 = method_out.get("filtered_gt_moments")
    if exact_k29 is None:
        exact_k29 = np.asarray(patch_radiance(*args64, method="filtered_gt_moments"))
    lut_table = []
    for d_mu, n_sigma in cfg.lut_resolutions:
        t0 = time.perf_counter()
        lut = build_shat_lut(d_mu=d_mu, n_sigma=n_sigma)
        jax.block_until_ready(lut)
        build_s = time.perf_counter() - t0
        knobs = {"d_mu": d_mu, "n_sigma": n_sigma, "shat": "lut"}
        fn = patch_fn(method="filtered_gt_moments", shat="lut")
        out = run(lambda f, t, a, fn=fn, lut=lut: fn(f, t, a, lut), args64,
                  f"filtered_gt_moments LUT Δμ={d_mu:g} nσ={n_sigma}", "LUT", knobs,
                  np.float64, ref, ref_name, lut_build_s=build_s)
        rows[-1]["vs_exact_shat"] = error_stats(out, exact_k29)
        lut_table.append({"d_mu": d_mu, "n_sigma": n_sigma, "build_s": build_s,
                          "shat_max_abs_error": lut_max_error(d_mu=d_mu, n_sigma=n_sigma,
                                                              n=4000),
                          "table_shape": list(lut.table.shape),
                          "table_MiB": lut.table.size * lut.table.dtype.itemsize / 2**20,
                          **{f"patch_vs_exact_{k}": v
                             for k, v in rows[-1]["vs_exact_shat"].items()}})
    if cfg.extras:
        run(patch_fn(method="filtered_gt_moments", shat="gaussian"), args64,
            "filtered_gt_moments Gaussian Ŝ", "patch method",
            {"method": "filtered_gt_moments", "shat": "gaussian"}, np.float64, ref, ref_name)

    kernel_rows, kernel_check = bench_kernels(cfg, film, theta, alpha, names, ref, exact_k29,
                                              method_out.get("ideal"), labels, verbose)
    rows += kernel_rows
    ref_check = {
        "reference": f"patch_radiance(method='reference', quadrature=({q_ref}, {q_ref}))",
        "order_check": cfg.check_quadrature,
        "max_band_diff_vs_order_check": (float(np.abs(quad_out[cfg.check_quadrature]
                                                      - ref).max())
                                         if cfg.check_quadrature in quad_out else None),
        "monte_carlo": mc_check,
        **kernel_check,
    }
    return rows, ref_check, lut_table


def _chunked_mc(fn, args, chunk, repeats):
    """`_chunked` for a function returning (mean, se)."""
    def stacked(*a):
        mean, se = fn(*a)
        return jnp.stack([mean, se])

    out, t, ch = _chunked(lambda *a: jnp.moveaxis(stacked(*a), 0, 1), args, chunk, repeats)
    return (out[:, 0], out[:, 1]), t, ch


def bench_kernels(cfg, film, theta, alpha, names, ref, exact_k29, ideal_out, labels, verbose):
    """Per-shading-point real-time kernels on `cfg.kernel_points` points (float32 unless
    stated); the points tile the patch grid, whose outputs × A are scored against `ref`."""
    rows, fam = [], "b: real-time kernel"
    a, mean, cov = lobe_moments(theta, alpha)
    p = len(theta)
    n = max(cfg.kernel_points, p)
    idx = np.arange(n) % p
    lut32 = build_shat_lut(dtype=jnp.float32)
    lut64 = build_shat_lut(dtype=jnp.float64)
    ref_name = f"reference quadrature {cfg.reference_quadrature}² f64 (× A)"

    def inputs(dtype, sel=None):
        i = idx if sel is None else np.flatnonzero(sel)[np.arange(n) % int(sel.sum())]
        return _as((_take(film, i), np.cos(theta[i]), mean[i], cov[i]), dtype), i

    def run(kernel, dtype, path, knobs, sel=None, lut=None):
        _log(f"(kernel) {path}", verbose)
        (f, co, mu, cv), i = inputs(dtype, sel)
        if kernel == "ideal":
            fn = jax.jit(functools.partial(ideal_point_kernel, shat=knobs.get("shat", "tabulated"),
                                           base=knobs.get("base", "general")))
            args = (f, co)
        else:
            fn = jax.jit(lambda f, co, mu, cv, lut: filtered_point_kernel(
                f, co, mu, cv, lut, shat=knobs["shat"], base=knobs.get("base", "general")))
            args = (f, co, mu, cv, lut)
        out, t = time_call(fn, args, cfg.repeats)
        m = p if sel is None else int(sel.sum())
        est = np.asarray(out)[:m] * a[i[:m], None]
        rows.append(make_row(fam, path, "real-time kernel", knobs, dtype, n, t,
                             error_stats(est, ref[i[:m]], SB, labels[i[:m]]), ref_name))
        return est

    ideal = run("ideal", jnp.float32, "kernel ideal M=2 f32", {"kernel": "ideal", "terms": 2})
    k_lut = run("filtered", jnp.float32, "kernel K29 LUT f32",
                {"kernel": "K29", "shat": "lut"}, lut=lut32)
    k_exact = run("filtered", jnp.float32, "kernel K29 exact Ŝ f32",
                  {"kernel": "K29", "shat": "exact"})
    diel = np.isin(names, DIELECTRIC_MATERIALS)
    if cfg.extras:
        run("ideal", jnp.float32, "kernel ideal M=2 Gaussian Ŝ f32",
            {"kernel": "ideal", "terms": 2, "shat": "gaussian"})
        run("filtered", jnp.float32, "kernel K29 Gaussian Ŝ f32",
            {"kernel": "K29", "shat": "gaussian"})
        run("filtered", jnp.float64, "kernel K29 LUT f64", {"kernel": "K29", "shat": "lut"},
            lut=lut64)
    if cfg.extras and diel.any():
        for base in ("general", "dielectric"):
            run("ideal", jnp.float32, f"kernel ideal M=2 f32, {base} (dielectric films)",
                {"kernel": "ideal", "terms": 2, "base": base}, sel=diel)
            run("filtered", jnp.float32, f"kernel K29 LUT f32, {base} (dielectric films)",
                {"kernel": "K29", "shat": "lut", "base": base}, sel=diel, lut=lut32)
    check = {"kernel_K29_exact_vs_patch_filtered_gt_moments_max_abs":
             float(np.abs(k_exact - exact_k29).max()),
             "kernel_K29_lut_vs_exact_max_abs": float(np.abs(k_lut - k_exact).max())}
    if ideal_out is not None:
        check["kernel_ideal_vs_patch_ideal_max_abs"] = float(np.abs(ideal - ideal_out).max())
    return rows, check


# ======================================================================================
# peers: tmm (Byrnes), a vectorised NumPy closed form, colour-science
# ======================================================================================


def numpy_airy(eta_outer, eta_film, n_base, thickness, cos_theta, wavelength):
    """Unpolarised Airy R (SPEC §2) in vectorised complex NumPy, the same formula as
    `airy_reflectance`: r = (r₁₂ + r₂₃e^{iδ})/(1 + r₁₂r₂₃e^{iδ}), δ = 4π d q₂/λ,
    q_k = √(η_k² − η₁² sin²θ₁) on the branch Im q ≥ 0; `n_base` complex."""
    s2 = eta_outer**2 * (1.0 - cos_theta) * (1.0 + cos_theta)

    def q(eps):
        r = np.sqrt(eps - s2 + 0j)
        return np.where(r.imag < 0, -r, r)

    e1, e2, e3 = eta_outer**2 + 0j, eta_film**2 + 0j, np.asarray(n_base, complex) ** 2
    q1, q2, q3 = eta_outer * cos_theta + 0j, q(e2), q(e3)
    phase = np.exp(4j * np.pi * thickness * q2 / wavelength)
    r = 0.0
    for r12, r23 in (((q1 - q2) / (q1 + q2), (q2 - q3) / (q2 + q3)),
                     ((e2 * q1 - e1 * q2) / (e2 * q1 + e1 * q2),
                      (e3 * q2 - e2 * q3) / (e3 * q2 + e2 * q3))):
        amp = (r12 + r23 * phase) / (1.0 + r12 * r23 * phase)
        r = r + 0.5 * (amp.real**2 + amp.imag**2)
    return r


def tmm_unpolarised(eta_outer, eta_film, n_base, thickness, theta, wavelength):
    """½(R_s + R_p) from `tmm.coh_tmm` (one (θ, λ) pair, two calls)."""
    import tmm

    n_list = [eta_outer, eta_film, n_base]
    d_list = [np.inf, thickness, np.inf]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return 0.5 * (tmm.coh_tmm("s", n_list, d_list, theta, wavelength)["R"]
                      + tmm.coh_tmm("p", n_list, d_list, theta, wavelength)["R"])


def colour_unpolarised(eta_outer, eta_film, n_base, thickness, theta, wavelength):
    """½(R_s + R_p) from `colour.phenomena.thin_film_tmm` on the outer product
    θ (A,) × λ (W,) → (A, W). colour takes degrees and returns (W, A, T, 2)."""
    from colour.phenomena import thin_film_tmm

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        r, _ = thin_film_tmm([eta_outer, eta_film, n_base], thickness, wavelength,
                             np.rad2deg(theta))
    return r[:, :, 0, :].mean(axis=-1).T


def bench_peers(cfg: BenchConfig, verbose: bool = True) -> dict:
    """Throughput of `airy_reflectance` (value; value + gradient) against tmm, NumPy and
    colour-science on side × side (θ, λ) grids, θ ∈ [0°, 89°], λ ∈ [380, 780] nm."""
    import colour

    out = {"colour_function": "colour.phenomena.thin_film_tmm",
           "colour_version": colour.__version__, "grids": {},
           "colour_note": "colour.phenomena.tmm.snell_law takes np.real of both indices, so the "
                          "angle in an absorbing base is real: wrong R at oblique incidence on "
                          "absorbing bases (max_abs_diff.colour_vs_tmm; dielectric films agree "
                          "to rounding) and NaN beyond a critical angle (arcsin > 1)"}
    rng = np.random.default_rng(1959)
    films = (("fig7", "general"), ("tio2_glass", "dielectric"))
    for mat, base in films if cfg.extras else films[1:]:
        eta2, eta3, kap3, eta1 = MATERIALS[mat]
        n3 = complex(eta3, kap3)
        d = 600.0
        film = Film(d, eta2, eta3, kap3, eta1)
        for side in cfg.peer_sides:
            key = f"{mat}/{side}x{side}"
            _log(f"(peers) {key}", verbose)
            th = np.deg2rad(np.linspace(0.0, 89.0, side))
            lam = np.linspace(380.0, 780.0, side)
            c = np.cos(th)[:, None]
            n_eval = side * side
            value = jax.jit(lambda f, c, lam, base=base: airy_reflectance(f, c, lam, base=base))
            vg = jax.jit(jax.value_and_grad(
                lambda f, c, lam, base=base: jnp.sum(airy_reflectance(f, c, lam, base=base)),
                argnums=(0, 1)))
            ours, t_val = time_call(value, (film, c, lam[None, :]), cfg.repeats)
            _, t_vg = time_call(vg, (film, c, lam[None, :]), cfg.repeats)
            ours = np.asarray(ours)
            npy = numpy_airy(eta1, eta2, n3, d, c, lam[None, :])
            t_np = time_host(lambda: numpy_airy(eta1, eta2, n3, d, c, lam[None, :]), cfg.repeats)
            # the same pairs as flat arrays: no outer-product structure for NumPy to exploit
            cf, lf = (x.ravel() for x in np.meshgrid(np.cos(th), lam, indexing="ij"))
            _, t_val_flat = time_call(value, (film, cf, lf), cfg.repeats)
            t_np_flat = time_host(lambda: numpy_airy(eta1, eta2, n3, d, cf, lf), cfg.repeats)
            col = colour_unpolarised(eta1, eta2, n3, d, th, lam)
            t_col = time_host(lambda: colour_unpolarised(eta1, eta2, n3, d, th, lam),
                              cfg.repeats)
            k = min(cfg.tmm_calls, n_eval)
            ia, iw = rng.integers(0, side, k), rng.integers(0, side, k)

            def tmm_loop(ia=ia, iw=iw):
                return np.array([tmm_unpolarised(eta1, eta2, n3, d, th[i], lam[j])
                                 for i, j in zip(ia, iw)])

            t0 = time.perf_counter()
            ref = tmm_loop()
            t_tmm = time.perf_counter() - t0
            per = {"airy_value": t_val.warm_s / n_eval, "airy_value_and_grad": t_vg.warm_s / n_eval,
                   "numpy_closed_form": t_np.warm_s / n_eval,
                   "airy_value_flat": t_val_flat.warm_s / n_eval,
                   "numpy_closed_form_flat": t_np_flat.warm_s / n_eval,
                   "colour_thin_film_tmm": t_col.warm_s / n_eval, "tmm_coh_tmm": t_tmm / k}
            col_bad = ~np.isfinite(col)
            out["grids"][key] = {
                "material": mat, "base": base, "thickness_nm": d, "n_eval": n_eval,
                "tmm_calls": int(k), "s_per_eval": per,
                "compile_s": {"airy_value": t_val.compile_s,
                              "airy_value_and_grad": t_vg.compile_s},
                "speedup_airy_vs": {
                    **{name: per[name] / per["airy_value"]
                       for name in ("numpy_closed_form", "colour_thin_film_tmm", "tmm_coh_tmm")},
                    "numpy_closed_form_flat": per["numpy_closed_form_flat"]
                    / per["airy_value_flat"]},
                "grad_over_value_cost": per["airy_value_and_grad"] / per["airy_value"],
                "max_abs_diff": {
                    "airy_vs_tmm": float(np.abs(ours[ia, iw] - ref).max()),
                    "numpy_vs_airy": float(np.abs(npy - ours).max()),
                    "colour_vs_tmm": float(np.nanmax(np.abs(col[ia, iw] - ref))),
                    "colour_vs_airy": float(np.nanmax(np.abs(col - ours))),
                },
                "colour_nonfinite": int(col_bad.sum()),
            }
    return out


# ======================================================================================
# summary, table, figure
# ======================================================================================


def _find(rows, path):
    return next((r for r in rows if r["path"] == path), None)


def summarise_targets(rows, peers) -> dict:
    """Item 4 of issue 4: the cost of each specialisation and the stated targets."""
    def per(path):
        r = _find(rows, path)
        return None if r is None or "warm_s_per_eval" not in r else r["warm_s_per_eval"]

    def ratio(a, b):
        pa, pb = per(a), per(b)
        return None if pa is None or pb is None else pa / pb

    s = {
        "filtered_K29_lut_f32_points_per_s": (1.0 / per("kernel K29 LUT f32")
                                              if per("kernel K29 LUT f32") else None),
        "target_points_per_s": 1e7,
        "filtered_over_ideal_cost (K29 LUT f32 / ideal M=2 f32)":
            ratio("kernel K29 LUT f32", "kernel ideal M=2 f32"),
        "filtered_over_ideal_cost, both Gaussian Ŝ (K29 / ideal M=2, f32)":
            ratio("kernel K29 Gaussian Ŝ f32", "kernel ideal M=2 Gaussian Ŝ f32"),
        "target_filtered_over_ideal": 1.5,
        "lut_over_exact_shat_cost (K29 f32)": ratio("kernel K29 LUT f32",
                                                    "kernel K29 exact Ŝ f32"),
        "f32_over_f64_cost (K29 LUT)": ratio("kernel K29 LUT f32", "kernel K29 LUT f64"),
        "f32_over_f64_cost (spectral)": ratio("spectral f32", "spectral (reference)"),
        "dielectric_over_general_cost (spectral)": ratio("spectral, dielectric arithmetic",
                                                         "spectral, general arithmetic"),
        "dielectric_over_general_cost (Fourier M=2)": ratio(
            "Fourier M=2, dielectric arithmetic", "Fourier M=2, general arithmetic"),
        "cie1931_over_stiles_burch_cost (spectral)": ratio("spectral CIE 1931 (reference)",
                                                           "spectral (reference)"),
        "patch_filtered_over_ideal_cost": ratio("filtered", "ideal"),
        "patch_filtered_gt_moments_over_ideal_cost": ratio("filtered_gt_moments", "ideal"),
    }
    for key, g in peers.get("grids", {}).items():
        s[f"airy_speedup_vs_numpy [{key}]"] = g["speedup_airy_vs"]["numpy_closed_form"]
        s[f"airy_speedup_vs_numpy, flat pairs [{key}]"] = g["speedup_airy_vs"][
            "numpy_closed_form_flat"]
        s[f"airy_speedup_vs_tmm [{key}]"] = g["speedup_airy_vs"]["tmm_coh_tmm"]
    s["target_airy_vs_numpy_at_1e6"] = 2.0
    s["target_airy_vs_tmm"] = 100.0
    return s


def _fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return format(x, spec)


def markdown_table(rows) -> str:
    """The error-vs-time table as markdown (times in µs per evaluation)."""
    head = ("| family | path | dtype | ΔE₀₀ mean | ΔE₀₀ p95 | ΔE₀₀ max | max abs band err "
            "| warm µs / eval | evals / s | compile s | error vs | worst case |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:
        us = r.get("warm_s_per_eval")
        lines.append(
            f"| {r['family']} | {r['path']} | {r['dtype']} | {_fmt(r['dE_mean'])} "
            f"| {_fmt(r['dE_p95'])} | {_fmt(r['dE_max'])} | {_fmt(r['band_abs_max'])} "
            f"| {_fmt(None if us is None else us * 1e6)} | {_fmt(r.get('evals_per_s'), '.3g')} "
            f"| {_fmt(r.get('compile_s'), '.2f')} | {r['error_vs']} "
            f"| {r.get('worst_case', '')} |")
    return "\n".join(lines)


def peers_table(peers) -> str:
    lines = ["| grid | airy value µs | airy value+grad µs | NumPy µs | colour µs | tmm µs "
             "| ×NumPy | ×colour | ×tmm | flat pairs: airy µs | NumPy µs | ×NumPy "
             "| max \\|airy−tmm\\| | max \\|colour−tmm\\| |",
             "|" + "---|" * 14]
    for key, g in peers.get("grids", {}).items():
        p, s, m = g["s_per_eval"], g["speedup_airy_vs"], g["max_abs_diff"]
        lines.append(
            f"| {key} ({g['base']}) | {p['airy_value'] * 1e6:.3g} "
            f"| {p['airy_value_and_grad'] * 1e6:.3g} | {p['numpy_closed_form'] * 1e6:.3g} "
            f"| {p['colour_thin_film_tmm'] * 1e6:.3g} | {p['tmm_coh_tmm'] * 1e6:.3g} "
            f"| {s['numpy_closed_form']:.3g} | {s['colour_thin_film_tmm']:.3g} "
            f"| {s['tmm_coh_tmm']:.3g} | {p['airy_value_flat'] * 1e6:.3g} "
            f"| {p['numpy_closed_form_flat'] * 1e6:.3g} | {s['numpy_closed_form_flat']:.3g} "
            f"| {m['airy_vs_tmm']:.2g} | {m['colour_vs_tmm']:.2g} |")
    return "\n".join(lines)


def pareto_front(times, errors):
    """Indices of the non-dominated points (smaller time and smaller error), by time."""
    order = np.argsort(times, kind="stable")
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(int(i))
            best = errors[i]
    return front


def render_error_vs_runtime(rows, path, *, metric: str = "dE_p95", title: str = "") -> None:
    """Error (ΔE₀₀, log) against warm time per evaluation (s, log), one panel per family,
    Pareto front as a step line. Points carry their row number, listed beside each panel;
    errors below `ERROR_FLOOR` (the references, exact specialisations) are drawn on the floor
    as open markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("a", "(a) per shading point: band reflectance R_j(cos θ)",
               "warm run time per shading point (s)"),
              ("b", "(b) per patch under uniform light: L_j(θ_o, α)",
               "warm run time per patch; per shading point for the kernels (▲) (s)")]
    fig, axes = plt.subplots(1, 2, figsize=(19, 7.5), constrained_layout=True)
    cmap = plt.get_cmap("tab10")
    for ax, (fam, ptitle, xlabel) in zip(axes, panels):
        sel = [(i, r) for i, r in enumerate(rows) if r["family"].startswith(fam)
               and "warm_s_per_eval" in r and np.isfinite(r[metric])]
        groups = sorted({r["group"] for _, r in sel})
        legend = []
        for gi, g in enumerate(groups):
            pts = [(i, r) for i, r in sel if r["group"] == g]
            t = np.array([r["warm_s_per_eval"] for _, r in pts])
            e = np.array([r[metric] for _, r in pts])
            low = e < ERROR_FLOOR
            marker = "^" if g == "real-time kernel" else "o"
            ax.scatter(t[~low], e[~low], color=cmap(gi % 10), label=g, s=34, zorder=3,
                       marker=marker)
            ax.scatter(t[low], np.full(low.sum(), ERROR_FLOOR), facecolors="none",
                       edgecolors=cmap(gi % 10), s=34, zorder=3, marker=marker,
                       label=None if (~low).any() else g)
            for (i, r), x, y in zip(pts, t, np.maximum(e, ERROR_FLOOR)):
                ax.annotate(str(i), (x, y), fontsize=7, xytext=(3, 2),
                            textcoords="offset points")
                legend.append(f"{i:2d} {r['path']} ({r['dtype']})")
        front = [r for _, r in sel if r.get("comparable", True)]
        if front:
            t = np.array([r["warm_s_per_eval"] for r in front])
            e = np.array([max(r[metric], ERROR_FLOOR) for r in front])
            f = pareto_front(t, e)
            ax.step(t[f], e[f], where="post", color="k", lw=1.2, alpha=0.7, zorder=2,
                    label="Pareto front (full-grid rows)")
        ax.axhline(1.0, color="grey", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"CIEDE2000 ΔE vs float64 reference, {metric.split('_')[1]} over the "
                      f"grid (open: < {ERROR_FLOOR:g})")
        ax.set_title(ptitle, fontsize=11)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7, loc="lower left")
        ax.text(1.01, 1.0, "\n".join(sorted(legend, key=lambda x: int(x.split()[0]))),
                transform=ax.transAxes, fontsize=6.3, va="top", ha="left", family="monospace")
    fig.suptitle(title, fontsize=10)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


def environment() -> dict:
    """What ran the benchmark (the table is meaningless without it)."""
    devices = [str(d) for d in jax.devices()]
    return {"jax": jax.__version__, "devices": devices,
            "backend": jax.default_backend(),
            "gpu_available": any(d.platform == "gpu" for d in jax.devices()),
            "x64_enabled": bool(jax.config.jax_enable_x64), "python": platform.python_version(),
            "platform": platform.platform(), "cpu_count": os.cpu_count(),
            "processor": platform.processor(),
            "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
            "date": time.strftime("%Y-%m-%d %H:%M:%S %z")}


def run_bench(out="figures", quick: bool = False, *, config: BenchConfig | None = None,
              verbose: bool = True) -> dict:
    """Run the whole study and write bench.json, error_vs_runtime.png and .md into `out`.

    Args:
        out: output folder.
        quick: the ≤ 1 minute smoke configuration (`BenchConfig.quick`).
        config: an explicit configuration (overrides `quick`).
        verbose: progress on stderr and the tables on stdout.

    Returns:
        the JSON-serialisable result (also written to ``out/bench.json``).
    """
    if not jax.config.jax_enable_x64:
        raise RuntimeError("run_bench needs float64: jax.config.update('jax_enable_x64', True)")
    cfg = config or (BenchConfig.quick() if quick else BenchConfig.full())
    out = Path(out)
    t_start = time.perf_counter()
    env = environment()
    _log(f"config {cfg.name}; devices {env['devices']}", verbose)
    rows_a, m_sweep = bench_shading(cfg, verbose)
    rows_b, ref_check, lut_table = bench_patches(cfg, verbose)
    peers = bench_peers(cfg, verbose)
    rows = rows_a + rows_b
    result = {
        "environment": env,
        "config": dataclasses.asdict(cfg),
        "materials": {k: dict(zip(("eta_film", "eta_base", "kappa_base", "eta_outer"), v))
                      for k, v in MATERIALS.items()},
        "grids": {
            "a": "materials × d ∈ linspace(0, 1000, n_thickness) nm × θ ∈ linspace(0°, 89°, "
                 "n_angle); Stiles & Burch 1959 10° bands unless stated",
            "b": "materials × patch_thickness × patch_theta_deg × patch_alpha (GGX); "
                 "uniform light; Stiles & Burch 1959 10° bands",
            "peers": "θ ∈ linspace(0°, 89°, side) × λ ∈ linspace(380, 780, side) nm, d = 600 nm",
        },
        "rows": rows,
        "pareto": {fam: [rows[i]["path"] for i in _pareto_rows(rows, fam)]
                   for fam in ("a", "b")},
        "m_selection": m_sweep,
        "reference_check": ref_check,
        "lut": lut_table,
        "peers": peers,
        "targets": summarise_targets(rows, peers),
    }
    if cfg.stability:
        _log("stability report", verbose)
        result["stability"] = write_stability_report(out / "stability_report.md")
    result["seconds_total"] = time.perf_counter() - t_start
    title = (f"thinfilm_jax {cfg.name} benchmark on {', '.join(env['devices'])} "
             f"({env['cpu_count']} CPUs, load {env['load_average'][0]:.1f} at start); "
             f"warm median of {cfg.repeats}")
    write_json(out / "bench.json", _jsonable(result))
    render_error_vs_runtime(rows, out / "error_vs_runtime.png", title=title)
    text = report_markdown(result)
    atomic_write(out / "error_vs_runtime.md", lambda tmp: Path(tmp).write_text(text))
    if verbose:
        print(text)
    return result


def _pareto_rows(rows, fam):
    idx = [i for i, r in enumerate(rows) if r["family"].startswith(fam)
           and "warm_s_per_eval" in r and np.isfinite(r["dE_p95"]) and r["comparable"]]
    t = np.array([rows[i]["warm_s_per_eval"] for i in idx])
    e = np.array([max(rows[i]["dE_p95"], ERROR_FLOOR) for i in idx])
    return [idx[j] for j in pareto_front(t, e)] if idx else []


def report_markdown(result: dict) -> str:
    """The printed report: environment, the table, M per tolerance, peers, targets."""
    env, rows = result["environment"], result["rows"]
    lines = [f"## thinfilm_jax benchmark ({result['config']['name']})", "",
             f"Devices: {env['devices']} (GPU available: {env['gpu_available']}), "
             f"{env['cpu_count']} CPUs, jax {env['jax']}, load average at start "
             f"{env['load_average']}, {env['date']}. Warm time: median of "
             f"{result['config']['repeats']} calls per evaluation; compile = first call − warm.",
             "", markdown_table(rows), ""]
    lines += ["Pareto front (ΔE p95 vs time; rows on another grid or reference excluded): "
              "(a) " + ", ".join(result["pareto"]["a"])
              + "; (b) " + ", ".join(result["pareto"]["b"]), ""]
    ms = result["m_selection"]
    lines.append("Smallest Fourier order M (family (a) grid, up to "
                 f"{result['config']['m_sweep_max']}; None = not reached):")
    for shat, e in ms.items():
        lines.append(f"- {shat} Ŝ: ΔE max < 1: {e['smallest_M_dE_max_below_1']}, "
                     f"< 0.1: {e['smallest_M_dE_max_below_0.1']}; ΔE p95 < 1: "
                     f"{e['smallest_M_dE_p95_below_1']}, < 0.1: "
                     f"{e['smallest_M_dE_p95_below_0.1']}; θ ≤ 80° only: ΔE max < 1: "
                     f"{e['smallest_M_dE_max_below_1_theta_le_80deg']}, < 0.1: "
                     f"{e['smallest_M_dE_max_below_0.1_theta_le_80deg']}")
    lines += ["", "Peers (µs per (θ, λ) evaluation; ×: speed-up of airy_reflectance value):",
              "", peers_table(result["peers"]), ""]
    lines.append("Targets and specialisation costs:")
    for k, v in result["targets"].items():
        lines.append(f"- {k}: {_fmt(v, '.3g') if isinstance(v, float) else v}")
    lines += ["", "LUT of Ŝ(μ, σ²) against the exact quadrature (`lut_max_error`, 4000 random "
              "(μ, σ)) and its effect on K 29 (filtered_gt_moments, patch grid):", "",
              "| Δμ nm | nσ | MiB | build s | max \\|Ŝ_LUT − Ŝ\\| | patch ΔE max vs exact Ŝ "
              "| patch max abs band err vs exact Ŝ |", "|---|---|---|---|---|---|---|"]
    for t in result["lut"]:
        lines.append(f"| {t['d_mu']:g} | {t['n_sigma']} | {t['table_MiB']:.2f} "
                     f"| {t['build_s']:.2f} | {t['shat_max_abs_error']:.2g} "
                     f"| {_fmt(t['patch_vs_exact_dE_max'], '.2g')} "
                     f"| {_fmt(t['patch_vs_exact_band_abs_max'], '.2g')} |")
    rc = result["reference_check"]
    lines += ["", f"Reference check: {rc['reference']}; max band diff vs order "
              f"{rc['order_check']}: {_fmt(rc['max_band_diff_vs_order_check'], '.2g')}; "
              "Monte Carlo max z = " + ", ".join(f"{k}: {v['max_z']:.2f}"
                                                 for k, v in rc["monte_carlo"].items())]
    if "stability" in result:
        s = result["stability"]
        lines.append(f"Stability: {s['n_checks']} checks, {s['n_problems']} problems "
                     "(see stability_report.md)")
    return "\n".join(lines) + "\n"


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.floating | float):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


# ======================================================================================
# stability: stiff and extreme inputs (tests/test_stability.py asserts on these results)
# ======================================================================================

STIFF_THICKNESS = (0.0, 1e-6, 500.0, 1e4, 1e5)  # nm
STIFF_OPTICS = (  # (eta_outer, eta_film, eta_base, kappa_base) and what each stresses
    (1.0, 1.0, 1.5, 0.0),  # η₂ = η₁: no 1|2 interface
    (1.0, 1.0 + 1e-12, 1.5, 0.0),  # η₂ = η₁ + 1e-12 (= η₁ in float32)
    (1.0, 4.0, 1.5, 0.0),  # high-index film
    (1.0, 1.3, 2.0, 0.5),  # the Figure 7 film
    (1.0, 1.3, 2.0, 1e-12),  # κ₃ → 0⁺
    (1.0, 1.3, 2.0, 50.0),  # κ₃ huge (perfect-conductor limit)
    (1.0, 1.3, 1.3, 0.0),  # η₃ = η₂: no 2|3 interface
    (1.5, 1.2, 1.0, 0.0),  # η₁ > η₂ > η₃: TIR at 1|2 beyond 53.1° (and at 1|3 beyond 41.8°)
    (1.5, 1.2, 2.0, 0.5),  # TIR at 1|2 over an absorbing base
    (1.33, 1.33, 1.0, 0.0),  # η₂ = η₁ with TIR at the base
)
STIFF_THETA = (0.0, 1e-9, 0.7, 1.2, np.pi / 2 - 1e-9, np.pi / 2)
STIFF_ALPHA = (1e-4, 0.3, 1.0)
STIFF_WAVELENGTH = (380.0, 555.0, 830.0)
STABILITY_QUADRATURE = 8  # patch quadrature order of the stability grid (finiteness, bounds)
F32_BELOW_HALF_PI = float(np.nextafter(np.float32(np.pi / 2), np.float32(0)))
PATCH_METHODS = ("reference", "ideal", "filtered", "filtered_gt_moments", "filtered_gt_opd")
STABILITY_FUNCTIONS = (
    "airy_reflectance", "airy_reflectance[dielectric]", "rgb_reflectance[spectral]",
    "rgb_reflectance[spectral,cie_1931_2]", "rgb_reflectance[fourier,M=2]",
    "rgb_reflectance[fourier,M=2,gaussian]", *(f"patch_radiance[{m}]" for m in PATCH_METHODS),
    "patch_radiance[filtered_gt_moments,lut]", "lut.lookup", "sensitivity_ft[tabulated]",
    "sensitivity_ft[gaussian]", "opd.taylor_opd_moments", "filtered.filtered_bands",
)
# rounding slack of the bounds, by dtype (R ≤ 1: see tests/test_fresnel_airy.py R_MAX_ROUNDING)
BOUND_SLACK = {"float64": 1e-12, "float32": 2e-6}


@dataclass
class StabilityResult:
    """Findings for one public function and dtype over its grid of extreme inputs."""

    function: str
    dtype: str
    n_cases: int = 0
    nonfinite_value: int = 0
    nonfinite_grad: dict = dataclasses.field(default_factory=dict)
    value_min: float = math.nan
    value_max: float = math.nan
    bound: str = ""
    bound_violations: int = 0
    bound_excess: float = 0.0
    reference: str = ""
    ref_tol: float = math.nan
    ref_error: float = math.nan
    ref_violations: int = 0
    documented: list = dataclasses.field(default_factory=list)
    examples: list = dataclasses.field(default_factory=list)
    seconds: float = 0.0

    @property
    def problems(self) -> int:
        bad_doc = sum(1 for d in self.documented if not d["holds"])
        return (self.nonfinite_value + sum(self.nonfinite_grad.values()) + self.bound_violations
                + self.ref_violations + bad_doc)


def _rounded(tree, dtype):
    """`tree` rounded to `dtype`, as float64 NumPy: the inputs a `dtype` run really sees, on
    which its float64 reference is evaluated."""
    return jax.tree.map(lambda x: np.asarray(x).astype(dtype).astype(np.float64), tree)


def stiff_cos(theta):
    """cos θ with cos(π/2) = 0 exactly (the grazing case, not 6e-17)."""
    theta = np.asarray(theta, np.float64)
    return np.where(theta == np.pi / 2, 0.0, np.cos(theta))


def stiff_grid(*axes):
    """Flat product grid of thickness × optics × the extra `axes` (float64 NumPy).

    Returns (Film, [flattened extra axes…]); optics rows come from `STIFF_OPTICS`.
    """
    optics = np.asarray(STIFF_OPTICS)
    grids = np.meshgrid(np.asarray(STIFF_THICKNESS), np.arange(len(optics)),
                        *(np.asarray(a, np.float64) for a in axes), indexing="ij")
    d, o = grids[0].ravel(), grids[1].ravel().astype(int)
    film = Film(d, optics[o, 1], optics[o, 2], optics[o, 3], optics[o, 0])
    return film, [g.ravel() for g in grids[2:]]


def _flat_names(tree, prefix):
    if isinstance(tree, Film):
        return [f"{prefix}.{k}" for k in Film._fields]
    return [prefix]


def value_and_grads(fn, args: tuple, names: tuple[str, ...]):
    """(value, {input name: gradient}) of an elementwise `fn` in one compiled call.

    The gradient is the VJP with an all-ones cotangent, i.e. for an elementwise function
    the per-case derivative of the sum over its outputs (bands, real and imaginary parts).
    """
    def real_fn(*a):
        y = fn(*a)
        return jnp.stack([jnp.real(y), jnp.imag(y)]) if jnp.iscomplexobj(y) else y

    @jax.jit
    def run(*a):
        y, pull = jax.vjp(real_fn, *a)
        return y, pull(jnp.ones_like(y))

    y, grads = run(*args)
    out = {}
    for name, g in zip(names, grads):
        leaves = jax.tree.leaves(g)
        for leaf_name, leaf in zip(_flat_names(g, name), leaves):
            out[leaf_name] = np.asarray(leaf)
    return np.asarray(y), out


def _repro(call: str, args: dict, i: int, dtype: str) -> str:
    parts = []
    for k, v in args.items():
        if isinstance(v, Film):
            f = ", ".join(f"{n}={float(np.asarray(x)[i])!r}" for n, x in zip(Film._fields, v))
            parts.append(f"Film({f}).astype(jnp.{dtype})")
        else:
            parts.append(f"{k}=jnp.{dtype}({float(np.asarray(v).reshape(-1)[i])!r})")
    return f"{call}({', '.join(parts)})"


def _finish(res: StabilityResult, value, grads, case_args: dict, call: str, per_case):
    """Count non-finite values and gradients, and record reproducers of the first ones."""
    v = np.asarray(value)
    bad_v = ~np.isfinite(per_case(v)).all(axis=1)
    res.nonfinite_value = int(bad_v.sum())
    fin = v[np.isfinite(v)]
    res.value_min = float(fin.min()) if fin.size else math.nan
    res.value_max = float(fin.max()) if fin.size else math.nan
    for name, g in grads.items():
        bad = ~np.isfinite(g.reshape(len(bad_v), -1)).all(axis=1)
        res.nonfinite_grad[name] = int(bad.sum())
        if bad.any() and len(res.examples) < 6:
            res.examples.append(f"non-finite d/d{name}: " + _repro(
                call, case_args, int(np.flatnonzero(bad)[0]), res.dtype))
    if bad_v.any():
        res.examples.append("non-finite value: " + _repro(call, case_args,
                                                           int(np.flatnonzero(bad_v)[0]),
                                                           res.dtype))


def _bound_check(res, v, lo, hi, case_args, call, what):
    slack = BOUND_SLACK[res.dtype]
    lo_x = np.maximum(lo - slack - v, 0.0)
    hi_x = np.maximum(v - hi - slack, 0.0)
    excess = np.maximum(lo_x, hi_x)
    per = excess.reshape(excess.shape[0], -1).max(axis=1)
    per = np.where(np.isfinite(per), per, 0.0)
    res.bound = what
    res.bound_violations = int((per > 0).sum())
    res.bound_excess = float(per.max()) if per.size else 0.0
    if res.bound_violations and len(res.examples) < 6:
        i = int(np.argmax(per))
        res.examples.append(f"bound {what} exceeded by {per[i]:.3g}: "
                            + _repro(call, case_args, i, res.dtype))


def _ref_check(res, err, tol, case_args, call, what):
    """Compare per-case errors with tolerances (NaN error = reference not defined there).

    `err` and `tol` broadcast to (cases,) or (cases, bands); with bands, each case is
    judged by its worst band (largest err − tol), and that band's err and tol are reported.
    """
    err = np.asarray(err, np.float64)
    tol = np.broadcast_to(np.asarray(tol, np.float64), err.shape)
    if err.ndim == 2:
        margin = np.where(np.isfinite(err), err - tol, -np.inf)
        j = np.argmax(margin, axis=1)[:, None]
        err = np.take_along_axis(err, j, 1)[:, 0]
        tol = np.take_along_axis(tol, j, 1)[:, 0]
    defined = np.isfinite(err)
    res.reference = what
    res.ref_error = float(err[defined].max()) if defined.any() else math.nan
    res.ref_tol = float(tol[defined].max()) if defined.any() else math.nan
    bad = defined & (err > tol)
    res.ref_violations = int(bad.sum())
    if bad.any() and len(res.examples) < 6:
        i = int(np.argmax(np.where(bad, err - tol, -np.inf)))
        res.examples.append(f"{what}: error {err[i]:.3g} > tol {tol[i]:.3g}: "
                            + _repro(call, case_args, i, res.dtype))


def _weights_range(observer):
    w = get_observer(observer).weights
    return np.minimum(w, 0).sum(0), np.maximum(w, 0).sum(0), np.abs(w).sum(0)


def _tir12(film: Film, cos_theta):
    s2 = np.asarray(film.eta_outer) ** 2 * (1 - np.asarray(cos_theta)) * (1 + np.asarray(cos_theta))
    return s2 > np.asarray(film.eta_film) ** 2


def _tmm_grid(film: Film, cos_theta, lam):
    """tmm.coh_tmm reference per case; NaN where θ = 90° (outside tmm's domain)."""
    out = np.full(len(cos_theta), np.nan)
    for i in range(len(cos_theta)):
        if cos_theta[i] <= 0:
            continue
        n3 = complex(film.eta_base[i], film.kappa_base[i])
        out[i] = tmm_unpolarised(float(film.eta_outer[i]), float(film.eta_film[i]), n3,
                                 float(film.thickness[i]), float(np.arccos(cos_theta[i])),
                                 float(lam[i]))
    return out


def airy_longdouble(film: Film, cos_theta, wavelength):
    """The closed form of `numpy_airy` in NumPy extended precision (x87 80-bit long double
    on x86-64: eps 1.1e-19): a reference where tmm itself loses accuracy (near grazing,
    tmm's cos θ = √(1 − sin²θ) cancels). NaN at cos θ = 0 (0/0 at η₂ = η₁)."""
    ld, cld = np.longdouble, np.clongdouble
    n1, n2, n3r, k3, d = (np.asarray(x, ld) for x in (film.eta_outer, film.eta_film,
                                                     film.eta_base, film.kappa_base,
                                                     film.thickness))
    c, lam = np.asarray(cos_theta, ld), np.asarray(wavelength, ld)
    s2 = n1 * n1 * (1 - c) * (1 + c)

    def q(eps):
        r = np.sqrt(eps - s2.astype(cld))
        return np.where(r.imag < 0, -r, r)

    n3 = n3r.astype(cld) + cld(1j) * k3.astype(cld)
    e1, e2, e3 = (n1 * n1).astype(cld), (n2 * n2).astype(cld), n3 * n3
    q1, q2, q3 = (n1 * c).astype(cld), q(e2), q(e3)
    pi = ld("3.14159265358979323846264338327950288")
    phase = np.exp(cld(4j) * pi * d.astype(cld) * q2 / lam.astype(cld))
    r = np.zeros(np.shape(c), ld)
    with np.errstate(all="ignore"):
        for r12, r23 in (((q1 - q2) / (q1 + q2), (q2 - q3) / (q2 + q3)),
                         ((e2 * q1 - e1 * q2) / (e2 * q1 + e1 * q2),
                          (e3 * q2 - e2 * q3) / (e3 * q2 + e2 * q3))):
            amp = (r12 + r23 * phase) / (1 + r12 * r23 * phase)
            r = r + (amp.real**2 + amp.imag**2) / 2
    return np.where(c > 0, r, np.nan).astype(np.float64)


def check_airy(dtype: str = "float64", base: str = "auto") -> StabilityResult:
    """`airy_reflectance` value and gradients: 0 ≤ R ≤ 1, tmm agreement (float64, θ < 90°),
    R = 1 at grazing incidence, float32 within a phase-scaled tolerance of float64."""
    t0 = time.perf_counter()
    film, (theta, lam) = stiff_grid(STIFF_THETA, STIFF_WAVELENGTH)
    c = stiff_cos(theta)
    if base == "dielectric":  # the real path's domain: κ₃ = 0, η₂ ≥ η₁, η₃ ≥ η₁
        ok = ((film.kappa_base == 0) & (film.eta_film >= film.eta_outer)
              & (film.eta_base >= film.eta_outer))
        film, c, lam = _take(film, ok), c[ok], lam[ok]
    film, c, lam = _rounded((film, c, lam), dtype)
    name = "airy_reflectance" + ("[dielectric]" if base == "dielectric" else "")
    res = StabilityResult(name, dtype, len(c))
    args = _as((film, c, lam), dtype)
    val, grads = value_and_grads(
        lambda f, cc, ll: airy_reflectance(f, cc, ll, base="general" if base == "auto" else base),
        args, ("film", "cos_theta", "wavelength"))
    case_args = {"film": film, "cos_theta": c, "wavelength": lam}
    call = f"airy_reflectance{'' if base == 'auto' else ', base=' + repr(base)}"
    _finish(res, val, grads, case_args, call, lambda v: v[:, None])
    _bound_check(res, val, 0.0, 1.0, case_args, call, "0 ≤ R ≤ 1")
    if dtype == "float64":
        ref = airy_longdouble(film, c, lam)
        phase = 4 * np.pi * film.thickness * film.eta_film / lam  # |δ| bound
        tol = 1e-12 + 4 * np.finfo(np.float64).eps * phase
        _ref_check(res, np.abs(val - ref), tol, case_args, call,
                   "80-bit closed form (θ < 90°), |ΔR| ≤ 1e-12 + 4 eps₆₄ |δ|")
        # tmm where it is itself accurate (cos θ ≥ 1e-3: its √(1 − sin²θ) cancels near
        # grazing) and its transfer matrix is well conditioned (no strongly evanescent film)
        s2 = film.eta_outer**2 * (1 - c) * (1 + c)
        decay = 4 * np.pi * film.thickness * np.sqrt(np.maximum(s2 - film.eta_film**2, 0)) / lam
        use = (c >= 1e-3) & (decay < 30)
        err_tmm = np.abs(val - _tmm_grid(film, np.where(use, c, 0.0), lam))
        res.documented.append({
            "case": "agrees with tmm.coh_tmm to 1e-10 (SPEC §2) where cos θ ≥ 1e-3",
            "n": int(use.sum()), "max_error": float(np.nanmax(err_tmm[use])),
            "holds": bool(np.nanmax(err_tmm[use]) <= 1e-10),
            "note": "near grazing tmm's own error grows (4e-8 at cos θ = 1e-9 against the "
                    "80-bit form, where airy_reflectance is within 3e-13)"})
    else:
        ref = np.asarray(airy_reflectance(film, c, lam))
        phase = 4 * np.pi * film.thickness * film.eta_film / lam  # |δ| bound
        tol = 1e-5 + 4 * np.finfo(np.float32).eps * phase
        _ref_check(res, np.abs(val - ref), tol, case_args, call,
                   "float64, |ΔR| ≤ 1e-5 + 4 eps₃₂ |δ|")
    graz = c == 0
    res.documented.append({"case": "θ = 90° gives R = 1 (every film)", "n": int(graz.sum()),
                           "max_error": float(np.abs(val[graz] - 1).max()) if graz.any() else 0.0,
                           "holds": bool(np.all(np.abs(val[graz] - 1) <= BOUND_SLACK[dtype]))})
    res.seconds = time.perf_counter() - t0
    return res


RGB_VARIANTS = (("spectral", SB, 2, "tabulated"), ("spectral", CIE, 2, "tabulated"),
                ("fourier", SB, 2, "tabulated"), ("fourier", SB, 2, "gaussian"))


def _rgb_variants_fn(variants):
    def fn(film, cos_theta):
        return jnp.stack([rgb_reflectance(film, cos_theta, method=m, observer=o, terms=t,
                                          shat=sh, base="general") for m, o, t, sh in variants])
    return fn


@functools.cache
def _rgb_group(dtype: str):
    """The `RGB_VARIANTS` on the stiff grid in one reverse pass (see `_patch_group`)."""
    film, (theta,) = stiff_grid(STIFF_THETA)
    film, c = _rounded((film, stiff_cos(theta)), dtype)
    values, grads = value_and_grads(_rgb_variants_fn(RGB_VARIANTS), _as((film, c), dtype),
                                    ("film", "cos_theta"))
    return film, c, values, grads


def check_rgb(dtype: str = "float64", method: str = "spectral", observer: str = SB,
              terms: int = 2, shat: str = "tabulated") -> StabilityResult:
    """`rgb_reflectance`: spectral bands within [Σ W⁻, Σ W⁺] (exact: R ∈ [0, 1]); the Fourier
    path within its truncation bound of the spectral one where the series holds, and
    exactly Ŝ_j(0) (R = 1) under TIR at 1|2 (series.py's documented limitation)."""
    t0 = time.perf_counter()
    tag = method if method == "spectral" else f"fourier,M={terms}"
    tag += "" if observer == SB else f",{observer}"
    tag += "" if shat == "tabulated" else f",{shat}"
    res = StabilityResult(f"rgb_reflectance[{tag}]", dtype)
    variant = (method, observer, terms, shat)
    film, c, values, grads = _rgb_group(dtype)
    res.n_cases = len(c)
    val = values[RGB_VARIANTS.index(variant)] if variant in RGB_VARIANTS else None
    if val is None or any(not np.all(np.isfinite(g)) for g in grads.values()):
        val, grads = value_and_grads(_rgb_variants_fn((variant,)), _as((film, c), dtype),
                                     ("film", "cos_theta"))
        val = val[0]
    case_args = {"film": film, "cos_theta": c}
    call = "rgb_reflectance"
    _finish(res, val, grads, case_args, call, lambda v: v.reshape(len(c), -1))
    wlo, whi, wabs = _weights_range(observer)
    spec = np.asarray(rgb_reflectance(film, c, observer=observer, method="spectral",
                                      base="general"))
    tir = _tir12(film, c)
    if method == "spectral":
        _bound_check(res, val, wlo, whi, case_args, call,
                     "Σ_k min(W_kj, 0) ≤ R_j ≤ Σ_k max(W_kj, 0) (R(λ) ∈ [0, 1])")
        if dtype == "float32":
            film_np = film
            phase = 4 * np.pi * film_np.thickness * film_np.eta_film / 380.0
            tol = 2e-5 + 4 * np.finfo(np.float32).eps * phase * wabs.max()
            _ref_check(res, np.abs(val - spec).max(axis=1), tol, case_args, call,
                       "float64 spectral, ≤ 2e-5 + 4 eps₃₂ |δ_max| ‖W‖₁")
        else:
            res.reference = "is the reference (float64)"
    else:
        tail, fit = _series_error_bounds(film, c, terms, observer)
        _bound_check(res, val, wlo - tail, whi + tail, case_args, call,
                     "spectral range ± truncation tail 2|R*−T|·|z|^{M+1}/(1−|z|)·‖W_j‖₁")
        err = np.abs(val - spec)
        eps = np.finfo(dtype).eps
        slack = (1e-12 if dtype == "float64" else 2e-5) + 4 * eps * wabs * (
            4 * np.pi * film.thickness * film.eta_film / 380.0)[:, None]
        no_tir = ~tir[:, None]
        if shat == "tabulated":
            _ref_check(res, np.where(no_tir, err, np.nan), tail + slack, case_args, call,
                       "spectral, |ΔR_j| ≤ truncation tail (no TIR at 1|2)")
            s0 = np.asarray(shat_at_zero(observer))
            holds = np.abs(val[tir] - s0).max() <= BOUND_SLACK[dtype] if tir.any() else True
        else:
            # the Gaussian fit is accurate on x = m D ≤ 8000 nm (spectra.gaussian_fit)
            opd = np.asarray(series_terms(film, jnp.asarray(c)).opd)
            fitted = no_tir & (terms * opd <= 8000.0)[:, None]
            _ref_check(res, np.where(fitted, err, np.nan), tail + fit + slack, case_args, call,
                       "spectral, |ΔR_j| ≤ tail + (|C₀||1 − Ŝ_j(0)| + 2|R*−T| Σ|z|^m)·fit "
                       "error (M·D ≤ 8000 nm, no TIR at 1|2)")
            far = no_tir & ~fitted
            res.documented.append({
                "case": "Gaussian Ŝ beyond its fitted range M·D > 8000 nm (thick films)",
                "n": int(far[:, 0].sum()),
                "max_error": float(err[far[:, 0]].max()) if far.any() else 0.0, "holds": True,
                "note": "reported: the fit decays where the tabulated Ŝ keeps the sampled "
                        "(aliased beyond 15.2 µm) oscillation"})
            holds = np.abs(val[tir] - 1.0).max() <= BOUND_SLACK[dtype] if tir.any() else True
        res.documented.append({
            "case": "TIR at 1|2: the series gives R = 1, i.e. R_j = Ŝ_j(0) (series.py)",
            "n": int(tir.sum()), "max_error": float(err[tir].max()) if tir.any() else 0.0,
            "holds": bool(holds),
            "note": "max error = |Fourier − spectral|: frustrated transmission through thin "
                    "films is lost (documented limitation of the BB17 series)"})
    res.seconds = time.perf_counter() - t0
    return res


def _series_error_bounds(film: Film, cos_theta, terms: int, observer: str):
    """Per case and band: the truncation tail ‖W_j‖₁ · mean_pol 2|R*−T||z|^{M+1}/(1−|z|)
    and the Gaussian-fit term (|C₀||1 − Ŝ_j(0)| + 2|R*−T| Σ_{m≤M}|z|^m) · fit error_j,
    both computed in float64 from `series_terms`."""
    from .spectra import gaussian_fit_error

    st = series_terms(film, jnp.asarray(cos_theta, jnp.float64), base="general")
    amp, az = np.abs(np.asarray(st.amp)), np.abs(np.asarray(st.z))
    c0 = np.abs(np.asarray(st.c0))
    wabs = _weights_range(observer)[2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tail = np.where(amp > 0, 2 * amp * az ** (terms + 1) / np.maximum(1 - az, 1e-300), 0.0)
    partial = 2 * amp * sum(az**m for m in range(1, terms + 1))
    fit_err = gaussian_fit_error(observer)
    s0_err = np.abs(1.0 - np.asarray(shat_at_zero(observer)))
    tail = tail.mean(axis=0)[:, None] * wabs
    fit = (c0.mean(axis=0)[:, None] * s0_err + partial.mean(axis=0)[:, None] * fit_err)
    return tail, fit


PATCH_VARIANTS = (*((m, "exact") for m in PATCH_METHODS), ("filtered_gt_moments", "lut"))


def _patch_variants_fn(variants, dtype, n):
    lut = build_shat_lut(dtype=dtype)
    q = STABILITY_QUADRATURE

    def fn(film, theta_o, alpha):
        # batch_size = all patches: one vmapped batch, no lax.map remainder (half the compile)
        return jnp.stack([patch_radiance(film, theta_o, alpha, method=m, shat=sh, lut=lut,
                                         quadrature=(q, q), base="general", batch_size=n)
                          for m, sh in variants])
    return fn


@functools.cache
def _patch_group(dtype: str):
    """Every `PATCH_VARIANTS` method on the stiff patch grid in ONE reverse pass (compile time
    dominates: one compile instead of six). The gradient is that of the sum over the variants,
    which is finite iff each variant's is (NaN and ±inf propagate; a non-finite sum is then
    attributed by `check_patch` re-running the variant alone)."""
    film, (theta, alpha) = stiff_grid(STIFF_THETA, STIFF_ALPHA)
    if dtype == "float32":  # π/2 (and π/2 − 1e-9) round above π/2 in float32
        theta = np.minimum(theta.astype(np.float32).astype(np.float64), F32_BELOW_HALF_PI)
    film, theta, alpha = _rounded((film, theta, alpha), dtype)
    values, grads = value_and_grads(_patch_variants_fn(PATCH_VARIANTS, dtype, len(theta)),
                                    _as((film, theta, alpha), dtype),
                                    ("film", "theta_o", "alpha"))
    return film, theta, alpha, values, grads


def check_patch(dtype: str = "float64", method: str = "reference",
                shat: str = "exact") -> StabilityResult:
    """`patch_radiance`: finite values and gradients (film, θ_o, α) at extreme inputs,
    reference within [A Σ W⁻, A Σ W⁺] (A = `microfacet.albedo`, same quadrature), `ideal` =
    A · Fourier(cos θ_o), every method → its mirror value at α = 1e-4 for d ≤ 500 nm."""
    t0 = time.perf_counter()
    q = STABILITY_QUADRATURE
    name = f"patch_radiance[{method}{',' + shat if shat != 'exact' else ''}]"
    film, theta, alpha, values, grads = _patch_group(dtype)
    k = PATCH_VARIANTS.index((method, shat))
    val = values[k]
    if any(not np.all(np.isfinite(g)) for g in grads.values()):
        # attribute: this variant's own gradient (the group's is summed over variants)
        val, grads = value_and_grads(_patch_variants_fn(((method, shat),), dtype, len(theta)),
                                     _as((film, theta, alpha), dtype),
                                     ("film", "theta_o", "alpha"))
        val = val[0]
    res = StabilityResult(name, dtype, len(theta))
    case_args = {"film": film, "theta_o": theta, "alpha": alpha}
    call = "patch_radiance"
    _finish(res, val, grads, case_args, call, lambda v: v.reshape(len(theta), -1))
    a = np.asarray(albedo(theta, alpha, n_u=q, n_phi=q))
    wlo, whi, wabs = _weights_range(SB)
    c_o = np.cos(theta)
    # mirror limit: D varies by ~2η₂d·α·sin θ_o over the lobe, negligible for d ≤ 500 nm
    mirror = (alpha == alpha.min()) & (theta <= 0.7) & (film.thickness <= 500.0)
    if method == "reference":
        _bound_check(res, val, a[:, None] * wlo, a[:, None] * whi, case_args, call,
                     "A·Σ min(W, 0) ≤ L_j ≤ A·Σ max(W, 0), A = albedo ≤ 1")
        spec = np.asarray(rgb_reflectance(film, c_o, method="spectral", base="general"))
        err = np.where(mirror, np.abs(val - a[:, None] * spec).max(axis=1), np.nan)
        _ref_check(res, err, 1e-4, case_args, call,
                   "α = 1e-4, θ_o ≤ 0.7, d ≤ 500 nm: A·R_j^spectral(cos θ_o), ≤ 1e-4")
    else:
        fourier = np.asarray(rgb_reflectance(film, c_o, method="fourier", terms=2,
                                             base="general"))
        # |K 29| ≤ (|C₀| + 2|R*−T| Σ_{m≤2}|z|^m) ‖W‖₁ with |C₀| ≤ 2, |R*−T| ≤ 1, |z| ≤ 1
        hi = a[:, None] * 6.0 * wabs[None, :]
        _bound_check(res, val, -hi, hi, case_args, call,
                     "|L_j| ≤ 6 A ‖W_j‖₁ (|C₀| ≤ 2, |R*−T| ≤ 1, |z| ≤ 1, M = 2)")
        if method == "ideal":
            err = np.abs(val - a[:, None] * fourier).max(axis=1)
            tol = 1e-12 if dtype == "float64" else 1e-4
            _ref_check(res, err, tol, case_args, call,
                       f"A · rgb_reflectance(fourier, cos θ_o), ≤ {tol:g}")
            if dtype == "float32":  # what a user gets from np.float32(np.pi / 2) = π/2 + 4e-8
                f7 = Film(*MATERIALS["fig7"][:3], 1.0).astype(jnp.float32)
                over = np.asarray(patch_radiance(f7, np.float32(np.pi / 2), np.float32(0.3),
                                                 method=method, quadrature=(q, q)))
                below = np.asarray(patch_radiance(f7, np.float32(F32_BELOW_HALF_PI),
                                                  np.float32(0.3), method=method,
                                                  quadrature=(q, q)))
                res.documented.append({
                    "case": "θ_o = np.float32(π/2) (rounds to π/2 + 4.4e-8, accepted by the "
                            "validation; cos θ_o = −4.4e-8)", "n": 1,
                    "max_error": float(np.abs(over - below).max()),
                    "holds": bool(np.all(np.isfinite(over))
                                  and np.abs(over - below).max() < 1e-5),
                    "note": "finite, within 1e-5 of the largest float32 below π/2"})
        else:
            err = np.where(mirror, np.abs(val - a[:, None] * fourier).max(axis=1), np.nan)
            tol = 1e-4 if shat != "lut" else 2e-4
            _ref_check(res, err, tol, case_args, call,
                       f"α = 1e-4, θ_o ≤ 0.7, d ≤ 500 nm: → ideal (mirror limit), ≤ {tol:g}")
        lo_x = np.maximum(a[:, None] * wlo - val, 0).max(axis=1)
        hi_x = np.maximum(val - a[:, None] * whi, 0).max(axis=1)
        over = np.maximum(lo_x, hi_x)
        res.documented.append({
            "case": "outside the exact range [A Σ W⁻, A Σ W⁺] (truncated series, M = 2)",
            "n": int((over > BOUND_SLACK[dtype]).sum()), "max_error": float(over.max()),
            "holds": True, "note": "reported, not asserted: K 4/K 29 with M = 2 is not "
                                   "positivity-preserving"})
    res.seconds = time.perf_counter() - t0
    return res


def check_lookup(dtype: str = "float64") -> StabilityResult:
    """`lut.lookup` at μ, σ over, at and beyond the table: |Ŝ| ≤ ‖W‖₁, exact inside,
    0 beyond μ_max, < 1e-12 beyond σ_max."""
    from .lut import _exact_np, lookup

    t0 = time.perf_counter()
    lut = build_shat_lut(dtype=dtype)
    mmax, smax = float(lut.mu_max), float(lut.sigma_max)
    mus = np.array([0.0, 1e-6, 500.0, mmax - 1e-3, mmax, mmax + 1.0, 1e5, 1e9])
    mus = np.concatenate([mus, -mus[1:]])
    sig = np.array([0.0, 1e-6, 500.0, smax, 1e4, 1e9])
    m, s = _rounded(tuple(g.ravel() for g in np.meshgrid(mus, sig, indexing="ij")), dtype)
    res = StabilityResult("lut.lookup", dtype, len(m))
    val, grads = value_and_grads(lambda mu, sg: lookup(lut, mu, sg), _as((m, s), dtype),
                                 ("mu", "sigma"))
    case_args = {"mu": m, "sigma": s}
    call = "lookup"
    cval = val[0] + 1j * val[1]  # value_and_grads stacks (real, imag)
    _finish(res, val, grads, case_args, call, lambda v: np.moveaxis(v, 0, -1).reshape(len(m), -1))
    wabs = _weights_range(SB)[2]
    _bound_check(res, np.abs(cval), 0.0, wabs * (1 + 1e-6), case_args, call, "|Ŝ_j| ≤ ‖W_j‖₁")
    exact = _exact_np(m, s, get_observer(SB))
    inside = (np.abs(m) <= mmax) & (s <= smax)
    err = np.where(inside, np.abs(cval - exact).max(axis=1), np.nan)
    tol = 5e-5 if dtype == "float64" else 8e-5
    _ref_check(res, err, tol, case_args, call,
               f"exact filtered quadrature inside the table, ≤ {tol:g} (tests/test_lut.py)")
    beyond_mu = np.abs(m) > mmax
    beyond_s = (s > smax) & ~beyond_mu
    res.documented.append({"case": "|μ| > μ_max returns 0 (continuous-band limit, lut.py)",
                           "n": int(beyond_mu.sum()),
                           "max_error": float(np.abs(cval[beyond_mu]).max()),
                           "holds": bool(np.all(cval[beyond_mu] == 0))})
    lim = 1e-12 if dtype == "float64" else 1e-6
    res.documented.append({"case": f"σ > σ_max is clamped (|Ŝ| < {lim:g}, lut.py)",
                           "n": int(beyond_s.sum()),
                           "max_error": float(np.abs(cval[beyond_s]).max()),
                           "holds": bool(np.all(np.abs(cval[beyond_s]) < lim))})
    res.seconds = time.perf_counter() - t0
    return res


def check_sensitivity(dtype: str = "float64", method: str = "tabulated") -> StabilityResult:
    """`sensitivity_ft(x, sigma2=…)`: finite value and gradient for x up to 1e7 nm and σ²
    from 0 to 1e30 nm²; tabulated: |Ŝ| ≤ ‖W‖₁ and equal to the host quadrature."""
    from .lut import _exact_np

    t0 = time.perf_counter()
    xs = np.array([0.0, 1e-6, 500.0, 1e4, 1e5, 1e7])
    xs = np.concatenate([xs, -xs[1:]])
    s2 = np.array([0.0, 1e-12, 1e4, 1e6, 1e12, 1e30])
    x, v2 = _rounded(tuple(g.ravel() for g in np.meshgrid(xs, s2, indexing="ij")), dtype)
    res = StabilityResult(f"sensitivity_ft[{method}]", dtype, len(x))
    val, grads = value_and_grads(lambda a, b: sensitivity_ft(a, sigma2=b, method=method),
                                 _as((x, v2), dtype), ("x", "sigma2"))
    case_args = {"x": x, "sigma2": v2}
    call = "sensitivity_ft"
    cval = val[0] + 1j * val[1]
    _finish(res, val, grads, case_args, call, lambda v: np.moveaxis(v, 0, -1).reshape(len(x), -1))
    if method == "tabulated":
        wabs = _weights_range(SB)[2]
        _bound_check(res, np.abs(cval), 0.0, wabs * (1 + 1e-6), case_args, call,
                     "|Ŝ_j| ≤ ‖W_j‖₁")
        exact = _exact_np(x, np.sqrt(v2), get_observer(SB))
        err = np.abs(cval - exact).max(axis=1)
        eps = np.finfo(dtype).eps
        base_tol = 1e-12 if dtype == "float64" else 1e-6
        tol = base_tol + 4 * eps * 2 * np.pi * np.abs(x) / 360.0 * wabs.max()
        _ref_check(res, err, tol, case_args, call,
                   f"host NumPy quadrature, ≤ {base_tol:g} + 4 eps |2πx/λ_min| ‖W‖₁")
    else:
        res.bound = "none asserted (closed form of the Gaussian fit)"
        res.reference = "none (fit error: spectra.gaussian_fit_error)"
    res.seconds = time.perf_counter() - t0
    return res


def check_opd(dtype: str = "float64") -> StabilityResult:
    """`opd.taylor_opd_moments`: μ_D, σ_D ≥ 0 and finite (with gradients) for μ_c ∈ [−1, 1],
    σ_c² ∈ [0, 1e6]; at σ_c² = 0, σ_D = 0 and μ_D = D(cos θ₁*) exactly (K 22–24)."""
    from .opd import opd_of_cos

    t0 = time.perf_counter()
    film, (mu_c, var_c) = _rounded(stiff_grid([-1.0, -0.5, 0.0, 0.5, 1.0],
                                              [0.0, 1e-12, 0.1, 1.0, 1e6]), dtype)
    res = StabilityResult("opd.taylor_opd_moments", dtype, len(mu_c))
    val, grads = value_and_grads(lambda f, m, v: jnp.stack(taylor_opd_moments(f, m, v), -1),
                                 _as((film, mu_c, var_c), dtype), ("film", "mu_c", "var_c"))
    case_args = {"film": film, "mu_c": mu_c, "var_c": var_c}
    call = "taylor_opd_moments"
    _finish(res, val, grads, case_args, call, lambda v: v)
    _bound_check(res, val, 0.0, np.inf, case_args, call, "μ_D ≥ 0, σ_D ≥ 0")
    d_star = np.asarray(opd_of_cos(film, cos_incidence_from_projection(jnp.asarray(mu_c))))
    zero = var_c == 0
    scale = 1 + np.abs(d_star)
    rel = 1e-12 if dtype == "float64" else 1e-5
    err = np.where(zero, np.maximum(np.abs(val[:, 0] - d_star), np.abs(val[:, 1])) / scale,
                   np.nan)
    _ref_check(res, err, rel, case_args, call,
               f"σ_c² = 0: μ_D = D(cos θ₁*), σ_D = 0 (relative {rel:g})")
    k = film.eta_outer**2 / (2 * film.eta_film**2)
    mu_cos2_sq = 1 + k * (mu_c - 1)
    near = (var_c > 0) & (mu_cos2_sq > 0) & (mu_cos2_sq < 1e-6)
    res.documented.append({
        "case": "σ_D → ∞ as μ_cosθ₂ → 0⁺ (K 26 divides by μ_cosθ₂) but σ_D = 0 at μ_cosθ₂ = 0 "
                "(safe_div limit; also under TIR at 1|2)",
        "n": int(near.sum()),
        "max_error": float(val[near, 1].max()) if near.any() else 0.0, "holds": True,
        "note": "max error = largest σ_D (nm) next to the jump; harmless in K 29, where "
                "R₁₂ = 1 makes every C_m (m ≥ 1) vanish at that point"})
    res.seconds = time.perf_counter() - t0
    return res


def check_filtered_bands(dtype: str = "float64") -> StabilityResult:
    """`filtered.filtered_bands` (K 29) with σ_D ∈ {0, 1e-6, 1e3, 1e9} nm and the exact, LUT
    and Gaussian Ŝ: finite with gradients; σ_D = 0 gives the Fourier path (Ŝ(μ, 0) = Ŝ(μ));
    σ_D → ∞ gives the incoherent limit C₀* Ŝ_j(0)."""
    from .opd import OPDMoments, opd_of_cos

    t0 = time.perf_counter()
    sig = np.array([0.0, 1e-6, 1e3, 1e9])
    film, (theta, s_d) = stiff_grid(STIFF_THETA, sig)
    film, c = _rounded((film, stiff_cos(theta)), dtype)
    mu_d = np.asarray(opd_of_cos(film, jnp.asarray(c))).astype(dtype).astype(np.float64)
    res = StabilityResult("filtered.filtered_bands", dtype, len(c))
    lut = build_shat_lut(dtype=dtype)
    shats = ("exact", "lut", "gaussian")

    def fn(f, cc, m, s):
        return jnp.stack([filtered_bands(f, cc, OPDMoments(m, s), SB, shat=sh, lut=lut,
                                         base="general") for sh in shats])

    val, grads = value_and_grads(fn, _as((film, c, mu_d, s_d), dtype),
                                 ("film", "cos_theta", "mu_D", "sigma_D"))
    case_args = {"film": film, "cos_theta": c, "mu_D": mu_d, "sigma_D": s_d}
    call = "filtered_bands"
    _finish(res, val, grads, case_args, call,
            lambda v: np.moveaxis(v, 0, 1).reshape(len(c), -1))
    st = series_terms(film, jnp.asarray(c), base="general")
    incoh = np.asarray(jnp.mean(st.c0, axis=0))[:, None] * np.asarray(shat_at_zero(SB))
    fourier = np.asarray(rgb_reflectance(film, c, method="fourier", terms=2, base="general"))
    wabs = _weights_range(SB)[2]
    hi = 6.0 * wabs
    _bound_check(res, np.moveaxis(val, 0, 1), -hi, hi, case_args, call,
                 "|R_j| ≤ 6 ‖W_j‖₁ (M = 2)")
    tol = 1e-12 if dtype == "float64" else 2e-4
    # Ŝ(μ, 0) = Ŝ(μ): the exact-Ŝ K 29 equals the Fourier path
    err = np.where(s_d == 0, np.abs(val[0] - fourier).max(axis=1), np.nan)
    big = s_d == 1e9
    err_inc = np.abs(val[:2] - incoh[None]).max(axis=(0, 2))
    err = np.where(big, err_inc, err)
    phase_tol = tol if dtype == "float64" else tol + 8 * np.finfo(np.float32).eps * (
        2 * np.pi * 2 * mu_d / 380.0)
    _ref_check(res, err, phase_tol, case_args, call,
               "σ_D = 0: exact-Ŝ K 29 = Fourier path; σ_D = 1e9: exact/LUT = C₀* Ŝ_j(0)")
    res.seconds = time.perf_counter() - t0
    return res


def stability_check(name: str, dtype: str) -> StabilityResult:
    """Run the check called `name` (one of `STABILITY_FUNCTIONS`) in `dtype`."""
    if name.startswith("airy_reflectance"):
        return check_airy(dtype, "dielectric" if "dielectric" in name else "auto")
    if name.startswith("rgb_reflectance"):
        opts = name[name.index("[") + 1:-1].split(",")
        method = opts[0]
        terms = int(opts[1][2:]) if method == "fourier" else 2
        return check_rgb(dtype, method, CIE if CIE in opts else SB, terms,
                         "gaussian" if "gaussian" in opts else "tabulated")
    if name.startswith("patch_radiance"):
        opts = name[name.index("[") + 1:-1].split(",")
        return check_patch(dtype, opts[0], opts[1] if len(opts) > 1 else "exact")
    if name == "lut.lookup":
        return check_lookup(dtype)
    if name.startswith("sensitivity_ft"):
        return check_sensitivity(dtype, name[name.index("[") + 1:-1])
    if name == "opd.taylor_opd_moments":
        return check_opd(dtype)
    if name == "filtered.filtered_bands":
        return check_filtered_bands(dtype)
    raise ValueError(f"unknown stability check {name!r}; expected one of {STABILITY_FUNCTIONS}")


def run_stability_checks(dtypes=("float64", "float32"), names=STABILITY_FUNCTIONS,
                         verbose: bool = False) -> list[StabilityResult]:
    out = []
    for name in names:
        for dt in dtypes:
            _log(f"stability {name} {dt}", verbose)
            out.append(stability_check(name, dt))
    return out


def _cell(text: str) -> str:
    """Text for a markdown table cell (a literal | would end the cell)."""
    return str(text).replace("|", "\\|")


def stability_markdown(results: list[StabilityResult]) -> str:
    """The stability report: one row per (function, dtype), then the documented behaviours
    and reproducers of every problem."""
    env = environment()
    lines = ["# Stability report: stiff and extreme inputs", "",
             f"Generated by `thinfilm_jax.bench.write_stability_report` on {env['devices']} "
             f"(jax {env['jax']}, {env['date']}); asserted by `tests/test_stability.py`.", "",
             "Inputs (product grids, one vectorised call per function and dtype; gradients are "
             "VJPs with an all-ones cotangent, w.r.t. every Film field and every other input):",
             f"- thickness d ∈ {list(STIFF_THICKNESS)} nm",
             "- optics (η₁, η₂, η₃, κ₃) ∈ " + ", ".join(str(o) for o in STIFF_OPTICS),
             "- θ ∈ {0, 1e-9, 0.7, 1.2, π/2 − 1e-9, π/2} (cos θ inputs use cos(π/2) = 0 exactly; "
             "float32 patches use the largest float32 ≤ π/2)",
             f"- α ∈ {list(STIFF_ALPHA)}, λ ∈ {list(STIFF_WAVELENGTH)} nm, patch quadrature "
             f"{STABILITY_QUADRATURE}², σ_D ∈ {{0, 1e-6, 1e3, 1e9}} nm, σ² up to 1e30 nm²", "",
             "| function | dtype | cases | non-finite value | non-finite grad | value range "
             "| bound | violations (max excess) | reference | max error (tol) | ref. violations "
             "| s (a shared group's compile is counted once) |", "|" + "---|" * 12]
    for r in results:
        ng = sum(r.nonfinite_grad.values())
        lines.append(
            f"| {r.function} | {r.dtype} | {r.n_cases} | {r.nonfinite_value} | {ng} "
            f"| [{_fmt(r.value_min, '.3g')}, {_fmt(r.value_max, '.3g')}] | {_cell(r.bound)} "
            f"| {r.bound_violations} ({_fmt(r.bound_excess, '.2g')}) | {_cell(r.reference)} "
            f"| {_fmt(r.ref_error, '.2g')} ({_fmt(r.ref_tol, '.2g')}) | {r.ref_violations} "
            f"| {r.seconds:.1f} |")
    lines += ["", "## Documented behaviours and known inaccuracies", "",
              "| function | dtype | case | cases | max error | holds | note |",
              "|---|---|---|---|---|---|---|"]
    for r in results:
        for d in r.documented:
            lines.append(f"| {r.function} | {r.dtype} | {_cell(d['case'])} | {d['n']} "
                         f"| {_fmt(d['max_error'], '.3g')} | {d['holds']} "
                         f"| {_cell(d.get('note', ''))} |")
    problems = [r for r in results if r.problems or r.examples]
    lines += ["", "## Problems and reproducers", ""]
    if not problems:
        lines.append("None: every value and gradient is finite and every asserted bound and "
                     "reference holds.")
    for r in problems:
        lines.append(f"- **{r.function} ({r.dtype})**: {r.problems} problem(s)")
        lines += [f"  - `{e}`" for e in r.examples]
    return "\n".join(lines) + "\n"


def write_stability_report(path="figures/stability_report.md", dtypes=("float64", "float32"),
                           verbose: bool = False) -> dict:
    """Run every stability check and write the markdown report; returns a summary dict."""
    results = run_stability_checks(dtypes, verbose=verbose)
    text = stability_markdown(results)
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))
    return {"n_checks": len(results), "n_problems": int(sum(r.problems for r in results)),
            "results": [dataclasses.asdict(r) for r in results]}
