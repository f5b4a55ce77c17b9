r"""Error against run time of every evaluation path, the rows of `python -m benchmarks.bench`.

For every path and knob: the error against a converged reference and the warm run time per
evaluation (`benchmarks.bench.run_bench` writes them to ``bench.json``, ``error_vs_runtime.png``
and ``error_vs_runtime.md``).

Two families of paths, each against its own converged float64 reference:

(a) **per shading point** — band reflectance R_j(cos θ) of one film at one angle:
    `rgb_reflectance(method="spectral")` (the reference), the same quadrature on every
    2nd / 4th observer sample, the Fourier path (K 4) with M terms and tabulated or
    Gaussian-fit Ŝ, float32, the CIE 1931 observer, and the real dielectric arithmetic.
    Grid `shading_grid`: 4 materials (`MATERIALS`) × d ∈ [0, 1000] nm × θ ∈ [0°, 89°].
(b) **per patch** — L_j(θ_o, α) under uniform light (SPEC §7): the half-vector quadrature
    of `patch_radiance(method="reference")` at several orders, Monte Carlo
    (`patch_radiance_mc`), every approximate method of `patch_radiance` in the registry
    (`patch_method_rows`: `core.methods.names("patch", exact=False)` — ideal, the filtered
    variants, `improved` at each named preset of `ModelOptions.preset`, `khr` — read when the
    bench runs; the registry's methods without a uniform-light form are named in the report,
    `absent_from_patches`), the LUT against the exact filtered Ŝ, float32; reference:
    `patch_radiance(method="reference", quadrature=(96, 96))` (its own error is checked
    against order 64 and against Monte Carlo, `bench.json["reference_check"]`).
    Grid `patch_grid`: 4 materials × d ∈ {200, 600, 1000} nm × θ_o ∈ {0, 45, 70, 85, 89}° ×
    α ∈ {0.01, 0.1, 0.4}. Also in (b), the **real-time kernels** (`kernels.ideal_kernel`,
    `kernels.filtered_kernel`: one shading point given its light-lobe moments, as a renderer
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

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.optics.airy import airy_reflectance
from thinfilm_jax.core.film import Film
from thinfilm_jax.core.material import expand_batch
from thinfilm_jax.realtime.kernels import filtered_kernel, ideal_kernel, lobe_moments
from thinfilm_jax.spectral.lut import build_shat_lut, lut_max_error
from thinfilm_jax.core.methods import names as method_names
from thinfilm_jax.realtime.options import PRESETS, ModelOptions
from thinfilm_jax.shading.patch import patch_radiance, patch_radiance_mc
from thinfilm_jax.spectral.reflectance import fourier_bands, rgb_reflectance
from thinfilm_jax.spectral.spectra import get_observer, trapezoid_weights
from ._common import (
    CIE,
    DIELECTRIC_MATERIALS,
    MATERIALS,
    SB,
    BenchConfig,
    case_labels,
    error_stats,
    make_row,
    material_film,
    view_vector,
)
from ._timing import as_dtype, chunked, chunked_mc, log, take, time_call


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
def jitted_patch(method="reference", observer=SB, **knobs):
    """`patch_radiance` with fixed options under one `jax.jit`; `knobs` are `ModelOptions`
    fields (terms, shat, quadrature, ndf, arithmetic)."""
    options = ModelOptions(**knobs)
    return jax.jit(lambda film, theta_o, alpha, lut=None: patch_radiance(
        film, theta_o, alpha, method=method, observer=observer, options=options, lut=lut))


def subsampled_observer(observer: str, step: int):
    """(λ, W) of `observer` on every `step`-th tabulated sample, trapezoid weights on the
    kept nodes, each band renormalised to unit area (step 1 is the library's quadrature).

    Example:
        >>> import numpy as np
        >>> lam, w = subsampled_observer("stiles_burch_1959_10", 1)
        >>> bool(np.allclose(w, get_observer("stiles_burch_1959_10").weights))
        True
        >>> lam, w = subsampled_observer("stiles_burch_1959_10", 2)
        >>> lam.shape, [round(float(s), 12) for s in w.sum(axis=0)]
        ((45,), [1.0, 1.0, 1.0])
    """
    obs = get_observer(observer)
    s = obs.weights / trapezoid_weights(obs.wavelengths)[:, None]  # ∝ S_j(λ_k)
    lam = obs.wavelengths[::step]
    w = trapezoid_weights(lam)[:, None] * s[::step]
    return lam, w / w.sum(axis=0)


def spectral_subsampled(film: Film, cos_theta, lam, weights, arithmetic: str = "complex"):
    """Σ_k W_kj R(θ, λ_k) with `airy_reflectance` on the given nodes (broadcast inputs)."""
    film_k = expand_batch(film)
    dtype = jnp.result_type(cos_theta, float)
    r = airy_reflectance(film_k, jnp.asarray(cos_theta)[..., None], jnp.asarray(lam, dtype),
                         arithmetic=arithmetic)
    return r @ jnp.asarray(weights, dtype)


def patch_method_rows(cfg: BenchConfig) -> list[tuple[str, str, str | None]]:
    """(path, method, preset) of panel (b)'s method rows: every approximate uniform-light
    method of the registry as it stands when called (`core.methods.names("patch",
    exact=False)`; `cfg.patch_methods` when set), `improved` once per preset of
    `cfg.improved_presets` (`ModelOptions.preset`; preset None for the other methods).

    Example:
        >>> rows = patch_method_rows(BenchConfig())
        >>> [p for p, m, _ in rows if m == "improved"][:2]
        ['improved fast (K=2)', 'improved default (K=3)']
        >>> {m for _, m, _ in rows} == set(method_names("patch", exact=False))
        True
    """
    methods = (method_names("patch", exact=False) if cfg.patch_methods is None
               else cfg.patch_methods)
    rows = []
    for m in methods:
        if m != "improved":
            rows.append((m, m, None))
            continue
        for preset in cfg.improved_presets:
            o = ModelOptions.preset(preset)
            reads = (f", {o.bin_reads} reads a bin: under uniform light = K={o.bins}"
                     if o.bin_reads > 1 else "")
            rows.append((f"improved {preset} (K={o.bins}{reads})", m, preset))
    return rows


def absent_from_patches() -> dict[str, str]:
    """{method: why it has no row of its own in panel (b)}: the methods of the registry's
    other entry points (`names("envmap")`) that `patch_radiance` does not offer.

    Example:
        >>> sorted(absent_from_patches())
        ['colour_table', 'mc']
    """
    why = {"mc": "its uniform-light form is patch_radiance_mc: the 'Monte Carlo' rows",
           "colour_table": "no uniform-light form (a table of one material under one map, "
                           "prefilter_colour); its cost under a map: method_cost.md"}
    patch = set(method_names("patch"))
    return {m: why.get(m, "no uniform-light form (not offered by patch_radiance)")
            for m in method_names("envmap") if m not in patch}


def _smallest_m(errs: list[dict], key: str, tol: float):
    for m, e in enumerate(errs):
        if e[key] < tol:
            return m
    return None


def _shading_extras(cfg, run, rgb, film, c, film32, c32, names, ref, m32):
    """Family (a) specialisation rows: float32, CIE 1931, dielectric arithmetic."""
    run(rgb(method="spectral", arithmetic="complex"), (film32, c32), "spectral f32", "float32",
        {"lambda_step": 1}, np.float32, ref)
    run(rgb(method="fourier", terms=m32,
            arithmetic="complex"), (film32, c32), f"Fourier M={m32} f32",
        "float32", {"terms": m32, "shat": "exact"}, np.float32, ref)
    run(rgb(method="fourier", terms=m32, shat="gaussian", arithmetic="complex"), (film32, c32),
        f"Fourier M={m32}, Gaussian Ŝ f32", "float32", {"terms": m32, "shat": "gaussian"},
        np.float32, ref)
    # one observer: the cost scales with its number of samples (CIE 1931 at 1 nm: 471)
    ref_cie = run(rgb(method="spectral", observer=CIE, arithmetic="complex"), (film, c),
                  "spectral CIE 1931 (reference)", "observer",
                  {"observer": CIE, "n_lambda": len(get_observer(CIE).wavelengths)},
                  np.float64, None, observer=CIE, error_vs="spectral CIE 1931 f64")
    run(rgb(method="fourier", terms=m32, observer=CIE, arithmetic="complex"), (film, c),
        f"Fourier M={m32} CIE 1931", "observer", {"observer": CIE, "terms": m32}, np.float64,
        ref_cie, observer=CIE, error_vs="spectral CIE 1931 f64")
    # dielectric specialisation (real arithmetic) on the dielectric materials only
    diel = np.isin(names, DIELECTRIC_MATERIALS)
    fd, cd = take(film, diel), c[diel]
    ref_d = ref[diel]
    for arith in ("complex", "real"):
        run(rgb(method="spectral", arithmetic=arith), (fd, cd), f"spectral, {arith} arithmetic",
            "dielectric subset", {"arithmetic": arith, "grid": "dielectric materials"}, np.float64,
            ref_d, n_eval=int(diel.sum()), sel=diel)
        run(rgb(method="fourier", terms=m32, arithmetic=arith), (fd, cd),
            f"Fourier M={m32}, {arith} arithmetic", "dielectric subset",
            {"arithmetic": arith, "terms": m32, "grid": "dielectric materials"}, np.float64, ref_d,
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
        log(f"(a) {path}", verbose)
        out, t = time_call(fn, args, cfg.repeats)
        out = np.asarray(out)
        lab = labels if sel is None else labels[sel]
        rows.append(make_row(fam, path, group, knobs, dtype, n_eval, t,
                             error_stats(out, out if ref is None else ref, observer, lab),
                             error_vs))
        return out

    ref = run(rgb(method="spectral", arithmetic="complex"), (film, c), "spectral (reference)",
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
        fourier_out[m] = run(rgb(method="fourier", terms=m, arithmetic="complex"), (film, c),
                             f"Fourier M={m}", "Fourier (tabulated Ŝ)",
                             {"terms": m, "shat": "exact"}, np.float64, ref)
    for m in cfg.gaussian_terms:
        run(rgb(method="fourier", terms=m, shat="gaussian", arithmetic="complex"), (film, c),
            f"Fourier M={m}, Gaussian Ŝ", "Fourier (Gaussian Ŝ)",
            {"terms": m, "shat": "gaussian"}, np.float64, ref)
    m32 = 2 if 2 in cfg.fourier_terms else cfg.fourier_terms[0]
    if cfg.extras:
        _shading_extras(cfg, run, rgb, film, c, film32, c32, names, ref, m32)

    # M per tolerance: every M at once, checked against the timed rgb_reflectance values
    sweep = {}
    for shat in ("exact", "gaussian") if cfg.gaussian_terms else ("exact",):
        log(f"(a) M sweep 0…{cfg.m_sweep_max}, {shat} Ŝ", verbose)
        fn = jax.jit(functools.partial(fourier_bands, observer=SB, terms=cfg.m_sweep_max,
                                       shat=shat, partial_sums=True))
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
        if shat == "exact":
            entry["max_diff_vs_rgb_reflectance"] = float(max(
                np.abs(sums[m] - fourier_out[m]).max() for m in fourier_out
                if m <= cfg.m_sweep_max))
        sweep[shat] = entry
    return rows, sweep


def bench_patches(cfg: BenchConfig, verbose: bool = True):
    """Rows of family (b), the reference checks and the LUT accuracy table."""
    rows, fam = [], "b: patch"
    film, theta, alpha, names = patch_grid(cfg)
    p = len(theta)
    labels = case_labels(names, film, theta_o=theta, alpha=alpha)
    args64 = (film, theta, alpha)
    args32 = as_dtype(args64, jnp.float32)
    q_ref = cfg.reference_quadrature

    patch_fn = jitted_patch

    def run(fn, args, path, group, knobs, dtype, ref, error_vs, chunk=cfg.patch_chunk,
            **extra):
        log(f"(b) {path}", verbose)
        out, t, ch = chunked(fn, args, chunk, cfg.repeats)
        rows.append(make_row(fam, path, group, knobs, dtype, ch, t,
                             error_stats(out, ref, SB, labels), error_vs, **extra))
        return out

    ref_name = f"reference quadrature {q_ref}² f64"
    log(f"(b) reference {q_ref}²", verbose)
    ref, t_ref, ch = chunked(patch_fn(method="reference", quadrature=(q_ref, q_ref)), args64,
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
    mc_args = (*take(args64, sub), jax.random.split(jax.random.PRNGKey(20190707), len(sub)))
    mc_check = {}
    for n in cfg.mc_samples:
        def mc(f, t, a, keys, n=n):
            def one(x):
                return patch_radiance_mc(*x, n_samples=n)
            return jax.lax.map(one, (f, t, a, keys))

        log(f"(b) Monte Carlo {n}", verbose)
        (mean, se), t, ch = chunked_mc(jax.jit(mc), mc_args, cfg.mc_chunk, cfg.repeats)
        rows.append(make_row(fam, f"Monte Carlo {n:.0e}", "Monte Carlo", {"samples": n},
                             np.float64, ch, t, error_stats(mean, ref[sub], SB, labels[sub]),
                             ref_name + " (MC subset)", n_patches=int(len(sub))))
        z = np.abs(mean - ref[sub]) / np.maximum(se, 1e-300)
        mc_check[str(n)] = {"max_abs_diff": float(np.abs(mean - ref[sub]).max()),
                            "max_standard_error": float(se.max()),
                            "max_z": float(z.max()), "patches": int(len(sub))}

    method_out = {}
    for path, method, preset in patch_method_rows(cfg):
        knobs = {} if preset is None else PRESETS[preset]
        out = run(patch_fn(method=method, **knobs), args64, path, "patch method",
                  {"method": method, "terms": 2, "shat": "exact", **knobs,
                   **({} if preset is None else {"preset": preset})}, np.float64, ref, ref_name)
        method_out.setdefault(method, out)
    for method in ("ideal", "filtered_gt_moments"):
        if cfg.extras and method in method_out:
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


def bench_kernels(cfg, film, theta, alpha, names, ref, exact_k29, ideal_out, labels, verbose):
    """Per-shading-point real-time kernels on `cfg.kernel_points` points (float32 unless
    stated); the points tile the patch grid, whose outputs × A are scored against `ref`."""
    rows, fam = [], "b: real-time kernel"
    a, mean, cov = (np.asarray(x) for x in lobe_moments(theta, alpha))
    p = len(theta)
    n = max(cfg.kernel_points, p)
    idx = np.arange(n) % p
    lut32 = build_shat_lut(dtype=jnp.float32)
    lut64 = build_shat_lut(dtype=jnp.float64)
    ref_name = f"reference quadrature {cfg.reference_quadrature}² f64 (× A)"

    def inputs(dtype, sel=None):
        i = idx if sel is None else np.flatnonzero(sel)[np.arange(n) % int(sel.sum())]
        return as_dtype((take(film, i), np.cos(theta[i]), mean[i], cov[i]), dtype), i

    def run(kernel, dtype, path, knobs, sel=None, lut=None):
        log(f"(kernel) {path}", verbose)
        (f, co, mu, cv), i = inputs(dtype, sel)
        if kernel == "ideal":
            fn = jax.jit(functools.partial(ideal_kernel, shat=knobs.get("shat", "exact"),
                                           arithmetic=knobs.get("arithmetic", "complex")))
            args = (f, co)
        else:
            fn = jax.jit(lambda f, wo, mu, cv, lut: filtered_kernel(
                f, wo, mu, cv, lut=lut, shat=knobs["shat"],
                    arithmetic=knobs.get("arithmetic", "complex")))
            args = (f, view_vector(co), mu, cv, lut)
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
        for arith in ("complex", "real"):
            run("ideal", jnp.float32, f"kernel ideal M=2 f32, {arith} (dielectric films)",
                {"kernel": "ideal", "terms": 2, "arithmetic": arith}, sel=diel)
            run("filtered", jnp.float32, f"kernel K29 LUT f32, {arith} (dielectric films)",
                {"kernel": "K29", "shat": "lut", "arithmetic": arith}, sel=diel, lut=lut32)
    check = {"kernel_K29_exact_vs_patch_filtered_gt_moments_max_abs":
             float(np.abs(k_exact - exact_k29).max()),
             "kernel_K29_lut_vs_exact_max_abs": float(np.abs(k_lut - k_exact).max())}
    if ideal_out is not None:
        check["kernel_ideal_vs_patch_ideal_max_abs"] = float(np.abs(ideal - ideal_out).max())
    return rows, check
