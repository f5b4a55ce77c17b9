"""The K 29 tail's table reads and the real-time chunk loop (SPEC §5, §9; Kneiphof et al. 2019,
K 29): the cheaper forms compute the same numbers.

* `lut.lookup(interpolation="linear_mu")`, the 8-tap read of `filtered` under a map, against
  the exact Ŝ next to the 16-tap bicubic read.
* `lut.read_parts(channel=(k, K))` reads light channel k of a cross-band table in place: the
  same values, bit for bit, as the strided copy `filtered.split_by_light` makes.
* `filtered._read_orders` (16-tap bicubic reads, unrolled) takes the carrier of order m as the
  m-th power of order 1's: equal to K 29 written out with `lut.lookup` per order to float64
  rounding.
* `envmap_radiance`'s chunk loop (`ibl._realtime_jit`): each chunk is a `lax.cond` branch, so
  XLA:CPU does not fuse the K 29 tail into the loop's in-place output update (which it runs on
  one thread); a chunk that faces away from the eye is skipped. Both are checked: the values
  against one unchunked call, the structure in the compiled program.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, prefilter_envmap
from thinfilm_jax.optics.opd import OPDMoments
from thinfilm_jax.optics.series import fused_terms
from thinfilm_jax.realtime.filtered import _read_orders, split_by_light
from thinfilm_jax.shading.envmap import downsample, load_envmap
from thinfilm_jax.shading.ibl import MAP_SHAT_READ, envmap_radiance
from thinfilm_jax.spectral.lut import build_shat_lut, lookup, read_parts

CROSS = "stiles_burch_1959_10+mallett2019"


@pytest.fixture(scope="module")
def cross_lut():
    return build_shat_lut(CROSS)


@pytest.mark.parametrize("interpolation, with_sigma", [("cubic", True), ("cubic", False),
                                                       ("linear_mu", True), ("linear", True)])
def test_channel_read_in_place_equals_the_split_copy(cross_lut, interpolation, with_sigma):
    rng = np.random.default_rng(1)
    a = jnp.asarray(rng.uniform(0.0, 16000.0, 200))  # past μ_max too (zeros)
    sig = jnp.asarray(rng.uniform(0.0, 1200.0, 200)) if with_sigma else None
    split = split_by_light(cross_lut, 3)
    for k in range(3):
        got = read_parts(cross_lut, a, sig, interpolation=interpolation, channel=(k, 3))
        ref = read_parts(split[k], a, sig, interpolation=interpolation)
        for g, r in zip(got, ref):
            assert g.shape == (200, 3)
            np.testing.assert_array_equal(np.asarray(g), np.asarray(r))


@pytest.mark.parametrize("observer, cubic, linear_mu", [
    ("stiles_burch_1959_10", 3.03e-5, 6.08e-5), (CROSS, 2.75e-5, 4.70e-5)])
def test_eight_tap_read_against_exact_shat(observer, cubic, linear_mu):
    """The reads of `lut.lookup` against the exact Ŝ (SPEC §5 quadrature, float64) at 20,000
    random (μ, σ) in the table's range, a third each at σ = 0, 0.1 σ_max-scale and full
    scale: the 8-tap read (linear in |μ|, cubic in σ), which `envmap_radiance` uses for
    `filtered`, errs at most 2.2× the 16-tap bicubic one (measured maxima in the parameters,
    asserted with a 15 % margin); bilinear (linear in σ too) errs 1.4e-3, so a read that
    lost its σ stencil fails."""
    from thinfilm_jax.spectral.spectra import shat_host

    lut = build_shat_lut(observer)
    rng = np.random.default_rng(0)
    mu = rng.uniform(0, float(lut.mu_max), 20000)
    sig = rng.uniform(0, float(lut.sigma_max), 20000) * rng.choice([0.0, 0.1, 1.0], 20000)
    exact = shat_host(mu, sig**2, observer)
    err = {i: np.abs(np.asarray(lookup(lut, mu, sig, interpolation=i)) - exact).max()
           for i in ("cubic", "linear_mu")}
    assert err["cubic"] <= 1.15 * cubic, err
    assert err["linear_mu"] <= 1.15 * linear_mu, err
    # the same read at −μ is the conjugate (Ŝ(−μ) = conj Ŝ(μ)), and 0 beyond μ_max
    np.testing.assert_allclose(np.asarray(lookup(lut, -mu, sig, interpolation="linear_mu")),
                               np.conj(np.asarray(lookup(lut, mu, sig,
                                                         interpolation="linear_mu"))),
                               atol=1e-15)
    assert np.all(np.asarray(lookup(lut, 1.01 * float(lut.mu_max), 0.0,
                                    interpolation="linear_mu")) == 0)


@pytest.mark.parametrize("terms", [1, 2, 3])
def test_carrier_powers_equal_k29_per_order(terms):
    """The unrolled bicubic K 29 against the sum written out with complex `lookup` (its own
    carrier per order): measured ≤ 3e-16 (float64, values ≤ 1). A wrong power (e.g. order 1's
    carrier reused for every order) moves the sum by ~0.1."""
    lut = build_shat_lut()
    rng = np.random.default_rng(2)
    n = 300
    film = Film(*(jnp.asarray(v) for v in (rng.uniform(0, 1000, n), rng.uniform(1.2, 2.4, n),
                                           rng.uniform(1.0, 2.5, n), rng.uniform(0, 3, n),
                                           np.ones(n))))
    ft = fused_terms(film, jnp.asarray(rng.uniform(0.05, 1.0, n)))
    mu = ft.opd
    std = jnp.asarray(rng.uniform(0.0, 150.0, n))
    s0 = jnp.asarray(rng.uniform(0.9, 1.1, 3))
    got = _read_orders(ft, s0, terms, OPDMoments(mu, std), lut, "cubic")
    ref = 0.5 * (ft.c0[0] + ft.c0[1])[:, None] * s0
    z = [jax.lax.complex(ft.z_re[p], ft.z_im[p]) for p in range(2)]
    for m in range(1, terms + 1):
        wr = sum(ft.amp[p] * jnp.real(z[p] ** m) for p in range(2))
        wi = sum(ft.amp[p] * jnp.imag(z[p] ** m) for p in range(2))
        s = lookup(lut, m * mu, m * std)  # Re(W conj S) = Re W Re S + Im W Im S
        ref = ref + wr[:, None] * jnp.real(s) + wi[:, None] * jnp.imag(s)
    np.testing.assert_allclose(np.asarray(got), np.asarray(ref), rtol=0, atol=1e-14)


@pytest.fixture(scope="module")
def small_pref():
    return prefilter_envmap(downsample(load_envmap("forest_slope"), 4), levels=9)


@pytest.mark.parametrize("method", ["ideal", "filtered", "improved"])
def test_chunked_equals_one_call_and_skips_hidden_chunks(small_pref, method):
    """Chunks of 64 points, the middle ones facing away from the eye (skipped, zeros), the
    last one part padding, against the same points in one call: equal to float32 rounding
    of the differently fused kernels (measured ≤ 2.4e-7 of values ≤ 2)."""
    rng = np.random.default_rng(3)
    n = 64 * 5 + 17
    t = rng.uniform(0.0, 1.4, n)
    view = np.stack([np.sin(t), 0 * t, np.cos(t)], -1)
    normal = np.tile([0.0, 0.0, 1.0], (n, 1))
    normal[64:192] = -normal[64:192]  # two whole chunks face away
    normal[300] = -normal[300]  # and one point of a shaded chunk
    film = Film(*(jnp.asarray(v, jnp.float32) for v in (
        rng.uniform(0, 1000, n), rng.uniform(1.2, 2.4, n), rng.uniform(1.0, 2.5, n),
        rng.uniform(0, 3, n), np.ones(n))))
    pref = small_pref.astype(jnp.float32)
    args = (film, jnp.asarray(rng.uniform(0.05, 0.6, n), jnp.float32),
            jnp.asarray(normal, jnp.float32), jnp.asarray(view, jnp.float32), pref)
    one = np.asarray(envmap_radiance(*args, method=method))
    chunked = np.asarray(envmap_radiance(*args, method=method, batch_size=64))
    assert np.all(one[64:192] == 0) and np.all(chunked[64:192] == 0) and one[300].max() == 0
    assert one[:64].max() > 0.01 and one[192:].max() > 0.01
    np.testing.assert_allclose(chunked, one, rtol=0, atol=1e-6 * one.max())


def test_k29_tail_is_not_fused_into_the_loop_output():
    """The compiled chunk loop of `filtered` (2 chunks of 65,536 abstract float32 points): the
    fusion that holds the tail's LUT gathers must not be the loop's in-place
    dynamic-update-slice, which XLA:CPU runs on one thread. With a bare `lax.map` it is
    (measured: its 32 gathers of the 16-tap read in `bitcast_dynamic-update-slice_fusion`)."""
    f32 = jnp.float32
    n = 2 * 65536

    def spec(*shape):
        return jax.ShapeDtypeStruct((n, *shape), f32)

    pref = prefilter_envmap(np.ones((8, 16, 3)), levels=3, resolution=(8, 16),
                            albedo_shape=(8, 5)).astype(f32)
    pref = jax.tree.map(lambda x: jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)), pref)
    hlo = jax.jit(lambda f, a, nn, v, p: envmap_radiance(f, a, nn, v, p, method="filtered")
                  ).lower(Film(*(spec() for _ in range(5))), spec(), spec(3), spec(3),
                          pref).compile().as_text()
    bodies = dict(re.findall(r"^(%[\w.\-]+) \(.*?\{\n(.*?)\n\}", hlo, re.S | re.M))
    count, name = max((b.count(" gather("), k) for k, b in bodies.items())
    taps = {"cubic": 16, "linear_mu": 8}[MAP_SHAT_READ]
    assert count >= 2 * taps, count  # taps × 2 orders (one row of the 9 cross bands each)
    caller = next(line for line in hlo.splitlines() if f"calls={name}," in line)
    assert "dynamic-update-slice" not in caller.split("=")[0], caller[:200]
