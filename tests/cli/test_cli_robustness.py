"""The command line at its boundary: bad input is a one-line error found
before any work, never a traceback; outputs are never the input, never partial."""

import json
import os

import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.cli import fit as fit_cli
from thinfilm_jax.cli.main import main

PATCH_CSV = ("# alpha = 0.25\n"
             '# initial = {"thickness": 350, "eta_film": 1.3, "eta_base": 2.0, "kappa_base": 0.5}\n'
             "# free = thickness\n"
             "theta_o_deg,R,G,B\n0,0.04,0.09,0.05\n30,0.05,0.08,0.06\n60,0.07,0.07,0.08\n")


@pytest.fixture
def no_fit(monkeypatch):
    """Make any attempt to fit fail loudly: the checks must come first."""
    def boom(*a, **k):
        raise AssertionError("the fit ran although the arguments were bad")

    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_film", boom)
    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_spectrum", boom)


@pytest.fixture
def no_figure(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("figure7 computed although the arguments were bad")

    monkeypatch.setattr("thinfilm_jax.cli.main._figure7", boom)  # build_parser binds it per call


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"thinfilm-jax {tf.__version__}"


@pytest.mark.parametrize("argv, words", [
    (["--resolution", "-3"], "--resolution: must be an integer in [1, inf), got -3"),
    (["--resolution", "0"], "--resolution"),
    (["--alpha", "0"], "--alpha: must be a number in (0.0, 1.0], got 0.0"),
    (["--alpha", "1.5"], "--alpha"),
    (["--alpha", "nan"], "--alpha: must be finite"),
    (["--eta-film", "0.5"], "--eta-film"),
    (["--eta-base", "0"], "--eta-base"),
    (["--kappa-base", "-1"], "--kappa-base"),
    (["--thickness", "-5"], "--thickness"),
    (["--thickness-max", "0"], "--thickness-max"),
    (["--terms", "-1"], "--terms"),
    (["--quadrature", "1", "8"], "--quadrature"),
    (["--exposure", "inf"], "--exposure"),
    (["--resolution", "abc"], "invalid int value"),
])
def test_figure7_bad_arguments_fail_before_computing(argv, words, no_figure, capsys):
    with pytest.raises(SystemExit) as e:
        main(["figure7", *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert "thinfilm-jax figure7: error:" in err


@pytest.mark.parametrize("argv, words", [
    (["--resolution", "0"], "--resolution: must be an integer in [1, inf)"),
    (["--exposure", "-1"], "--exposure"),
])
def test_render_bad_arguments_fail_before_computing(argv, words, monkeypatch, capsys):
    def boom(*a, **k):
        raise AssertionError("render computed although the arguments were bad")

    monkeypatch.setattr("thinfilm_jax.cli.main._render", boom)
    with pytest.raises(SystemExit) as e:
        main(["render", *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert words in err and "thinfilm-jax render: error:" in err


def test_figure7_out_must_be_a_folder(tmp_path, no_figure, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    for out in (f, f / "sub"):
        with pytest.raises(SystemExit) as e:
            main(["figure7", "--out", str(out)])
        assert e.value.code == 2
    assert "is not a folder" in capsys.readouterr().err
    assert f.read_text() == "x"


def test_errors_while_running_are_one_line(monkeypatch, capsys, tmp_path):
    def disk_full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("thinfilm_jax.cli.main._figure7", disk_full)
    assert main(["figure7", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.strip() == "thinfilm-jax figure7: error: [Errno 28] No space left on device"
    monkeypatch.setenv("THINFILM_JAX_TRACEBACK", "1")
    with pytest.raises(OSError):
        main(["figure7", "--out", str(tmp_path)])


def test_fit_refuses_to_overwrite_its_input(tmp_path, no_fit):
    src = tmp_path / "obs.csv"
    src.write_text(PATCH_CSV)
    for out in (src, tmp_path / "." / "obs.csv"):
        with pytest.raises(SystemExit, match="is the input file"):
            main(["fit", str(src), "--out", str(out), "--overwrite"])
    assert src.read_text() == PATCH_CSV
    link = tmp_path / "link.csv"
    os.symlink(src, link)
    with pytest.raises(SystemExit, match="is the input file"):
        main(["fit", str(src), "--out", str(link), "--overwrite"])


def test_fit_out_directory_is_refused_before_fitting(tmp_path, no_fit):
    src = tmp_path / "obs.csv"
    src.write_text(PATCH_CSV)
    (tmp_path / "results").mkdir()
    with pytest.raises(SystemExit, match="is a directory"):
        main(["fit", str(src), "--out", str(tmp_path / "results")])
    with pytest.raises(SystemExit, match="is a directory"):
        main(["fit", str(src), "--out", str(tmp_path / "results"), "--overwrite"])
    with pytest.raises(SystemExit, match="is not a directory"):
        main(["fit", str(src), "--out", str(src / "res.json")])
    with pytest.raises(SystemExit, match="not a file"):
        main(["fit", str(tmp_path / "results")])


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "utf-16-le-bom", "utf-16-be-bom"])
def test_fit_reads_bom_prefixed_and_utf16_csv(tmp_path, encoding):
    ref = tmp_path / "ref.csv"
    ref.write_text(PATCH_CSV, encoding="utf-8")
    src = tmp_path / "obs.csv"
    if encoding.endswith("-bom"):
        codec = encoding[:-4]
        bom = "\ufeff".encode(codec)
        src.write_bytes(bom + PATCH_CSV.replace("\n", "\r\n").encode(codec))
    else:
        src.write_bytes(PATCH_CSV.encode(encoding))
    assert fit_cli.read_observations(src) == fit_cli.read_observations(ref)
    # and JSON with a UTF-8 BOM
    js = tmp_path / "obs.json"
    js.write_bytes(json.dumps({"theta_o_deg": [0.0], "observed": [[0.1, 0.1, 0.1]]})
                   .encode("utf-8-sig"))
    assert fit_cli.read_observations(js)["observed"] == [[0.1, 0.1, 0.1]]


def test_fit_non_utf8_and_bomless_utf16_are_clear_errors(tmp_path, no_fit):
    src = tmp_path / "latin1.csv"
    src.write_bytes(("# measured by Jérôme\n" + PATCH_CSV).encode("latin-1"))
    with pytest.raises(SystemExit, match=r"not UTF-8 text: byte 0xe9 on line 1.*save the file"):
        main(["fit", str(src)])
    src = tmp_path / "u16.csv"
    src.write_bytes(PATCH_CSV.encode("utf-16-le"))
    with pytest.raises(SystemExit, match="UTF-16 without a byte-order mark"):
        main(["fit", str(src)])
    assert not list(tmp_path.glob("*.fit.json"))


def test_fit_settings_below_the_header_are_an_error(tmp_path, no_fit):
    src = tmp_path / "obs.csv"
    src.write_text(PATCH_CSV + "# free = thickness, eta_film\n90,0.1,0.1,0.1\n")
    with pytest.raises(SystemExit, match=r"line 8: setting '# free = thickness, eta_film' below "
                                         r"the header"):
        main(["fit", str(src)])
    # a plain comment below the header is still fine
    src.write_text(PATCH_CSV + "# end of run 3\n")
    assert fit_cli.read_observations(src)["theta_o_deg"] == [0.0, 30.0, 60.0]


def test_fit_interrupted_leaves_nothing(tmp_path, monkeypatch, capsys):
    src = tmp_path / "obs.csv"
    src.write_text(PATCH_CSV)

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_film", ctrl_c)
    assert main(["fit", str(src)]) == 130
    assert "interrupted; no partial output" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obs.csv"]


def test_fit_interrupted_while_writing_leaves_nothing(tmp_path, monkeypatch):
    """Ctrl-C during the write of the result: the atomic write removes its temporary file
    and the previous result (if any) stays intact."""
    src = tmp_path / "obs.csv"
    src.write_text(PATCH_CSV)
    out = tmp_path / "obs.fit.json"
    out.write_text('{"old": true}')

    class Result:
        def to_dict(self):
            return {"params": {"thickness": 600.0}, "stderr": {"thickness": 1.0}, "loss": 0.0,
                    "converged": True, "degenerate": []}

    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_film", lambda *a, **k: Result())

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(json, "dump", ctrl_c)
    assert main(["fit", str(src), "--overwrite"]) == 130
    assert out.read_text() == '{"old": true}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obs.csv", "obs.fit.json"]


def test_fit_names_every_out_of_range_material_by_its_option(tmp_path):
    """A spectrum from 150 nm with ``--eta-film water --eta-base Si`` (data from 182 and
    250 nm): one message names both, as the options typed (``--eta-film``, ``--eta-base``;
    ``--layers layer i`` for a stack), not the library's ``initial.eta[0]``; the same
    materials given in the file's ``initial`` setting keep the file's names."""
    lam = np.linspace(150.0, 1100.0, 40)
    rows = "\n".join(f"{w},0.1" for w in lam)
    path = tmp_path / "spec.csv"
    path.write_text(f"# theta_deg = 0\nwavelength_nm,R\n{rows}\n")
    with pytest.raises(SystemExit) as e:
        main(["fit", str(path), "--eta-film", "water", "--eta-base", "Si"])
    msg = str(e.value.code)
    assert "--eta-film (water)" in msg and "--eta-base (Si)" in msg
    assert "initial." not in msg and "eta[0]" not in msg
    with pytest.raises(SystemExit) as e:
        main(["fit", str(path), "--layers", "water:100,SiO2:50", "--eta-base", "Si"])
    msg = str(e.value.code)
    assert all(s in msg for s in ("--layers layer 0 (water)", "--layers layer 1 (SiO2)",
                                  "--eta-base (Si)"))
    path.write_text('# theta_deg = 0\n# initial = {"eta_film": "water", "eta_base": "Si"}\n'
                    f"wavelength_nm,R\n{rows}\n")
    with pytest.raises(SystemExit) as e:
        main(["fit", str(path)])
    msg = str(e.value.code)
    assert "initial.eta_film (water)" in msg and "initial.eta_base (Si)" in msg


def test_bench_runs_the_clones_studies_or_says_where_they_are(tmp_path, monkeypatch, capsys):
    """``thinfilm-jax bench ARGS`` is ``python -m benchmarks.bench ARGS`` of the clone (its
    options, ``--help`` included); without a clone (an installed wheel, run elsewhere) it
    exits 2 with one line naming the folder and the command, no traceback."""
    import thinfilm_jax.cli.main as cli

    with pytest.raises(SystemExit) as e:
        cli.main(["bench", "--help"])
    assert e.value.code == 0 and "python -m benchmarks.bench" in capsys.readouterr().out
    monkeypatch.setattr(cli, "__file__", str(tmp_path / "site" / "thinfilm_jax" / "cli" /
                                             "main.py"))
    monkeypatch.chdir(tmp_path)
    assert cli.main(["bench", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "benchmarks/" in err and "pip install -e" in err and "Traceback" not in err
