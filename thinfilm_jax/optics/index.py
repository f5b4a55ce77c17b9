"""Refractive-index models (SPEC §12): n + iκ as a function of wavelength.

An index model is a pytree (`equinox.Module`) called with wavelengths in nm and returning the
complex index n + iκ (κ ≥ 0) with the complex dtype matching the wavelengths' precision. Its
numeric fields are leaves (so `jax.grad` reaches, e.g., Cauchy coefficients); its name,
citation and wavelength range are static.

`index_at(eta, wavelength)` is the one place the exact paths evaluate an index: a number
(real or complex) or array is a constant index, a model is called.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array


class IndexModel(eqx.Module):
    """Base class of index models: ``model(wavelength_nm)`` → complex n + iκ."""

    def __call__(self, wavelength) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError


def is_index_model(x) -> bool:
    """True for an index model (a callable pytree), False for a number or an array."""
    return isinstance(x, IndexModel)


def index_at(eta, wavelength) -> Array:
    """The index `eta` at `wavelength` (nm): a model is evaluated, a number or array is
    returned as an array (a constant index; its shape broadcasts with the wavelengths)."""
    if is_index_model(eta):
        return eta(wavelength)
    return jnp.asarray(eta)
