"""Differentiability, float32, and JAX transformations of the spectral core (SPEC §8).

* values and jax.grad w.r.t. every Film field and cos θ are finite at the singular points
  θ = 0, θ = 90° (cos θ = 0), d = 0, κ = 0, η_film = η_outer, in float64 and float32;
* jax.test_util.check_grads (finite differences, fwd and rev) at interior points;
* float32 results against float64 within measured, named tolerances;
* jit, vmap, grad and broadcasting against a Python loop of scalar calls.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import thinfilm_jax as tf

# float32 vs float64 (max abs difference over 4000 random films), measured on the samples of
# test_float32_matches_float64, tolerance ≈ 3× the measurement:
# d ≤ 2 µm:  R(λ) 1.3e-5 (the phase 4πdq₂/λ reaches ~200 rad, float32 keeps it to ~1e-5 rad),
#            bands (spectral; fourier M = 8) 6.7e-6;
# d ≤ 20 µm: R(λ) 1.0e-4, bands 3.5e-5.
F32_ATOL_R = 4e-5
F32_ATOL_BANDS = 2e-5
F32_ATOL_R_THICK = 3e-4
F32_ATOL_BANDS_THICK = 1e-4

# Singular points, one per column: (d, η_film, η_base, κ, η_outer, cos θ)
EDGE = np.array([
    (500.0, 1.4, 1.8, 0.3, 1.0, 1.0),  # θ = 0
    (500.0, 1.4, 1.8, 0.3, 1.0, 0.0),  # θ = 90°
    (500.0, 1.4, 1.8, 0.0, 1.0, 0.0),  # θ = 90°, κ = 0
    (0.0, 1.4, 1.8, 0.3, 1.0, 0.6),  # d = 0
    (0.0, 1.4, 1.8, 0.0, 1.0, 1.0),  # d = 0, κ = 0, θ = 0
    (500.0, 1.4, 1.8, 0.0, 1.0, 0.6),  # κ = 0
    (500.0, 1.0, 1.8, 0.3, 1.0, 0.6),  # η_film = η_outer
    (500.0, 1.0, 1.8, 0.0, 1.0, 0.0),  # η_film = η_outer, θ = 90°
    (500.0, 1.0, 1.8, 0.0, 1.0, 1.0),  # η_film = η_outer, θ = 0
    (0.0, 1.0, 1.8, 0.0, 1.0, 0.0),  # all at once
    (500.0, 1.33, 1.8, 0.0, 1.33, 0.0),  # water outside, η_film = η_outer, grazing
    (500.0, 1.4, 1.4, 0.0, 1.0, 0.0),  # η_base = η_film, grazing
    (300.0, 1.2, 1.5, 0.0, 1.5, 0.2),  # TIR at 1|2 (general path only)
    (300.0, 1.2, 2.0, 5.0, 1.5, 0.2),  # TIR at 1|2 on a metal
]).T
DIELECTRIC_OK = (EDGE[3] == 0) & (EDGE[1] >= EDGE[4]) & (EDGE[2] >= EDGE[4])


def _edge(dtype, mask=slice(None)):
    film = tf.Film(*(jnp.asarray(EDGE[i][mask]) for i in range(5))).astype(dtype)
    return film, jnp.asarray(EDGE[5][mask], dtype)


def _public_fns(dtype, arithmetic):
    lam = jnp.asarray(550.0, dtype)
    fns = {
        "airy": lambda f, c: tf.airy_reflectance(f, c, lam, arithmetic=arithmetic),
        "spectral": lambda f, c: tf.rgb_reflectance(f, c, arithmetic=arithmetic),
        "fourier2": lambda f, c: tf.rgb_reflectance(f, c, method="fourier", terms=2,
                                                 arithmetic=arithmetic),
        "fourier8": lambda f, c: tf.rgb_reflectance(f, c, method="fourier", terms=8,
                                                 arithmetic=arithmetic),
    }
    if arithmetic == "real":  # the real path is also exercised in test_fresnel_airy.py
        del fns["spectral"], fns["fourier8"]
    return fns


# (arithmetic, dtype); the dielectric path in float64 is covered (finite, equal to the general path,
# θ = 0 and 90° included) by test_fresnel_airy.py::test_dielectric_path_equals_general_path...
SINGULAR_CASES = [("complex", jnp.float64), ("complex", jnp.float32),
                  ("real", jnp.float32)]


@pytest.mark.parametrize("arithmetic, dtype", SINGULAR_CASES,
                         ids=["complex-f64", "complex-f32", "real-f32"])
def test_values_and_gradients_finite_at_singular_points(arithmetic, dtype):
    mask = slice(None) if arithmetic == "complex" else DIELECTRIC_OK
    film, c = _edge(dtype, mask)
    fns = _public_fns(dtype, arithmetic)

    @jax.jit  # one compilation for all functions and all singular points
    def values_and_grads(f, cc):
        out = {}
        for name, fn in fns.items():
            # per-case values and per-case gradients (each output depends on its own column)
            val, vjp = jax.vjp(fn, f, cc)
            out[name] = (val, vjp(jnp.ones_like(val)))
        return out

    for name, (val, (g_film, g_cos)) in values_and_grads(film, c).items():
        val = np.asarray(val)
        assert val.dtype == dtype, name
        assert np.all(np.isfinite(val)), name
        assert np.all((val >= -1e-6) & (val <= 1 + 1e-5)), name
        for field, g in zip((*tf.Film._fields, "cos_theta"), (*g_film, g_cos)):
            g = np.asarray(g)
            assert g.dtype == dtype and g.shape == c.shape, (name, field)
            assert np.all(np.isfinite(g)), (name, field, g)
    # the public (validating, un-jitted) entry point accepts the singular points too
    assert np.all(np.isfinite(np.asarray(fns["airy"](film, c))))


def _interior(rng, n):
    film = tf.Film(rng.uniform(50.0, 1500.0, n), rng.uniform(1.2, 2.5, n), rng.uniform(1.3, 3.0, n),
                   rng.uniform(0.1, 5.0, n), np.where(np.arange(n) % 2 == 0, 1.0, 1.1))
    return film, rng.uniform(0.2, 0.95, n)


CHECK_GRADS_CASES = [  # (arithmetic, function): each case compiles f, its JVP and its VJP
    ("complex", "airy"), ("complex", "fourier2"), ("real", "airy"),
]


@pytest.mark.parametrize("arithmetic, fname", CHECK_GRADS_CASES)
def test_check_grads_interior(arithmetic, fname):
    rng = np.random.default_rng(71)
    n = 4
    kappa = np.zeros(n) if arithmetic == "real" else rng.uniform(0.1, 5.0, n)
    film = tf.Film(rng.uniform(50.0, 1500.0, n), rng.uniform(1.2, 2.5, n),
                   rng.uniform(1.3, 3.0, n), kappa, np.array([1.0, 1.1, 1.0, 1.33]))
    c = rng.uniform(0.2, 0.95, n)
    lam = np.array([420.0, 510.0, 600.0, 700.0])
    fn = {
        "airy": lambda f, cc: tf.airy_reflectance(f, cc, lam, arithmetic=arithmetic),
        "spectral": lambda f, cc: tf.rgb_reflectance(f, cc, arithmetic=arithmetic),
        "fourier2": lambda f, cc: tf.rgb_reflectance(f, cc, method="fourier", terms=2,
                                                   arithmetic=arithmetic),
    }[fname]
    # jit: compiled once for the finite-difference evaluations, and the domain checks (which
    # would reject the ±eps steps at η_outer = 1) are skipped on tracers
    check_grads(jax.jit(fn), (film, c), order=1, modes=["fwd", "rev"], eps=1e-5, atol=1e-6,
                rtol=1e-5)


@pytest.mark.parametrize("dmax, atol_r, atol_bands", [(2000.0, F32_ATOL_R, F32_ATOL_BANDS),
                                                      (20000.0, F32_ATOL_R_THICK,
                                                       F32_ATOL_BANDS_THICK)])
def test_float32_matches_float64(dmax, atol_r, atol_bands):
    rng = np.random.default_rng(72)
    n = 4000
    film = tf.Film(rng.uniform(0.0, dmax, n), rng.uniform(1.0, 3.0, n), rng.uniform(1.0, 4.0, n),
                   np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.0, 10.0, n)),
                   np.where(rng.random(n) < 0.3, 1.33, 1.0))
    c, lam = rng.uniform(0.0, 1.0, n), rng.uniform(360.0, 830.0, n)
    f32, c32 = film.astype(jnp.float32), jnp.asarray(c, jnp.float32)
    r64 = np.asarray(tf.airy_reflectance(film, c, lam))
    r32 = tf.airy_reflectance(f32, c32, jnp.asarray(lam, jnp.float32))
    assert r32.dtype == jnp.float32
    errs = {"R": np.abs(np.asarray(r32) - r64).max()}
    for method, m in (("spectral", 2), ("fourier", 8)):  # fourier M = 2: singular-point test
        b64 = np.asarray(tf.rgb_reflectance(film, c, method=method, terms=m))
        b32 = tf.rgb_reflectance(f32, c32, method=method, terms=m)
        assert b32.dtype == jnp.float32
        errs[f"{method}{m}"] = np.abs(np.asarray(b32) - b64).max()
    print(f"\nfloat32 vs float64, d ≤ {dmax:g} nm:",
          ", ".join(f"{k} {v:.2e}" for k, v in errs.items()))
    assert errs.pop("R") <= atol_r
    assert max(errs.values()) <= atol_bands


# ------------------------------------------------------------------------------ transforms


def test_jit_vmap_grad_compose():
    rng = np.random.default_rng(73)
    film, c = _interior(rng, 5)
    fourier2 = lambda f, cc: tf.rgb_reflectance(f, cc, method="fourier", terms=2)  # noqa: E731
    broadcast = np.asarray(fourier2(film, c))
    # vmap over a batch of Films (each a scalar film inside), under jit (validation is skipped
    # on tracers, base "auto" → general)
    np.testing.assert_allclose(jax.jit(jax.vmap(fourier2))(film, c), broadcast, rtol=0,
                               atol=1e-14)
    # per-example gradients: jit(vmap(grad)) against a Python loop of scalar jax.grad calls
    airy = lambda f, cc: tf.airy_reflectance(f, cc, 550.0)  # noqa: E731
    g = jax.jit(jax.vmap(jax.grad(airy, argnums=(0, 1))))(film, c)
    for i in range(len(c)):
        fi = tf.Film(*(float(np.asarray(x)[i]) for x in film))
        gi = jax.grad(airy, argnums=(0, 1))(fi, float(c[i]))
        for k, name in enumerate((*tf.Film._fields, "cos_theta")):
            want = gi[1] if k == 5 else gi[0][k]
            got = g[1][i] if k == 5 else g[0][k][i]
            assert float(got) == pytest.approx(float(want), rel=1e-12, abs=1e-14), name


SHAPE_CASES = [  # (thickness shape, cos θ shape, expected output batch shape)
    ((6,), (), (6,)),
    ((2, 3), (2, 3), (2, 3)),
    ((2, 3, 1), (4,), (2, 3, 4)),
]


@pytest.mark.parametrize("d_shape, c_shape, out_shape", SHAPE_CASES)
def test_broadcasting_matches_scalar_loop(d_shape, c_shape, out_shape):
    rng = np.random.default_rng(74)
    d = rng.uniform(0.0, 2000.0, d_shape)
    c = rng.uniform(0.0, 1.0, c_shape)
    film = tf.Film(d, 1.45, 2.0, 0.4)
    r = np.asarray(tf.airy_reflectance(film, c, 550.0))
    bands = np.asarray(tf.rgb_reflectance(film, c, method="fourier", terms=2))
    assert r.shape == out_shape and bands.shape == (*out_shape, 3)
    db, cb = np.broadcast_arrays(d, c)
    for idx in np.ndindex(out_shape):
        f1 = tf.Film(float(db[idx]), 1.45, 2.0, 0.4)
        c1 = float(cb[idx])
        assert r[idx] == pytest.approx(float(tf.airy_reflectance(f1, c1, 550.0)), abs=1e-15)
        np.testing.assert_allclose(bands[idx], tf.rgb_reflectance(f1, c1, method="fourier",
                                                                  terms=2), rtol=0, atol=1e-15)


def test_every_field_may_be_an_array():
    """Film fields broadcast against each other and against cos θ and λ."""
    film = tf.Film(np.array([100.0, 400.0]), np.array([[1.3], [1.6], [2.0]]), 2.0,
                   np.array([0.0, 0.5]), 1.0)
    assert film.shape == (3, 2)
    r = np.asarray(tf.airy_reflectance(film, np.array([1.0, 0.5])[:, None, None], 550.0))
    assert r.shape == (2, 3, 2)
    assert r[1, 2, 0] == pytest.approx(
        float(tf.airy_reflectance(tf.Film(100.0, 2.0, 2.0, 0.0), 0.5, 550.0)), abs=1e-15)
