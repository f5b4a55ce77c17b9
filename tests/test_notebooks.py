"""Notebooks are executed so they never go stale (small resolution, errors fail the test)."""

import os
from pathlib import Path

import pytest

NB_DIR = Path(__file__).resolve().parent.parent / "notebooks"


def run_notebook(name: str, tmp_path, env: dict[str, str]) -> None:
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(NB_DIR / name, as_version=4)
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                resources={"metadata": {"path": str(tmp_path)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@pytest.mark.slow
def test_figure7_notebook(tmp_path):
    run_notebook("figure7.ipynb", tmp_path, {"THINFILM_NB_RESOLUTION": "8",
                                             "THINFILM_NB_OUT": str(tmp_path)})
    assert (tmp_path / "figure7.png").exists() and (tmp_path / "figure7_error.png").exists()


@pytest.mark.slow
def test_error_vs_runtime_notebook(tmp_path):
    run_notebook("error_vs_runtime.ipynb", tmp_path, {"THINFILM_NB_RUN": "tiny",
                                                      "THINFILM_NB_OUT": str(tmp_path)})


@pytest.mark.slow
def test_ibl_notebook(tmp_path):
    run_notebook("ibl.ipynb", tmp_path, {"THINFILM_NB_RESOLUTION": "12",
                                         "THINFILM_NB_SMALL_MAP": "1"})
