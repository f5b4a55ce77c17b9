"""Real materials through every exact path (SPEC §12): a `Stack` and a `Film` with index models
in `rgb_reflectance`, `patch_radiance`, `envmap_radiance`; the registry's refusals; the
real-time methods' band-centroid approximation of dispersion.

Independent references: `tmm` (Byrnes' coh_tmm) integrated over the observer's wavelengths
with the observer's own weights; the one-film Airy path (a `Film` is the one-layer stack);
finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import thinfilm_jax as tf
from thinfilm_jax.spectral.reflectance import band_centroids
from thinfilm_jax.spectral.spectra import get_observer

FILM = tf.Film(600.0, 1.3, 2.0, 0.5)  # Kneiphof et al. 2019, Figure 7
ONE_LAYER = tf.Stack([600.0], (1.3,), 2.0 + 0.5j)
COS = np.array([1.0, 0.7, 0.2])
VIEW = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
NORMAL = np.array([0.0, 0.0, 1.0])
WHITE = np.ones((8, 16, 3))  # a constant map: the IBL reference is the uniform patch (SPEC §9)


def test_film_is_the_one_layer_stack_on_every_exact_path():
    """SPEC §12: the same values to 1e-12 (measured ≤ 3e-17)."""
    pairs = [
        (tf.rgb_reflectance(ONE_LAYER, COS), tf.rgb_reflectance(FILM, COS)),
        (tf.patch_radiance(ONE_LAYER, np.array([0.2, 1.3]), 0.3),
         tf.patch_radiance(FILM, np.array([0.2, 1.3]), 0.3)),
        (tf.envmap_radiance(ONE_LAYER, 0.3, NORMAL, VIEW, WHITE),
         tf.envmap_radiance(FILM, 0.3, NORMAL, VIEW, WHITE)),
        (tf.envmap_radiance(ONE_LAYER, 0.3, NORMAL, VIEW, WHITE, method="mc", n_samples=256),
         tf.envmap_radiance(FILM, 0.3, NORMAL, VIEW, WHITE, method="mc", n_samples=256)),
    ]
    for a, b in pairs:
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def _tmm_bands(n_list, d_list, cos_theta, observer="stiles_burch_1959_10"):
    """Σ_k W_kj R(λ_k) with R from tmm.coh_tmm, unpolarised (the independent reference)."""
    obs = get_observer(observer)
    th = np.arccos(cos_theta)
    r = np.array([[0.5 * (tmm.coh_tmm("s", [n(lam) for n in n_list], d_list, t, lam)["R"]
                          + tmm.coh_tmm("p", [n(lam) for n in n_list], d_list, t, lam)["R"])
                   for lam in obs.wavelengths] for t in th])
    return r @ obs.weights


def test_dispersive_stack_bands_equal_tmm():
    """A nitride/oxide stack on dispersive silicon: rgb_reflectance(method="spectral") equals
    tmm integrated with the observer's weights to 1e-10 (measured 2e-16)."""
    si, sio2, si3n4 = (tf.refractive_index(m) for m in ("Si", "SiO2", "Si3N4"))
    stack = tf.Stack([80.0, 250.0], (si3n4, sio2), si)
    ours = tf.rgb_reflectance(stack, COS)

    def host(model):
        return lambda lam: complex(np.asarray(model(np.float64(lam))))

    ref = _tmm_bands([lambda lam: 1.0, host(si3n4), host(sio2), host(si)],
                     [np.inf, 80.0, 250.0, np.inf], COS)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10)


def test_constant_models_equal_numbers_on_every_path():
    """Index models that are constants give the numbers' values: exact paths through the
    stack code (1e-12), real-time paths through the band films (each band's film is the
    film itself: 1e-12). (`ideal` of a modelled film takes the exact bands at h = n:
    `test_ideal_tabulates_a_homogeneous_stack`.)"""
    modelled = tf.Film(600.0, tf.ConstantIndex(1.3), tf.ConstantIndex(2.0 + 0.5j))
    theta = np.array([0.3, 1.1])
    for method in ("reference", "filtered", "improved"):
        np.testing.assert_allclose(tf.patch_radiance(modelled, theta, 0.25, method=method),
                                   tf.patch_radiance(FILM, theta, 0.25, method=method),
                                   rtol=0, atol=1e-12, err_msg=method)
    np.testing.assert_allclose(tf.rgb_reflectance(modelled, COS, method="fourier"),
                               tf.rgb_reflectance(FILM, COS, method="fourier"), atol=1e-12)
    for method in ("reference", "filtered"):
        np.testing.assert_allclose(
            tf.envmap_radiance(modelled, 0.3, NORMAL, VIEW, WHITE, method=method),
            tf.envmap_radiance(FILM, 0.3, NORMAL, VIEW, WHITE, method=method),
            rtol=0, atol=1e-12, err_msg=method)


