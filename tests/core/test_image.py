"""Photographs read and decoded (core/image.py, SPEC §13): files written here with OpenImageIO
(and a minimal DNG), decoded values against colour-science's IEC 61966-2-1 decoder and closed
forms, the clipped mask, Immerkær noise estimates against known Gaussian noise."""

import struct

import colour
import numpy as np
import OpenImageIO as oiio
import pytest

from thinfilm_jax.core.image import (
    ENCODINGS,
    estimate_noise,
    read_mask,
    read_photo,
    srgb_decoding_derivative,
)


def write(path, pixels, fmt, compression=None):
    pixels = np.ascontiguousarray(pixels)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    if compression:
        spec.attribute("Compression", compression)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(pixels), out.geterror()
    out.close()
    return path


def smooth(h=256, w=256):
    """A slowly varying linear RGB image in (0.04, 0.8)."""
    y, x = np.mgrid[0:h, 0:w]
    base = 0.5 + 0.3 * np.sin(2 * np.pi * x / 200) * np.cos(2 * np.pi * y / 300)
    return np.stack([base, 0.8 * base, 0.6 * base + 0.1], -1)


def encode(linear, bits):
    """sRGB-encode (colour-science) and round to b-bit codes."""
    v = colour.cctf_encoding(linear, function="sRGB")
    return np.round(v * (2**bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)


def quantisation_bound(linear, bits):
    """|decoded − linear| ≤ (q/2)·max dL/dv over [v − q/2, v + q/2]; dL/dv increases with v."""
    q = 1 / (2**bits - 1)
    v = colour.cctf_encoding(linear, function="sRGB")
    return q / 2 * srgb_decoding_derivative(v + q / 2) + 1e-12


# --- files -----------------------------------------------------------------------------------

@pytest.mark.parametrize("bits, suffix", [(8, "png"), (16, "png"), (16, "tif"), (8, "tif")])
def test_srgb_integer_round_trip(tmp_path, bits, suffix):
    t = np.linspace(0, 1, 300).reshape(10, 30, 1)  # a ramp through the whole curve
    linear = t * np.array([1.0, 0.9, 0.8])
    code = encode(linear, bits)
    path = write(tmp_path / f"ramp.{suffix}", code, oiio.UINT8 if bits == 8 else oiio.UINT16)
    photo = read_photo(path, bit_depth=bits)
    assert (photo.encoding, photo.bit_depth, photo.source) == ("srgb", bits, str(path))
    assert photo.linear.shape == (10, 30, 3) and photo.linear.dtype == np.float64
    bound = quantisation_bound(linear, bits)
    err = np.abs(photo.linear - linear)
    assert np.all(err <= bound), (err / bound).max()  # measured max 0.995 (8), 0.998 (16)
    decoded = colour.cctf_decoding(code / (2**bits - 1), function="sRGB")
    np.testing.assert_allclose(photo.linear, decoded, rtol=0, atol=1e-15)
    # clipped: the black first pixel, and those whose red rounds to the last code, i.e. whose
    # encoded red is above 1 − q/2 (1 pixel in 16 bits, 2 in 8 bits)
    top = colour.cctf_encoding(linear[..., 0], function="sRGB") >= 1 - 0.5 / (2**bits - 1)
    assert photo.clipped[0, 0] and np.array_equal(photo.clipped.flat[1:], top.flat[1:])
    n = int(photo.clipped.sum())
    assert n == {8: 3, 16: 2}[bits]
    assert photo.describe() == (f"ramp.{suffix}: 30×10, {bits}-bit, sRGB (IEC 61966-2-1) "
                                f"decoded to linear; {n} clipped pixels")


def test_exr_float_linear(tmp_path):
    linear = (smooth(20, 24) * 3).astype(np.float32)  # HDR: values up to 2.4
    path = write(tmp_path / "hdr.exr", linear, oiio.FLOAT)
    photo = read_photo(path, encoding="linear")
    assert photo.bit_depth is None and photo.encoding == "linear"
    np.testing.assert_array_equal(photo.linear, linear.astype(np.float64))
    assert not photo.clipped.any()  # linear float: nothing is clipped
    assert read_photo(path, encoding=None).encoding == "linear"
    with pytest.raises(ValueError, match="above 1 is not sRGB-encoded; pass encoding='linear'"):
        read_photo(path)  # the default, "srgb"
    with pytest.raises(ValueError, match="file is float, declared 16-bit"):
        read_photo(path, "linear", bit_depth=16)


def test_half_exr_srgb_within_unit_range(tmp_path):
    v = np.linspace(0, 1, 60).reshape(4, 5, 3)
    path = write(tmp_path / "half.exr", v.astype(np.float16), oiio.HALF)
    photo = read_photo(path, "srgb")
    np.testing.assert_allclose(photo.linear, colour.cctf_decoding(
        v.astype(np.float16).astype(np.float64), function="sRGB"), atol=1e-15)
    assert photo.clipped.sum() == 1 and photo.clipped[-1, -1]  # v = 1: at the format's maximum


def test_jpeg_within_compression_error(tmp_path):
    linear = smooth(64, 96)
    path = write(tmp_path / "x.jpg", encode(linear, 8), oiio.UINT8, "jpeg:95")
    photo = read_photo(path)
    assert photo.bit_depth == 8
    err = np.abs(photo.linear - linear)
    assert err.max() < 0.03  # measured 0.017 (quality 95, chroma subsampled)
    assert err.mean() < 0.006  # measured 0.0035
    assert err.max() > 1e-3  # lossy: not the exact codes


def test_bit_depth_mismatch(tmp_path):
    path = write(tmp_path / "deep.png", np.full((4, 4, 3), 300, np.uint16), oiio.UINT16)
    with pytest.raises(ValueError, match="file is 16-bit, declared 8-bit") as e:
        read_photo(path, bit_depth=8)
    assert str(path) in str(e.value)
    with pytest.raises(ValueError, match="array is 8-bit, declared 16-bit"):
        read_photo(np.zeros((4, 4, 3), np.uint8), bit_depth=16)
    dark = read_photo(np.full((4, 4, 3), 200, np.uint16))  # fits 0-255: suspicious, allowed
    assert dark.bit_depth == 16 and np.allclose(dark.linear, colour.cctf_decoding(200 / 65535))
    with pytest.raises(ValueError, match="bit_depth must be 8, 16 or None, got 12"):
        read_photo(dark.linear, bit_depth=12)


@pytest.mark.parametrize("name", ["x.png", "x.jpg", "x.exr", "x.dng"])
def test_corrupt_file_names_path(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"not an image " * 40)
    with pytest.raises(ValueError, match="unreadable") as e:
        read_photo(path, encoding=None)
    assert str(path) in str(e.value)


def test_truncated_and_missing_files(tmp_path):
    path = write(tmp_path / "t.png", encode(smooth(64, 64), 8), oiio.UINT8)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # the header reads, the pixels do not
    with pytest.raises(ValueError, match=r"t\.png.*unreadable.*end of file"):
        read_photo(path)
    with pytest.raises(ValueError, match=r"missing\.png.*unreadable"):
        read_photo(tmp_path / "missing.png")
    with pytest.raises(ValueError, match=r"missing\.nef.*LibRaw"):
        read_photo(tmp_path / "missing.nef", "raw")


# --- camera RAW: a minimal DNG (TIFF 6.0 + DNG 1.4 tags, one uncompressed CFA strip) --------

def write_dng(path, cfa, black, white):
    """Uncompressed 16-bit RGGB mosaic as a DNG 1.4 file: header, pixel strip, IFD 0 (the raw
    image), then the IFD's values longer than 4 bytes."""
    h, w = cfa.shape
    data = np.ascontiguousarray(cfa, "<u2").tobytes()
    kinds = {1: "B", 2: "s", 3: "H", 4: "I", 10: "i"}  # BYTE ASCII SHORT LONG SRATIONAL
    tags = {254: (4, [0]), 256: (4, [w]), 257: (4, [h]), 258: (3, [16]), 259: (3, [1]),
            262: (3, [32803]), 271: (2, "Synthetic"), 272: (2, "Test"), 273: (4, [8]),
            274: (3, [1]), 277: (3, [1]), 278: (4, [h]), 279: (4, [len(data)]), 284: (3, [1]),
            33421: (3, [2, 2]), 33422: (1, [0, 1, 1, 2]), 50706: (1, [1, 4, 0, 0]),
            50708: (2, "Synthetic Test"), 50714: (4, [black]), 50717: (4, [white]),
            50721: (10, [1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1]),
            50778: (3, [21])}
    ifd_at = 8 + len(data)
    extra_at = ifd_at + 2 + 12 * len(tags) + 4
    ifd, extra = struct.pack("<H", len(tags)), b""
    for tag, (kind, vals) in sorted(tags.items()):
        if kind == 2:
            raw, count = vals.encode() + b"\0", len(vals) + 1
        else:
            raw = struct.pack("<" + kinds[kind] * len(vals), *vals)
            count = len(vals) // 2 if kind == 10 else len(vals)
        if len(raw) <= 4:
            value = raw.ljust(4, b"\0")
        else:
            value = struct.pack("<I", extra_at + len(extra))
            extra += raw + b"\0" * (len(raw) % 2)
        ifd += struct.pack("<HHI", tag, kind, count) + value
    path.write_bytes(b"II*\0" + struct.pack("<I", ifd_at) + data + ifd + struct.pack("<I", 0)
                     + extra)
    return path


def test_raw_dng_decoded_linear(tmp_path):
    black, white = 512, 4095  # a 12-bit sensor
    level = np.array([0.25, 0.5, 0.125])  # R, G, B as fractions of white − black
    cfa = np.empty((48, 64), np.uint16)  # LibRaw refuses files under a few kB
    for (i, j), c in {(0, 0): 0, (0, 1): 1, (1, 0): 1, (1, 1): 2}.items():
        cfa[i::2, j::2] = np.round(black + level[c] * (white - black))
    cfa[41, 51] = black + 0.8 * (white - black)  # the brightest value: not rescaled to 1
    path = write_dng(tmp_path / "tiny.dng", cfa, black, white)
    photo = read_photo(path, encoding="raw")
    assert (photo.encoding, photo.bit_depth, photo.linear.shape) == ("raw", 16, (48, 64, 3))
    codes = np.round(black + level * (white - black))
    expected = (codes - black) / (white - black)  # black subtracted, white level = 1.0
    # a flat CFA colour plane demosaics to itself; measured |error| 9.8e-6 (16-bit output)
    np.testing.assert_allclose(photo.linear[8:24, 8:24], np.broadcast_to(expected, (16, 16, 3)),
                               atol=2e-5)
    # LibRaw's default adjust_maximum_thr=0.75 would make this 0.8 the white (1.0)
    assert abs(photo.linear[..., 2].max() - 0.8) < 1e-3  # a blue site; measured 0.79988
    assert not photo.clipped.any()
    assert read_photo(path, encoding=None).encoding == "raw"
    assert photo.describe() == ("tiny.dng: 64×48, 16-bit, camera RAW (LibRaw linear camera RGB); "
                                "0 clipped pixels")
    for wrong in ("srgb", "linear"):
        with pytest.raises(ValueError, match=f"camera RAW.*declared encoding '{wrong}'"):
            read_photo(path, encoding=wrong)


# --- arrays, encodings, clipping -------------------------------------------------------------

def test_array_inputs_and_errors():
    rgba = np.zeros((3, 4, 4), np.uint8)
    rgba[..., :3], rgba[..., 3] = 100, 255
    photo = read_photo(rgba)
    assert photo.linear.shape == (3, 4, 3) and photo.source == "array"
    assert np.allclose(photo.linear, colour.cctf_decoding(100 / 255, function="sRGB"))
    assert np.array_equal(read_photo(rgba, "linear").linear, np.full((3, 4, 3), 100 / 255))
    for bad, words in [(np.zeros((3, 4)), r"shape \(3, 4\)"), (np.zeros((3, 4, 2)), "shape"),
                       (np.zeros((3, 4, 3), np.int32), "dtype int32"),
                       (np.full((3, 4, 3), np.nan), "NaN or inf"),
                       (np.full((3, 4, 3), -0.1), "negative"),
                       (np.full((3, 4, 3), 1.5), "above 1 is not sRGB-encoded")]:
        with pytest.raises(ValueError, match=words):
            read_photo(bad)
    with pytest.raises(ValueError, match=r"\('srgb', 'linear', 'raw'\)") as e:
        read_photo(rgba, "gamma22")
    assert str(ENCODINGS) in str(e.value)


def test_clipped_mask():
    a = np.full((2, 4, 3), 128, np.uint8)
    a[0, 0] = (255, 10, 10)  # one channel at the maximum code
    a[0, 1] = (0, 0, 0)  # black in every channel
    a[0, 2] = (0, 0, 1)  # dark but measured
    a[0, 3] = (254, 254, 254)  # bright but below the maximum
    np.testing.assert_array_equal(read_photo(a).clipped, [[1, 1, 0, 0], [0, 0, 0, 0]])
    b = a.astype(np.uint16) * 257  # the same codes in 16 bits: 255 → 65535
    np.testing.assert_array_equal(read_photo(b).clipped, [[1, 1, 0, 0], [0, 0, 0, 0]])
    f = np.full((1, 3, 3), 0.5)
    f[0, 0, 1], f[0, 1] = 1.0, 0.0  # float sRGB: ≥ 1 clipped; float black is not
    np.testing.assert_array_equal(read_photo(f).clipped, [[1, 0, 0]])
    f[0, 2] = 7.0  # linear float: no clipping at all
    assert not read_photo(f, "linear").clipped.any()


def test_srgb_derivative_matches_finite_differences():
    v = np.concatenate([np.linspace(0, 0.0404, 50), np.linspace(0.0406, 1, 400)])
    h = 1e-6
    fd = (colour.cctf_decoding(v + h, function="sRGB")
          - colour.cctf_decoding(v - h, function="sRGB")) / (2 * h)
    # measured max relative difference 1.0e-10 (central-difference truncation and rounding)
    np.testing.assert_allclose(srgb_decoding_derivative(v), fd, rtol=1e-8)
    assert srgb_decoding_derivative(0.0) == 1 / 12.92


# --- noise -----------------------------------------------------------------------------------

@pytest.mark.parametrize("sigma", [0.01, 0.003])
def test_estimate_noise_recovers_known_sigma(sigma):
    rng = np.random.default_rng(0)
    clean = smooth()
    est = estimate_noise(clean + rng.normal(0, sigma, clean.shape))
    # 256 × 256 per channel; measured relative errors ≤ 1.1 % over seeds 0-2, for both σ
    np.testing.assert_allclose(est, sigma, rtol=0.03)
    assert np.all(estimate_noise(clean) < 1e-7)  # measured 1.0e-8: the image alone (smooth)


def test_estimate_noise_edges_and_valid_mask():
    assert np.array_equal(estimate_noise(np.ones((2, 9, 3))), np.zeros(3))
    with pytest.raises(ValueError, match=r"\(H, W, 3\).*\(4, 4\)"):
        estimate_noise(np.ones((4, 4)))
    rng = np.random.default_rng(1)
    img = smooth(128, 128) + rng.normal(0, 0.01, (128, 128, 3))
    img[:, 64:] = 1.0  # a saturated half: no noise there, an edge at its border
    valid = np.ones((128, 128), bool)
    valid[:, 64:] = False
    kept = estimate_noise(img, valid)
    np.testing.assert_allclose(kept, estimate_noise(img[:, :64]), rtol=1e-12)
    np.testing.assert_allclose(kept, 0.01, rtol=0.05)  # measured 0.986-0.995
    assert np.all(estimate_noise(img) < 0.8 * kept)  # measured 0.50: the flat half dilutes σ


@pytest.mark.parametrize("bits", [8, 16])
def test_photo_noise_predicts_the_decoded_error(bits):
    """Gaussian noise σ = 0.01 added to the sRGB-encoded values of a known image: the decoded
    error divided by Photo.noise has unit standard deviation (the propagation through dL/dv)."""
    rng = np.random.default_rng(3)
    linear = smooth() ** 2.2 * 0.9
    v = colour.cctf_encoding(linear, function="sRGB") + rng.normal(0, 0.01, linear.shape)
    code = np.round(np.clip(v, 0, 1) * (2**bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)
    photo = read_photo(code)
    z = ((photo.linear - linear) / photo.noise)[~photo.clipped]
    assert abs(z.std() - 1) < 0.03  # measured 0.993 (8-bit), 0.999 (16-bit)
    assert photo.noise.shape == (256, 256, 3) and np.all(photo.noise > 0)


@pytest.mark.parametrize("bits", [8, 16])
def test_flat_image_noise_is_the_quantisation_floor(bits):
    """No sensor noise: σ_v = q/√12 (uniform rounding error of step q), times dL/dv."""
    code = 0.6 * (2**bits - 1)
    photo = read_photo(np.full((8, 8, 3), round(code), np.uint8 if bits == 8 else np.uint16))
    v = round(code) / (2**bits - 1)
    h = 1e-7  # dL/dv by a central difference of colour-science's decoder
    slope = (colour.cctf_decoding(v + h, function="sRGB")
             - colour.cctf_decoding(v - h, function="sRGB")) / (2 * h)
    np.testing.assert_allclose(photo.noise, slope / (2**bits - 1) / np.sqrt(12), rtol=1e-6)


def test_float_linear_noise_is_the_estimate():
    rng = np.random.default_rng(2)
    img = smooth() * 4 + rng.normal(0, 0.02, (256, 256, 3))  # HDR, linear
    photo = read_photo(img, "linear")
    np.testing.assert_array_equal(photo.noise, np.broadcast_to(estimate_noise(img), img.shape))
    np.testing.assert_allclose(photo.noise[0, 0], 0.02, rtol=0.03)  # measured ≤ 1 %, no σ_q


# --- masks -----------------------------------------------------------------------------------

def test_read_mask(tmp_path):
    m = np.zeros((6, 8), bool)
    m[2:4, 3:6] = True
    np.testing.assert_array_equal(read_mask(m.astype(float), (6, 8)), m)
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[m, 1] = 255
    path = write(tmp_path / "m.png", rgb, oiio.UINT8)
    np.testing.assert_array_equal(read_mask(path, (6, 8)), m)
    with pytest.raises(ValueError, match=r"ref0: shape \(6, 8\) differs from the image's \(8, 6\)"):
        read_mask(m, (8, 6), name="ref0")
    with pytest.raises(ValueError, match="ref1: no True"):
        read_mask(np.zeros((6, 8)), (6, 8), name="ref1")
    with pytest.raises(ValueError, match=r"ref2 .*nope\.png.*unreadable"):
        read_mask(tmp_path / "nope.png", (6, 8), name="ref2")
