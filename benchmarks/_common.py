"""Materials, error statistics and table rows shared by the studies."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from thinfilm_jax.spectral.colorimetry import delta_e2000
from thinfilm_jax.core.film import Film
from thinfilm_jax.brdf.microfacet import view_direction
from ._timing import Timing

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
    # the approximate methods of panel (b): None = every uniform-light method of the registry
    # (`core.methods.names("patch", exact=False)`, read when the bench runs, so a method
    # registered at run time gets its row); `improved` once per named preset of
    # `improved_presets` (`ModelOptions.preset`)
    patch_methods: tuple[str, ...] | None = None
    improved_presets: tuple[str, ...] = ("fast", "default", "accurate")
    patch_chunk: int = 12  # patches per timed call (the error pass runs all chunks)
    mc_samples: tuple[int, ...] = (1_000, 10_000, 100_000)
    mc_patches: int = 12
    mc_chunk: int = 4
    lut_resolutions: tuple[tuple[float, int], ...] = ((12.5, 256), (25.0, 128), (50.0, 64),
                                                      (100.0, 32))
    kernel_points: int = 1_000_000
    # float32 shading points of the specialisation study (`specialisation`); 0: skip it
    specialisation_points: int = 200_000
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
                   quadrature_orders=(8, 16, 32),
                   patch_chunk=8, mc_samples=(1_000,), mc_patches=4, mc_chunk=4,
                   lut_resolutions=((25.0, 128),), kernel_points=10_000,
                   specialisation_points=20_000, peer_sides=(100,),
                   tmm_calls=40, stability=False)

    @classmethod
    def tiny(cls) -> BenchConfig:
        """The smallest configuration that runs every code path (the smoke test)."""
        return cls(name="tiny", repeats=1, n_thickness=3, n_angle=3, lambda_steps=(1, 2),
                   fourier_terms=(2,), gaussian_terms=(), m_sweep_max=3,
                   patch_thickness=(600.0,), patch_theta_deg=(30.0,), patch_alpha=(0.2,),
                   reference_quadrature=12, check_quadrature=8, quadrature_orders=(8,),
                   improved_presets=("default",), patch_chunk=2,
                   mc_samples=(64,), mc_patches=1, mc_chunk=1, lut_resolutions=((50.0, 32),),
                   kernel_points=64, specialisation_points=256, peer_sides=(4,),
                   tmm_calls=2, extras=False,
                   stability=False)


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


def material_film(names, thickness) -> Film:
    """A `Film` per (material name, thickness) pair (flat arrays, float64)."""
    p = np.array([MATERIALS[n] for n in names], np.float64).reshape(-1, 4)
    d = np.asarray(thickness, np.float64)
    return Film(d, p[:, 0], p[:, 1], p[:, 2], p[:, 3])


def view_vector(cos_o):
    """ω_o (..., 3) from cos θ_o: `microfacet.view_direction`, the frame of
    `kernels.lobe_moments`."""
    return view_direction(jnp.arccos(jnp.asarray(cos_o)))