def test_band_centroid_films_see_each_band_at_its_centroid():
    """The real-time approximation of dispersion: band j is the constant-index film at λ̄_j,
    so its value equals a constant-index computation at that wavelength (1e-12), and differs
    from the exact dispersive bands by the approximation (a few percent on SiO₂/Si)."""
    si, sio2 = tf.refractive_index("Si"), tf.refractive_index("SiO2")
    film = tf.Film(300.0, sio2, si)
    lam = band_centroids()
    got = tf.rgb_reflectance(film, COS, method="fourier")
    for j, lj in enumerate(lam):
        nb = complex(np.asarray(si(lj)))
        fj = tf.Film(300.0, float(np.real(sio2(lj))), nb.real, nb.imag)
        np.testing.assert_allclose(got[:, j], tf.rgb_reflectance(fj, COS, method="fourier")[:, j],
                                   rtol=0, atol=1e-12)
    exact = tf.rgb_reflectance(film, COS)
    gap = float(np.max(np.abs(got - exact)))
    assert 1e-3 < gap < 0.05, gap  # measured 5.0e-3 (M = 2 truncation + the centroid indices)


def test_stack_thickness_batch_and_gradient():
    """A Stack's thicknesses carry a batch (each point its own stack, the indices shared);
    d/d thickness[i] of the exact patch equals central differences (rtol 1e-6)."""
    si = tf.refractive_index("Si")

    def patch(t):
        return tf.patch_radiance(tf.Stack(t, (1.46, 2.0), si), 0.4, 0.3)

    t = jnp.array([[120.0, 60.0], [300.0, 90.0]])
    batch = patch(t)
    for i in range(2):
        np.testing.assert_allclose(batch[i], patch(t[i]), rtol=0, atol=1e-14)
    g = jax.jacfwd(lambda x: patch(x).sum())(t[1])
    h = 1e-3
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        fd = (patch(t[1] + e).sum() - patch(t[1] - e).sum()) / (2 * h)
        np.testing.assert_allclose(g[i], fd, rtol=1e-6)
    assert np.all(np.isfinite(np.asarray(jax.grad(lambda x: patch(x).sum())(
        jnp.array([0.0, 0.0])))))  # d = 0 layers: finite gradients


def test_methods_refuse_what_they_cannot_model():
    """The registry names the method and what it lacks (SPEC §12)."""
    stack = tf.Stack([100.0, 50.0], (1.46, 2.0), 3.9)
    for method in ("filtered", "improved", "khr"):
        with pytest.raises(ValueError, match=rf"method='{method}' cannot model layer stacks"):
            tf.patch_radiance(stack, 0.3, 0.25, method=method)
    with pytest.raises(ValueError, match="method='fourier' cannot model layer stacks"):
        tf.rgb_reflectance(stack, 0.5, method="fourier")
    disp = tf.Film(300.0, tf.refractive_index("SiO2"), 3.9)
    with pytest.raises(ValueError, match="method='khr' cannot model dispersive"):
        tf.rgb_reflectance(disp, 0.5, method="khr")
    with pytest.raises(ValueError, match="method='filtered' cannot model layer stacks"):
        tf.envmap_radiance(stack, 0.3, NORMAL, VIEW, WHITE, method="filtered")


def test_bad_material_inputs(tmp_path):
    """Clear errors at the boundary: a table that does not cover the observer's wavelengths
    names its range; negative thickness; κ < 0; thickness without one entry per layer."""
    csv = tmp_path / "short.csv"
    csv.write_text("wavelength_nm,n,k\n400,1.5,0\n800,1.6,0\n")
    short = tf.refractive_index(str(csv))
    with pytest.raises(ValueError, match="400"):
        tf.rgb_reflectance(tf.Film(100.0, short, 2.0), 0.5)
    with pytest.raises(ValueError, match="thickness"):
        tf.patch_radiance(tf.Stack([-1.0, 5.0], (1.4, 1.5), 2.0), 0.3, 0.25)
    with pytest.raises(ValueError, match=r"eta\[1\]"):
        tf.rgb_reflectance(tf.Stack([1.0, 5.0], (1.4, 1.5 - 0.1j), 2.0), 0.5)
    with pytest.raises(ValueError, match="last axis"):
        tf.rgb_reflectance(tf.Stack([1.0, 5.0, 3.0], (1.4, 1.5), 2.0), 0.5)


def test_ideal_tabulates_a_homogeneous_stack():
    """`ideal` of a Stack: A(θ_o, α) times its exact bands at h = n; under a map the bands come
    from a table over cos θ built once per stack. Under a white map it is the uniform-light
    patch up to the split-sum albedo table (measured 2.2e-5 abs, as for a Film: 2.0e-5)."""
    si, sio2, si3n4 = (tf.refractive_index(m) for m in ("Si", "SiO2", "Si3N4"))
    stack = tf.Stack([250.0, 80.0], (sio2, si3n4), si)
    theta = np.array([0.0, 0.8, 1.3])
    view = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    patch = tf.patch_radiance(stack, theta, 0.25, method="ideal")
    albedo = tf.albedo(theta, 0.25)
    np.testing.assert_allclose(patch, albedo[:, None] * tf.rgb_reflectance(stack, np.cos(theta)),
                               rtol=1e-6)
    env = tf.envmap_radiance(stack, 0.25, NORMAL, view, np.ones((32, 64, 3)), method="ideal")
    np.testing.assert_allclose(env, patch, rtol=0, atol=5e-5)
    with pytest.raises(ValueError, match="homogeneous"):
        tf.envmap_radiance(tf.Stack([[250.0, 80.0], [200.0, 80.0]], (sio2, si3n4), si), 0.25,
                           NORMAL, VIEW, WHITE, method="ideal")
