"""The executable method registry (`core.methods`): a method is one object and one row.

A toy method registered at test time, a constant-albedo "grey" surface (R_j ≡ g in every
band), runs through both public entry points, and its values are checked against quantities
computed without it: under uniform light L_j = g · A(θ_o, α), A the directional albedo of
`brdf.microfacet.albedo` (K 12, the same quadrature); under a white map at normal view the
split sum gives g · A(0, α) again (the prefiltered albedo table is exact at its nodes, as
`ibl`'s docstring measures for `ideal`), and 0 where the point faces away. The row is removed
afterwards and the method is then refused.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.core import methods
from thinfilm_jax.render import scene, study_scenes  # noqa: F401  before any registration:
# a method list frozen at import would miss the toy method, and the tests would see that
from thinfilm_jax.shading.methods import ShadingMethod
from thinfilm_jax.shading.prefilter import lookup_albedo, lookup_radiance
from thinfilm_jax.spectral.spectra import get_observer

GREY = 0.37
QUAD = (16, 16)


class Grey(ShadingMethod):
    """R_j ≡ GREY: L_j = GREY · A(θ_o, α) under uniform light, GREY · A · P(ω_r, α) under a
    map (the split sum with a constant Fresnel term)."""

    name = "grey"
    envmap_kind = "realtime"

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        n = get_observer(observer).n_bands
        return GREY * jnp.sum(quad.weight) * jnp.ones(n, quad.weight.dtype)

    def rgb(self, film, cos_theta, observer, terms, shat, arithmetic, layer):
        shape = jnp.broadcast_shapes(film.shape, jnp.shape(cos_theta))
        return jnp.full(shape + (get_observer(observer).n_bands,), GREY)

    def map_light(self, film, alpha, normal, view, pref, cfg):
        cos_o = jnp.sum(normal * view, axis=-1)
        up = cos_o > 0
        co = jnp.where(up, cos_o, 1.0)
        sqa = jnp.sqrt(alpha)
        rad = lookup_radiance(pref, 2 * co[..., None] * normal - view, sqa)
        a = lookup_albedo(pref, co, sqa)
        return jnp.where(up[..., None], GREY * a[..., None] * rad, 0.0)


@pytest.fixture
def grey():
    methods.register(methods.Method("grey", ("rgb", "patch", "envmap"), False, "", False,
                                    "a constant albedo (test)", impl=Grey()))
    try:
        yield
    finally:
        methods.unregister("grey")


def test_grey_method_through_the_entry_points(grey):
    assert "grey" in methods.names("patch") and "grey" in methods.names("envmap", exact=False)
    assert "grey" not in methods.names("envmap", exact=True) and "grey" in methods.names("rgb")
    # the public constants read the registry at each use (not frozen at import)
    assert all("grey" in c for c in (tf.spectral.RGB_METHODS, tf.PATCH_METHODS,
                                     tf.ENVMAP_METHODS))
    film = tf.Film(np.array([0.0, 350.0]), 1.33, 1.5)
    # rgb_reflectance calls the row's object too (R_j ≡ g at every cosine)
    np.testing.assert_array_equal(tf.rgb_reflectance(film,
                                                     np.array([[1.0], [0.3]]), method="grey"),
                                  np.full((2, 2, 3), GREY))
    theta = np.array([0.2, 1.1])
    got = tf.patch_radiance(film, theta, 0.3, method="grey",
                            options=tf.ModelOptions(quadrature=QUAD))
    want = GREY * np.asarray(tf.albedo(theta, 0.3, quadrature=QUAD))
    np.testing.assert_allclose(got, np.broadcast_to(want[:, None], got.shape), rtol=1e-12)

    pref = tf.prefilter_envmap(np.ones((8, 16, 3)), levels=3, resolution=(8, 16),
                               albedo_shape=(8, 5), sources=0)
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    env = tf.envmap_radiance(film, 0.25, n, np.array([0.0, 0.0, 1.0]), pref, method="grey")
    normal_view = GREY * float(tf.albedo(0.0, 0.25, quadrature=(48, 48)))
    np.testing.assert_allclose(env[0], normal_view, atol=1e-6)
    assert np.all(np.asarray(env[1]) == 0.0)
    # what the row says it lacks is refused by the registry, naming the method
    with pytest.raises(ValueError, match="method='grey' cannot model dispersive"):
        tf.patch_radiance(tf.Film(300.0, tf.ConstantIndex(1.45), 1.5), 0.2, 0.3, method="grey")


def test_unregistered_method_is_refused(grey):
    methods.unregister("grey")
    try:
        assert "grey" not in methods.names("patch")
        with pytest.raises(ValueError, match="method"):
            tf.patch_radiance(tf.Film(300.0, 1.33, 1.5), 0.2, 0.3, method="grey")
    finally:
        methods.register(methods.Method("grey", ("patch",), False, "", False, "again",
                                        impl=Grey()))  # the fixture removes it


def test_builtin_rows_and_material_path():
    """Every built-in shading row resolves to its object; the built-ins cannot be removed;
    `material_path` is the one decision between the one-film, stack and per-band paths."""
    for name in methods.names("patch") + methods.names("envmap"):
        assert methods.implementation(name).name == name
    with pytest.raises(ValueError, match="built in"):
        methods.unregister("reference")
    with pytest.raises(ValueError, match="already registered"):
        methods.register(methods.METHODS["reference"])
    disp = tf.Film(300.0, tf.ConstantIndex(1.45), 1.5)
    stack = tf.Stack([100.0, 50.0], (1.46, 2.0), 3.9)
    assert methods.material_path(tf.Film(300.0, 1.45, 1.5), "khr") == "film"
    assert [methods.material_path(disp, m) for m in ("reference", "ideal", "filtered")] == \
        ["stack", "stack", "bands"]
    assert methods.material_path(stack, "ideal") == "stack"
    with pytest.raises(ValueError, match="method='filtered' cannot model layer stacks"):
        methods.material_path(stack, "filtered")


def test_material_kinds_by_type():
    """`patch_radiance` and `envmap_radiance` take every material kind, by type: a classic-lobe
    `Material` with a film Fresnel term and a GGX lobe is the film's reference (two separate
    quadratures of one integral), a Lambert `Material` under a white map is its albedo 0.6,
    and a Lambert `CarPaint` is its coat's Fresnel plus the lobe albedo (closed forms)."""
    from thinfilm_jax.brdf import carpaint as C

    film = tf.Film(600.0, 1.3, 2.0, 0.5)
    theta = np.array([0.2, 1.0])
    mat = tf.Material(tf.ggx_lobe(0.3), tf.film_fresnel(film), tf.no_diffuse())
    np.testing.assert_allclose(tf.patch_radiance(mat, theta), tf.patch_radiance(film, theta, 0.3),
                               atol=1e-12)
    lam = tf.Material(tf.no_specular(), tf.no_fresnel(), tf.lambert_diffuse(0.6))
    n, v = np.array([0.0, 0.0, 1.0]), np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    np.testing.assert_allclose(tf.envmap_radiance(lam, None, n, v, np.ones((8, 16, 3))), 0.6,
                               atol=1e-12)
    paint = C.car_paint(0.8, [0.0], [0.5], [0.0], C.plain_colour([1.0, 1.0, 1.0]), 1.5)
    want = C.coat_reflectance(paint, np.cos(0.5)) + C.lobe_albedo(paint, np.cos(0.5))[-1]
    np.testing.assert_allclose(tf.patch_radiance(paint, 0.5), want, atol=1e-13)
    with pytest.raises(ValueError, match="alpha must be None"):
        tf.patch_radiance(mat, 0.2, 0.3)
    with pytest.raises(ValueError, match="method"):
        tf.envmap_radiance(lam, None, n, v, np.ones((8, 16, 3)), method="ideal")
    with pytest.raises(TypeError, match="Film, Stack, Material or CarPaint"):
        tf.patch_radiance("film", 0.2, 0.3)
    with pytest.raises(TypeError, match="needs alpha"):
        tf.envmap_radiance(film, None, n, v, np.ones((8, 16, 3)))


