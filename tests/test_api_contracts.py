"""Contracts of the public API beyond values: gradients that match finite differences on the
patch and K 29 paths, and no implicit rank promotion with matching input shapes."""

import jax
import numpy as np
import pytest
from jax.test_util import check_grads

import thinfilm_jax as tf
from thinfilm_jax.realtime import kernels
from thinfilm_jax.spectral.lut import build_shat_lut

FILM = tf.Film(600.0, 1.3, 2.0, 0.5)  # the Figure 7 film; interior point of every path
THETA_O, ALPHA = 0.6, 0.3
QUAD = (8, 8)  # small quadrature: gradients of the quadrature sum, not of the converged value


@pytest.mark.parametrize("method", ["reference", "filtered_gt_moments"])
def test_check_grads_patch(method):
    """d patch_radiance / d(film, θ_o, α), forward and reverse, against finite differences
    (`filtered_gt_moments` is A · K 29 with the exact filtered Ŝ, through the lobe moments)."""
    def fn(film, theta_o, alpha):
        return tf.patch_radiance(film, theta_o, alpha, method=method,
                                 options=tf.ModelOptions(quadrature=QUAD))

    # jit: one compile for the finite-difference evaluations; validation skips tracers
    check_grads(jax.jit(fn), (FILM, THETA_O, ALPHA), order=1, modes=["fwd", "rev"], eps=1e-5,
                atol=1e-6, rtol=1e-5)


def test_check_grads_k29_lut():
    """K 29 (`kernels.filtered_kernel`) with the Ŝ LUT (bicubic, C¹) w.r.t. the film and the
    light-lobe moments (the exact-Ŝ K 29 is covered through `filtered_gt_moments` above)."""
    _, mean, cov = kernels.lobe_moments(THETA_O, ALPHA, quadrature=(16, 16))
    wo = np.array([np.sin(THETA_O), 0.0, np.cos(THETA_O)])
    lut = build_shat_lut()

    def fn(film, mean, cov):
        return kernels.filtered_kernel(film, wo, mean, cov, shat="lut", lut=lut)

    check_grads(jax.jit(fn), (FILM, mean, cov), order=1, modes=["fwd", "rev"], eps=1e-5,
                atol=1e-6, rtol=1e-5)


N = 4
FILMS = tf.Film(np.linspace(0.0, 900.0, N), np.full(N, 1.3), np.full(N, 2.0), np.full(N, 0.5))
COS = np.linspace(0.2, 1.0, N)
CALLS = {
    "airy_reflectance": lambda: tf.airy_reflectance(FILMS, COS, np.full(N, 550.0)),
    "rgb_reflectance[spectral]": lambda: tf.rgb_reflectance(FILMS, COS),
    "rgb_reflectance[fourier]": lambda: tf.rgb_reflectance(FILMS, COS, method="fourier"),
    "rgb_reflectance[fourier,gaussian]": lambda: tf.rgb_reflectance(FILMS, COS, method="fourier",
                                                                    shat="gaussian"),
    "patch_radiance[reference]": lambda: tf.patch_radiance(FILMS, np.full(N, 0.5),
                                                           np.full(N, 0.2),
                                                               options=tf.ModelOptions(quadrature=QUAD)),
    **{f"patch_radiance[{m},{s}]": (lambda m=m, s=s: tf.patch_radiance(
        FILMS, np.full(N, 0.5), np.full(N, 0.2), method=m,
            options=tf.ModelOptions(shat=s, quadrature=QUAD)))
       for m, s in (("ideal", "exact"), ("filtered", "exact"), ("filtered_gt_moments", "lut"),
                    ("filtered_gt_moments", "gaussian"), ("filtered_gt_opd", "exact"),
                    ("improved", "lut"))},
}


@pytest.mark.parametrize("call", CALLS.values(), ids=CALLS.keys())
def test_no_rank_promotion(call):
    """With inputs of matching shapes, no implicit rank promotion happens anywhere inside."""
    with jax.numpy_rank_promotion("raise"):
        out = call()
    assert np.all(np.isfinite(np.asarray(out)))
