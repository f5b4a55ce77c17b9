"""Does `fit_film` find the global minimum, and do its standard errors mean what they say?

    python -m benchmarks.coverage [--n-global 100] [--n-coverage 200] [--seed 0]
        [--methods reference] [--out figures/coverage.json] [--figure figures/coverage.png]

Two seeded experiments, one fixed mid-range initial guess for every film (d = 500 nm,
η₂ = 1.4, α = 0.25 when free), observations from the converged `reference` patch radiance
(quadrature 48 × 48) and fits with the default `FitOptions` (quadrature 16 × 16):

* **global** (README, the global minimum): `--n-global` noise-free films, d ~ U(150, 1200) nm,
  η₂ ~ U(1.2, 1.7), η₃ = 2.0, κ₃ = 0.5, six views 0–70°, α = 0.15 known; d and η₂ free.
  A fit is in the global minimum when |Δd| < 1 nm and |Δη₂| < 1e-3 (noise-free data: the
  global minimum is the truth, loss ≈ 0).
* **coverage** (README, error bars): `--n-coverage` films with d ~ U(150, 1200) nm,
  η₂ ~ U(1.2, 1.7), η₃ ~ U(1.5, 2.5), κ₃ ~ U(0, 0.8), α ~ U(0.1, 0.4), views drawn from three
  sets (six 0–70°, nine 0–80°, four 10–60°), Gaussian noise of standard deviation 1 % of
  the RMS of each film's observations; d, η₂ and α free (σ not given: s² is estimated
  from the residuals). Reported: the fraction in the right basin (|Δd| below a quarter
  fringe order), the fraction flagged `ambiguous`, and per parameter the fraction of
  fits with |fit − truth| ≤ 1 and ≤ 2 standard errors (nominal 68.3 % / 95.4 %, and
  the Student-t values for n − p degrees of freedom), over all fits and over those in the
  right basin; the z = (fit − truth)/SE are plotted against N(0, 1).

Results go to `--out` (JSON, written atomically, also every 10 fits) and the figure to
`--figure`; the table is printed.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time

import jax
import numpy as np

from thinfilm_jax.core.files import write_json
from thinfilm_jax.core.film import Film
from thinfilm_jax.fit.film_fit import FitOptions, fit_film
from thinfilm_jax.shading.patch import patch_radiance

VIEWS = {
    "six 0-70": np.deg2rad(np.linspace(0.0, 70.0, 6)),
    "nine 0-80": np.deg2rad(np.linspace(0.0, 80.0, 9)),
    "four 10-60": np.deg2rad(np.linspace(10.0, 60.0, 4)),
}
INITIAL = dict(thickness=500.0, eta_film=1.4, alpha=0.25)
FREE_GLOBAL = ("thickness", "eta_film")
FREE_COVERAGE = ("thickness", "eta_film", "alpha")
NOISE = 0.01
OBS_QUADRATURE = (48, 48)


def observe(p, theta):
    film = Film(p["thickness"], p["eta_film"], p["eta_base"], p["kappa_base"])
    return np.asarray(patch_radiance(film, theta, p["alpha"]))


def one_fit(obs, theta, p, free, method):
    init = Film(INITIAL["thickness"], INITIAL["eta_film"], p["eta_base"], p["kappa_base"])
    alpha = INITIAL["alpha"] if "alpha" in free else p["alpha"]
    t0 = time.perf_counter()
    res = fit_film(obs, theta, alpha=alpha, initial=init, free=free, method=method,
                   options=FitOptions())
    jax.block_until_ready(res.loss)
    dt = time.perf_counter() - t0
    fitted = {k: float(v) for k, v in res.params.items()}
    order = 550.0 / (2.0 * p["eta_film"])  # ~ one fringe order in d (nm)
    return {
        "truth": {k: p[k] for k in free}, "fit": fitted,
        "stderr": {k: float(v) for k, v in res.stderr.items()},
        "loss": float(res.loss), "converged": bool(res.converged), "time_s": dt,
        "n_obs": int(obs.size), "n_free": len(free),
        "right_basin": abs(fitted["thickness"] - p["thickness"]) < 0.25 * order,
        "ambiguous": res.ambiguous, "runner_ups": res.runner_ups,
        "correlation": np.asarray(res.correlation).tolist(),
    }


def _t_cdf(x, dof):
    from scipy.stats import t

    return float(t.cdf(x, dof))


def summarise_global(rows):
    ok = [abs(r["fit"]["thickness"] - r["truth"]["thickness"]) < 1.0
          and abs(r["fit"]["eta_film"] - r["truth"]["eta_film"]) < 1e-3 for r in rows]
    misses = [{"truth": r["truth"], "fit": r["fit"]} for r, g in zip(rows, ok) if not g]
    return {"n": len(rows), "global_minimum_fraction": float(np.mean(ok)),
            "ambiguous_fraction": float(np.mean([r["ambiguous"] for r in rows])),
            "misses": misses,
            "time_per_fit_s": float(np.median([r["time_s"] for r in rows]))}


def summarise_coverage(rows, free):
    z = {k: np.array([(r["fit"][k] - r["truth"][k]) / r["stderr"][k] for r in rows])
         for k in free}
    basin = np.array([r["right_basin"] for r in rows])
    dof = rows[0]["n_obs"] - rows[0]["n_free"] if rows else 1
    out = {"n": len(rows), "right_basin_fraction": float(basin.mean()),
           "ambiguous_fraction": float(np.mean([r["ambiguous"] for r in rows])),
           "ambiguous_among_wrong_basin": (float(np.mean([r["ambiguous"] for r in rows
                                                          if not r["right_basin"]]))
                                           if (~basin).any() else None),
           "converged_fraction": float(np.mean([r["converged"] for r in rows])),
           "time_per_fit_s": float(np.median([r["time_s"] for r in rows])),
           "nominal": {"1se": math.erf(1 / math.sqrt(2)), "2se": math.erf(2 / math.sqrt(2))},
           # ±1, ±2 SE under Student's t (s² from the residuals), averaged over the fits
           "nominal_student_t": {
               "1se": float(np.mean([2 * _t_cdf(1.0, r["n_obs"] - r["n_free"]) - 1
                                     for r in rows])),
               "2se": float(np.mean([2 * _t_cdf(2.0, r["n_obs"] - r["n_free"]) - 1
                                     for r in rows]))},
           "coverage": {}, "coverage_right_basin": {}, "median_abs_z": {}}
    from scipy.stats import t

    dofs = np.array([r["n_obs"] - r["n_free"] for r in rows])
    out["t_interval_coverage"] = {}  # `FitResult.interval`: Student-t with each fit's n − p
    for k in free:
        a = np.abs(z[k])
        out["t_interval_coverage"][k] = {
            f"{lvl:.3f}": float(np.mean(a <= t.ppf(0.5 + lvl / 2, dofs)))
            for lvl in (out["nominal"]["1se"], out["nominal"]["2se"])}
        out["coverage"][k] = {"1se": float(np.mean(a <= 1)), "2se": float(np.mean(a <= 2))}
        out["coverage_right_basin"][k] = {"1se": float(np.mean(a[basin] <= 1)),
                                          "2se": float(np.mean(a[basin] <= 2))}
        # |z| of a well-calibrated estimate has median 0.674 (≈ 0.69 for a t with few dof)
        out["median_abs_z"][k] = float(np.median(a[basin]))
    out["student_t_dof_of_first_view_set"] = dof
    return out


def run(n_global, n_coverage, seed, methods, out=None, progress=True):
    rng = np.random.default_rng(seed)
    result = {
        "command": "python -m benchmarks.coverage " + " ".join(sys.argv[1:]),
        "seed": seed, "initial": INITIAL, "noise": "Gaussian, sd = 1 % of the RMS of each "
        "film's observations", "observations": "reference, quadrature 48x48",
        "machine": {"platform": platform.platform(), "jax": jax.__version__,
                    "devices": [str(d) for d in jax.devices()]},
        "global": {}, "coverage": {}, "per_fit": {},
    }
    t_start = time.perf_counter()
    films_g = [dict(thickness=rng.uniform(150, 1200), eta_film=rng.uniform(1.2, 1.7),
                    eta_base=2.0, kappa_base=0.5, alpha=0.15) for _ in range(n_global)]
    films_c = []
    for _ in range(n_coverage):
        films_c.append(dict(thickness=rng.uniform(150, 1200), eta_film=rng.uniform(1.2, 1.7),
                            eta_base=rng.uniform(1.5, 2.5), kappa_base=rng.uniform(0.0, 0.8),
                            alpha=rng.uniform(0.1, 0.4),
                            views=list(VIEWS)[int(rng.integers(len(VIEWS)))]))
    noise = rng.standard_normal((n_coverage, 9, 3))
    for m in methods:
        rows_g, rows_c = [], []
        result["per_fit"][m] = {"global": rows_g, "coverage": rows_c}
        theta = VIEWS["six 0-70"]
        for i, p in enumerate(films_g):
            rows_g.append(one_fit(observe(p, theta), theta, p, FREE_GLOBAL, m))
            _tick(progress, f"{m} global", i, n_global, t_start, out, result)
        for i, p in enumerate(films_c):
            theta = VIEWS[p["views"]]
            clean = observe(p, theta)
            obs = clean + NOISE * np.sqrt(np.mean(clean**2)) * noise[i, :theta.size]
            obs = np.maximum(obs, 0.0)
            rows_c.append(one_fit(obs, theta, p, FREE_COVERAGE, m) | {"views": p["views"]})
            _tick(progress, f"{m} coverage", i, n_coverage, t_start, out, result)
        if rows_g:
            result["global"][m] = summarise_global(rows_g)
        if rows_c:
            result["coverage"][m] = summarise_coverage(rows_c, FREE_COVERAGE)
    result["films_global"], result["films_coverage"] = films_g, films_c
    if progress:
        print(file=sys.stderr)
    if out:
        write_json(out, result)
    return result


def _tick(progress, what, i, n, t0, out, result):
    if progress:
        print(f"\r{what} {i + 1}/{n}  {time.perf_counter() - t0:.0f} s", end="",
              file=sys.stderr, flush=True)
    if out and (i + 1) % 10 == 0:
        write_json(out, result)  # partial results survive an interrupted run


def plot(result, path):
    from thinfilm_jax.core.files import atomic_write
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    methods = [m for m in result["coverage"]]
    if not methods:
        return
    fig, axes = plt.subplots(1, len(FREE_COVERAGE) + 1, figsize=(4 * (len(FREE_COVERAGE) + 1)
                                                                   + 1.5, 3.4),
                             layout="constrained")
    zgrid = np.linspace(-4, 4, 200)
    names = {"thickness": "d", "eta_film": "η₂", "alpha": "α"}
    for j, k in enumerate(FREE_COVERAGE):
        ax = axes[j]
        for m in methods:
            rows = [r for r in result["per_fit"][m]["coverage"] if r["right_basin"]]
            z = np.array([(r["fit"][k] - r["truth"][k]) / r["stderr"][k] for r in rows])
            ax.hist(np.clip(z, -4, 4), bins=24, range=(-4, 4), density=True, alpha=0.5,
                    label=f"{m} (n = {z.size})")
        ax.plot(zgrid, np.exp(-zgrid**2 / 2) / np.sqrt(2 * np.pi), "k-", lw=1, label="N(0, 1)")
        ax.set(xlabel=f"z = ({names[k]} fit − truth) / SE", ylabel="density",
               title=f"{names[k]}: standardised error")
        ax.legend(fontsize=7)
    ax = axes[-1]
    m = methods[0]
    summ = result["coverage"][m]
    cov, tcov = summ["coverage"], summ.get("t_interval_coverage", {})
    bars = [("±1 SE", lambda k: cov[k]["1se"], "C0", ""),
            ("t interval 68.3 %", lambda k: list(tcov[k].values())[0], "C0", "//"),
            ("±2 SE", lambda k: cov[k]["2se"], "C1", ""),
            ("t interval 95.4 %", lambda k: list(tcov[k].values())[1], "C1", "//")]
    if not tcov:
        bars = bars[::2]
    width = 0.8 / len(bars)
    x0 = np.arange(len(FREE_COVERAGE))
    for i, (label, val, colour, hatch) in enumerate(bars):
        ax.bar(x0 + i * width, [val(k) for k in FREE_COVERAGE], width * 0.9, color=colour,
               alpha=0.6, hatch=hatch, label=label)
    nom = summ["nominal"]
    ax.axhline(nom["1se"], color="k", ls=":", lw=1, label="nominal 68.3 % / 95.4 %")
    ax.axhline(nom["2se"], color="k", ls=":", lw=1)
    if "nominal_student_t" in summ:
        nt = summ["nominal_student_t"]
        ax.axhline(nt["2se"], color="C3", ls="--", lw=1, label=f"±2 SE under t: {nt['2se']:.3f}")
    ax.set_xticks(x0 + 0.4 - width / 2, [names[k] for k in FREE_COVERAGE])
    ax.set(ylim=(0.5, 1.02), ylabel="fraction of fits covering the truth",
           title=f"coverage ({m}, all {summ['n']} fits)")
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    n = result["coverage"][methods[0]]["n"]
    fig.suptitle(f"fit_film, d, η₂, α free, 1 % Gaussian noise, {n} films "
                 f"(d 150–1200 nm, η₂ 1.2–1.7, α 0.1–0.4; 4–9 views), one initial guess",
                 fontsize=9)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


def print_table(result):
    for m, s in result["global"].items():
        print(f"global minimum ({m}, noise-free, d and η₂ free, n = {s['n']}): "
              f"{s['global_minimum_fraction']:.3f}; ambiguous flagged {s['ambiguous_fraction']:.3f}")
    for m, s in result["coverage"].items():
        print(f"coverage ({m}, 1 % noise, d, η₂, α free, n = {s['n']}): right basin "
              f"{s['right_basin_fraction']:.3f}, ambiguous {s['ambiguous_fraction']:.3f}")
        for k in FREE_COVERAGE:
            c, cb = s["coverage"][k], s["coverage_right_basin"][k]
            ti = s.get("t_interval_coverage", {}).get(k, {})
            print(f"  {k:10s} within 1 SE {c['1se']:.3f} (right basin {cb['1se']:.3f})  "
                  f"within 2 SE {c['2se']:.3f} (right basin {cb['2se']:.3f})  "
                  f"median |z| {s['median_abs_z'][k]:.3f}  t-intervals 68.3/95.4 %: "
                  + " / ".join(f"{v:.3f}" for v in ti.values()))
        if "nominal_student_t" in s:
            nt = s["nominal_student_t"]
            print(f"  expected for ±1/±2 SE under Student t (n − p dof): {nt['1se']:.3f} / "
                  f"{nt['2se']:.3f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-global", type=int, default=100, help="noise-free films (100)")
    ap.add_argument("--n-coverage", type=int, default=200, help="noisy films (200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--methods", default="reference", help="comma list of fit methods")
    ap.add_argument("--out", default="figures/coverage.json", help="JSON output ('' for none)")
    ap.add_argument("--figure", default="figures/coverage.png", help="figure ('' for none)")
    ap.add_argument("--from-json", help="re-print and re-plot a finished run's JSON")
    args = ap.parse_args(argv)
    if args.from_json:
        import json

        with open(args.from_json) as f:
            result = json.load(f)
        for m, rows in result["per_fit"].items():  # summaries as this version computes them
            if rows["coverage"]:
                result["coverage"][m] = summarise_coverage(rows["coverage"], FREE_COVERAGE)
            if rows["global"]:
                result["global"][m] = summarise_global(rows["global"])
        print_table(result)
        if args.figure:
            plot(result, args.figure)
        return
    jax.config.update("jax_enable_x64", True)
    methods = tuple(m for m in args.methods.split(",") if m)
    result = run(args.n_global, args.n_coverage, args.seed, methods, args.out or None)
    print_table(result)
    if args.figure:
        plot(result, args.figure)
        print(f"wrote {args.figure}")
    if args.out:
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
