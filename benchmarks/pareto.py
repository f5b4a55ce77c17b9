"""The error-vs-run-time table, its Pareto front and figures (`error_vs_runtime.md/.png`, and
`improved_pareto.png`: the real-time kernel options against `method="improved"`)."""

from __future__ import annotations

import math
import textwrap

import numpy as np

from thinfilm_jax.core.files import atomic_write
from ._timing import fmt

ERROR_FLOOR = 1e-6  # ΔE below this (the references: 0) is drawn on the floor of the log plot


def markdown_table(rows) -> str:
    """The error-vs-time table as markdown (times in µs per evaluation)."""
    head = ("| family | path | dtype | ΔE₀₀ mean | ΔE₀₀ p95 | ΔE₀₀ max | max abs band err "
            "| warm µs / eval | evals / s | compile s | error vs | worst case |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:
        us = r.get("warm_s_per_eval")
        lines.append(
            f"| {r['family']} | {r['path']} | {r['dtype']} | {fmt(r['dE_mean'])} "
            f"| {fmt(r['dE_p95'])} | {fmt(r['dE_max'])} | {fmt(r['band_abs_max'])} "
            f"| {fmt(None if us is None else us * 1e6)} | {fmt(r.get('evals_per_s'), '.3g')} "
            f"| {fmt(r.get('compile_s'), '.2f')} | {r['error_vs']} "
            f"| {r.get('worst_case', '')} |")
    return "\n".join(lines)


def pareto_front(times, errors):
    """Indices of the non-dominated points (smaller time and smaller error), by time.

    Example (point 1 is slower and worse than point 0: dominated):
        >>> pareto_front([1.0, 2.0, 3.0], [1.0, 2.0, 0.5])
        [0, 2]
    """
    order = np.argsort(times, kind="stable")
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(int(i))
            best = errors[i]
    return front


def render_error_vs_runtime(rows, path, *, metric: str = "dE_p95", title: str = "",
                            absent: dict | None = None):
    """Error (ΔE₀₀, log) against warm time per evaluation (s, log), one panel per family,
    Pareto front as a step line. Every point is labelled on the plot with its path (the
    table's "path" column: method and knobs, f32 where float32), not a number keyed to a
    list; errors below `ERROR_FLOOR` (the references, exact specialisations) are drawn on the
    floor as open markers. `absent` ({method: why}) is written under panel (b): the methods
    that have no point there and why. Returns the figure (written to `path`)."""
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    panels = [("a", "(a) per shading point: band reflectance R_j(cos θ)",
               "warm run time per shading point (s)"),
              ("b", "(b) per patch under uniform light: L_j(θ_o, α)",
               "warm run time per patch; per shading point for the kernels (▲) (s)")]
    fig, axes = plt.subplots(1, 2, figsize=(20, 9), constrained_layout=True)
    cmap = plt.get_cmap("tab10")
    for ax, (fam, ptitle, xlabel) in zip(axes, panels):
        sel = [(i, r) for i, r in enumerate(rows) if r["family"].startswith(fam)
               and "warm_s_per_eval" in r and np.isfinite(r[metric])]
        groups = sorted({r["group"] for _, r in sel})
        labels = []  # (x, y, text, colour): placed once the axes' scales are set
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
            labels += [(x, y, point_label(r), cmap(gi % 10))
                       for (_, r), x, y in zip(pts, t, np.maximum(e, ERROR_FLOOR))]
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
        _place_labels(ax, labels)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"CIEDE2000 ΔE vs float64 reference, {metric.split('_')[1]} over the "
                      f"grid (open: < {ERROR_FLOOR:g})")
        if fam == "b" and absent:  # the registry's methods without a point here, and why
            ptitle += "\n" + textwrap.fill("No point here: " + "; ".join(
                f"{m}: {why}" for m, why in absent.items()), 150)
        ax.set_title(ptitle, fontsize=11 if "\n" not in ptitle else 9)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7, loc="lower left")
    fig.suptitle(title, fontsize=10)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return fig


