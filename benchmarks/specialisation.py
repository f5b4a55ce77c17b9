r"""Leave out what a scene does not need, measured.

Each specialisation is static — a Python value fixed at trace time, so `jax.jit` compiles a
smaller program with no run-time branch — and is timed on one float32 batch of shading
points against the path that keeps what it leaves out, with the error it adds:

| scene feature | left out | baseline → specialised |
|---|---|---|
| dielectric base (κ₃ = 0, η₂, η₃ ≥ η₁) | complex arithmetic | arithmetic complex → real |
| near-mirror surface (small α) | lobe filtering (K 20–28, filtered Ŝ) | K 29 → ideal |
| one band needed | the other bands | three bands → one |
| smooth enough interference | Fourier orders m > M | M = 4 → 2, M = 2 → 1 |
| Ŝ from a table / closed form | the per-point λ quadrature | exact Ŝ → LUT, Gaussian fit |
| no film (d = 0) | the film (series terms, Ŝ(mD)) | `ideal_kernel` at d = 0 → `reflectance.bare_bands` |

The public functions choose two of these from concrete inputs (`ModelOptions.arithmetic` and
`.layer`, "auto"); one band has no code path of its own and is measured as a renderer would
build it, an `spectra.Observer` holding one of the three bands (`band_subset`).

Inputs: `points` shading points, float32: θ_o on 32 angles in [0°, 85°] × α ∈ {0.01, 0.05,
0.1, 0.25, 0.4} (light-lobe moments from `kernels.lobe_moments`), d ~ U(0, 1000) nm, films
`MATERIALS["fig7"]` (absorbing), `["tio2_glass"]` (dielectric) or the Figure 7 film at d = 0.
Times: compile (first call − warm) and warm µs per point (median of `repeats`), the time
saved 1 − t_spec/t_base and the speed-up t_base/t_spec. Error added: CIEDE2000 ΔE₀₀ p95 /
max and max |ΔR_j| of the specialised output against the baseline output on the same points
(one band: the baseline with that band replaced); for rows on `ideal_kernel` also the ΔE₀₀
of both against the float64 spectral reference (`rgb_reflectance(method="spectral")`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.realtime.kernels import filtered_kernel, ideal_kernel, lobe_moments
from thinfilm_jax.spectral.lut import build_shat_lut
from thinfilm_jax.spectral.reflectance import bare_bands, rgb_reflectance
from thinfilm_jax.spectral.spectra import Observer, get_observer
from ._common import MATERIALS, SB, BenchConfig, error_stats, view_vector
from ._timing import environment, fmt, log, time_call, write_report

THETA_DEG = np.linspace(0.0, 85.0, 32)
ALPHAS = (0.01, 0.05, 0.1, 0.25, 0.4)
NEAR_MIRROR_ALPHA = 0.05  # the near-mirror row scores α ≤ this
BAND = 1  # the band kept by the one-band rows (G of Stiles & Burch)
N_REFERENCE = 4000  # points scored against the float64 spectral reference


def band_subset(observer: str, j: int) -> Observer:
    """`observer` reduced to its band `j` (an `Observer` the kernels accept by value).

    Example (the G band alone, still of unit area):
        >>> obs = band_subset("stiles_burch_1959_10", 1)
        >>> obs.name, obs.n_bands, round(float(obs.weights.sum()), 12)
        ('stiles_burch_1959_10[G]', 1, 1.0)
    """
    obs = get_observer(observer)
    return Observer(f"{obs.name}[{obs.band_names[j]}]", obs.wavelengths,
                    obs.weights[:, j:j + 1], obs.areas[j:j + 1], (obs.band_names[j],))


def _ideal(terms=2, shat="exact", arithmetic="complex", observer=SB):
    return lambda f, c, wo, mu, cv, lut: ideal_kernel(f, c, observer=observer, terms=terms,
                                                      shat=shat, arithmetic=arithmetic)


def _k29(shat="lut", arithmetic="complex", observer=SB, terms=2):
    return lambda f, c, wo, mu, cv, lut: filtered_kernel(
        f, wo, mu, cv, observer=observer, terms=terms, shat=shat, lut=lut, arithmetic=arithmetic)


def _fresnel(f, c, wo, mu, cv, lut):
    return bare_bands(f, c, SB)


ONE_BAND = band_subset(SB, BAND)
# (feature, left out, films, (baseline label, path), (specialised label, path), kind)
# kind: "ref" (ideal-kernel rows: also scored against the spectral reference), "band" (one
# band replaces band BAND of the baseline), "mirror" (error scored on α ≤ NEAR_MIRROR_ALPHA)
ROWS = (
    ("dielectric base", "complex arithmetic", "dielectric",
     ("ideal M=2, general", _ideal()), ("ideal M=2, dielectric", _ideal(arithmetic="real")),
     "ref"),
    ("dielectric base", "complex arithmetic", "dielectric",
     ("K29 LUT, general", _k29()), ("K29 LUT, dielectric", _k29(arithmetic="real")), ""),
    ("near-mirror surface", "light-lobe filtering (K 20–28, filtered Ŝ)", "absorbing",
     ("K29 Gaussian Ŝ", _k29(shat="gaussian")), ("ideal M=2, Gaussian Ŝ", _ideal(shat="gaussian")),
     "mirror"),
    ("near-mirror surface", "light-lobe filtering; the ideal kernel has no LUT path",
     "absorbing", ("K29 LUT", _k29()), ("ideal M=2", _ideal()), "mirror"),
    ("one band needed", "the other two bands", "absorbing",
     ("ideal M=2", _ideal()), ("ideal M=2, band G only", _ideal(observer=ONE_BAND)), "band"),
    ("one band needed", "the other two bands", "absorbing",
     ("K29 exact Ŝ", _k29(shat="exact")),
     ("K29 exact Ŝ, band G only", _k29(shat="exact", observer=ONE_BAND)), "band"),
    ("M = 2 is enough", "Fourier orders 3, 4", "absorbing",
     ("ideal M=4", _ideal(terms=4)), ("ideal M=2", _ideal()), "ref"),
    ("M = 1 is enough", "Fourier order 2", "absorbing",
     ("ideal M=2", _ideal()), ("ideal M=1", _ideal(terms=1)), "ref"),
    ("M = 1 is enough", "Fourier order 2", "absorbing",
     ("K29 LUT", _k29()), ("K29 LUT M=1", _k29(terms=1)), ""),
    ("Ŝ from a table", "per-point filtered-Ŝ quadrature (89 λ)", "absorbing",
     ("K29 exact Ŝ", _k29(shat="exact")), ("K29 LUT", _k29()), ""),
    ("Ŝ from a closed form", "per-point filtered-Ŝ quadrature (89 λ)", "absorbing",
     ("K29 exact Ŝ", _k29(shat="exact")), ("K29 Gaussian Ŝ", _k29(shat="gaussian")), ""),
    ("Ŝ from a closed form", "per-point Ŝ quadrature (89 λ)", "absorbing",
     ("ideal M=2", _ideal()), ("ideal M=2, Gaussian Ŝ", _ideal(shat="gaussian")), "ref"),
    ("no film (d = 0)", "the film: series terms, Ŝ(mD)", "bare",
     ("ideal M=2", _ideal()), ("Fresnel only", _fresnel), "ref"),
)


def shading_points(n: int, seed: int = 9):
    """(inputs by film set, α per point): float32 (film, cos θ_o, ω_o, μ_ω, Σ_ω) per set."""
    rng = np.random.default_rng(seed)
    th, al = (g.ravel() for g in np.meshgrid(np.deg2rad(THETA_DEG), ALPHAS, indexing="ij"))
    _, mean, cov = (np.asarray(x) for x in lobe_moments(th, al))
    i = rng.integers(0, len(th), n)
    d = rng.uniform(0.0, 1000.0, n)
    c = np.cos(th[i])
    geometry = tuple(jnp.asarray(x, jnp.float32) for x in (c, view_vector(c), mean[i], cov[i]))
    films = {"absorbing": ("fig7", d), "dielectric": ("tio2_glass", d),
             "bare": ("fig7", np.zeros(n))}
    sets = {}
    for key, (mat, thick) in films.items():
        eta2, eta3, kap3, eta1 = MATERIALS[mat]
        film = Film(thick, np.full(n, eta2), np.full(n, eta3), np.full(n, kap3), np.full(n, eta1))
        sets[key] = (film.astype(jnp.float32), *geometry)
    return sets, al[i]


def run_specialisation(cfg: BenchConfig, out=None, verbose: bool = True) -> dict:
    """Time every `ROWS` pair on `cfg.specialisation_points` float32 points; write
    ``specialisation.json`` and ``specialisation.md`` into `out` (if given)."""
    n = cfg.specialisation_points
    sets, alpha = shading_points(n)
    lut = build_shat_lut(dtype=jnp.float32)
    k = min(n, N_REFERENCE)

    def first_k(tree):  # the first k points of every leaf, float64
        return jax.tree.map(lambda x: np.asarray(x[:k], np.float64), tree)

    refs = {key: np.asarray(rgb_reflectance(first_k(f), first_k(c), method="spectral"))
            for key, (f, c, *_) in sets.items()}
    cache = {}

    def timed(films, label, path):
        if (films, label) not in cache:
            log(f"(specialisation) {label} on {films} films", verbose)
            res, t = time_call(jax.jit(path), (*sets[films], lut), cfg.repeats)
            cache[films, label] = np.asarray(res, np.float64), t
        return cache[films, label]

    rows = []
    for feature, left_out, films, (b_label, b_path), (s_label, s_path), kind in ROWS:
        b_out, b_t = timed(films, b_label, b_path)
        s_out, s_t = timed(films, s_label, s_path)
        if kind == "band":
            s_full = b_out.copy()
            s_full[:, BAND] = s_out[:, 0]
            s_out = s_full
        sel = alpha <= NEAR_MIRROR_ALPHA if kind == "mirror" else np.ones(n, bool)
        err = error_stats(s_out[sel], b_out[sel])
        row = {"feature": feature, "left_out": left_out, "films": films,
               "baseline": b_label, "specialised": s_label,
               "baseline_us": b_t.warm_s / n * 1e6, "specialised_us": s_t.warm_s / n * 1e6,
               "baseline_compile_s": b_t.compile_s, "specialised_compile_s": s_t.compile_s,
               "dE_added_p95": err["dE_p95"], "dE_added_max": err["dE_max"],
               "band_abs_added_max": err["band_abs_max"]}
        row["time_saved"] = 1.0 - row["specialised_us"] / row["baseline_us"]
        row["speedup"] = row["baseline_us"] / row["specialised_us"]
        if kind == "mirror":
            row["scored_on"] = f"α ≤ {NEAR_MIRROR_ALPHA:g}"
            row["dE_added_p95_all_alpha"] = error_stats(s_out, b_out)["dE_p95"]
        if kind == "ref":
            for name, o in (("baseline", b_out), ("specialised", s_out)):
                e = error_stats(o[:k], refs[films])
                row[f"{name}_dE_vs_reference_max"] = e["dE_max"]
                row[f"{name}_dE_vs_reference_p95"] = e["dE_p95"]
        rows.append(row)
    result = {"environment": environment(), "points": n, "repeats": cfg.repeats,
              "dtype": "float32", "reference_points": k, "rows": rows}
    if out is not None:
        write_report(out, "specialisation", result, specialisation_markdown)
    if verbose:
        print(specialisation_markdown(result))
    return result


def specialisation_markdown(result: dict) -> str:
    """The table: scene feature → what is left out → time saved → error added."""
    env = result["environment"]
    lines = [f"Specialisations, {result['points']:,} float32 shading points on "
             f"{env['devices']} ({env['cpu_count']} CPUs, load "
             f"{fmt(env['load_average'][0], '.1f')}), warm median of {result['repeats']}; "
             "error added = specialised vs baseline on "
             "the same points; vs ref. = ΔE₀₀ max against the float64 spectral reference "
             f"(first {result['reference_points']:,} points).", "",
             "| scene feature | left out | baseline → specialised | µs / point | time saved "
             "| compile s | ΔE₀₀ added p95 / max | max \\|ΔR_j\\| added | ΔE₀₀ max vs ref. |",
             "|" + "---|" * 9]
    for r in result["rows"]:
        scored = f" ({r['scored_on']}; all α: p95 {fmt(r['dE_added_p95_all_alpha'], '.2g')})" \
            if "scored_on" in r else ""
        ref = (f"{fmt(r['baseline_dE_vs_reference_max'], '.2g')} → "
               f"{fmt(r['specialised_dE_vs_reference_max'], '.2g')}"
               if "baseline_dE_vs_reference_max" in r else "–")
        lines.append(
            f"| {r['feature']} | {r['left_out']} | {r['baseline']} → {r['specialised']} "
            f"({r['films']} films) | {r['baseline_us']:.3g} → {r['specialised_us']:.3g} "
            f"| {100 * r['time_saved']:.0f} % (×{r['speedup']:.2f}) "
            f"| {r['baseline_compile_s']:.2f} → {r['specialised_compile_s']:.2f} "
            f"| {fmt(r['dE_added_p95'], '.2g')} / {fmt(r['dE_added_max'], '.2g')}{scored} "
            f"| {fmt(r['band_abs_added_max'], '.2g')} | {ref} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """``python -m benchmarks.specialisation [--points N] [--out figures]``."""
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--points", type=int, default=BenchConfig.specialisation_points,
                   help="float32 shading points per timed call")
    p.add_argument("--repeats", type=int, default=BenchConfig.repeats)
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    cfg = dataclasses.replace(BenchConfig(), specialisation_points=args.points,
                              repeats=args.repeats)
    run_specialisation(cfg, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
