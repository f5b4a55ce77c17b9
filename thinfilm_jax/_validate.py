"""Checks at the public boundary: bad input raises a clear error naming the argument.

Checks run on concrete values only. Inside `jax.jit` (traced values) they are skipped:
validate before entering a jitted function, or call the public functions un-jitted once.
"""

from __future__ import annotations

from collections.abc import Iterable

import jax
import numpy as np

from .film import Film


def is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _values(x):
    return np.asarray(x)


def check_finite(name: str, x) -> None:
    if is_concrete(x):
        v = _values(x)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite; got NaN or inf in {name}")


def check_range(name: str, x, lo=None, hi=None, *, lo_open=False, hi_open=False, why="") -> None:
    """Raise ValueError if any concrete value of `x` lies outside [lo, hi] (or open ends)."""
    if not is_concrete(x):
        return
    check_finite(name, x)
    v = _values(x)
    bad = np.zeros(v.shape, bool)
    if lo is not None:
        bad |= (v <= lo) if lo_open else (v < lo)
    if hi is not None:
        bad |= (v >= hi) if hi_open else (v > hi)
    if np.any(bad):
        lb = "(" if lo_open else "["
        hb = ")" if hi_open else "]"
        rng = f"{lb}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{hb}"
        first = v[bad].flat[0]
        raise ValueError(f"{name} must lie in {rng}{why}; got {first!r}")


def check_broadcast(names_values: Iterable[tuple[str, object]]) -> tuple[int, ...]:
    """The broadcast shape of the arguments, or a ValueError that names their shapes."""
    items = [(n, np.shape(v)) for n, v in names_values]
    try:
        return np.broadcast_shapes(*(s for _, s in items))
    except ValueError:
        desc = ", ".join(f"{n} {s}" for n, s in items)
        raise ValueError(f"arguments have incompatible shapes: {desc}") from None


def check_film(film) -> None:
    """Validate a `Film` (SPEC §1 domain)."""
    if not isinstance(film, Film):
        raise TypeError(f"film must be a thinfilm_jax.Film, got {type(film).__name__}")
    check_range("film.thickness", film.thickness, 0.0, why=" (nm, d >= 0)")
    check_range("film.eta_film", film.eta_film, 1.0, why=" (supported domain eta >= 1)")
    check_range("film.eta_outer", film.eta_outer, 1.0, why=" (supported domain eta >= 1)")
    check_range("film.eta_base", film.eta_base, 0.0, lo_open=True)
    check_range("film.kappa_base", film.kappa_base, 0.0, why=" (absorption kappa >= 0)")
    check_broadcast((f"film.{k}", v) for k, v in film._asdict().items())


def check_cos_theta(cos_theta, name: str = "cos_theta") -> None:
    check_range(name, cos_theta, 0.0, 1.0)


def check_choice(name: str, value, choices) -> None:
    if value not in choices:
        raise ValueError(f"unknown {name} {value!r}; expected one of {sorted(choices)}")
