r"""The free parameters of `fit_film` and `fit_spectrum` and the checks of their inputs: the
box map of the parameters (`engine.to_box`), `_Spec` (names, the `params.ParamMap` into the
material, layer thicknesses, boxes), validation of the free names, the material, the options,
σ and the batching (`fit.film_fit` module docstring).

Example (the box map and its inverse):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax.fit.film_spec import _to_x, _to_y
    >>> y = _to_y(jnp.float64(250.0), 0.0, 1000.0)  # logit(0.25)
    >>> round(float(y), 6), round(float(_to_x(y, 0.0, 1000.0)), 9)
    (-1.098612, 250.0)
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.film import Film
from ..core.material import is_dispersive
from ..core.stack import Stack
from ..spectral.spectra import get_observer
from . import params as P
from .engine import from_box, to_box
from .options import _PATCH_ONLY, BATCHING, DEFAULT_BOUNDS, FILM_PARAMS, FitOptions

__all__ = []

# ----------------------------------------------------------------------------- parameter map
_to_x, _to_y = to_box, from_box  # the engine's box transform (module docstring)


class _Spec(NamedTuple):
    """The free parameters: names, the static `params.ParamMap` that puts them into the
    (material, α) pytree, which of them are layer thicknesses (position in `free`, layer)
    and where "eta_film" of a `Film` is (the d–η₂ ridge moves), and their boxes lo, hi (p,)
    (host arrays, passed to the jitted solve as traced arrays: new bounds never
    recompile)."""

    free: tuple
    pmap: P.ParamMap
    thick: tuple
    eta_k: int | None
    lo: object
    hi: object

    def x_free(self, y):
        """Physical values of the free parameters from the unconstrained y (p,)."""
        return _to_x(y, jnp.asarray(self.lo, y.dtype), jnp.asarray(self.hi, y.dtype))

    def with_free(self, x_free, base):
        """(material, α) with the free parameters from `x_free` and the rest from the leaves
        `base` (`params.ParamMap.rebuild`: element by element, so that derivatives with
        respect to the free parameters never flow through the fixed ones: a jvp through the
        patch model then skips e.g. the α-dependence of the quadrature when α is fixed)."""
        return self.pmap.rebuild(x_free, base)

    def x_full(self, y, base):
        """(material, α) with the free parameters mapped from y."""
        return self.with_free(self.x_free(y), base)

    def y_of(self, x_free):
        return _to_y(x_free, jnp.asarray(self.lo, x_free.dtype), jnp.asarray(self.hi, x_free.dtype))


# ----------------------------------------------------------------------------- validation
def _check_free(free, table, material):
    """`free` as a tuple of names (as given), each naming one scalar of `table` (aliases:
    `params.resolve`) and none twice."""
    if isinstance(free, str):
        free = (free,)
    free = tuple(free)
    if not free:
        raise ValueError("free must name at least one parameter")
    resolved = []
    for k in free:
        r = P.resolve(k, table, material) if isinstance(k, str) else k
        if r not in table:
            raise ValueError(f"unknown free parameter {k!r}; expected names from "
                             f"{P.describe(table)}")
        resolved.append(r)
    if len(set(resolved)) != len(resolved):
        raise ValueError(f"free names a parameter twice: {free}")
    return free


def _make_spec(free, user_bounds, material, alpha, table):
    """The free parameters' `_Spec` and their initial values (host floats).

    A free name's box: `user_bounds` under its name (or its alias), else
    `params.default_box` (`DEFAULT_BOUNDS` for the `Film` fields, "alpha" and every layer
    thickness; the rules for other scalars there)."""
    names = [P.resolve(k, table, material) for k in free]
    for k in user_bounds:
        if P.is_path_name(k) and P.resolve(k, table, material) not in table:
            raise ValueError(f"bounds: unknown parameter {k!r} for this material; expected "
                             f"names from {P.describe(table)}")
    pmap = P.ParamMap.of(material, [table[n] for n in names])
    x0 = np.asarray(pmap.host_values(material, alpha), float)
    lo, hi = [], []
    for i, (k, n) in enumerate(zip(free, names)):
        given = [user_bounds[b] for b in (k, n) if b in user_bounds]
        if not given and n != k and n in ("thickness", "thickness[0]"):
            given = [user_bounds[b] for b in ("thickness", "thickness[0]") if b in user_bounds]
        v = float(x0[i])
        box = given[0] if given else P.default_box(n, v, material, DEFAULT_BOUNDS)
        if not box[0] <= v <= box[1]:
            raise ValueError(f"initial {k} = {v!r} lies outside its bounds [{box[0]}, "
                             f"{box[1]}]")
        lo.append(box[0])
        hi.append(box[1])
    thick = tuple((i, P.layer_of(n, material)) for i, n in enumerate(names)
                  if P.layer_of(n, material) is not None)
    eta_k = (names.index("eta_film") if isinstance(material, Film) and "eta_film" in names
             and thick else None)
    spec = _Spec(free, pmap, thick, eta_k, np.asarray(lo, float), np.asarray(hi, float))
    return spec, x0


def _check_material(initial, wavelengths):
    """The checked `initial` material: a constant `Film` (`_check_scalar_film`), a dispersive
    `Film` (its index models cover `wavelengths`; a complex constant base folded into
    kappa_base) or a `Stack` (one thickness per layer, no batch axes)."""
    if isinstance(initial, Film) and not is_dispersive(initial):
        return _check_scalar_film(initial)
    if not isinstance(initial, Film | Stack):
        raise TypeError(f"initial must be a thinfilm_jax.Film or Stack, got "
                        f"{type(initial).__name__}")
    checked = V.check_material(initial, "initial", wavelengths)
    if isinstance(initial, Stack):
        if np.ndim(checked.thickness) != 1:
            raise ValueError(f"initial.thickness must hold one thickness per layer, shape "
                             f"({initial.n_layers},); got shape {np.shape(checked.thickness)}")
        return checked
    for k in ("thickness", "kappa_base"):
        if np.shape(getattr(initial, k)) != ():
            raise ValueError(f"initial.{k} must be a scalar, got shape "
                             f"{np.shape(getattr(initial, k))}")
    film = initial._replace(**{k: jnp.asarray(getattr(initial, k)) for k in FILM_PARAMS
                               if not callable(getattr(initial, k))})
    return film if callable(film.eta_base) else film.real_base()


def _real_dtype(*xs):
    """The real floating dtype of arrays `xs` (complex ones count as their real part)."""
    return jnp.result_type(*(jnp.finfo(jnp.result_type(x)).dtype
                             if jnp.iscomplexobj(x) else x for x in xs), float)


def _static(spec):
    """(static part for the jit cache key, dynamic boxes): bounds never trigger a recompile."""
    return spec._replace(lo=None, hi=None), (spec.lo, spec.hi)


def _check_batching(batching):
    V.check_choice("batching", batching, BATCHING)
    if batching == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batching


def _check_scalar_film(film):
    """The checked, normalised `initial` film (complex eta_base folded into kappa_base)."""
    film = V.check_film(film, "initial")
    for k, v in film._asdict().items():
        if np.shape(v) != ():
            raise ValueError(f"initial.{k} must be a scalar, got shape {np.shape(v)}")
    return film


def _check_options(options, kind):
    """The `FitOptions` of a fit (default if None); patch-only fields rejected for spectra."""
    if options is None:
        options = FitOptions()
    if not isinstance(options, FitOptions):
        raise TypeError(f"options must be a thinfilm_jax.FitOptions, got "
                        f"{type(options).__name__}")
    if kind == "spectrum":
        default = FitOptions()
        changed = [k for k in _PATCH_ONLY if getattr(options, k) != getattr(default, k)]
        if changed:
            raise ValueError(f"FitOptions field(s) {changed} apply to fit_film (patch models) "
                             f"only")
    return options


def _weights(sigma, shape, dtype):
    if sigma is None:
        return jnp.ones(shape, dtype)
    V.check_range("sigma", sigma, 0.0, lo_open=True)
    try:
        return 1.0 / jnp.broadcast_to(jnp.asarray(sigma, dtype), shape)
    except ValueError:
        raise ValueError(f"sigma of shape {np.shape(sigma)} does not broadcast to the "
                         f"observations {shape}") from None


def _mean_wavelength(observer):
    """λ̄ of an observer: the mean of its bands' centroids Σ_k λ_k W_kj (nm)."""
    obs = get_observer(observer)
    return float(np.mean(np.asarray(obs.wavelengths) @ np.asarray(obs.weights)))


def _n_candidates(y_starts, grid, n_solves):
    """n_solves, by default 2 per screened row (≥ 8 per free thickness), at most the number
    of starts."""
    if n_solves is None:
        rows = (y_starts.shape[0] - 1) // int(np.prod(grid))
        n_solves = max(8 * len(grid), 2 * rows + 2)
    return min(int(n_solves), y_starts.shape[0])


def _check_background(background, shape, dtype):
    """A raw spectrum's known background (`fit_spectrum`), finite, broadcast to the
    observations' shape; None stays None."""
    if background is None:
        return None
    background = V.check_finite("background", V.as_array("background", background))
    try:
        return jnp.broadcast_to(jnp.asarray(background, dtype), shape)
    except ValueError:
        raise ValueError(f"background of shape {np.shape(background)} does not "
                         f"broadcast to the observations {shape}") from None
