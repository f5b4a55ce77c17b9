r"""The figures of the real-materials study (`materials_study`): the colour charts, the
constant-silicon costs and the real-time methods on dispersive films, drawn from its result
dict (`materials_study.run`) and written atomically with PNG metadata that depends on the
pixels only.

Example (the PNG metadata: no software version, so a rerun on another machine writes the
same bytes):
    >>> from benchmarks.materials_figures import PNG_METADATA
    >>> PNG_METADATA
    {'Software': None}
"""

from __future__ import annotations

import numpy as np

from thinfilm_jax.core.methods import METHODS as METHOD_INFO

PNG_METADATA = {"Software": None}  # PNGs depend on their pixels only


def fit_key(r: dict) -> tuple:
    """The model of a fit row of the silicon study: (film, base, data set, free parameters)."""
    return r["model_film"], r["model_base"], r["data"], r["free"]


def fit_groups(fits: list) -> list:
    """The distinct `fit_key`s of the fit rows, in order of first appearance."""
    return list(dict.fromkeys(fit_key(r) for r in fits))


def _pyplot():
    """pyplot's calls on figures of our own (`_plot`: Agg canvas, no display needed, the
    caller's backend untouched)."""
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    return plt


def _save(fig, path):
    """Lay out `fig`, write it atomically as a PNG at `path` and close it."""
    from pathlib import Path

    from thinfilm_jax.core.files import atomic_write

    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png",
                                               metadata=PNG_METADATA))
    _pyplot().close(fig)


def plot_charts(res: dict, path: str, films):
    """Rows: film × angle (`films`: the study's (label, film, base) triples); columns:
    illuminants; each a thickness strip."""
    plt = _pyplot()

    ch = res["charts"]
    d = np.asarray(ch["thickness_nm"])
    ills = res["config"]["illuminants"]
    angles = ch["angles_deg"]
    nrow = len(films) * len(angles)
    fig, axes = plt.subplots(nrow, len(ills), figsize=(6.2 * len(ills), 0.62 * nrow + 1.3),
                             squeeze=False)
    for j, ill in enumerate(ills):
        for i, (label, _, _) in enumerate(films):
            rgb = np.asarray(ch["charts"][f"{label} | {ill}"]["srgb"])
            for k, a in enumerate(angles):
                ax = axes[i * len(angles) + k, j]
                ax.imshow(rgb[None, :, k], aspect="auto", interpolation="nearest",
                          extent=(d[0], d[-1], 0, 1))
                ax.set_yticks([])
                ax.set_xticks(np.arange(0, d[-1] + 1, 100))
                if i * len(angles) + k < nrow - 1:
                    ax.set_xticklabels([])
                if j == 0:
                    ax.set_ylabel(f"{label.replace('2', '₂').replace('3N4', '₃N₄')}\n"
                                  f"θ = {a:g}°", rotation=0, ha="right", va="center",
                                  fontsize=8)
            axes[0, j].set_title(f"{ill}" + ("" if ill == "D65" else " (CAT02 → D65)"))
        axes[-1, j].set_xlabel("film thickness d (nm)")
    fig.suptitle("Exact R(λ) 360–830 nm (stack_reflectance, Malitson SiO₂, Philipp Si₃N₄, "
                 "Schinke Si, unpolarised)\n→ CIE 1931 2° XYZ under the illuminant → sRGB "
                 "(perfect diffuser = white, no exposure)", fontsize=9)
    _save(fig, path)


def plot_silicon(res: dict, path: str):
    """ΔE₀₀ against thickness per Si constant; fitted-thickness bias against thickness."""
    plt = _pyplot()

    si = res["silicon"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    d = np.asarray(si["thickness_nm"])
    for r in si["rows"]:
        axes[0].plot(d, r["dE_curve"], label=f"{r['constant']}, θ = {r['theta_deg']:g}°",
                     ls="-" if r["theta_deg"] == 0 else "--")
    axes[0].set(xlabel="SiO₂ thickness (nm)", ylabel="ΔE₀₀ vs dispersive Si",
                title="SiO₂ on constant Si against Schinke Si (bands, equal-energy light)")
    axes[0].legend(fontsize=7)
    for key in fit_groups(si["fits"]):
        if key[1].startswith("Si at"):
            continue  # within 1.5 nm of the 3.9 + 0.02i rows (the table has both)
        g = [r for r in si["fits"] if fit_key(r) == key]
        axes[1].plot([r["thickness_nm"] for r in g], [r["bias_nm"] for r in g], "o", ms=3,
                     ls="-" if key[3] == "thickness" else ":",
                     label=f"model {key[0]} on {key[1]}; data: {key[2]}; free: {key[3]}")
    axes[1].axhline(0.0, color="k", lw=0.5)
    axes[1].set(xlabel="true SiO₂ thickness (nm)", ylabel="fitted − true (nm)",
                title="fit_spectrum with constant indices, dispersive data")
    axes[1].legend(fontsize=6)
    _save(fig, path)


def plot_realtime(res: dict, path: str):
    """Mean ΔE₀₀ per material and method: dispersive (band centroids) vs constant film."""
    plt = _pyplot()

    rt = res["realtime"]
    alphas = rt["alphas"]
    mats = list(dict.fromkeys(r["material"] for r in rt["rows"]))
    methods = list(dict.fromkeys(r["method"] for r in rt["rows"]))
    fig, axes = plt.subplots(len(alphas), 1, figsize=(11, 3.4 * len(alphas)), squeeze=False)
    w = 0.8 / (2 * len(methods) + 1)
    for ia, alpha in enumerate(alphas):
        ax = axes[ia, 0]
        for im, m in enumerate(methods):
            for iv, (var, hatch) in enumerate((("dispersive", ""), ("constant", "//"))):
                vals = [next(r[var]["dE_mean"] for r in rt["rows"] if r["material"] == mat
                             and r["method"] == m and r["alpha"] == alpha) for mat in mats]
                ax.bar(np.arange(len(mats)) + (2 * im + iv + 0.5) * w - 0.4, vals, w,
                       hatch=hatch,
                       color=f"C{im}", edgecolor="k", lw=0.4,
                       label=f"{m} [{METHOD_INFO[m].dispersion}], {var}" if ia == 0 else None)
        cen = [next(r["centroid_only"]["dE_mean"] for r in rt["per_material"]
                    if r["material"] == mat and r["alpha"] == alpha) for mat in mats]
        ax.scatter(np.arange(len(mats)) + (2 * len(methods) + 0.5) * w - 0.4, cen, marker="D",
                   color="k", s=14, label="exact integrator at the centroids" if ia == 0 else None)
        held = {r["material"]: r["held_out"] for r in rt["rows"]}
        ax.set_xticks(np.arange(len(mats)))
        ax.set_xticklabels([m + (" (held out)" if held[m] else "") for m in mats], fontsize=7)
        ax.set_ylabel("mean ΔE₀₀ vs reference")
        ax.set_title(f"α = {alpha:g}: dispersive film ([bands]: indices at the band centroids; "
                     f"[exact]: at every λ) vs the constant film (n at "
                     f"{rt['constant_at_nm']:.0f} nm), each against its own reference",
                     fontsize=9)
    axes[0, 0].legend(fontsize=7, ncol=4)
    _save(fig, path)
