"""`shading.compare.compare_methods`: every method of `envmap_radiance` from one `EnvMap`, in
one space, with ΔE₀₀ against the reference.

One 16 × 32 sky with a one-texel sun (0.004 sr: small enough for `extract_sources`, so the
"improved" map really splits it), six shading points with tilted normals, α = 0.3; tiny
prefiltered tables (3 levels, an 8 × 5 albedo table) to stay quick.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, prefilter_envmap
from thinfilm_jax.shading.compare import compare_methods
from thinfilm_jax.shading.ibl import DEFAULT_SOURCES
from thinfilm_jax.shading.prefilter import lookup_albedo, lookup_radiance
from thinfilm_jax.spectral.colorimetry import delta_e2000_rec709, rec709_to_bands
from thinfilm_jax.spectral.khr import khr_bands

PREFILTER = dict(levels=3, albedo_shape=(8, 5))
ALPHA = 0.3


def _sky():
    sky = np.full((16, 32, 3), 0.2) * np.array([0.9, 1.0, 1.3])
    sky[:, :, :] *= np.linspace(1.5, 0.5, 16)[:, None, None]
    sky[0, 5] = np.array([400.0, 380.0, 330.0])
    return sky


def _points():
    rng = np.random.default_rng(11)
    normal = rng.normal(size=(6, 3)) * [0.25, 0.25, 0.3] + [0.0, 0.0, 1.0]
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    view = np.array([0.2, -0.3, 0.93]) / np.linalg.norm([0.2, -0.3, 0.93])
    film = Film(np.linspace(250.0, 600.0, 6), 1.4, 1.6)
    return film, normal, view


@pytest.fixture(scope="module")
def result():
    film, normal, view = _points()
    return compare_methods(film, ALPHA, normal, view, _sky(),
                           methods=("ideal", "filtered", "improved", "khr", "colour_table"),
                           prefilter=PREFILTER)


def test_one_space_and_khr_delta_e_by_hand(result):
    """Every method comes back as (6, 3) bands of the observer, the reference included (run
    though not listed). khr's values are `rec709_to_bands` of its raw glTF Rec. 709 built by
    hand from a map prefiltered here with no sun split (A and P read from its tables at the
    mirror direction, times `khr_bands`), and the helper's ΔE for khr equals
    `delta_e2000_rec709` applied to that raw RGB against the reference: the independent path
    of a user who converts by hand (measured agreement 1e-16 and 1e-13; asserted 1e-12 and
    1e-9)."""
    film, normal, view = _points()
    assert set(result.radiance) == {"reference", "ideal", "filtered", "improved", "khr"}
    for v in result.radiance.values():
        assert v.shape == (6, 3) and np.all(np.isfinite(v))
    pref = prefilter_envmap(_sky(), **PREFILTER)
    co = np.sum(normal * view, -1)
    assert np.all(co > 0.3)
    sqa = jnp.full(6, np.sqrt(ALPHA))
    raw = (np.asarray(lookup_albedo(pref, jnp.asarray(co), sqa))[:, None]
           * np.asarray(lookup_radiance(pref, jnp.asarray(2 * co[:, None] * normal - view), sqa))
           * np.asarray(khr_bands(film, jnp.asarray(co))))
    np.testing.assert_allclose(result.radiance["khr"], rec709_to_bands(raw), rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.delta_e["khr"],
                               delta_e2000_rec709(raw, result.radiance["reference"]),
                               rtol=0, atol=1e-9)


def test_delta_e_against_the_reference(result):
    """The reference against itself is ΔE 0; the real-time methods' ΔE are finite and > 0
    (an approximation under a sun is never exact); each method read the map it needs:
    `improved` with its suns split (`DEFAULT_SOURCES`), the published ones as it is, the
    reference the `EnvMap`."""
    assert np.all(result.delta_e["reference"] == 0)
    for m in ("ideal", "filtered", "improved", "khr"):
        d = result.delta_e[m]
        assert d.shape == (6,) and np.all(np.isfinite(d)) and d.max() > 0, (m, d)
    assert result.sources == {"reference": None, "ideal": 0, "filtered": 0,
                              "improved": DEFAULT_SOURCES, "khr": 0}
    assert result.reference == "reference"


def test_colour_table_skipped_for_many_films(result):
    """colour_table models one film and one α: with six films it is skipped, with the reason,
    not run and not an error."""
    assert "colour_table" not in result.radiance
    assert "one film" in result.skipped["colour_table"]


def test_refuses_a_prefiltered_map():
    film, normal, view = _points()
    with pytest.raises(ValueError, match="EnvMap"):
        compare_methods(film, ALPHA, normal, view, prefilter_envmap(_sky(), **PREFILTER),
                        methods=("khr",))


def test_colour_table_runs_for_one_film():
    """For one film and one α the helper builds the `ColourTable` itself (`prefilter_colour`
    with the given keyword arguments, a tiny table here) and reports the table's band
    radiances and a finite, non-zero ΔE against the reference."""
    _, normal, view = _points()
    res = compare_methods(Film(400.0, 1.4, 1.6), ALPHA, normal, view, _sky(),
                          methods=("colour_table",), prefilter=PREFILTER,
                          colour=dict(resolution=(4, 8), n_view=4, n_azimuth=4,
                                      brightness_resolution=(16, 32), n_cos=128))
    assert not res.skipped and res.sources["colour_table"] is None
    assert res.radiance["colour_table"].shape == (6, 3)
    d = res.delta_e["colour_table"]
    assert np.all(np.isfinite(d)) and d.max() > 0
