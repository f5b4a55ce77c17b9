"""The error-vs-run-time figure names every point on the plot itself: each row's path is a
text beside its marker (clusters stepped apart), not a number keyed to a side list."""

import numpy as np

from benchmarks.pareto import point_label, render_error_vs_runtime


def _row(fam, group, path, dtype, t, e):
    return {"family": fam, "group": group, "path": path, "dtype": dtype,
            "warm_s_per_eval": t, "dE_p95": e, "comparable": True}


def test_every_point_is_labelled_with_its_path(tmp_path):
    rows = [_row("a: shading point", "spectral", "spectral (reference)", "float64", 5e-7, 0.0),
            _row("a: shading point", "Fourier", "Fourier M=2", "float64", 2e-6, 0.9),
            _row("b: patch", "patch method", "filtered_gt_moments", "float64", 3e-4, 17.9),
            _row("b: patch", "patch method", "filtered_gt_opd", "float64", 3e-4, 17.5),
            _row("b: patch", "patch method", "improved", "float64", 3.2e-4, 0.5),
            _row("b: patch", "float32", "ideal", "float32", 1.8e-4, 29.9)]
    fig = render_error_vs_runtime(rows, tmp_path / "evr.png", title="t")
    assert (tmp_path / "evr.png").read_bytes()[:4] == b"\x89PNG"
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert sorted(texts) == sorted(point_label(r) for r in rows)
    assert "ideal (f32)" in texts and not any(t.strip().isdigit() for t in texts)
    # two points at one place: their labels do not sit on each other
    ax = fig.axes[1]
    ys = {t.get_text(): t.get_position()[1] for t in ax.texts}
    pos = [np.asarray(t.xyann) for t in ax.texts
           if t.get_text() in ("filtered_gt_moments", "filtered_gt_opd")]
    assert len(ys) == 4 and abs(pos[0][1] - pos[1][1]) > 5