def _place_labels(ax, labels, fontsize: float = 6.2) -> None:
    """Write each point's text beside it, stepping a label up or down (with a thin leader
    line) until its box overlaps no label already written and no other point's marker and
    stays inside the axes: clusters of points (the filtered variants, the kernels) stay
    readable."""
    ax.autoscale_view()
    fig = ax.figure
    pt = fig.dpi / 72.0  # display pixels per typographic point
    h = 1.25 * fontsize * pt
    m = 4.0 * pt  # half a marker's width: no label is written over another point's marker
    inside = ax.get_window_extent()  # labels stay within the axes (off the title)
    boxes: list = []
    for x, y, _, _ in labels:
        px, py = ax.transData.transform((x, y))
        boxes.append((px - m, py - h / 2, 2 * m))
    for x, y, text, colour in sorted(labels, key=lambda v: (v[1], v[0]), reverse=True):
        px, py = ax.transData.transform((x, y))
        w = 0.56 * fontsize * pt * len(text)
        x0, best = px + m + pt, None  # best: (overlaps, k) of the least crowded place
        for k in (0, -1, 1, -2, 2, -3, 3, -4, 4, -5, 5, -6, 6, -7, 7, -8, 8, -10, 10, -12, 12,
                  -14, 14, -16, 16):
            y0 = py + k * h - 0.3 * h
            if not (inside.y0 <= y0 and y0 + h <= inside.y1):
                continue
            hits = sum(x0 < bx + bw and bx < x0 + w and y0 < by + h and by < y0 + h
                       for bx, by, bw in boxes)
            if best is None or hits < best[0]:
                best = (hits, k)
            if hits == 0:
                break
        k = 0 if best is None else best[1]
        y0 = py + k * h - 0.3 * h
        boxes.append((x0, y0, w))
        ax.annotate(text, (x, y), xytext=((x0 - px) / pt, k * h / pt), textcoords="offset points",
                    fontsize=fontsize, color=colour, va="center",
                    arrowprops=None if k == 0 else dict(arrowstyle="-", lw=0.4,
                                                         color=colour, alpha=0.6))


def point_label(row) -> str:
    """A point's text on the error-vs-time plot: the row's path, its dtype added where the
    path does not say it.

    Example:
        >>> point_label({"path": "Fourier M=2", "dtype": "float64"})
        'Fourier M=2'
        >>> point_label({"path": "ideal", "dtype": "float32"})
        'ideal (f32)'
    """
    path = str(row["path"])
    if row.get("dtype") == "float32" and "f32" not in path:
        path += " (f32)"
    return path


def pareto_rows(rows, fam):
    """Row indices of family `fam` on the Pareto front of ΔE p95 against warm time."""
    idx = [i for i, r in enumerate(rows) if r["family"].startswith(fam)
           and "warm_s_per_eval" in r and np.isfinite(r["dE_p95"]) and r["comparable"]]
    t = np.array([rows[i]["warm_s_per_eval"] for i in idx])
    e = np.array([max(rows[i]["dE_p95"], ERROR_FLOOR) for i in idx])
    return [idx[j] for j in pareto_front(t, e)] if idx else []


def render_kernel_pareto(rows, path, title: str = "") -> None:
    """ΔE (mean and p95 panels, log) against cost per shading point (µs, log) of real-time
    kernel options (rows with "path", "group" ∈ {ideal, filtered, improved}, "us_per_point",
    "mean", "p95"; `benchmarks.improved_study`), with the Pareto front."""
    from thinfilm_jax.render import plot as plt  # the caller's backend untouched

    fig, axes = plt.subplots(1, 2, figsize=(15, 6.2), constrained_layout=True)
    colours = {"ideal": "tab:grey", "filtered": "tab:blue", "improved": "tab:red"}
    for ax, metric in zip(axes, ("mean", "p95")):
        labels = []  # placed once the scales are set, stepped apart where they would overlap
        for g, c in colours.items():
            sel = [r for r in rows if r["group"] == g]
            ax.scatter([r["us_per_point"] for r in sel], [r[metric] for r in sel], color=c,
                       label=g, s=40, zorder=3)
            labels += [(r["us_per_point"], r[metric], r["path"].replace("filtered K29", "K29"),
                        "k") for r in sel]
        t = np.array([r["us_per_point"] for r in rows])
        e = np.array([r[metric] for r in rows])
        f = pareto_front(t, e)
        ax.step(t[f], e[f], where="post", color="k", lw=1, alpha=0.6, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _place_labels(ax, labels, fontsize=7)
        ax.set_xlabel("warm cost per shading point, float32, CPU (µs, median, interleaved)")
        ax.set_ylabel(f"CIEDE2000 ΔE vs reference, {metric} over the wide grid")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
