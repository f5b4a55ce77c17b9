"""``thinfilm-jax fit-map PHOTO --camera ...`` (SPEC §13): a 16-bit photograph of an oxide
wedge with a bare-substrate reference gives back its map and every output; bad input is a
clear error that leaves no output behind; the misfit warning reaches the console."""

import json
import re

import numpy as np
import OpenImageIO as oiio
import pytest

import thinfilm_jax as tf
from thinfilm_jax.cli.main import main
from thinfilm_jax.fit.photo import render_photo

pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")

OXIDE = tf.Film(0.0, tf.refractive_index("SiO2"), tf.refractive_index("Si"))
H, W = 24, 32


def _write(path, a, fmt):
    a = a if a.ndim == 3 else a[..., None]
    spec = oiio.ImageSpec(a.shape[1], a.shape[0], a.shape[2], fmt)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(a))
    out.close()


@pytest.fixture(scope="module")
def wafer(tmp_path_factory):
    """A 16-bit linear TIFF of an oxide wedge (Nikon 5100 under D65, exposure 0.6, white
    balance (1.8, 1, 1.5)), its bare strip (rows 0–2) as a mask PNG, and the truth."""
    tmp = tmp_path_factory.mktemp("wafer")
    y = np.arange(H)[:, None] / (H - 1)
    d = np.broadcast_to(np.where(y < 3 / H, 0.0, 40.0 + 800.0 * y), (H, W)).copy()
    lin = render_photo(OXIDE, d, camera="Nikon 5100 (NPL)", exposure=0.6,
                       white_balance=(1.8, 1.0, 1.5))
    _write(tmp / "wafer.tif", np.round(np.clip(lin, 0, 1) * 65535).astype(np.uint16),
           oiio.UINT16)
    bare = np.zeros((H, W), np.uint8)
    bare[:3] = 255
    _write(tmp / "bare.png", bare, oiio.UINT8)
    _write(tmp / "small.png", bare[:10], oiio.UINT8)
    _write(tmp / "empty.png", np.zeros((H, W), np.uint8), oiio.UINT8)
    return tmp, d


BASE = ["--camera", "Nikon 5100 (NPL)", "--encoding", "linear", "--eta-film", "SiO2",
        "--eta-base", "Si", "--thickness-range", "0", "1000", "--quiet"]


