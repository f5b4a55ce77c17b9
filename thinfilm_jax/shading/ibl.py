r"""Reflected radiance of a film under an environment map, every method of SPEC §9.

$$ L_j(n, \omega_o) = \sum_k \int \tilde\rho(\omega_i, \omega_o)\langle n,\omega_i\rangle
   R_{jk}(\langle h,\omega_i\rangle)\, c_k(\omega_i)\, d\omega_i \qquad (K\ 7, 11;\ SPEC\ §9) $$

| method      | how                                                                          |
|-------------|------------------------------------------------------------------------------|
| `reference` | texel-space quadrature of the piecewise-constant map (`ibl_reference`): one node per texel with the midpoint rule's error term, s×s Gauss–Legendre nodes in (cos θ, φ) in the texels where the lobe is narrow or cut by the horizon, R_jk(c) exact spectral on a fine c-grid, interpolated |
| `mc`        | GGX visible-normal sampling (Heitz 2018), weight G₂/G₁, exact spectral R_jk per sample, nearest-texel radiance; fixed key and count |
| `ideal`     | A(θ_o, α) · Σ_k R_jk(cos θ_o) P_k(ω_r, α): BB17 under the split sum (`kernels.ideal_kernel`, Ŝ from the LUT at σ = 0 by default) |
| `filtered`  | A(θ_o, α) · Σ_k R̄_jk P_k(ω_r, α), R̄ = K 29 with the prefiltered moments μ_ω, Σ_ω (`kernels.filtered_kernel`; Ŝ read with 8 taps, linear in \|μ\| and cubic in σ: `MAP_SHAT_READ`) |
| `khr`       | A(θ_o, α) · F_iridescence(cos θ_o) ⊙ P(ω_r, α): glTF `KHR_materials_iridescence` (SPEC §10, `spectral.khr`) at h = n as `ideal`, per channel: its linear Rec. 709 RGB times the map's linear RGB, the vec3 Fresnel × vec3 prefiltered specular product glTF engines compute (the Khronos sample renderer's `pbr.frag` reads F_iridescence at ⟨n, v⟩ and multiplies the prefiltered radiance by it with no split-sum scale: its value is this one over A); suns split from the map add F_iridescence(cos θ_o) ⊙ Σ_s m_s L_s (the same Fresnel for every light, as the renderer's punctual lights; `sources.source_light`); the RGB sum is then taken to the observer's bands by the library's one conversion (`colorimetry.rec709_to_bands`, exact and invertible: `bands_to_rec709` gives the engine's RGB back), so every method returns the same space; `cross_band`, `options` and the map's Ŝ table do not apply |
| `colour_table` | A(θ_o, α) · Σ_k C_jk(ω_r, θ_o) P_k(ω_r, α): Kneiphof & Klein 2022, the colour R_jk prefiltered with the map and the GGX lobe into a table over (ω_r, θ_o), decomposed into a map of ω_r times a function of θ_o (`colour_table`, SPEC §11); `envmap` is the `ColourTable` that `prefilter_colour` built for this film and α (checked) |
| `improved`  | A(θ_o, α) · (1/K) Σ_b Σ_k R_jk(bin b) P_k,b: K 29 per equal-probability bin b of cos θ₁, each bin times read b of K prefiltered reads fitted to the lobe's shape (`improved.lookup_reads`), at the bin's cosine moved by the read's light-weighted mean direction (`ibl.improved_envmap`, docs/improved.md) |

R_jk are the cross bands S_j B_k of the Mallett–Yuksel uplift (`uplift`); the per-channel
("diagonal") approximation L_j ≈ R_j P_j is the option `cross_band=False`.

Reference accuracy and cost: `thinfilm_jax.shading.ibl_reference` (its docstring); the exhaustive
rule (every texel with s × s nodes) stays reachable there as `exhaustive=True`, and
tests/shading/test_ibl_reference.py compares the two. The convergence (the SPEC's 1e-3 of the band
maximum) is tested in tests/shading/test_ibl.py; where a grazing view squeezes the lobe below
two node spacings the reference is not converged and warns (`ibl_reference`, "Grazing views").

Example (a white map is the uniform light of `patch_radiance`, since Σ_k R_jk = R_j: at normal
view the tabulated A and the level √α = 0.5 are exact nodes, measured agreement 3e-9; a point
that faces away from the eye gives 0):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, patch_radiance, prefilter_envmap
    >>> from thinfilm_jax.shading.ibl import envmap_radiance
    >>> pref = prefilter_envmap(np.ones((8, 16, 3)), levels=3, resolution=(8, 16),
    ...                         albedo_shape=(8, 5))
    >>> film, n = Film(600.0, 1.3, 2.0, 0.5), np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    >>> L = envmap_radiance(film, 0.25, n, np.array([0.0, 0.0, 1.0]), pref, method="ideal")
    >>> L.shape
    (2, 3)
    >>> bool(np.allclose(L[0], patch_radiance(film, 0.0, 0.25, method="ideal"), atol=1e-6))
    True
    >>> L[1].tolist()
    [0.0, 0.0, 0.0]
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.material import batch_shape, expand_batch, is_dispersive, needs_stack
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import names as method_names
from ..core.methods import require
from ..core.stack import Stack
from ..spectral.reflectance import band_centroids, band_film
from ..optics.airy import choose_arithmetic
from .colour_table import ColourTable, check_colour_table, colour_table_radiance
from .envmap import EnvMap, load_envmap
from ..core.film import Film
from .ibl_integrand import _interp, _lobe_cos_weight, _r_table, texel_nodes  # noqa: F401 (re-exported)
from .ibl_reference import auto_subdivisions, exact_radiance  # noqa: F401 (re-exported)
from ..optics.fresnel import safe_sqrt
from ..realtime.improved import BinTable, bin_bands, bin_table, lookup_bins, scan_bins
from ..realtime.kernels import filtered_kernel, ideal_kernel
from ..spectral.khr import khr_bands, khr_to_bands
from ..spectral.lut import ShatLUT, build_shat_lut
from ..realtime.options import ModelOptions, check_options
from .prefilter import (PrefilteredEnvMap, bin_radiance_parts, lookup_albedo, lookup_prefiltered,
                        lookup_radiance, moments_to_mean_cov, prefilter_envmap)
from .sources import source_light, source_radiance
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from ..spectral.uplift import cross_band_name

METHODS = method_names("envmap")  # the registry's order (core/methods.py)
REALTIME_OPTIONS = ModelOptions(shat="lut")  # the real-time default: Ŝ from the map's table
HIGHEST = jax.lax.Precision.HIGHEST
DEFAULT_SOURCES = 4  # suns split from a map that `improved` prefilters itself
# `filtered`'s Ŝ read under a map: linear in |μ|, Catmull–Rom in σ (8 taps, within 4.7e-5 of
# the exact cross bands against the bicubic read's 2.8e-5, `lut.lookup`), 1.2× faster a point
# at frame size (docs/studies/performance.md, "Real-time IBL at frame size")
MAP_SHAT_READ = "linear_mu"


# ----------------------------------------------------------------------------- public
def envmap_radiance(film: Film, alpha, normal, view, envmap, *, method: str = "reference",
                    observer: str = DEFAULT_OBSERVER, options: ModelOptions = REALTIME_OPTIONS,
                    cross_band: bool = True, subdivisions: int | None = None,
                    n_cos: int = 1024, n_samples: int = 4096, key=None,
                    batch_size: int | None = None, max_height: int | None = 256,
                    sources: int | None = None) -> Array:
    """Band radiances L_j (..., J) of a film under an environment map (SPEC §9).

    The first call in a process compiles (XLA) for the shapes, dtypes and options given:
    tens of seconds on a small CPU (27–35 s measured on a 2-core machine), then each call
    with the same shapes runs compiled. ``thinfilm_jax.enable_compilation_cache()`` keeps the
    compilations on disk for later processes (the ``thinfilm-jax`` command and the notebooks
    turn it on).

    Args:
        film: `Film`, fields broadcasting with the shading points.
        alpha: GGX roughness α ∈ (0, 1].
        normal, view: unit world vectors (..., 3) (z-up); view points toward the eye.
        envmap: `EnvMap` (any method; real-time methods prefilter it on the host each call)
            or `PrefilteredEnvMap` (real-time methods only; build it once); for
            "colour_table" the `ColourTable` of `prefilter_colour(map, film, alpha)`.
        method: "reference" | "mc" | "ideal" | "filtered" | "improved" | "khr" (glTF
            `F_iridescence` under the split sum, module table: computed in linear Rec. 709
            as engines do, returned in the observer's bands like every method,
            `colorimetry.rec709_to_bands`; suns split from the map are shaded with the same
            per-channel Fresnel).
        observer: colour bands of the result, for every method (ΔE between any two methods:
            `colorimetry.delta_e2000`; `shading.compare.compare_methods` runs several).
        options: `ModelOptions` (default `REALTIME_OPTIONS`: shat="lut", the map's table;
            shat="auto", `ModelOptions()`'s, is "lut" here, so equal options give one program):
            terms = Fourier orders M and shat = Ŝ source of the real-time methods,
            arithmetic ("auto" specialises a concrete dielectric film), bins = K of
            `improved` (fewer: cheaper, less accurate); ndf must be "ggx" (the prefiltered
            maps are GGX); quadrature does not apply.
        cross_band: True: R_jk under RGB light (SPEC §9); False: the diagonal approximation.
        subdivisions: s Gauss nodes per axis inside each refined texel (reference); None = auto.
        n_cos: nodes of the reference's R_jk(cos θ₁) table.
        n_samples, key: Monte Carlo sample count and PRNG key (default key 0).
        batch_size: shading points evaluated together (default: 65536 for the real-time
            methods, about 2¹⁹ quadrature nodes' worth for the exact ones).
        max_height: the reference resamples a map taller than this (solid-angle-exact
            `envmap.downsample` by a power of two while the texel stays ≤ α_min/8 and
            the map ≥ 128 rows) and warns; None integrates every texel
            (`ibl_reference.resample_factor`).
        sources: when a real-time method prefilters an `EnvMap` here: split up to this
            many compact bright sources (suns) and shade them apart (`sources`,
            docs/improved.md). None: 4 for "improved", 0 for "ideal" and "filtered" (the
            published method). A `PrefilteredEnvMap` carries its own split (it was made
            by `prefilter_envmap(sources=...)`) and every real-time method shades it.
    Shading points with ⟨n, ω_o⟩ ≤ 0 give 0.

    A `Stack`, or a `Film` with index models (SPEC §12), runs the stack code in the exact
    methods (its thicknesses may vary per point, its indices are shared); the real-time ones
    take a dispersive single film at each band's centroid (`spectral.reflectance.band_film`);
    `core.methods.require` names what any other method lacks.
    """
    if needs_stack(film):
        return _material_envmap(film, alpha, normal, view, envmap, method, observer, dict(
            options=options, cross_band=cross_band, subdivisions=subdivisions, n_cos=n_cos,
            n_samples=n_samples, key=key, batch_size=batch_size, max_height=max_height,
            sources=sources))
    V.check_film(film)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    V.check_choice("method", method, METHODS)
    if method == "colour_table" or isinstance(envmap, ColourTable):
        return _colour_table(film, alpha, normal, view, envmap, method, observer)
    V.check_choice("observer", observer, OBSERVERS)
    options = check_options(options, shat_auto="lut")  # "auto": the map's Ŝ table
    if options.ndf != "ggx":
        raise ValueError(f"envmap_radiance supports ndf='ggx' only (the prefiltered maps and "
                         f"the reference's lobe are GGX), got ndf={options.ndf!r}")
    if options.layer == "bare":
        raise ValueError("envmap_radiance has no bare-interface path (ModelOptions.layer): "
                         "use layer='auto' or 'film'")
    terms, shat = options.terms, options.shat
    _check_directions(normal, view)
    shape = V.check_broadcast([("film", np.zeros(film.shape)), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    arithmetic = choose_arithmetic(film, options.arithmetic)
    realtime = method in ("ideal", "filtered", "improved", "khr")
    if isinstance(envmap, PrefilteredEnvMap):
        if not realtime:
            raise ValueError(f"method={method!r} integrates the map itself: pass an EnvMap, "
                             "not a PrefilteredEnvMap")
        pref = envmap
    elif realtime:
        if sources is None:
            sources = DEFAULT_SOURCES if method == "improved" else 0
        pref = prefilter_envmap(envmap, observer=observer, sources=sources)
    else:
        env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    dtype = jnp.result_type(alpha, normal, view, *jax.tree.leaves(film), float)
    film = jax.tree.map(lambda x: _broadcast(x, dtype, shape), film)
    alpha = _broadcast(alpha, dtype, shape)
    nv = [_broadcast(v, dtype, shape + (3,)) for v in (normal, view)]
    if realtime:
        if shat == "lut" and pref.lut.table.shape[-1] != 3 * get_observer(observer).n_bands:
            raise ValueError("the PrefilteredEnvMap was built for another observer")
        cfg = (method, observer, terms, shat, bool(cross_band), arithmetic,
               method == "improved" and options.light_spread)
        if method == "improved":  # its (θ_o, α) tables travel with the map
            pref = (pref, bin_table(options.bins, reads=options.bin_reads, dtype=dtype))
        return _realtime_jit(film, alpha, *nv, pref, cfg, int(batch_size or 65536))
    return exact_radiance(film, alpha, *nv, env, method=method, observer=observer,
                          cross_band=bool(cross_band), arithmetic=arithmetic,
                          one_film=film.shape == (), subdivisions=subdivisions, n_cos=n_cos,
                          n_samples=n_samples, key=key, batch_size=batch_size,
                          max_height=max_height)



def _broadcast(x, dtype, shape):
    """x as a JAX array of `dtype` broadcast to `shape`; one already so is passed on as it is
    (eager conversions cost 0.1–0.4 ms each: 5 % of a 52-point reference call)."""
    if not isinstance(x, jax.Array):  # a number or host array: one transfer
        return jnp.asarray(np.broadcast_to(np.asarray(x, dtype), shape))
    if x.dtype == dtype and x.shape == shape:
        return x
    return jnp.broadcast_to(jnp.asarray(x, dtype), shape)


def _material_envmap(material, alpha, normal, view, envmap, method, observer, kw):
    """`envmap_radiance` of a `Stack` or a dispersive `Film` (see there)."""
    V.check_choice("method", method, METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    require(method, dispersive=is_dispersive(material), stack=isinstance(material, Stack))
    if method == "ideal":  # a homogeneous material's exact R_jk(cos θ) table
        return _tabulated_ideal(material, alpha, normal, view, envmap, observer, kw)
    if not METHOD_INFO[method].exact:  # a dispersive single film, one band at a time
        V.check_material(material, wavelengths=band_centroids(observer))
        if not isinstance(envmap, PrefilteredEnvMap):  # prefilter once for the J bands
            src = kw["sources"]
            src = (DEFAULT_SOURCES if method == "improved" else 0) if src is None else src
            envmap = prefilter_envmap(envmap if isinstance(envmap, EnvMap)
                                      else load_envmap(envmap), observer=observer, sources=src)
        lift = [jnp.asarray(alpha)[..., None]] + [jnp.asarray(v)[..., None, :]
                                                  for v in (normal, view)]
        kw = {k: v for k, v in kw.items() if k != "sources"}
        out = envmap_radiance(band_film(material, observer), *lift, envmap, method=method,
                              observer=observer, **kw)
        return jnp.diagonal(out, axis1=-2, axis2=-1)
    stack = V.check_material(material, wavelengths=get_observer(observer).wavelengths)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    _check_directions(normal, view)
    shape = V.check_broadcast([("film", np.zeros(batch_shape(stack))), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    if isinstance(envmap, PrefilteredEnvMap):
        raise ValueError(f"method={method!r} integrates the map itself: pass an EnvMap, "
                         "not a PrefilteredEnvMap")
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    dtype = jnp.result_type(alpha, normal, view, float)
    alpha = jnp.broadcast_to(jnp.asarray(alpha, dtype), shape)
    nv = [jnp.broadcast_to(jnp.asarray(v, dtype), shape + (3,)) for v in (normal, view)]
    return exact_radiance(stack, alpha, *nv, env, method=method, observer=observer,
                          cross_band=bool(kw["cross_band"]), arithmetic="complex",
                          one_film=batch_shape(stack) == (), subdivisions=kw["subdivisions"],
                          n_cos=kw["n_cos"], n_samples=kw["n_samples"], key=kw["key"],
                          batch_size=kw["batch_size"], max_height=kw["max_height"])


def _tabulated_ideal(material, alpha, normal, view, envmap, observer, kw):
    """`ideal` for a `Stack` or a dispersive `Film` with one set of thicknesses (a homogeneous
    material): the split sum A(θ_o, α) Σ_k R_jk(cos θ_o) P_k(ω_r, α) with R_jk the exact cross
    bands tabulated once over cos θ (`n_cos` nodes, linear interpolation) instead of BB17's
    M-term series: the table an engine would upload per material."""
    stack = V.check_material(material, wavelengths=get_observer(observer).wavelengths)
    if batch_shape(stack) != ():
        raise ValueError("method='ideal' tabulates one homogeneous material: its thicknesses "
                         "must not vary per point (use method='reference', or vmap)")
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    _check_directions(normal, view)
    shape = V.check_broadcast([("alpha", alpha), ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    pref = envmap
    if not isinstance(pref, PrefilteredEnvMap):
        pref = prefilter_envmap(envmap if isinstance(envmap, EnvMap) else load_envmap(envmap),
                                observer=observer, sources=kw["sources"] or 0)
    if pref.has_sources:
        raise ValueError("method='ideal' of a tabulated material shades the prefiltered map "
                         "only: prefilter it with sources=0")
    dtype = jnp.result_type(alpha, normal, view, float)
    cross = bool(kw["cross_band"])
    obs = cross_band_name(observer) if cross else observer
    table = _r_table(stack, obs, int(kw["n_cos"]), "complex", dtype)
    alpha = jnp.broadcast_to(jnp.asarray(alpha, dtype), shape)
    nv = [jnp.broadcast_to(jnp.asarray(v, dtype), shape + (3,)) for v in (normal, view)]
    return _tabulated_ideal_jit(table, alpha, *nv, pref, cross)


@functools.partial(jax.jit, static_argnums=5)
def _tabulated_ideal_jit(table, alpha, normal, view, pref, cross):
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    sqa = jnp.sqrt(alpha)
    rad = lookup_radiance(pref, 2 * co[..., None] * normal - view, sqa)
    r = _interp(table, co)
    if cross:
        out = jnp.sum(r.reshape(r.shape[:-1] + (-1, 3)) * rad[..., None, :], axis=-1)
    else:
        out = r * rad
    return jnp.where(up[..., None], lookup_albedo(pref, co, sqa)[..., None] * out, 0.0)


def _check_directions(normal, view):
    """normal and view: (..., 3), finite unit vectors (concrete)."""
    for name, v in (("normal", normal), ("view", view)):
        if np.shape(v)[-1:] != (3,):
            raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
        if V.is_concrete(v):
            V.check_finite(name, v)
            nrm = np.linalg.norm(np.asarray(v, float), axis=-1)
            if np.any(np.abs(nrm - 1) > 1e-3):
                raise ValueError(f"{name} must be unit vectors; got a norm of "
                                 f"{nrm.flat[np.argmax(np.abs(nrm - 1))]:.6g}")


def _colour_table(film, alpha, normal, view, table, method, observer):
    """method="colour_table": the checks of SPEC §11, then `colour_table_radiance`."""
    if method != "colour_table":
        raise ValueError(f"a ColourTable is read by method='colour_table' only, got "
                         f"method={method!r}")
    check_colour_table(table, film, alpha)
    if observer != table.observer:
        raise ValueError(f"the ColourTable holds the bands of observer={table.observer!r}, "
                         f"got observer={observer!r}")
    for name, v in (("normal", normal), ("view", view)):
        if np.shape(v)[-1:] != (3,):
            raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
        if V.is_concrete(v):
            V.check_finite(name, v)
    shape = V.check_broadcast([("film", np.zeros(film.shape)), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    nv = [jnp.broadcast_to(jnp.asarray(v), shape + (3,)) for v in (normal, view)]
    return colour_table_radiance(table, *nv)


# ----------------------------------------------------------------------------- real time
@functools.partial(jax.jit, static_argnums=(5, 6))
def _realtime_jit(film, alpha, normal, view, pref, cfg, chunk):
    """Flatten the shading points and shade them `chunk` at a time (bounded memory).

    Each chunk is the branch of a `lax.cond` (`_chunk`), so its result is a buffer of its
    own: in a bare `lax.map` XLA:CPU fuses the chunk's last kernel (for `filtered` the K 29
    tail with its LUT gathers, most of the work) into the loop's in-place update of the
    output, which it runs on one thread (docs/studies/performance.md, "Real-time IBL at
    frame size"). A chunk whose points all face away from the eye is not shaded (its zeros
    are what the methods return there)."""
    shape = alpha.shape
    flat = (jax.tree.map(lambda x: x.reshape(-1), film), alpha.reshape(-1),
            normal.reshape(-1, 3), view.reshape(-1, 3))
    n = flat[1].shape[0]
    if n <= chunk:
        out = _realtime_points(*flat, pref, cfg)
    else:
        m = -(-n // chunk)

        def block(x):  # pad to m whole chunks (edge values), one chunk per map step
            x = jnp.pad(x, [(0, m * chunk - n)] + [(0, 0)] * (x.ndim - 1), mode="edge")
            return x.reshape((m, chunk) + x.shape[1:])

        out = jax.lax.map(lambda xs: _chunk(xs, pref, cfg), jax.tree.map(block, flat))
        out = out.reshape(m * chunk, -1)[:n]
    return out.reshape(*shape, out.shape[-1])


def _chunk(xs, pref, cfg):
    """`_realtime_points` of one chunk, or its zeros where no point faces the eye: every
    method returns 0 at ⟨n, ω_o⟩ ≤ 0, and the test keeps a margin of 1e-6 below 0 (far above
    the rounding of the kernels' own dot products), so the skip changes no value."""
    res = jax.eval_shape(lambda: _realtime_points(*xs, pref, cfg))
    visible = jnp.any(jnp.sum(xs[2] * xs[3], axis=-1) > -1e-6)
    return jax.lax.cond(visible, lambda: _realtime_points(*xs, pref, cfg),
                        lambda: jnp.zeros(res.shape, res.dtype))


def _realtime_points(film, alpha, normal, view, pref, cfg):
    """The map's method plus the sources split from it (if any), at flat shading points."""
    method, observer, terms, shat, cross, arithmetic, _ = cfg
    if method == "khr":
        return _khr_points(film, alpha, normal, view, pref, observer)
    out = _map_points(film, alpha, normal, view, pref, cfg)
    pref = pref[0] if method == "improved" else pref
    if pref.has_sources:
        lut = pref.lut if cross else (build_shat_lut(observer, dtype=alpha.dtype)
                                      if shat == "lut" else None)
        out = out + source_radiance(film, alpha, normal, view, pref.sources,
                                    observer=observer, terms=terms, shat=shat, lut=lut,
                                    arithmetic=arithmetic, cross_band=cross)
    return out


def _khr_points(film, alpha, normal, view, pref, observer):
    """`khr` at flat shading points (module table): per channel, Rec. 709 F_iridescence(cos θ_o)
    × (A · the prefiltered map's RGB + the split suns' Σ_s m_s L_s), then to the bands."""
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    sqa = jnp.sqrt(alpha)
    rad = lookup_radiance(pref, 2 * co[..., None] * normal - view, sqa)
    light = lookup_albedo(pref, co, sqa)[..., None] * rad
    if pref.has_sources:  # the same Fresnel for every light, as the renderer's punctual ones
        light = light + source_light(alpha, normal, view, pref.sources)
    rgb = jnp.where(up[..., None], khr_bands(film, co) * light, 0.0)
    return khr_to_bands(rgb, observer)


def _map_points(film, alpha, normal, view, pref, cfg):
    method, observer, terms, shat, cross, arithmetic, light_spread = cfg
    if method == "improved":
        pref, table = pref
        lut = pref.lut if cross else (build_shat_lut(observer, dtype=alpha.dtype)
                                      if shat == "lut" else None)
        return improved_envmap(film, alpha, normal, view, pref, table, observer=observer,
                               terms=terms, shat=shat, lut=lut, arithmetic=arithmetic,
                               cross_band=cross, light_spread=light_spread)
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    refl = 2 * co[..., None] * normal - view
    sqa = jnp.sqrt(alpha)
    rad, mom = lookup_prefiltered(pref, refl, sqa)
    a = lookup_albedo(pref, co, sqa)
    obs = cross_band_name(observer) if cross else observer
    lut = pref.lut if cross else None
    if shat == "lut" and not cross:  # the diagonal path reads the plain bands' table
        lut = build_shat_lut(observer, dtype=alpha.dtype)
    per_light = cross and shat == "lut" and not pref.per_channel
    if per_light:  # Σ_k R_jk P_k read per light channel (`filtered.filtered_bands`)
        kw = dict(observer=obs, terms=terms, shat=shat, lut=lut, arithmetic=arithmetic,
                  light=rad)
        if method == "ideal":
            out = ideal_kernel(film, co, **kw)
        else:
            out = filtered_kernel(film, view, *moments_to_mean_cov(mom), **kw,
                                  interpolation=MAP_SHAT_READ)
        return jnp.where(up[..., None], a[..., None] * out, 0.0)
    if method == "ideal":
        r = ideal_kernel(film, co, observer=obs, terms=terms, shat=shat, lut=lut,
                         arithmetic=arithmetic)
    else:
        if pref.per_channel:  # moments of channel k drive R_jk (..., 3[k], 9)
            mean, cov = moments_to_mean_cov(mom)
            f3 = expand_batch(film)
            r = filtered_kernel(f3, view[..., None, :], mean, cov, observer=obs, terms=terms,
                                shat=shat, lut=lut, arithmetic=arithmetic,
                                interpolation=MAP_SHAT_READ)
        else:
            mean, cov = moments_to_mean_cov(mom)
            r = filtered_kernel(film, view, mean, cov, observer=obs, terms=terms, shat=shat,
                                lut=lut, arithmetic=arithmetic, interpolation=MAP_SHAT_READ)
    if cross:
        r = r.reshape(r.shape[:-1] + (3, 3))  # (..., [k,] j, k)
        if r.ndim > rad.ndim + 1:  # per-channel moments: keep k of the moments = k of R
            r = jnp.diagonal(r, axis1=-3, axis2=-1)  # (..., j, k)
        out = jnp.sum(r * rad[..., None, :], axis=-1)
    else:
        if r.ndim > rad.ndim:
            r = jnp.diagonal(r, axis1=-2, axis2=-1)
        out = r * rad
    return jnp.where(up[..., None], a[..., None] * out, 0.0)


def improved_envmap(film: Film, alpha, normal, view, pref, table: BinTable, *,
                    observer=DEFAULT_OBSERVER, terms: int = 2, shat: str = "lut",
                    lut: ShatLUT | None = None, arithmetic: str = "complex",
                    cross_band: bool = True, light_spread: bool = False) -> Array:
    r"""`envmap_radiance(method="improved")` at shading points: L_j (..., J), 0 where ⟨n,ω_o⟩ ≤ 0.

    $$ L_j = \frac{A(\theta_o,\alpha)}{K}\sum_{k=1}^{K}\sum_c
       R_{jc}(\bar c_k + \Delta c_k, s_k)\, P_c(d_k, \alpha_k) $$

    The bins split the lobe exactly (E[R L] = (1/K) Σ_k E[R L | bin k]); bin k's film
    reflectance (`improved_bins`) multiplies read k of the K prefiltered reads fitted to the
    lobe's shape (`improved.lookup_reads`), at the bin's mean incidence cosine moved by what
    the read's luminance-weighted mean direction says, Δc_k (`prefilter.bin_radiance_parts`:
    the covariance of R and L inside a bin). A constant environment gives Δc = 0 and the
    uniform-light model. Per point: K reads of 3 radiance and 3 moment channels (9 with
    `light_spread`, which also moves each bin's spread), against `filtered`'s one read of
    3 + 9 (docs/improved.md); g·K reads when `table` has g reads a bin
    (`bin_table(reads=g)`, `ModelOptions.bin_reads`), pooled per bin.

    Args:
        film: `Film` broadcasting with the shading points.
        alpha: GGX α (...).
        normal, view: unit world vectors (..., 3).
        pref: `prefilter.PrefilteredEnvMap` (its radiance levels and albedo table).
        table: `bin_table(...)`.
        observer: plain band name (the cross bands are used when `cross_band`).
        terms, shat, lut, arithmetic: as `improved_bins`; `lut` must hold the bands used
            (the map's cross-band table when `cross_band`).
        cross_band: R_jc under RGB light (SPEC §9) or the diagonal R_j P_j.
        light_spread: each bin's spread of cos θ₁ follows its read's light too
            (`prefilter.bin_radiance_parts`; `ModelOptions.light_spread`).
    """
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    a = lookup_albedo(pref, co, safe_sqrt(alpha))
    cb, sb = lookup_bins(table, co, alpha)
    light = bin_radiance_parts(pref, table, normal, view, co, alpha, sb,
                               light_spread=light_spread)  # bins first
    obs = cross_band_name(observer) if cross_band else observer
    # Σ_c R_jc P_c: the cross-band table read per light channel in place (`lut.read_parts(
    # channel=...)`); three strided copies (`split_by_light`) made in every chunk cost 8 %
    per_light = cross_band and shat == "lut"
    bands = functools.partial(bin_bands, observer=obs, terms=terms, shat=shat, lut=lut,
                              arithmetic=arithmetic)

    def under_light(film, c, s, light):  # the bin's film × its radiance P_k (..., 3)
        if per_light:
            return bands(film, c, s, light)
        r = bands(film, c, s)
        if cross_band:
            return jnp.sum(r.reshape(r.shape[:-1] + (3, 3)) * light[..., None, :], axis=-1)
        return r * light

    out = scan_bins(film, cb, sb, under_light, extra=light)  # Σ_k (..., J)
    return jnp.where(up[..., None], a[..., None] * out * (1.0 / cb.shape[-1]), 0.0)
