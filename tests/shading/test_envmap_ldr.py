"""LDR image files as environment maps (`load_envmap`, thinfilm_jax/shading/envmap.py).

An 8-bit PNG or JPEG (or a 16-bit PNG) holds display-encoded sRGB code values, not radiance:
`load_envmap` refuses it with a ValueError that says so and names the way out,
``ldr_srgb=True``, which decodes it with the sRGB EOTF of IEC 61966-2-1. The decoded values
are checked against that EOTF written out here (the piecewise formula, independent of
colour-science), at codes on both sides of its knee V = 0.04045. The CLI's ``render
--ldr-srgb`` reaches `load_envmap` (checked on a map that then fails a later check, so nothing
renders). Files are written with OpenImageIO into tmp_path; no compilation: ≈ 1 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from thinfilm_jax.shading.envmap import load_envmap, save_envmap

H, W = 4, 8


def srgb_eotf(v):
    """IEC 61966-2-1 decoding, written out: V/12.92 up to 0.04045, ((V + 0.055)/1.055)^2.4."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def codes(top: int) -> np.ndarray:
    """(H, W, 3) integer codes spanning 0..top, with the two around the EOTF's knee
    (8-bit: 10 → V = 0.0392 linear part, 11 → 0.0431 power part)."""
    c = np.linspace(0, top, H * W * 3).round().astype(np.int64).reshape(H, W, 3)
    knee = round(0.04045 * top)
    c[0, 1] = (knee - 1, knee, knee + 1)
    return c


def write_ldr(path, c: np.ndarray, bits: int):
    import OpenImageIO as oiio

    fmt, dt = (oiio.UINT8, np.uint8) if bits == 8 else (oiio.UINT16, np.uint16)
    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), oiio.ImageSpec(c.shape[1], c.shape[0], 3, fmt))
    assert out.write_image(np.ascontiguousarray(c.astype(dt)))
    out.close()
    return path


LDR_FILES = [("map.png", 8), ("map16.png", 16), ("map.jpg", 8)]


@pytest.mark.parametrize("name,bits", LDR_FILES)
def test_ldr_file_is_refused_with_the_reason_and_the_remedy(tmp_path, name, bits):
    path = write_ldr(tmp_path / name, codes(2**bits - 1), bits)
    with pytest.raises(ValueError) as e:
        load_envmap(path)
    msg = str(e.value)
    assert str(path) in msg and "LDR" in msg and "not radiance" in msg, msg
    assert "ldr_srgb=True" in msg and "--ldr-srgb" in msg, msg
    assert f"uint{bits}" in msg, msg


@pytest.mark.parametrize("name,bits", LDR_FILES[:2])  # lossless: the codes come back exactly
def test_ldr_srgb_decodes_with_the_srgb_eotf(tmp_path, name, bits):
    top = 2**bits - 1
    c = codes(top)
    env = load_envmap(write_ldr(tmp_path / name, c, bits), ldr_srgb=True)
    got = np.asarray(env.radiance)
    want = srgb_eotf(c / top)
    # OpenImageIO returns code/top in float32 (relative error ≤ 6e-8, ×2.4 through the power):
    # measured max |Δ| 1.6e-7 (8-bit) and 6.0e-8 (16-bit)
    np.testing.assert_allclose(got, want, rtol=0, atol=5e-7)
    assert got.dtype == np.float64 and got.shape == (H, W, 3)
    assert got.min() == 0.0 and abs(got.max() - 1.0) < 1e-7  # white is radiance 1
    # read as radiance, the codes would be far off: the mid-grey code is 0.21, not 0.5
    assert np.abs(got - c / top).max() > 0.2


def test_jpeg_decodes_to_its_own_codes(tmp_path):
    """A lossy file: the EOTF of the codes the JPEG decoder returns (read back undecoded with
    OpenImageIO), whatever compression did to them."""
    import OpenImageIO as oiio

    path = write_ldr(tmp_path / "map.jpg", codes(255), 8)
    raw = np.asarray(oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT), np.float64)[..., :3]
    got = np.asarray(load_envmap(path, ldr_srgb=True).radiance)
    np.testing.assert_allclose(got, srgb_eotf(raw), rtol=0, atol=1e-12)


def test_float_files_and_arrays_are_read_as_they_are(tmp_path):
    """`ldr_srgb` concerns integer files only: an HDR (float) file and an array are radiance
    already, and come back the same with or without it."""
    rad = np.random.default_rng(1).uniform(0.0, 5.0, size=(H, W, 3))
    path = save_envmap(tmp_path / "map.exr", rad)
    a = np.asarray(load_envmap(path).radiance)
    b = np.asarray(load_envmap(path, ldr_srgb=True).radiance)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a, rad, rtol=6e-8)  # float32 storage
    np.testing.assert_array_equal(np.asarray(load_envmap(rad, ldr_srgb=True).radiance), rad)


def test_render_cli_refuses_an_ldr_map_and_passes_ldr_srgb_on(tmp_path, capsys):
    """`thinfilm-jax render --envmap photo.png` stops before any frame with the reason; with
    --ldr-srgb the file is decoded and the next check speaks (this map is 4 × 4, not 2:1)."""
    from thinfilm_jax.cli.main import main

    path = write_ldr(tmp_path / "square.png", np.full((4, 4, 3), 128), 8)
    argv = ["render", "--envmap", str(path), "--scene", "fig4", "--method", "ideal",
            "--resolution", "4", "--out", str(tmp_path / "out")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert "LDR" in err and "--ldr-srgb" in err and len(err.splitlines()) == 1, err
    assert main([*argv, "--ldr-srgb"]) == 1
    err = capsys.readouterr().err.strip()
    assert "not an equirectangular map" in err and "LDR" not in err, err
    assert not (tmp_path / "out").exists()


def test_a_prefiltered_map_where_the_map_is_expected_is_named():
    """`prefilter_colour` and the exact methods take the map itself; handed the prefiltered
    one (a NamedTuple of tables) they said "setting an array element with a sequence"."""
    import thinfilm_jax as tf

    img = np.ones((8, 16, 3))
    pref = tf.prefilter_envmap(img, levels=2, resolution=(8, 16), albedo_shape=(8, 5),
                               sources=0)
    with pytest.raises(TypeError, match="got a PrefilteredEnvMap: pass the map it was made"):
        tf.prefilter_colour(pref, tf.Film(300.0, 1.33, 1.5), 0.3)
    with pytest.raises(ValueError, match="pass an EnvMap, not a PrefilteredEnvMap"):
        tf.envmap_radiance(tf.Film(300.0, 1.33, 1.5), 0.3, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0],
                           pref, method="reference")
