"""The library draws its figures without touching the caller's matplotlib: writing Figure 7
(`render_figure7`, `render_error`), a render composite (`scene.plot_panels`) or a thickness
map PNG keeps the backend the caller chose and the caller's own open pyplot figures (a
notebook's inline plots no longer vanish), and no module of the package (nor a study of
benchmarks/, which draws through the same `render.plot`) calls ``matplotlib.use``."""

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2] / "thinfilm_jax"


@pytest.fixture
def svg_backend():
    """The caller's session: the svg backend (not Agg) and one open figure of its own."""
    before = matplotlib.get_backend()
    plt.close("all")
    matplotlib.use("svg")
    fig = plt.figure()
    yield fig
    plt.close("all")
    matplotlib.use(before)


def test_writing_figures_keeps_the_callers_backend_and_figures(svg_backend, tmp_path):
    from thinfilm_jax.cli._output import save_thickness_png
    from thinfilm_jax.render.figure7 import (METHOD_ORDER, ROWS, Figure7Config,
                                              render_error, render_figure7)
    from thinfilm_jax.render.scene import plot_panels

    cfg = Figure7Config(resolution=4)
    rng = np.random.default_rng(0)
    data = {"values": {row: {m: rng.uniform(0.05, 0.3, (4, 4, 3)) for m in METHOD_ORDER}
                       for row in ROWS}}
    render_figure7(data, cfg, tmp_path / "f7.png")
    render_error(data, cfg, tmp_path / "f7_error.png")
    plot_panels(tmp_path / "panels.png", [("a", np.full((4, 4, 3), 0.5)),
                                          ("ΔE", np.ones((4, 4)))], "t", 16)
    save_thickness_png(tmp_path / "d.png", np.linspace(0, 1, 12).reshape(3, 4), "d")
    assert matplotlib.get_backend() == "svg"
    assert plt.get_fignums() == [svg_backend.number]  # ours are not in pyplot's registry
    for name in ("f7.png", "f7_error.png", "panels.png", "d.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"


def test_no_module_selects_a_backend():
    files = sorted(ROOT.rglob("*.py")) + sorted((ROOT.parent / "benchmarks").rglob("*.py"))
    assert len(files) > 60  # both folders scanned
    calls = [f"{p.relative_to(ROOT.parent)}:{i}" for p in files
             for i, line in enumerate(p.read_text().splitlines(), 1)
             if "matplotlib.use(" in line and not line.lstrip().startswith(("#", ">>>"))]
    assert calls == []
