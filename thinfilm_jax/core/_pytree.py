"""The one way this package writes a pytree with static fields: a frozen dataclass registered
with JAX (`jax.tree_util.register_dataclass`), its array fields leaves and its static fields
part of the tree's structure (hashed into a jit's cache key). The container rule is on
docs/reference/style.md."""

import dataclasses

import jax

__all__ = ["pytree_dataclass"]


def pytree_dataclass(cls, data_fields, meta_fields):
    """`cls` as a frozen dataclass registered as a pytree: `data_fields` (arrays, or pytrees
    of arrays) are its leaves, `meta_fields` (strings, numbers, tuples: hashable) are static.

    Example:
        >>> import jax.numpy as jnp
        >>> class Lobe:
        ...     kind: str
        ...     alpha: object = 0.5
        >>> Lobe = pytree_dataclass(Lobe, ["alpha"], ["kind"])
        >>> leaves, tree = jax.tree_util.tree_flatten(Lobe("ggx", jnp.float32(0.3)))
        >>> len(leaves), leaves[0].dtype.name  # the kind is static: part of `tree`
        (1, 'float32')
        >>> tree == jax.tree_util.tree_structure(Lobe("beckmann", jnp.float32(0.3)))
        False
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    return jax.tree_util.register_dataclass(cls, data_fields=data_fields, meta_fields=meta_fields)
