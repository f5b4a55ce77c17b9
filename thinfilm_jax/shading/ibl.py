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
| `improved`  | A(θ_o, α) · (1/K) Σ_b Σ_k R_jk(bin b) P_k,b: K 29 per equal-probability bin b of cos θ₁, each bin times read b of K prefiltered reads fitted to the lobe's shape (`improved.lookup_reads`), at the bin's cosine moved by the read's light-weighted mean direction (`methods.improved.improved_envmap`, docs/improved.md) |

Each method is one object of `shading.methods` (its module holds the row above), looked up in
the registry (`core.methods.implementation`); the material's kind picks the path by type
(`_envmap_of`): a `Film` or `Stack` (one-film code, stack code or a dispersive film per band,
`core.methods.material_path`), a classic-lobe `Material` (`material_ibl`) or a `CarPaint`
(`carpaint_ibl`).

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

from ..brdf.carpaint import CarPaint
from ..brdf.material import Material
from ..core import _validate as V
from ..core.film import Film
from ..core.methods import implementation, material_path
from ..core.methods import MethodNames
from ..core.stack import Stack
from ..optics.airy import choose_arithmetic
from ..realtime.options import ModelOptions, check_options
from ..spectral.reflectance import band_centroids, band_film, choose_layer
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from .carpaint_ibl import PAINT_ENVMAP_METHODS as PAINT_METHODS
from .carpaint_ibl import paint_envmap_radiance
from .colour_table import ColourTable
from .envmap import EnvMap, load_envmap
from .ibl_reference import auto_subdivisions, exact_radiance  # noqa: F401 (re-exported)
from .material_ibl import MATERIAL_ENVMAP_METHODS as MATERIAL_METHODS
from .material_ibl import material_envmap_radiance
from .methods import DEFAULT_SOURCES, MapConfig  # noqa: F401 (DEFAULT_SOURCES re-exported)
from .methods.filtered import MAP_SHAT_READ  # noqa: F401 (re-exported)
from .methods.improved import improved_envmap  # noqa: F401 (re-exported)
from .prefilter import PrefilteredEnvMap, prefilter_envmap

__all__ = [
    "ENVMAP_METHODS", "REALTIME_OPTIONS", "HIGHEST", "envmap_radiance", "ENVMAP_KIND_METHODS",
]

#: the built-in methods, the registry's order (core/methods.py)
ENVMAP_METHODS = MethodNames("envmap")
REALTIME_OPTIONS = ModelOptions(shat="lut")  # the real-time default: Ŝ from the map's table
HIGHEST = jax.lax.Precision.HIGHEST


# ----------------------------------------------------------------------------- public
def envmap_radiance(film, alpha, normal, view, envmap, *, method: str = "reference",
                    observer: str = DEFAULT_OBSERVER, options: ModelOptions = REALTIME_OPTIONS,
                    cross_band: bool = True, subdivisions: int | None = None,
                    n_cos: int = 1024, n_samples: int = 4096, key=None,
                    batch_size: int | None = None, max_height: int | None = 256,
                    sources: int | None = None, **kind_options) -> Array:
    """Band radiances L_j (..., J) of a film under an environment map (SPEC §9).

    A process's first call compiles for its shapes, dtypes and options (27–35 s on a 2-core
    CPU); ``thinfilm_jax.enable_compilation_cache()`` keeps that on disk for later processes.

    Args:
        film: the material, by type: a `Film` (fields broadcasting with the shading points)
            or a `Stack` (SPEC §12); a classic-lobe `Material` or a `CarPaint`, which carry
            their own lobe (`alpha` None; methods "reference" and "mc"; the keywords
            cross_band, subdivisions, n_cos, n_samples, key and batch_size go to
            `material_envmap_radiance` / `paint_envmap_radiance` when given, as do
            `kind_options` (tangent, return_stderr); left at their defaults the kind's own
            defaults apply).
        alpha: GGX roughness α ∈ (0, 1] of a film or stack.
        normal, view: unit world vectors (..., 3) (z-up); view points toward the eye.
        envmap: `EnvMap` (any method; real-time methods prefilter it on the host each call)
            or `PrefilteredEnvMap` (real-time methods only; build it once); for
            "colour_table" the `ColourTable` of `prefilter_colour(map, film, alpha)`.
        method: one of `core.methods.names("envmap")`: "reference" | "mc" | "ideal" |
            "filtered" | "improved" | "colour_table" | "khr" (glTF
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
            `improved` (fewer: cheaper, less accurate); layer "auto" gives a film whose
            thicknesses are all concretely 0 the bare interface's exact R₁₃ Ŝ_jk(0) in the
            real-time methods, as `patch_radiance` does ("bare" forces it, "film" keeps
            the series); ndf must be "ggx" (the prefiltered maps are GGX); quadrature does
            not apply.
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
    Shading points with ⟨n, ω_o⟩ ≤ 0 give 0. Under a constant map `ideal` and `improved`
    give their own `patch_radiance` models to ≤ 4e-4 when the prefiltered levels have at
    least 64 rows, not from coarser ones (`prefilter_envmap`, "Uniform light", which also
    says where `filtered` departs from its model).

    A `Stack`, or a `Film` with index models (SPEC §12), runs the stack code in the exact
    methods (its thicknesses may vary per point, its indices are shared); the real-time ones
    take a dispersive single film at each band's centroid (`spectral.reflectance.band_film`);
    `core.methods.require` names what any other method lacks.
    """
    kw = dict(options=options, cross_band=cross_band, subdivisions=subdivisions, n_cos=n_cos,
              n_samples=n_samples, key=key, batch_size=batch_size, max_height=max_height,
              sources=sources)
    return _envmap_of(film, alpha, normal, view, envmap, method, observer, kw, kind_options)


