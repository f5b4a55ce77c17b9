"""The `Film` pytree: one dielectric film on a (possibly absorbing) base.

Conventions (SPEC §1): thickness in nm, real refractive indices for the outer medium
(η₁) and the film (η₂), complex index η₃ + iκ₃ for the base (``eta_base + 1j*kappa_base``;
a complex ``eta_base`` is accepted and read that way, see `Film.real_base`). `Film` is a
NamedTuple, hence a JAX pytree: `jax.grad` with respect to a `Film` returns a `Film` of
gradients, and any field may be an array (fields broadcast against each other and against the
angle/wavelength arguments of the functions that take a film).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

__all__ = ["Film"]


class Film(NamedTuple):
    """A film of thickness `thickness` (nm) and index `eta_film` on a base `eta_base + i kappa_base`,
    seen from an outer medium of index `eta_outer`.

    Example:
        >>> Film(600.0, 1.3, 2.0, 0.5)  # the Figure 2/7 film of Kneiphof et al. 2019
        Film(thickness=600.0, eta_film=1.3, eta_base=2.0, kappa_base=0.5, eta_outer=1.0)
    """

    thickness: ArrayLike
    eta_film: ArrayLike
    eta_base: ArrayLike
    kappa_base: ArrayLike = 0.0
    eta_outer: ArrayLike = 1.0

    def astype(self, dtype) -> Film:
        """All fields as arrays of `dtype` (e.g. to run a real-time path in float32)."""
        return jax.tree.map(lambda x: jnp.asarray(x, dtype), self.real_base())

    def real_base(self) -> Film:
        """The same film with a real `eta_base`: a complex ``eta_base = n + ik`` is read as the
        base index n + ik, i.e. (eta_base = n, kappa_base = kappa_base + k). The base index is
        always ``eta_base + 1j * kappa_base``. Works on traced fields (the dtype decides)."""
        eb = self.eta_base
        if not jnp.iscomplexobj(eb):
            return self
        if isinstance(eb, (complex, np.ndarray, np.generic)):
            re, im = np.real(eb), np.imag(eb)
            if isinstance(eb, complex):
                re, im = float(re), float(im)
        else:
            re, im = jnp.real(eb), jnp.imag(eb)
        return self._replace(eta_base=re, kappa_base=self.kappa_base + im)

    @property
    def shape(self) -> tuple[int, ...]:
        """The broadcast shape of the fields."""
        return jnp.broadcast_shapes(*(jnp.shape(x) for x in self))
