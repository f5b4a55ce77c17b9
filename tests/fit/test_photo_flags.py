"""The ambiguity flags of `fit_photo` (SPEC §13–§14, `fit.photo_flags`): each criterion flags
the pixel it is for and leaves a well-explained, isolated-order-free pixel alone."""

import numpy as np
import pytest

from thinfilm_jax.fit import photo_flags as F

pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")


def _row(d, chi=None, alt=None):
    n = len(d)
    chi = np.ones(n) if chi is None else np.asarray(chi, float)
    alt = np.full(n, 1e3) if alt is None else np.asarray(alt, float)
    return chi, alt, np.asarray(d, float), np.arange(n), (1, n)


def test_noise_and_misfit_margins():
    """An order 3 units worse is within the noise (4 · max(1, s)); one 120 worse is not,
    unless the pixel's own χ² is 50 (4 · 50 > 120) or the image's noise scale is 40."""
    chi, alt, d, where, shape = _row([100.0] * 3, [1.0, 1.0, 50.0], [4.0, 121.0, 170.0])
    why = F.reasons(chi, alt, 1.0, d, where, shape)
    assert why["noise"].tolist() == [True, False, False]
    assert why["misfit"].tolist() == [True, False, True]
    assert F.ambiguous(chi, alt, 40.0, d, where, shape).tolist() == [True, True, True]
    assert F.ambiguous(chi, np.full(3, np.inf), 1.0, d, where, shape).tolist() == [False] * 3


def test_neighbours_and_pads():
    """A pixel 200 nm off its neighbours on a smooth wedge is flagged, the wedge is not;
    with pads at 0–300 nm a pixel at 450 nm is beyond them, one at 380 nm is not."""
    h, w = 5, 6
    d = 100.0 + 5.0 * np.arange(h * w, dtype=float)
    d[14] += 200.0
    chi, alt = np.ones(h * w), np.full(h * w, 1e3)
    why = F.reasons(chi, alt, 1.0, d, np.arange(h * w), (h, w), pads_span=(0.0, 300.0))
    assert np.flatnonzero(why["neighbours"]).tolist() == [14]
    chi, alt, d, where, shape = _row([380.0, 450.0, 380.0])
    why = F.reasons(chi, alt, 1.0, d, where, (1, 3), pads_span=(0.0, 300.0))
    assert why["beyond_pads"].tolist() == [False, True, False]
    assert "beyond_pads" not in F.reasons(chi, alt, 1.0, d, where, (1, 3))


@pytest.mark.filterwarnings("ignore:reduced chi2")  # 45 on this 24 × 32 JPEG: not the point
def test_jpeg_standard_errors_are_said_uncalibrated(tmp_path):
    """The standard errors assume independent noise per pixel: a JPEG file's result says they
    are not calibrated (field, summary and a warning); the same image as a 16-bit PNG says
    they are."""
    import colour
    import OpenImageIO as oiio

    import thinfilm_jax as tf
    from thinfilm_jax.fit.photo import fit_photo, render_photo

    soap = tf.Film(0.0, tf.refractive_index("water"), 1.0)
    d = np.broadcast_to(np.linspace(200.0, 700.0, 32), (24, 32))
    enc = colour.cctf_encoding(np.clip(render_photo(soap, d, camera="srgb", exposure=3.0),
                                       0, 1), function="sRGB")
    paths = {}
    for name, codes, fmt, extra in (
            ("a.jpg", np.round(enc * 255).astype(np.uint8), oiio.UINT8, "jpeg:95"),
            ("a.png", np.round(enc * 65535).astype(np.uint16), oiio.UINT16, None)):
        spec = oiio.ImageSpec(32, 24, 3, fmt)
        if extra:
            spec.attribute("Compression", extra)
        out = oiio.ImageOutput.create(str(tmp_path / name))
        assert out.open(str(tmp_path / name), spec)
        out.write_image(np.ascontiguousarray(codes))
        out.close()
        paths[name] = str(tmp_path / name)
    kw = dict(camera="srgb", encoding="srgb", thickness_range=(0.0, 1000.0))
    jpg, png = (fit_photo(paths[n], soap, **kw) for n in ("a.jpg", "a.png"))
    assert not jpg.stderr_calibrated and not jpg.summary()["stderr_calibrated"]
    assert any("raw and linear (lossless) input only" in w for w in jpg.warnings)
    assert png.stderr_calibrated and not any("lossless" in w for w in png.warnings)