def test_grey_method_through_a_fit_and_a_render(grey, tmp_path):
    """The registered toy method needs no change elsewhere: the fits and the renderer read the
    registry. Its uniform-light radiance g·A(θ_o, α) depends on α alone (A decreases with α
    through the masking term), so `fit_film` with α free recovers the α of observations made
    by `patch_radiance` (noise-free: to 1e-6); under a white map the sphere `render_scene`
    draws holds g·A(θ_o, α) ≤ g on every pixel, ≈ g·A(0, α) at the pixel facing the camera
    (the albedo is flat in θ_o there: A(θ, α) − A(0, α) = O(θ²))."""
    film = tf.Film(300.0, 1.33, 1.5)
    theta = np.array([0.1, 0.7, 1.2])
    opts = tf.ModelOptions(quadrature=QUAD)
    obs = np.asarray(tf.patch_radiance(film, theta, 0.42, method="grey", options=opts))
    fit = tf.fit_film(obs, theta, initial=film, free=("alpha",), alpha=0.2, method="grey",
                      options=tf.FitOptions(quadrature=QUAD))
    assert abs(float(fit.alpha) - 0.42) < 1e-6, fit.alpha

    cfg = scene.SceneConfig(material=film, alpha=0.25, envmap=np.ones((16, 32, 3)), resolution=24,
                      methods=("grey",), exposure=1.0)
    scene.render_scene(cfg, out_dir=tmp_path, progress=False)
    with np.load(tmp_path / "render.npz") as z:
        img, mask = z["grey"], z["mask"]
    vals = img[mask]
    assert np.all(np.isfinite(vals)) and np.all((vals >= 0) & (vals <= GREY + 1e-9))
    centre = img[img.shape[0] // 2, img.shape[1] // 2]
    normal_view = GREY * float(tf.albedo(0.0, 0.25, quadrature=(48, 48)))
    np.testing.assert_allclose(centre, normal_view, rtol=2e-2)


def test_rows_resolve_within_the_package_they_were_imported_with():
    """A copy of the package imported under another name (how `benchmarks.kernel_bench` times
    an older checkout beside this one) resolves its rows to its own modules: the map path of
    one version must never call another version's method objects (their configuration tuples
    differ: it failed with "not enough values to unpack")."""
    import importlib
    import importlib.util
    import sys
    from pathlib import Path

    alias = "thinfilm_jax_registry_alias"
    root = Path(tf.__file__).parent
    spec = importlib.util.spec_from_file_location(alias, root / "__init__.py",
                                                  submodule_search_locations=[str(root)])
    sys.modules[alias] = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(sys.modules[alias])
        copy = importlib.import_module(f"{alias}.core.methods")
        for name in ("ideal", "improved"):
            assert type(copy.implementation(name)).__module__.startswith(f"{alias}."), name
            assert type(methods.implementation(name)).__module__.startswith("thinfilm_jax."), name
    finally:
        for key in [k for k in sys.modules if k == alias or k.startswith(f"{alias}.")]:
            del sys.modules[key]
