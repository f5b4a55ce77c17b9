"""What the exact paths take: a `Film` (constant or dispersive indices) or a `Stack` (SPEC §12).

A film whose indices are all numbers runs the one-film Airy code (`optics.airy`), the fast
path it always had. A film with an index model in any index field, or a `Stack`, runs the
layer-stack code (`optics.stack`), which evaluates every index at each wavelength; `as_stack`
gives the one-layer stack of a dispersive film, identical to 1e-12 (SPEC §12).

Batching. The per-point quantities of a material are its thicknesses: a `Film`'s fields all
broadcast with the shading points (as before), a `Stack`'s ``thickness`` (..., N) carries
leading batch axes while its indices are shared by every point (vmap over several stacks).
`point_split` flattens the per-point part for `jax.lax.map` and rebuilds one point's material,
with no positional unpacking of fields.

Example:
    >>> from thinfilm_jax import Film, Stack, ConstantIndex
    >>> needs_stack(Film(600.0, 1.3, 2.0)), needs_stack(Film(600.0, ConstantIndex(1.3), 2.0))
    (False, True)
    >>> batch_shape(Stack([[100.0, 50.0]] * 3, (1.46, 2.0), 3.9))
    (3,)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .film import Film
from .stack import Stack

__all__ = [
    "is_dispersive",
    "needs_stack",
    "as_stack",
    "batch_shape",
    "point_split",
    "first_point",
    "expand_batch",
]

INDEX_FIELDS = ("eta_film", "eta_base", "eta_outer")


def _is_model(x) -> bool:
    return callable(x) and not isinstance(x, (np.ndarray, jax.Array))


def is_dispersive(x) -> bool:
    """True for a `Film` with an index model in an index field, or a `Stack` with any index
    model; False for constant indices."""
    if isinstance(x, Stack):
        return any(_is_model(e) for e in (*x.eta, x.eta_base, x.eta_outer))
    if isinstance(x, Film):
        return any(_is_model(getattr(x, k)) for k in INDEX_FIELDS)
    return False


def needs_stack(x) -> bool:
    """True when `x` must run the stack code: a `Stack`, or a dispersive `Film`."""
    return isinstance(x, Stack) or is_dispersive(x)


def as_stack(x) -> Stack:
    """`x` as a `Stack` (a `Film` becomes its one-layer stack)."""
    if isinstance(x, Stack):
        return x
    if isinstance(x, Film):
        if _is_model(x.eta_base) and np.any(np.asarray(x.kappa_base) != 0):
            raise ValueError("film.kappa_base must be 0 when film.eta_base is an index model "
                             "(the model carries κ)")
        return Stack.from_film(x)
    raise TypeError(f"expected a thinfilm_jax.Film or Stack, got {type(x).__name__}")


def batch_shape(x) -> tuple[int, ...]:
    """The per-point (batch) shape of a material: a `Film`'s broadcast field shape, the
    leading axes of a `Stack`'s thickness."""
    if isinstance(x, Stack):
        return tuple(np.shape(x.thickness)[:-1])
    return tuple(x.shape)


def point_split(x, shape: tuple[int, ...]) -> tuple[Any, Callable[[Any], Any]]:
    """(the per-point part of material `x` flattened to (prod(shape), ...), the function that
    makes one point's material (or a block of points') from a slice of it).

    A `Film`: every field broadcast to `shape` and flattened (a `Film` of vectors). A `Stack`:
    its thicknesses broadcast to `shape` + (N,) and flattened; the indices are shared by every
    point and closed over. Use inside `jit` (the pieces are traced arrays)."""
    if isinstance(x, Stack):
        n = x.n_layers
        t = jnp.broadcast_to(jnp.asarray(x.thickness), (*shape, n)).reshape(-1, n)
        return t, lambda ti: x._replace(thickness=ti)
    flat = jax.tree.map(lambda v: jnp.broadcast_to(jnp.asarray(v), shape).reshape(-1), x)
    return flat, lambda f: f


def first_point(part):
    """The first point of a `point_split` part (what every point shares when they are one)."""
    return jax.tree.map(lambda v: v[0], part)


def expand_batch(x):
    """Material `x` with a unit batch axis appended, so that it broadcasts against an extra
    trailing axis of angles: a `Film`'s fields (..., 1), a `Stack`'s thickness (..., 1, N)."""
    if isinstance(x, Stack):
        return x._replace(thickness=jnp.asarray(x.thickness)[..., None, :])
    return jax.tree.map(lambda v: jnp.asarray(v)[..., None], x)
