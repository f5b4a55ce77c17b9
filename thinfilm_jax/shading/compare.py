r"""A fair comparison of `envmap_radiance`'s methods from one environment map (SPEC §9).

Every method of `envmap_radiance` returns band radiances of the observer (`khr` computes glTF's
linear Rec. 709 and takes it to the bands, `colorimetry.rec709_to_bands`), so two methods are
compared by `colorimetry.delta_e2000` of their outputs. What differs is what each method
reads: the exact ones the `EnvMap` itself, the real-time ones a `PrefilteredEnvMap` (the
published `ideal`, `filtered` and `khr` the map as it is, `improved` the map with its suns split
off and shaded apart, `ibl.DEFAULT_SOURCES`), `colour_table` a `ColourTable` built for one film
and one α. `compare_methods` builds each of these once from the one map (a prefiltered map
is shared by the methods that read the same split) and returns every method's radiances and
its ΔE₀₀ against the reference method, in one space.

Example (a tiny sky with a small sun; the reference compared with itself is ΔE 0):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.shading.compare import compare_methods
    >>> sky = np.full((8, 16, 3), 0.2); sky[2, 3] = 60.0
    >>> res = compare_methods(Film(400.0, 1.33, 1.5), 0.3, np.array([0.0, 0.0, 1.0]),
    ...                       np.array([0.0, 0.6, 0.8]), sky, methods=("reference", "khr"),
    ...                       prefilter=dict(levels=3, albedo_shape=(8, 5)))
    >>> res.radiance["khr"].shape, float(res.delta_e["reference"])
    ((3,), 0.0)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..core import _validate as V
from ..core.film import Film
from ..core.material import is_dispersive
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import implementation
from ..core.methods import names as method_names
from ..spectral.colorimetry import delta_e2000
from ..spectral.spectra import DEFAULT_OBSERVER
from .colour_table import prefilter_colour
from .envmap import EnvMap, load_envmap
from .ibl import DEFAULT_SOURCES, ENVMAP_METHODS, envmap_radiance  # noqa: F401 (re-exported)
from .prefilter import PrefilteredEnvMap, prefilter_envmap

__all__ = ["DEFAULT_METHODS", "Comparison", "compare_methods"]

#: What `compare_methods` runs by default: the reference and the real-time methods (Monte
#: Carlo and the per-film colour table only when asked for).
DEFAULT_METHODS = ("reference", "ideal", "filtered", "improved", "khr")


class Comparison(NamedTuple):
    """What `compare_methods` returns.

    radiance: method → band radiances (..., J) of `observer` (NumPy), every method in that
        one space, the reference included.
    delta_e: method → CIEDE2000 (...) against the reference's radiances
        (`colorimetry.delta_e2000`, the mirror as white).
    observer, reference: the bands and the reference method.
    sources: method → suns split from the map it read (0: the map as it is; None: the
        method read the `EnvMap` or a `ColourTable`).
    skipped: method → why it was not run.
    """

    radiance: dict
    delta_e: dict
    observer: str
    reference: str
    sources: dict
    skipped: dict


def compare_methods(film: Film, alpha, normal, view, envmap, *,
                    methods: tuple[str, ...] = DEFAULT_METHODS, reference: str = "reference",
                    observer: str = DEFAULT_OBSERVER, sources: int | None = None,
                    prefilter: dict | None = None, colour: dict | None = None,
                    **options) -> Comparison:
    """Each method's band radiances and ΔE₀₀ against `reference`, all from one `EnvMap`.

    Args:
        film, alpha, normal, view: as `envmap_radiance` (shading points broadcast).
        envmap: one `EnvMap` (or anything `load_envmap` reads): the exact methods integrate
            it, the real-time ones read it prefiltered here (module docstring).
        methods: `envmap_radiance` methods to run, in order; `reference` is run as well
            when not listed.
        reference: the method every ΔE is taken against (an exact one as a rule).
        observer: the colour bands of every output and of the ΔE.
        sources: suns split from the map for every real-time method; None: each method's own
            default (`ibl.DEFAULT_SOURCES` for "improved", 0 for the published ones).
        prefilter: keyword arguments of `prefilter_envmap` (levels, resolution,
            albedo_shape, moments, dtype), the same for every prefiltered map.
        colour: keyword arguments of `prefilter_colour` for "colour_table"; that method
            models one film and one α, so it runs only for a scalar film (no index model)
            and a scalar α, and is skipped with the reason otherwise.
        **options: passed to every `envmap_radiance` call (options, cross_band,
            subdivisions, n_samples, key, max_height, batch_size, ...).
    Returns:
        `Comparison` (NumPy values).
    """
    methods = tuple(methods)
    for m in methods + (reference,):
        V.check_choice("method", m, method_names("envmap"))
    if isinstance(envmap, PrefilteredEnvMap):
        raise ValueError("compare_methods prepares every method's input from one EnvMap: "
                         "pass the map itself, not a PrefilteredEnvMap")
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    order = methods if reference in methods else (reference,) + methods
    maps: dict = {}  # suns split → PrefilteredEnvMap, built once
    radiance, split, skipped = {}, {}, {}
    for m in order:
        if implementation(m).envmap_kind == "table":  # a table built for this film
            why = _colour_table_refusal(film, alpha)
            if why:
                skipped[m] = why
                continue
            table = prefilter_colour(env, film, float(alpha), observer=observer,
                                     **(colour or {}))
            radiance[m] = np.asarray(envmap_radiance(film, alpha, normal, view, table,
                                                     method=m, observer=observer))
            split[m] = None
            continue
        if METHOD_INFO[m].exact:
            source, n = env, None
        else:
            n = sources if sources is not None else implementation(m).default_sources
            if n not in maps:
                maps[n] = prefilter_envmap(env, observer=observer, sources=n,
                                           **(prefilter or {}))
            source = maps[n]
        radiance[m] = np.asarray(envmap_radiance(film, alpha, normal, view, source, method=m,
                                                 observer=observer, **options))
        split[m] = n
    ref = radiance[reference]
    delta = {m: np.asarray(delta_e2000(v, ref, observer)) for m, v in radiance.items()}
    return Comparison(radiance, delta, observer, reference, split, skipped)


def _colour_table_refusal(film, alpha) -> str:
    """Why "colour_table" cannot run on these shading points ("" when it can)."""
    if not isinstance(film, Film) or is_dispersive(film) or film.shape != ():
        return ("colour_table models one film: its table is built for a scalar Film "
                "(constant indices); run prefilter_colour and envmap_radiance for each film")
    if np.ndim(alpha):
        return ("colour_table models one α: its table is built for a scalar roughness; run "
                "prefilter_colour for each α")
    return ""
