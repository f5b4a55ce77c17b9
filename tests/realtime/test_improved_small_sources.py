"""`envmap_radiance(method="improved")` under a map of many small bright sources and no sun
(docs/studies/improved.md, "Many small sources"; thinfilm_jax/studies/small_sources.py).

The map: `small_sources.lamps_map(seed=7, h=128, n=200)`, a dim night sky with 200 small
lamps of many colours (1.4° texels, none split off as a source: each carries < 5 % of the
power), seed and size used by no study map. Shading points: the study's 12 px sphere
(Figure 3's film, d = 650 nm, η₂ = 1.3 on η₃ = 2.0 + 0.5i, α = 0.12, the renders' camera),
112 points. ΔE₀₀ against the exact reference (`method="reference"`: texel quadrature,
converged, SPEC §9) with the renders' exposure rule (the reference's 99th luminance
percentile → 0.9).
"""

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film
from thinfilm_jax.realtime.improved import bin_table
from thinfilm_jax.shading.ibl import DEFAULT_SOURCES, envmap_radiance
from thinfilm_jax.shading.prefilter import prefilter_envmap
from thinfilm_jax.spectral.colorimetry import delta_e2000
from thinfilm_jax.spectral.spectra import DEFAULT_OBSERVER
from thinfilm_jax.studies.render import _view_azimuth, camera, sphere
from thinfilm_jax.studies.scene import exposure_of
from thinfilm_jax.studies.small_sources import lamps_map, previous_improved

FILM = Film(650.0, 1.3, 2.0, 0.5)
ALPHA = 0.12


@pytest.fixture(scope="module")
def lamps():
    env = lamps_map(7, h=128, n=200)
    wo, right, up = camera(_view_azimuth(env), 15.0)
    mask, n = sphere(12, wo, right, up)
    pts = n[mask]
    ref = np.asarray(envmap_radiance(FILM, ALPHA, pts, wo, env))
    return env, pts, wo, ref


def _delta_e(values, ref):
    e = exposure_of(ref, DEFAULT_OBSERVER)  # the renders' rule
    return np.asarray(delta_e2000(values * e, ref * e))


def test_improved_beats_filtered_under_many_small_sources(lamps):
    """Measured (float64): filtered 4.309 mean ΔE₀₀, improved 2.604 (÷ filtered 0.604);
    the model before the lobe-fitted reads and light-weighted bins (`previous_improved`)
    4.850 (1.13 × filtered). Bounds: improved ≤ 1.25 × measured (3.26) and ≤ 0.7 × filtered
    (the design target on such maps); the previous model fails both, asserted below.
    Mutations (each fails both bounds): the bins at their uniform-light cosines (Δc = 0)
    3.76 / 0.87 ×; the moment-matched reads with the light-weighted cosines 4.40 / 1.02 ×."""
    env, pts, wo, ref = lamps
    pf = prefilter_envmap(env)
    pi = prefilter_envmap(env, sources=DEFAULT_SOURCES)
    assert not pi.has_sources  # no lamp is a sun: only the bins act
    de_f = _delta_e(np.asarray(envmap_radiance(FILM, ALPHA, pts, wo, pf, method="filtered")),
                    ref)
    de_i = _delta_e(np.asarray(envmap_radiance(FILM, ALPHA, pts, wo, pi, method="improved")),
                    ref)
    assert de_i.mean() <= 1.25 * 2.604, (de_i.mean(), de_f.mean())
    assert de_i.mean() <= 0.7 * de_f.mean(), (de_i.mean(), de_f.mean())
    view = jnp.broadcast_to(jnp.asarray(wo), pts.shape)
    before = np.asarray(previous_improved(FILM, jnp.full(len(pts), ALPHA), jnp.asarray(pts),
                                          view, pi, bin_table(),
                                          observer="stiles_burch_1959_10"))
    de_b = _delta_e(before, ref)
    assert de_b.mean() > 1.25 * 2.604 and de_b.mean() > 0.7 * de_f.mean(), de_b.mean()


def test_light_spread_under_many_small_sources(lamps):
    """`ModelOptions(light_spread=True)`: each bin's spread of cos θ₁ follows the second
    moments of its read's light (`prefilter.bin_radiance_parts`). On this map (no study map
    chose it) measured (float64): 2.520 mean ΔE₀₀ against 2.604 without; asserted: lower by
    at least half that gain (0.04). Mutation: the uniform-light variance without its
    −m₁²x_d² term gives 2.667, worse than without the option."""
    from thinfilm_jax import ModelOptions

    env, pts, wo, ref = lamps
    pi = prefilter_envmap(env, sources=DEFAULT_SOURCES)
    de = {ls: _delta_e(np.asarray(envmap_radiance(
        FILM, ALPHA, pts, wo, pi, method="improved",
        options=ModelOptions(shat="lut", light_spread=ls))), ref).mean() for ls in (False, True)}
    assert de[True] <= de[False] - 0.04, de