def test_cli_photo_recovers_map_and_writes_outputs(wafer, capsys):
    """Back to ≤ 0.05 nm (measured 0.002), the gains to 1e-4; every output written; the
    console says how the file was read."""
    tmp, d = wafer
    out = tmp / "out"
    rc = main(["fit-map", str(tmp / "wafer.tif"), *BASE, "--reference",
               f"{tmp / 'bare.png'}:0", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "16-bit, linear" in text
    got = np.load(out / "thickness.npy")
    assert np.max(np.abs(got - d)) < 0.05
    summary = json.loads((out / "fit_photo.json").read_text())
    assert abs(summary["exposure"] / 0.6 - 1) < 1e-4
    np.testing.assert_allclose(summary["white_balance"], (1.8, 1.0, 1.5), rtol=1e-4)
    for name in summary["outputs"]:
        assert (out / name).is_file(), name
    buf = oiio.ImageBuf(str(out / "maps.exr"))  # EXR stores channels sorted by name
    names = buf.spec().channelnames
    assert sorted(names) == ["ambiguous", "stderr", "thickness"]
    np.testing.assert_allclose(buf.get_pixels(oiio.FLOAT)[..., names.index("thickness")], got,
                               atol=1e-3)


@pytest.mark.parametrize("extra, match", [
    (["--reference", "{tmp}/small.png:0"], "shape"),
    (["--reference", "{tmp}/empty.png:0"], "reference.*no True"),
    (["--mask", "{tmp}/small.png"], "shape"),
    (["--bit-depth", "8"], "16-bit.*8-bit"),
    (["--camera", "Canon EOS"], "Nikon 5100"),
    (["--illuminant", "daylight"], "D65"),
    (["--camera", "unknown", "--reference", "{tmp}/bare.png:0"], "at least 3 regions"),
])
def test_cli_photo_bad_input_leaves_nothing(wafer, tmp_path, capsys, extra, match):
    tmp, _ = wafer
    out = tmp_path / "out"
    argv = ["fit-map", str(tmp / "wafer.tif"), *BASE, "--out", str(out)]
    argv += [a.format(tmp=tmp) for a in extra]
    assert main(argv) == 1
    assert re.search(match, capsys.readouterr().err)
    assert not out.exists() or not any(out.iterdir())


def test_cli_photo_corrupt_and_missing_camera(wafer, tmp_path, capsys):
    tmp, _ = wafer
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"\xff\xd8\xff garbage")
    assert main(["fit-map", str(bad), *BASE, "--out", str(tmp_path / "o")]) == 1
    assert "broken.jpg" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    with pytest.raises(SystemExit) as e:  # a photograph without --camera: a usage error
        main(["fit-map", str(tmp / "wafer.tif"), "--eta-film", "SiO2", "--eta-base", "Si"])
    assert e.value.code == 2 and "--camera" in capsys.readouterr().err


def test_cli_photo_misfit_warns_and_strict_exits(wafer, tmp_path, capsys):
    """The wrong material (η₂ = 2.2 for oxide): the console warns, --strict exits 3."""
    tmp, _ = wafer
    argv = ["fit-map", str(tmp / "wafer.tif"), "--camera", "Nikon 5100 (NPL)", "--encoding",
            "linear", "--eta-film", "2.2", "--eta-base", "Si", "--quiet", "--reference",
            f"{tmp / 'bare.png'}:0", "--thickness-range", "0", "1000"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert "warning: reduced chi2" in capsys.readouterr().out
    assert main([*argv, "--out", str(tmp_path / "b"), "--strict"]) == 3


def test_cli_photo_says_chi2_and_clipped_count_one_way(wafer, tmp_path, capsys, monkeypatch):
    """The figure's title leads with the reduced χ² exactly as the console says it (robust,
    then mean) and has no "τ=none" without a prior; the first line's clipped-pixel count is
    the warning's (7 pixels with a channel at full scale here)."""
    from thinfilm_jax.cli import _output

    titles = []
    real = _output.save_thickness_png
    monkeypatch.setattr(_output, "save_thickness_png",
                        lambda path, d, title, amb: (titles.append(title), real(path, d, title,
                                                                                 amb))[1])
    tmp, d = wafer
    buf = oiio.ImageBuf(str(tmp / "wafer.tif"))
    codes = np.asarray(buf.get_pixels(oiio.UINT16)).copy()
    codes[10, :7, 0] = 65535  # seven pixels with the red channel clipped
    _write(tmp_path / "clipped.tif", codes, oiio.UINT16)
    rc = main(["fit-map", str(tmp_path / "clipped.tif"), *BASE, "--reference",
               f"{tmp / 'bare.png'}:0", "--out", str(tmp_path / "out")])
    assert rc == 0
    text = capsys.readouterr().out
    first = text.splitlines()[0]
    assert first.endswith("; 7 pixels with a clipped channel"), first
    assert "warning: 7 pixel(s) with a clipped channel" in text
    chi2 = re.search(r"reduced chi2 = \S+ \(robust; mean \S+\)", text).group(0)
    assert len(titles) == 1 and chi2 in titles[0]
    assert "none" not in titles[0] and "τ" not in titles[0]


def test_progress_bar_counts_pixels(monkeypatch):
    """The progress bar's total and its final count are the image's pixels (the fit makes
    several passes over them: it counted 7 per pixel)."""
    import tqdm.auto

    from thinfilm_jax.fit.photo import fit_photo

    seen = {}

    class Bar:
        def __init__(self, total, **kw):
            self.total, self.n = total, 0
            seen["bar"] = self

        def update(self, m):
            self.n += m

        def close(self):
            seen["closed"] = True

    monkeypatch.setattr(tqdm.auto, "tqdm", Bar)
    y = np.arange(H)[:, None] / (H - 1)
    d = np.broadcast_to(40.0 + 800.0 * y, (H, W))
    res = fit_photo(render_photo(OXIDE, d, camera="srgb"), OXIDE, camera="srgb",
                    encoding="linear", thickness_range=(0, 1000), progress=True)
    assert seen["bar"].total == res.n_pixels == H * W
    assert seen["bar"].n == H * W and seen["closed"]
