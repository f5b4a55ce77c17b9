"""Over-exposed photographs and an unknown camera on few pads (SPEC §14): `fit_photo` chooses
fringe orders by continuation from the pixels its data decide (`pixelwise.grow`), treats a
JPEG's rung-down full-scale channels as censored (`photo._censoring`), and keeps an unknown
camera's fitted sensitivities non-negative (`photo_screen.matrix_from_pixels`).

The photographs are rendered independently of the fit's model (`studies.photo_scenes`: the
stack recursion on a 0.1 nm grid, colour-science's measured camera, a shot- and read-noise
sensor); the continuation is checked on a closed-form candidate field."""

import warnings

import numpy as np
import pytest

from thinfilm_jax.core.image import read_photo
from thinfilm_jax.fit import photo as P
from thinfilm_jax.fit.pixelwise import grow

pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")


# ----------------------------------------------------------------------------- continuation
def _ramp(h=12, w=30, sep=180.0):
    """A film d = 300 + 10 x nm (continuous) with two candidate orders per pixel, the truth
    and the truth + `sep`: the data decide (the other order 30 χ² units worse) except in
    the columns 10–19, where the wrong order is 0.5 χ² units *better* (within the noise)."""
    d = np.broadcast_to(300.0 + 10.0 * np.arange(w), (h, w)).ravel()
    cand = np.stack([d, d + sep], axis=-1)
    chi = np.tile([1.0, 31.0], (h * w, 1))
    band = ((np.arange(h * w) % w) >= 10) & ((np.arange(h * w) % w) < 20)
    chi[band] = [1.0, 0.5]
    return cand, chi, band, (h, w)


def _tol(chi):
    best = chi.min(axis=-1)  # fit_photo's: (2σ)² · max(1, the pixel's own χ²)
    return 4.0 * np.maximum(1.0, best)


def test_continuation_carries_the_order_across_ambiguous_pixels():
    cand, chi, band, shape = _ramp()
    n = cand.shape[0]
    where = np.arange(n)
    lowest = np.argmin(chi, axis=-1)
    assert np.all(lowest[band] == 1)  # per pixel, the whole band is in the wrong order
    pick = grow(cand, chi, where, np.ones(shape, bool), _tol(chi))
    assert np.all(pick == 0)


def test_continuation_does_not_overrule_the_data():
    """A pixel whose own data exclude the neighbours' order (the other order 20 χ² units
    worse, beyond (2σ)²) keeps its order; a region without a decided pixel keeps its lowest
    χ²; a known pixel seeds its region."""
    cand, chi, band, shape = _ramp()
    where = np.arange(cand.shape[0])
    chi2 = chi.copy()
    chi2[band] = [21.0, 1.0]
    pick = grow(cand, chi2, where, np.ones(shape, bool), _tol(chi2))
    assert np.all(pick[band] == 1) and np.all(pick[~band] == 0)
    # every pixel ambiguous: no seed, the lowest χ² everywhere …
    chi3 = np.tile([1.0, 0.5], (cand.shape[0], 1))
    assert np.all(grow(cand, chi3, where, np.ones(shape, bool), _tol(chi3)) == 1)
    # … unless one pixel's thickness is known (a pad): the film continues from it
    known = np.full(cand.shape[0], np.nan)
    known[0] = 300.0
    assert np.all(grow(cand, chi3, where, np.ones(shape, bool), _tol(chi3), known) == 0)


