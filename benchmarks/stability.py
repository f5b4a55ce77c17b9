"""Every public function at stiff and extreme inputs, value and gradient, float32 and float64.

`stability_check(name, dtype)` runs the check called `name` (`STABILITY_FUNCTIONS`) over the
product grids of `stiff` and returns a `stiff.StabilityResult`; tests/benchmarks/test_stability.py
asserts on these results and `write_stability_report` writes the same findings to
``stability_report.md`` (``python -m benchmarks.bench``, or ``python -m benchmarks.stability``).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.files import atomic_write
from thinfilm_jax.optics.airy import airy_reflectance
from thinfilm_jax.core.film import Film
from thinfilm_jax.realtime.filtered import filtered_bands
from thinfilm_jax.spectral.lut import build_shat_lut, lookup
from thinfilm_jax.brdf.microfacet import albedo
from thinfilm_jax.optics.opd import OPDMoments, cos_incidence_from_projection, opd_of_cos, taylor_opd_moments
from thinfilm_jax.realtime.options import ModelOptions
from thinfilm_jax.shading.patch import patch_radiance
from thinfilm_jax.spectral.reflectance import rgb_reflectance
from thinfilm_jax.core.methods import names as method_names
from thinfilm_jax.optics.series import series_terms
from thinfilm_jax.spectral.spectra import gaussian_fit_error, sensitivity_ft, shat_at_zero, shat_host
from ._common import CIE, SB
from ._timing import as_dtype, environment, fmt, log, take
from .stiff import (
    BOUND_SLACK,
    F32_BELOW_HALF_PI,
    STABILITY_QUADRATURE,
    STIFF_ALPHA,
    STIFF_OPTICS,
    STIFF_THETA,
    STIFF_THICKNESS,
    STIFF_WAVELENGTH,
    StabilityResult,
    airy_longdouble,
    bound_check,
    finish,
    ref_check,
    rounded,
    stiff_cos,
    stiff_grid,
    tir12,
    tmm_grid,
    value_and_grads,
    weights_range,
)

#: the registry's methods of `patch_radiance` (a registered one joins the study), less those
#: whose mirror limit is not BB17's film: glTF's own formula (its limits:
#: tests/spectral/test_khr.py)
OWN_FORMULA = ("khr",)
PATCH_METHODS = tuple(m for m in method_names("patch") if m not in OWN_FORMULA)
STABILITY_FUNCTIONS = (
    "airy_reflectance", "airy_reflectance[dielectric]", "rgb_reflectance[spectral]",
    "rgb_reflectance[spectral,cie_1931_2]", "rgb_reflectance[fourier,M=2]",
    "rgb_reflectance[fourier,M=2,gaussian]", *(f"patch_radiance[{m}]" for m in PATCH_METHODS),
    "patch_radiance[filtered_gt_moments,lut]", "lut.lookup", "sensitivity_ft[exact]",
    "sensitivity_ft[gaussian]", "opd.taylor_opd_moments", "filtered.filtered_bands",
)
def check_airy(dtype: str = "float64", arithmetic: str = "auto") -> StabilityResult:
    """`airy_reflectance` value and gradients: 0 ≤ R ≤ 1, tmm agreement (float64, θ < 90°),
    R = 1 at grazing incidence, float32 within a phase-scaled tolerance of float64."""
    t0 = time.perf_counter()
    film, (theta, lam) = stiff_grid(STIFF_THETA, STIFF_WAVELENGTH)
    c = stiff_cos(theta)
    if arithmetic == "real":  # the real path's domain: κ₃ = 0, η₂ ≥ η₁, η₃ ≥ η₁
        ok = ((film.kappa_base == 0) & (film.eta_film >= film.eta_outer)
              & (film.eta_base >= film.eta_outer))
        film, c, lam = take(film, ok), c[ok], lam[ok]
    film, c, lam = rounded((film, c, lam), dtype)
    name = "airy_reflectance" + ("[dielectric]" if arithmetic == "real" else "")
    res = StabilityResult(name, dtype, len(c))
    args = as_dtype((film, c, lam), dtype)
    val, grads = value_and_grads(
        lambda f, cc, ll: airy_reflectance(f, cc, ll,
                                           arithmetic="complex" if arithmetic == "auto" else arithmetic),
        args, ("film", "cos_theta", "wavelength"))
    case_args = {"film": film, "cos_theta": c, "wavelength": lam}
    call = f"airy_reflectance{'' if arithmetic == 'auto' else ', arithmetic=' + repr(arithmetic)}"
    finish(res, val, grads, case_args, call, lambda v: v[:, None])
    bound_check(res, val, 0.0, 1.0, case_args, call, "0 ≤ R ≤ 1")
    if dtype == "float64":
        ref = airy_longdouble(film, c, lam)
        phase = 4 * np.pi * film.thickness * film.eta_film / lam  # |δ| bound
        tol = 1e-12 + 4 * np.finfo(np.float64).eps * phase
        ref_check(res, np.abs(val - ref), tol, case_args, call,
                   "80-bit closed form (θ < 90°), |ΔR| ≤ 1e-12 + 4 eps₆₄ |δ|")
        # tmm where it is itself accurate (cos θ ≥ 1e-3: its √(1 − sin²θ) cancels near
        # grazing) and its transfer matrix is well conditioned (no strongly evanescent film)
        s2 = film.eta_outer**2 * (1 - c) * (1 + c)
        decay = 4 * np.pi * film.thickness * np.sqrt(np.maximum(s2 - film.eta_film**2, 0)) / lam
        use = (c >= 1e-3) & (decay < 30)
        err_tmm = np.abs(val - tmm_grid(film, np.where(use, c, 0.0), lam))
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
        ref_check(res, np.abs(val - ref), tol, case_args, call,
                   "float64, |ΔR| ≤ 1e-5 + 4 eps₃₂ |δ|")
    graz = c == 0
    res.documented.append({"case": "θ = 90° gives R = 1 (every film)", "n": int(graz.sum()),
                           "max_error": float(np.abs(val[graz] - 1).max()) if graz.any() else 0.0,
                           "holds": bool(np.all(np.abs(val[graz] - 1) <= BOUND_SLACK[dtype]))})
    res.seconds = time.perf_counter() - t0
    return res


RGB_VARIANTS = (("spectral", SB, 2, "exact"), ("spectral", CIE, 2, "exact"),
                ("fourier", SB, 2, "exact"), ("fourier", SB, 2, "gaussian"))


def _rgb_variants_fn(variants):
    def fn(film, cos_theta):
        return jnp.stack([rgb_reflectance(film, cos_theta, method=m, observer=o, terms=t,
                                          shat=sh,
                                              arithmetic="complex") for m, o, t, sh in variants])
    return fn


@functools.cache
def _rgb_group(dtype: str):
    """The `RGB_VARIANTS` on the stiff grid in one compiled reverse pass."""
    film, (theta,) = stiff_grid(STIFF_THETA)
    film, c = rounded((film, stiff_cos(theta)), dtype)
    values, grads = value_and_grads(_rgb_variants_fn(RGB_VARIANTS), as_dtype((film, c), dtype),
                                    ("film", "cos_theta"))
    return film, c, values, grads


def check_rgb(dtype: str = "float64", method: str = "spectral", observer: str = SB,
              terms: int = 2, shat: str = "exact") -> StabilityResult:
    """`rgb_reflectance`: spectral bands within [Σ W⁻, Σ W⁺] (exact: R ∈ [0, 1]); the Fourier
    path within its truncation bound of the spectral one where the series holds, and
    exactly Ŝ_j(0) (R = 1) under TIR at 1|2 (series.py's documented limitation)."""
    t0 = time.perf_counter()
    tag = method if method == "spectral" else f"fourier,M={terms}"
    tag += "" if observer == SB else f",{observer}"
    tag += "" if shat == "exact" else f",{shat}"
    res = StabilityResult(f"rgb_reflectance[{tag}]", dtype)
    variant = (method, observer, terms, shat)
    film, c, values, grads = _rgb_group(dtype)
    res.n_cases = len(c)
    val = values[RGB_VARIANTS.index(variant)] if variant in RGB_VARIANTS else None
    if val is None or any(not np.all(np.isfinite(g)) for g in grads.values()):
        val, grads = value_and_grads(_rgb_variants_fn((variant,)), as_dtype((film, c), dtype),
                                     ("film", "cos_theta"))
        val = val[0]
    case_args = {"film": film, "cos_theta": c}
    call = "rgb_reflectance"
    finish(res, val, grads, case_args, call, lambda v: v.reshape(len(c), -1))
    wlo, whi, wabs = weights_range(observer)
    spec = np.asarray(rgb_reflectance(film, c, observer=observer, method="spectral",
                                      arithmetic="complex"))
    tir = tir12(film, c)
    if method == "spectral":
        bound_check(res, val, wlo, whi, case_args, call,
                     "Σ_k min(W_kj, 0) ≤ R_j ≤ Σ_k max(W_kj, 0) (R(λ) ∈ [0, 1])")
        if dtype == "float32":
            film_np = film
            phase = 4 * np.pi * film_np.thickness * film_np.eta_film / 380.0
            tol = 2e-5 + 4 * np.finfo(np.float32).eps * phase * wabs.max()
            ref_check(res, np.abs(val - spec).max(axis=1), tol, case_args, call,
                       "float64 spectral, ≤ 2e-5 + 4 eps₃₂ |δ_max| ‖W‖₁")
        else:
            res.reference = "is the reference (float64)"
    else:
        tail, fit = _series_error_bounds(film, c, terms, observer)
        bound_check(res, val, wlo - tail, whi + tail, case_args, call,
                     "spectral range ± truncation tail 2|R*−T|·|z|^{M+1}/(1−|z|)·‖W_j‖₁")
        err = np.abs(val - spec)
        eps = np.finfo(dtype).eps
        slack = (1e-12 if dtype == "float64" else 2e-5) + 4 * eps * wabs * (
            4 * np.pi * film.thickness * film.eta_film / 380.0)[:, None]
        no_tir = ~tir[:, None]
        if shat == "exact":
            ref_check(res, np.where(no_tir, err, np.nan), tail + slack, case_args, call,
                       "spectral, |ΔR_j| ≤ truncation tail (no TIR at 1|2)")
            s0 = np.asarray(shat_at_zero(observer))
            holds = np.abs(val[tir] - s0).max() <= BOUND_SLACK[dtype] if tir.any() else True
        else:
            # the Gaussian fit is accurate on x = m D ≤ 8000 nm (spectra.gaussian_fit)
            opd = np.asarray(series_terms(film, jnp.asarray(c)).opd)
            fitted = no_tir & (terms * opd <= 8000.0)[:, None]
            ref_check(res, np.where(fitted, err, np.nan), tail + fit + slack, case_args, call,
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
    st = series_terms(film, jnp.asarray(cos_theta, jnp.float64), arithmetic="complex")
    amp, az = np.abs(np.asarray(st.amp)), np.abs(np.asarray(st.z))
    c0 = np.abs(np.asarray(st.c0))
    wabs = weights_range(observer)[2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tail = np.where(amp > 0, 2 * amp * az ** (terms + 1) / np.maximum(1 - az, 1e-300), 0.0)
    partial = 2 * amp * sum(az**m for m in range(1, terms + 1))
    fit_err = gaussian_fit_error(observer)
    s0_err = np.abs(1.0 - np.asarray(shat_at_zero(observer)))
    tail = tail.mean(axis=0)[:, None] * wabs
    fit = (c0.mean(axis=0)[:, None] * s0_err + partial.mean(axis=0)[:, None] * fit_err)
    return tail, fit


PATCH_VARIANTS = (*((m, "exact") for m in PATCH_METHODS), ("filtered_gt_moments", "lut"))


def _patch_variants_fn(variants, n):
    """fn(film, θ_o, α, lut): the variants stacked (the LUT an argument of the compiled call,
    `value_and_grads`)."""
    q = STABILITY_QUADRATURE

    def fn(film, theta_o, alpha, lut):
        # batch_size = all patches: one vmapped batch, no lax.map remainder (half the compile)
        return jnp.stack([patch_radiance(film, theta_o, alpha, method=m, lut=lut, batch_size=n,
                                         options=ModelOptions(shat=sh, quadrature=(q, q),
                                                              arithmetic="complex"))
                          for m, sh in variants])
    return fn


@functools.cache
def _patch_variant(dtype: str, method: str, shat: str):
    """One `PATCH_VARIANTS` entry on the stiff patch grid: values and gradients in one
    compiled reverse pass. One program per variant, not one for all of them: XLA's compile
    time grows faster than the program, so the seven programs compile in ~70 % of the time
    of their stack (and on two test workers at once), and a change to one method recompiles
    only its own."""
    film, (theta, alpha) = stiff_grid(STIFF_THETA, STIFF_ALPHA)
    if dtype == "float32":  # π/2 (and π/2 − 1e-9) round above π/2 in float32
        theta = np.minimum(theta.astype(np.float32).astype(np.float64), F32_BELOW_HALF_PI)
    film, theta, alpha = rounded((film, theta, alpha), dtype)
    values, grads = value_and_grads(_patch_variants_fn(((method, shat),), len(theta)),
                                    as_dtype((film, theta, alpha), dtype),
                                    ("film", "theta_o", "alpha"), (build_shat_lut(dtype=dtype),))
    return film, theta, alpha, values[0], grads


def check_patch(dtype: str = "float64", method: str = "reference",
                shat: str = "exact") -> StabilityResult:
    """`patch_radiance`: finite values and gradients (film, θ_o, α) at extreme inputs,
    reference within [A Σ W⁻, A Σ W⁺] (A = `microfacet.albedo`, same quadrature), `ideal` =
    A · Fourier(cos θ_o), every method → its mirror value at α = 1e-4 for d ≤ 500 nm."""
    t0 = time.perf_counter()
    q = STABILITY_QUADRATURE
    name = f"patch_radiance[{method}{',' + shat if shat != 'exact' else ''}]"
    film, theta, alpha, val, grads = _patch_variant(dtype, method, shat)
    res = StabilityResult(name, dtype, len(theta))
    case_args = {"film": film, "theta_o": theta, "alpha": alpha}
    call = "patch_radiance"
    finish(res, val, grads, case_args, call, lambda v: v.reshape(len(theta), -1))
    a = np.asarray(albedo(theta, alpha, quadrature=(q, q)))
    wlo, whi, wabs = weights_range(SB)
    c_o = np.cos(theta)
    # mirror limit: D varies by ~2η₂d·α·sin θ_o over the lobe, negligible for d ≤ 500 nm
    mirror = (alpha == alpha.min()) & (theta <= 0.7) & (film.thickness <= 500.0)
    if method == "reference":
        bound_check(res, val, a[:, None] * wlo, a[:, None] * whi, case_args, call,
                     "A·Σ min(W, 0) ≤ L_j ≤ A·Σ max(W, 0), A = albedo ≤ 1")
        spec = np.asarray(rgb_reflectance(film, c_o, method="spectral", arithmetic="complex"))
        err = np.where(mirror, np.abs(val - a[:, None] * spec).max(axis=1), np.nan)
        ref_check(res, err, 1e-4, case_args, call,
                   "α = 1e-4, θ_o ≤ 0.7, d ≤ 500 nm: A·R_j^spectral(cos θ_o), ≤ 1e-4")
    else:
        fourier = np.asarray(rgb_reflectance(film, c_o, method="fourier", terms=2,
                                             arithmetic="complex"))
        # |K 29| ≤ (|C₀| + 2|R*−T| Σ_{m≤2}|z|^m) ‖W‖₁ with |C₀| ≤ 2, |R*−T| ≤ 1, |z| ≤ 1
        hi = a[:, None] * 6.0 * wabs[None, :]
        bound_check(res, val, -hi, hi, case_args, call,
                     "|L_j| ≤ 6 A ‖W_j‖₁ (|C₀| ≤ 2, |R*−T| ≤ 1, |z| ≤ 1, M = 2)")
        if method == "ideal":
            err = np.abs(val - a[:, None] * fourier).max(axis=1)
            tol = 1e-12 if dtype == "float64" else 1e-4
            ref_check(res, err, tol, case_args, call,
                       f"A · rgb_reflectance(fourier, cos θ_o), ≤ {tol:g}")
            if dtype == "float32":  # what a user gets from np.float32(np.pi / 2) = π/2 + 4e-8
                # The film this check has always used, by name: the positional
                # Film(*MATERIALS["fig7"][:3], 1.0) read η₂, η₃, κ₃ of "fig7" as d, η₂, η₃
                # (figures/stability_report.md holds its result).
                f7 = Film(thickness=1.3, eta_film=2.0, eta_base=0.5,
                          kappa_base=1.0).astype(jnp.float32)
                over = np.asarray(patch_radiance(f7, np.float32(np.pi / 2), np.float32(0.3),
                                                 method=method,
                                                     options=ModelOptions(quadrature=(q, q))))
                below = np.asarray(patch_radiance(f7, np.float32(F32_BELOW_HALF_PI),
                                                  np.float32(0.3), method=method,
                                                      options=ModelOptions(quadrature=(q, q))))
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
            ref_check(res, err, tol, case_args, call,
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
    t0 = time.perf_counter()
    lut = build_shat_lut(dtype=dtype)
    mmax, smax = float(lut.mu_max), float(lut.sigma_max)
    mus = np.array([0.0, 1e-6, 500.0, mmax - 1e-3, mmax, mmax + 1.0, 1e5, 1e9])
    mus = np.concatenate([mus, -mus[1:]])
    sig = np.array([0.0, 1e-6, 500.0, smax, 1e4, 1e9])
    m, s = rounded(tuple(g.ravel() for g in np.meshgrid(mus, sig, indexing="ij")), dtype)
    res = StabilityResult("lut.lookup", dtype, len(m))
    val, grads = value_and_grads(lambda mu, sg, t: lookup(t, mu, sg), as_dtype((m, s), dtype),
                                 ("mu", "sigma"), (lut,))
    case_args = {"mu": m, "sigma": s}
    call = "lookup"
    cval = val[0] + 1j * val[1]  # value_and_grads stacks (real, imag)
    finish(res, val, grads, case_args, call, lambda v: np.moveaxis(v, 0, -1).reshape(len(m), -1))
    wabs = weights_range(SB)[2]
    bound_check(res, np.abs(cval), 0.0, wabs * (1 + 1e-6), case_args, call, "|Ŝ_j| ≤ ‖W_j‖₁")
    exact = shat_host(m, s * s, SB)
    inside = (np.abs(m) <= mmax) & (s <= smax)
    err = np.where(inside, np.abs(cval - exact).max(axis=1), np.nan)
    tol = 5e-5 if dtype == "float64" else 8e-5
    ref_check(res, err, tol, case_args, call,
               f"exact filtered quadrature inside the table, ≤ {tol:g} (tests/spectral/test_lut.py)")
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


def check_sensitivity(dtype: str = "float64", method: str = "exact") -> StabilityResult:
    """`sensitivity_ft(x, sigma2=…)`: finite value and gradient for x up to 1e7 nm and σ²
    from 0 to 1e30 nm²; exact: |Ŝ| ≤ ‖W‖₁ and equal to the host quadrature."""
    t0 = time.perf_counter()
    xs = np.array([0.0, 1e-6, 500.0, 1e4, 1e5, 1e7])
    xs = np.concatenate([xs, -xs[1:]])
    s2 = np.array([0.0, 1e-12, 1e4, 1e6, 1e12, 1e30])
    x, v2 = rounded(tuple(g.ravel() for g in np.meshgrid(xs, s2, indexing="ij")), dtype)
    res = StabilityResult(f"sensitivity_ft[{method}]", dtype, len(x))
    val, grads = value_and_grads(lambda a, b: sensitivity_ft(a, sigma2=b, shat=method),
                                 as_dtype((x, v2), dtype), ("x", "sigma2"))
    case_args = {"x": x, "sigma2": v2}
    call = "sensitivity_ft"
    cval = val[0] + 1j * val[1]
    finish(res, val, grads, case_args, call, lambda v: np.moveaxis(v, 0, -1).reshape(len(x), -1))
    if method == "exact":
        wabs = weights_range(SB)[2]
        bound_check(res, np.abs(cval), 0.0, wabs * (1 + 1e-6), case_args, call,
                     "|Ŝ_j| ≤ ‖W_j‖₁")
        exact = shat_host(x, v2, SB)
        err = np.abs(cval - exact).max(axis=1)
        eps = np.finfo(dtype).eps
        base_tol = 1e-12 if dtype == "float64" else 1e-6
        tol = base_tol + 4 * eps * 2 * np.pi * np.abs(x) / 360.0 * wabs.max()
        ref_check(res, err, tol, case_args, call,
                   f"host NumPy quadrature, ≤ {base_tol:g} + 4 eps |2πx/λ_min| ‖W‖₁")
    else:
        res.bound = "none asserted (closed form of the Gaussian fit)"
        res.reference = "none (fit error: spectra.gaussian_fit_error)"
    res.seconds = time.perf_counter() - t0
    return res


def check_opd(dtype: str = "float64") -> StabilityResult:
    """`opd.taylor_opd_moments`: μ_D, σ_D ≥ 0 and finite (with gradients) for μ_c ∈ [−1, 1],
    σ_c² ∈ [0, 1e6]; at σ_c² = 0, σ_D = 0 and μ_D = D(cos θ₁*) exactly (K 22–24)."""
    t0 = time.perf_counter()
    film, (mu_c, var_c) = rounded(stiff_grid([-1.0, -0.5, 0.0, 0.5, 1.0],
                                              [0.0, 1e-12, 0.1, 1.0, 1e6]), dtype)
    res = StabilityResult("opd.taylor_opd_moments", dtype, len(mu_c))
    val, grads = value_and_grads(lambda f, m, v: jnp.stack(taylor_opd_moments(f, m, v), -1),
                                 as_dtype((film, mu_c, var_c), dtype), ("film", "mu_c", "var_c"))
    case_args = {"film": film, "mu_c": mu_c, "var_c": var_c}
    call = "taylor_opd_moments"
    finish(res, val, grads, case_args, call, lambda v: v)
    bound_check(res, val, 0.0, np.inf, case_args, call, "μ_D ≥ 0, σ_D ≥ 0")
    d_star = np.asarray(opd_of_cos(film, cos_incidence_from_projection(jnp.asarray(mu_c))))
    zero = var_c == 0
    scale = 1 + np.abs(d_star)
    rel = 1e-12 if dtype == "float64" else 1e-5
    err = np.where(zero, np.maximum(np.abs(val[:, 0] - d_star), np.abs(val[:, 1])) / scale,
                   np.nan)
    ref_check(res, err, rel, case_args, call,
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
    t0 = time.perf_counter()
    sig = np.array([0.0, 1e-6, 1e3, 1e9])
    film, (theta, s_d) = stiff_grid(STIFF_THETA, sig)
    film, c = rounded((film, stiff_cos(theta)), dtype)
    mu_d = np.asarray(opd_of_cos(film, jnp.asarray(c))).astype(dtype).astype(np.float64)
    res = StabilityResult("filtered.filtered_bands", dtype, len(c))
    lut = build_shat_lut(dtype=dtype)
    shats = ("exact", "lut", "gaussian")

    def fn(f, cc, m, s, table):
        return jnp.stack([filtered_bands(f, cc, OPDMoments(m, s), SB, shat=sh, lut=table,
                                         arithmetic="complex") for sh in shats])

    val, grads = value_and_grads(fn, as_dtype((film, c, mu_d, s_d), dtype),
                                 ("film", "cos_theta", "mu_D", "sigma_D"), (lut,))
    case_args = {"film": film, "cos_theta": c, "mu_D": mu_d, "sigma_D": s_d}
    call = "filtered_bands"
    finish(res, val, grads, case_args, call,
            lambda v: np.moveaxis(v, 0, 1).reshape(len(c), -1))
    st = series_terms(film, jnp.asarray(c), arithmetic="complex")
    incoh = np.asarray(jnp.mean(st.c0, axis=0))[:, None] * np.asarray(shat_at_zero(SB))
    fourier = np.asarray(rgb_reflectance(film, c, method="fourier", terms=2, arithmetic="complex"))
    wabs = weights_range(SB)[2]
    hi = 6.0 * wabs
    bound_check(res, np.moveaxis(val, 0, 1), -hi, hi, case_args, call,
                 "|R_j| ≤ 6 ‖W_j‖₁ (M = 2)")
    tol = 1e-12 if dtype == "float64" else 2e-4
    # Ŝ(μ, 0) = Ŝ(μ): the exact-Ŝ K 29 equals the Fourier path
    err = np.where(s_d == 0, np.abs(val[0] - fourier).max(axis=1), np.nan)
    big = s_d == 1e9
    err_inc = np.abs(val[:2] - incoh[None]).max(axis=(0, 2))
    err = np.where(big, err_inc, err)
    phase_tol = tol if dtype == "float64" else tol + 8 * np.finfo(np.float32).eps * (
        2 * np.pi * 2 * mu_d / 380.0)
    ref_check(res, err, phase_tol, case_args, call,
               "σ_D = 0: exact-Ŝ K 29 = Fourier path; σ_D = 1e9: exact/LUT = C₀* Ŝ_j(0)")
    res.seconds = time.perf_counter() - t0
    return res


def stability_check(name: str, dtype: str) -> StabilityResult:
    """Run the check called `name` (one of `STABILITY_FUNCTIONS`) in `dtype`.

    Example (K 25–28 over μ_c ∈ [−1, 1], σ_c² and the stiff films: no finding):
        >>> r = stability_check("opd.taylor_opd_moments", "float64")
        >>> r.n_cases, r.problems
        (1250, 0)
    """
    if name.startswith("airy_reflectance"):
        return check_airy(dtype, "real" if "dielectric" in name else "auto")
    if name.startswith("rgb_reflectance"):
        opts = name[name.index("[") + 1:-1].split(",")
        method = opts[0]
        terms = int(opts[1][2:]) if method == "fourier" else 2
        return check_rgb(dtype, method, CIE if CIE in opts else SB, terms,
                         "gaussian" if "gaussian" in opts else "exact")
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
            log(f"stability {name} {dt}", verbose)
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
             "Generated by `benchmarks.stability.write_stability_report` on "
             f"{env['devices']} "
             f"(jax {env['jax']}, {env['date']}); asserted by `tests/benchmarks/test_stability.py`.", "",
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
            f"| [{fmt(r.value_min, '.3g')}, {fmt(r.value_max, '.3g')}] | {_cell(r.bound)} "
            f"| {r.bound_violations} ({fmt(r.bound_excess, '.2g')}) | {_cell(r.reference)} "
            f"| {fmt(r.ref_error, '.2g')} ({fmt(r.ref_tol, '.2g')}) | {r.ref_violations} "
            f"| {r.seconds:.1f} |")
    lines += ["", "## Documented behaviours and known inaccuracies", "",
              "| function | dtype | case | cases | max error | holds | note |",
              "|---|---|---|---|---|---|---|"]
    for r in results:
        for d in r.documented:
            lines.append(f"| {r.function} | {r.dtype} | {_cell(d['case'])} | {d['n']} "
                         f"| {fmt(d['max_error'], '.3g')} | {d['holds']} "
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


def main(argv=None) -> int:
    """``python -m benchmarks.stability [--out figures/stability_report.md]``."""
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures/stability_report.md", help="markdown path")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    summary = write_stability_report(args.out, verbose=True)
    print(f"{summary['n_checks']} checks, {summary['n_problems']} problems; wrote {args.out}")
    return 1 if summary["n_problems"] else 0


if __name__ == "__main__":
    sys.exit(main())