@functools.singledispatch
def _envmap_of(material, alpha, normal, view, envmap, method, observer, kw, kind_options):
    """`envmap_radiance` by the material's type (one handler per kind)."""
    raise TypeError(f"envmap_radiance takes a thinfilm_jax Film, Stack, Material or CarPaint, "
                    f"got {type(material).__name__}")


@_envmap_of.register(Film)
@_envmap_of.register(Stack)
def _film_envmap(film, alpha, normal, view, envmap, method, observer, kw, kind_options):
    """A `Film` or `Stack`: the path `core.methods.material_path` picks."""
    if kind_options:
        raise TypeError(f"envmap_radiance of a film or stack got unexpected keyword arguments "
                        f"{sorted(kind_options)}")
    if alpha is None:
        raise TypeError("envmap_radiance of a Film or Stack needs alpha, the GGX roughness "
                        "α ∈ (0, 1]")
    V.check_choice("method", method, ENVMAP_METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    path = material_path(film, method)
    if path == "stack":  # every index at each wavelength (`ideal`: an exact R_jk table)
        return implementation(method).envmap_stack(film, alpha, normal, view, envmap,
                                                   observer, kw)
    if path == "bands":
        return _band_envmap(film, alpha, normal, view, envmap, method, observer, kw)
    return _one_film_envmap(film, alpha, normal, view, envmap, method, observer, **kw)


def _band_envmap(material, alpha, normal, view, envmap, method, observer, kw):
    """A dispersive single film through a real-time method, one band at a time: the film at
    each band's centroid (`spectral.reflectance.band_film`), the map prefiltered once."""
    V.check_material(material, wavelengths=band_centroids(observer))
    if not isinstance(envmap, PrefilteredEnvMap):  # prefilter once for the J bands
        src = kw["sources"]
        src = implementation(method).default_sources if src is None else src
        envmap = prefilter_envmap(envmap if isinstance(envmap, EnvMap)
                                  else load_envmap(envmap), observer=observer, sources=src)
    lift = [jnp.asarray(alpha)[..., None]] + [jnp.asarray(v)[..., None, :]
                                              for v in (normal, view)]
    kw = {k: v for k, v in kw.items() if k != "sources"}
    out = envmap_radiance(band_film(material, observer), *lift, envmap, method=method,
                          observer=observer, **kw)
    return jnp.diagonal(out, axis1=-2, axis2=-1)


def _one_film_envmap(film, alpha, normal, view, envmap, method, observer, *, options,
                     cross_band, subdivisions, n_cos, n_samples, key, batch_size, max_height,
                     sources):
    """A `Film` of constant indices: the method's real-time, exact or colour-table path."""
    V.check_film(film)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    m = implementation(method)
    if m.envmap_kind == "table" or isinstance(envmap, ColourTable):
        if m.envmap_kind != "table":
            raise ValueError(f"a ColourTable is read by method='colour_table' only, got "
                             f"method={method!r}")
        return m.envmap_table(film, alpha, normal, view, envmap, observer)
    options = check_options(options, shat_auto="lut")  # "auto": the map's Ŝ table
    if options.ndf != "ggx":
        raise ValueError(f"envmap_radiance supports ndf='ggx' only (the prefiltered maps and "
                         f"the reference's lobe are GGX), got ndf={options.ndf!r}")
    terms, shat = options.terms, options.shat
    V.check_directions(normal, view)
    shape = V.check_broadcast([("film", np.zeros(film.shape)), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    arithmetic = choose_arithmetic(film, options.arithmetic)
    layer = choose_layer(film, options.layer)  # "bare" at d = 0: the real-time methods' R₁₃
    realtime = m.envmap_kind == "realtime"
    if isinstance(envmap, PrefilteredEnvMap):
        if not realtime:
            raise ValueError(f"method={method!r} integrates the map itself: pass an EnvMap, "
                             "not a PrefilteredEnvMap")
        pref = envmap
    elif realtime:
        if sources is None:
            sources = m.default_sources
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
        cfg = MapConfig(method, observer, terms, shat, bool(cross_band), arithmetic,
                        m.map_static(options), layer)
        pref = m.envmap_tables(pref, options, dtype)  # e.g. `improved`'s (θ_o, α) tables
        return _realtime_jit(film, alpha, *nv, pref, cfg, int(batch_size or 65536))
    return exact_radiance(film, alpha, *nv, env, method=method, observer=observer,
                          cross_band=bool(cross_band), arithmetic=arithmetic,
                          one_film=film.shape == (), subdivisions=subdivisions, n_cos=n_cos,
                          n_samples=n_samples, key=key, batch_size=batch_size,
                          max_height=max_height)


#: the keywords of `envmap_radiance` a `Material` / `CarPaint` takes, with the defaults they
#: have there (left at them, the kind's own defaults apply)
_LOBE_KEYWORDS = dict(cross_band=True, subdivisions=None, n_cos=1024, n_samples=4096,
                      key=None, batch_size=None)
#: the methods of the material kinds that carry their own lobe
ENVMAP_KIND_METHODS = {Material: MATERIAL_METHODS, CarPaint: PAINT_METHODS}


def _lobe_kind(fn, takes):
    """The handler of a material kind that carries its own lobe (`alpha` None)."""
    def handler(material, alpha, normal, view, envmap, method, observer, kw, kind_options):
        if alpha is not None:
            raise ValueError(f"alpha must be None for a {type(material).__name__} (it carries "
                             f"its own lobe), got {alpha!r}")
        V.check_choice("method", method, ENVMAP_KIND_METHODS[type(material)])
        given = {k: kw[k] for k in takes if kw[k] is not _LOBE_KEYWORDS[k]
                 and not (isinstance(kw[k], int) and kw[k] == _LOBE_KEYWORDS[k])}
        return fn(material, normal, view, envmap, method=method, **given, **kind_options)
    return handler


_envmap_of.register(Material, _lobe_kind(material_envmap_radiance, tuple(_LOBE_KEYWORDS)))
_envmap_of.register(CarPaint, _lobe_kind(paint_envmap_radiance, (
    "subdivisions", "n_samples", "key", "batch_size")))


def _broadcast(x, dtype, shape):
    """x as a JAX array of `dtype` broadcast to `shape`; one already so is passed on as it is
    (eager conversions cost 0.1–0.4 ms each: 5 % of a 52-point reference call)."""
    if not isinstance(x, jax.Array):  # a number or host array: one transfer
        return jnp.asarray(np.broadcast_to(np.asarray(x, dtype), shape))
    if x.dtype == dtype and x.shape == shape:
        return x
    return jnp.broadcast_to(jnp.asarray(x, dtype), shape)


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
    """The map's method plus the sources split from it (if any), at flat shading points: the
    method object's `map_points` (`shading.methods`)."""
    return implementation(cfg.method).map_points(film, alpha, normal, view, pref, cfg)