# ----------------------------------------------------------------------------- JPEG ceiling
def test_jpeg_full_scale_ringing_is_censored(tmp_path):
    """A JPEG (quality 90) of a red disc clipped at 255 on a smooth background: the DCT rings
    the clipped channel down by up to ~25 codes (chroma subsampling at the disc's edge), so
    `v ≥ 1` misses half the disc; the ceiling 239/255 censors ≥ 90 % of it (94 %) and no
    background pixel (codes ≤ 192 there)."""
    oiio = pytest.importorskip("OpenImageIO")
    n = 48
    y, x = np.mgrid[0:n, 0:n]
    codes = np.stack([40 + 3 * x, 60 + 2 * y, 90 + x + y], axis=-1).astype(np.uint8)
    disc = np.hypot(x - 24, y - 24) < 10
    codes[disc, 0] = 255
    spec = oiio.ImageSpec(n, n, 3, oiio.UINT8)
    spec.attribute("Compression", "jpeg:90")
    path = tmp_path / "disc.jpg"
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    photo = read_photo(str(path), "srgb")
    inner = np.hypot(x - 24, y - 24) < 9  # the disc less its edge pixel
    assert np.mean(photo.linear[inner, 0] >= 1.0) < 0.5  # the premise: ringing below 255
    cens, (black, ceiling, floor) = P._censoring(photo, lossy=True)
    assert floor == 0.0  # a reading is of the colour clipped at black (`photo_jpeg`)
    assert np.mean(cens[inner, 0] == 2) >= 0.9
    assert not np.any(cens[~disc & (np.hypot(x - 24, y - 24) > 12)] == 2)
    assert ceiling == pytest.approx(((239 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-6)
    assert black == pytest.approx(6 / 255 / 12.92, rel=1e-6)  # IEC 61966-2-1


# ----------------------------------------------------------------------------- unknown camera
@pytest.fixture(scope="module")
def wafer():
    """The oxide wafer of `photo_scenes` (terraces, bevel, dome; SiO₂ on Si, 0–880 nm) by the
    Nikon 5100 under D65, 48², seed 7."""
    import jax

    jax.config.update("jax_enable_x64", True)
    S = pytest.importorskip("benchmarks.photo_scenes")
    n = 48
    tpl = S.templates()["oxide"]
    d, pads = S.oxide_thickness(n)
    d_g, lam, r = S.reflectance_table(tpl, 901.0, 380.0, 780.0)
    raw, _ = S.camera_table(r, lam, "Nikon 5100 (NPL)", "D65")
    img = S.sensor(1.6 * S.apply_table(d_g, raw, d), np.random.default_rng(7))
    return img, tpl, d, pads


def test_unknown_camera_on_four_pads(wafer):
    """camera="unknown" anchored by four terraces (0, 120, 330, 520 nm) of six: the
    sensitivities, fitted from every pixel, must extrapolate to 880 nm. Unconstrained they
    bend negative and ~23 % of the pixels land in the wrong order (77 % within 15 nm); kept
    ≥ 0, 97 % are within 15 nm (margin to 93 %), and the wrong ones stay flagged."""
    img, tpl, d, pads = wafer
    ref = [pads[i] for i in (0, 1, 3, 4)]
    out = np.zeros(d.shape, bool)
    for m, _ in ref:
        out |= m
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = P.fit_photo(img, tpl, camera="unknown", encoding="linear", reference=ref,
                          thickness_range=(0.0, 900.0))
    err = np.abs(res.thickness - d)[~out]
    right = err < 15.0
    assert right.mean() > 0.93
    assert np.median(err) < 3.0
    assert res.ambiguous[~out][~right].mean() >= 0.9


def test_continuation_is_seeded_by_well_explained_pixels():
    """A pixel the model misses by χ² = 100 (a band no order explains) excludes its other
    order only by its misfit: it must not seed the continuation and carry its order into the
    ambiguous pixels beside it; the well-explained seed at the other end carries its own."""
    cand = np.tile([100.0, 300.0], (5, 1))
    chi = np.array([[0.0, 50.0], [1.0, 0.5], [1.0, 0.5], [1.0, 0.5], [500.0, 100.0]])
    where, valid = np.arange(5), np.ones((1, 5), bool)
    best = chi.min(axis=-1)
    noise = 4.0 * max(np.median(best) / (2 * np.log(2)), 1.0)  # fit_photo's (2σ)² · s
    tol = np.maximum(noise, 4.0 * best)
    assert grow(cand, chi, where, valid, tol)[3] == 1  # seeded by the misfit pixel too
    pick = grow(cand, chi, where, valid, tol, first=best <= noise)
    assert pick.tolist() == [0, 0, 0, 0, 1]  # the misfit pixel keeps its own order
