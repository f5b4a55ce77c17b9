"""The `Stack` pytree: N coherent layers on a semi-infinite base (SPEC §12).

Layer 0 faces the outer medium. ``thickness`` holds the N thicknesses in nm on its last axis
(leading axes, if any, are a batch); ``eta`` is a tuple of N indices, each a number (real or
complex n + iκ) or an index model (`thinfilm_jax.optics.index`); ``eta_base`` and
``eta_outer`` likewise. A `Film` is the one-layer stack (`Stack.from_film`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp
from jax.typing import ArrayLike

from .film import Film

__all__ = ["Stack"]


class Stack(NamedTuple):
    """N layers of thicknesses `thickness` (nm, last axis) and indices `eta` on `eta_base`,
    seen from `eta_outer`.

    Example:
        >>> Stack([100.0, 50.0], (1.46, 2.0), 3.9 + 0.02j).n_layers
        2
    """

    thickness: ArrayLike
    eta: tuple[Any, ...]
    eta_base: Any
    eta_outer: Any = 1.0

    @property
    def n_layers(self) -> int:
        return len(self.eta)

    @classmethod
    def from_film(cls, film: Film) -> Stack:
        """The one-layer stack of `film` (base index eta_base + i kappa_base)."""
        eb = film.eta_base
        if not hasattr(eb, "__call__"):
            eb = jnp.asarray(eb) + 1j * jnp.asarray(film.kappa_base)
        return cls(jnp.asarray(film.thickness)[..., None], (film.eta_film,), eb, film.eta_outer)
