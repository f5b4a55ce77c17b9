"""Every matrix contraction of the public float32 paths states precision=HIGHEST (GPUs default to TF32).

GPUs run float32 `dot_general` in TF32 by default; the library states the precision of each
contraction instead. The check traces on the CPU (`tests/_precision.py`), so it runs
everywhere; it also proves it can fail (`test_the_check_catches_a_default_contraction`).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _precision import assert_contractions_precise, count_contractions, imprecise_contractions

import thinfilm_jax as tf
from thinfilm_jax.spectral import lut as lut_mod
from thinfilm_jax.shading.patch import PATCH_METHODS

F32 = jnp.float32
FILM32 = tf.Film(600.0, 1.3, 2.0, 0.5).astype(F32)
C32 = jnp.asarray([0.3, 0.9], F32)


def test_the_check_catches_a_default_contraction():
    a, b = jnp.ones((3, 4), F32), jnp.ones((4, 2), F32)
    bad = imprecise_contractions(lambda x, y: x @ y, a, b)
    assert len(bad) == 1 and "precision=None" in bad[0]
    # inside sub-jaxprs too: jit, scan, cond, custom_jvp
    def nested(x, y):
        z = jax.jit(lambda u, v: jnp.einsum("ij,jk->ik", u, v))(x, y)
        z2, _ = jax.lax.scan(lambda c, _: (c, jnp.dot(x, y)), z, None, length=2)
        z3 = jax.lax.cond(True, lambda: jnp.tensordot(x, y, 1), lambda: z)
        return z + z2 + z3 + jax.nn.relu(jnp.matmul(x, y))

    assert len(imprecise_contractions(nested, a, b)) == 4
    with pytest.raises(AssertionError, match="HIGHEST"):
        assert_contractions_precise(nested, a, b)
    hi = jax.lax.Precision.HIGHEST
    assert_contractions_precise(lambda x, y: jnp.matmul(x, y, precision=hi), a, b)
    assert_contractions_precise(lambda x, y: jnp.matmul(x, y, precision=(hi, hi)), a, b)


def test_airy_and_bands():
    lam = jnp.asarray([450.0, 550.0], F32)
    assert_contractions_precise(lambda f, c: tf.airy_reflectance(f, c, lam), FILM32, C32)
    for method in ("spectral", "fourier"):
        for observer in tf.OBSERVERS:
            def fn(f, c, m=method, o=observer):
                return tf.rgb_reflectance(f, c, method=m, observer=o)

            assert count_contractions(fn, FILM32, C32) >= 1
            assert_contractions_precise(fn, FILM32, C32)
            # reverse mode: the transposed contractions keep the precision
            assert_contractions_precise(jax.grad(lambda f, c, fn=fn: fn(f, c).sum()), FILM32, C32)
    assert_contractions_precise(
        lambda f, c: tf.rgb_reflectance(f, c, method="fourier", shat="gaussian", terms=3),
        FILM32, C32)
    # concrete dielectric film (arithmetic="auto" picks the real path)
    diel = tf.Film(600.0, 1.3, 2.0).astype(F32)
    assert_contractions_precise(lambda c: tf.rgb_reflectance(diel, c, method="fourier"), C32)


def test_sensitivity_and_lut():
    x = jnp.asarray([0.0, 800.0, 2500.0], F32)
    s2 = jnp.asarray([0.0, 100.0, 4e4], F32)
    assert count_contractions(tf.sensitivity_ft, x) >= 1
    assert_contractions_precise(tf.sensitivity_ft, x)
    assert_contractions_precise(lambda a, b: tf.sensitivity_ft(a, sigma2=b), x, s2)
    lut = tf.build_shat_lut(dtype=F32)
    # the LUT read is elementwise (taps weighted on real parts, no contraction: one fused
    # loop, tests/realtime/test_kernel_fusion.py); should one come back, it must state its precision
    assert count_contractions(lut_mod.lookup, lut, x, jnp.sqrt(s2)) == 0
    assert_contractions_precise(lut_mod.lookup, lut, x, jnp.sqrt(s2))


@pytest.mark.parametrize("method", PATCH_METHODS)
def test_patch_radiance(method):
    theta, alpha = jnp.asarray([0.2, 1.1], F32), jnp.asarray(0.3, F32)
    shats = ("exact", "lut") if method.startswith("filtered") else ("exact",)
    for shat in shats:
        fn = lambda f, t, a, s=shat: tf.patch_radiance(  # noqa: E731
            f, t, a, method=method, options=tf.ModelOptions(shat=s, quadrature=(6, 6)))
        assert count_contractions(fn, FILM32, theta, alpha) >= 1
        assert_contractions_precise(fn, FILM32, theta, alpha)


def test_microfacet_and_mc():
    t, a = jnp.asarray([0.0, 0.7], F32), jnp.asarray([0.1, 0.5], F32)
    assert_contractions_precise(lambda t, a: tf.albedo(t, a, quadrature=(6, 6)), t, a)
    assert_contractions_precise(
        lambda k: tf.patch_radiance_mc(FILM32, F32(0.4), F32(0.3), k, n_samples=64),
        jax.random.PRNGKey(0))
    mean = jnp.asarray([0.1, 0.0, 0.9], F32)
    cov = jnp.eye(3, dtype=F32) * F32(0.01)
    from thinfilm_jax.optics.opd import project_light_moments

    # written as explicit products and sums (elementwise, fused into the kernels' loop)
    assert count_contractions(project_light_moments, mean, mean, cov) == 0
    assert_contractions_precise(project_light_moments, mean, mean, cov)


def test_fit_paths():
    """fit_film / fit_spectrum, optimistix's linear algebra included (fit.py sets
    jax.default_matmul_precision("highest") around the solve). Traced in float64: with x64
    enabled, optimistix's Levenberg–Marquardt mixes a float64 damping term into float32
    problems and fails to trace (a float32 fit is not supported); the precision parameter of
    a contraction does not depend on the dtype it is traced with."""
    theta = np.linspace(0.0, 1.2, 4)
    obs = jnp.full((4, 3), 0.1)
    kw = dict(alpha=0.3, initial=tf.Film(400.0, 1.3, 2.0, 0.5), method="filtered",
              options=tf.FitOptions(n_starts=4, n_solves=2, start_steps=2, max_steps=2,
                                    quadrature=(4, 4), start_quadrature=(4, 4)))
    fn = lambda o: tf.fit_film(o, theta, **kw).film.thickness  # noqa: E731
    assert count_contractions(fn, obs) >= 1
    assert_contractions_precise(fn, obs)
    lam = np.linspace(400.0, 700.0, 8)
    spec = lambda r: tf.fit_spectrum(  # noqa: E731
        r, lam, [1.0], initial=tf.Film(400.0, 1.46, 2.0),
        options=tf.FitOptions(n_starts=4, n_solves=2, start_steps=2, max_steps=2)).loss
    assert_contractions_precise(spec, jnp.full((1, 8), 0.1))
