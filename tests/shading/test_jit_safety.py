"""Every public shading entry point under `jax.jit` (twice, each a fresh trace), `jit(grad)`
and `vmap`: no state of one trace may leak into the next (a module-level cache that kept a
traced value raised UnexpectedTracerError on the third transform), and host-side
preparation (prefiltering a map, the reference's texel geometry) runs concretely inside a
trace. Tiny sizes: 4 shading points, an 8 × 16 map."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, envmap_radiance, load_envmap, patch_radiance, prefilter_envmap

D0 = 400.0
ALPHA = 0.25


@pytest.fixture(scope="module")
def env():
    rng = np.random.default_rng(7)
    return load_envmap(rng.uniform(0.5, 2.0, (8, 16, 3)))


def _views():
    th = np.array([0.0, 0.4, 0.8, 1.1])
    v = np.stack([np.sin(th) * np.cos(0.7), np.sin(th) * np.sin(0.7), np.cos(th)], -1)
    return np.array([0.0, 0.0, 1.0]), v


def _transforms(f, d0=D0, h=0.5):
    """(value, [two fresh jits], jit(grad), finite difference, vmap over two d) of f(d)."""
    x = jnp.asarray(d0)
    eager = float(f(x))
    jits = [float(jax.jit(lambda d: f(d))(x)) for _ in range(2)]  # two fresh traces
    grad = float(jax.jit(jax.grad(lambda d: f(d)))(x))
    fd = (float(f(x + h)) - float(f(x - h))) / (2 * h)
    batch = np.asarray(jax.vmap(lambda d: f(d))(jnp.asarray([d0, d0 + 10.0])))
    return eager, jits, grad, fd, batch, float(f(jnp.asarray(d0 + 10.0)))


def _check(f, rtol=1e-6):  # a trace may round differently (measured ≤ 8.3e-8)
    eager, jits, grad, fd, batch, other = _transforms(f)
    np.testing.assert_allclose(jits, eager, rtol=rtol)
    assert np.isfinite(grad) and grad != 0.0
    np.testing.assert_allclose(grad, fd, rtol=2e-2, atol=1e-6 * abs(eager))
    np.testing.assert_allclose(batch, [eager, other], rtol=rtol)


@pytest.fixture(scope="module")
def pref(env):
    return prefilter_envmap(env, levels=5)


@pytest.mark.parametrize("method", ["reference", "mc", "ideal", "filtered", "improved", "khr"])
def test_envmap_radiance_under_jit_grad_and_vmap(env, pref, method):
    """The exact methods integrate the `EnvMap`, the real-time ones read its prefiltered
    maps (closed over)."""
    n, v = _views()
    light = env if method in ("reference", "mc") else pref

    def f(d):
        return envmap_radiance(Film(d, 1.33, 1.5), ALPHA, n, v, light, method=method,
                               n_samples=64).mean()

    _check(f)


def test_a_map_prefiltered_inside_jit(env):
    """A real-time method given an `EnvMap` prefilters it on the host; inside `jit` (the
    map closed over, concrete) that host work runs concretely instead of raising
    TracerArrayConversionError, and gives the eager value."""
    n, v = _views()

    def f(d):
        return envmap_radiance(Film(d, 1.33, 1.5), ALPHA, n, v, env, method="filtered")

    np.testing.assert_allclose(jax.jit(f)(D0), f(D0), rtol=1e-6)


@pytest.mark.parametrize("method", ["reference", "ideal", "filtered_gt_moments",
                                    "filtered_gt_opd", "filtered", "improved", "khr"])
def test_patch_radiance_under_jit_grad_and_vmap(method):
    def f(d):
        return patch_radiance(Film(d, 1.33, 1.5), jnp.asarray([0.2, 0.9]), ALPHA,
                              method=method).mean()

    _check(f)


def test_prefiltering_a_traced_map_is_a_clear_error(env):
    """The map itself traced (a jit argument): prefiltering is host work, so the error
    says to prefilter outside `jit`."""
    with pytest.raises(ValueError, match="prefilter_envmap outside jit"):
        jax.jit(lambda e: prefilter_envmap(e).radiance)(env)
    n, v = _views()
    with pytest.raises(ValueError, match="prefilter_envmap outside jit"):
        jax.jit(lambda e: envmap_radiance(Film(D0, 1.33, 1.5), ALPHA, n, v, e,
                                          method="filtered"))(env)


@pytest.mark.parametrize("method", ["ideal", "filtered"])
def test_float32_film_under_a_float64_map(method, env):
    """Mixed precision at the boundary: a float32 film and float32 directions under a map
    prefiltered in float64 run (the K 29 sum's loop carry takes the film's and the table's
    common dtype; it raised a carry-type error in `ideal`) and give the float64 film's values
    to float32 rounding (measured ≤ 3e-8 of values ~0.02–0.5; asserted 1e-6). Under JAX's
    default ("standard") type promotion, which users have; the suite runs "strict" to catch
    unintended promotion, and mixing is intended here."""
    f32 = jnp.float32
    pref = prefilter_envmap(env, sources=0)
    n, v = _views()
    film32 = Film(f32(D0), f32(1.33), f32(1.5))
    with jax.numpy_dtype_promotion("standard"):
        got = envmap_radiance(film32, f32(ALPHA), jnp.asarray(n, f32), jnp.asarray(v, f32),
                              pref, method=method)
    want = envmap_radiance(Film(D0, 1.33, 1.5), ALPHA, n, v, pref, method=method)
    assert np.all(np.isfinite(np.asarray(got)))
    np.testing.assert_allclose(np.asarray(got, np.float64), want, rtol=1e-6, atol=1e-7)
