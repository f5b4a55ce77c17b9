"""The fits' parameters: every real scalar of a material, named by its path (SPEC §12).

A material is a pytree (a `Film`, a `Film` with index models, or a `Stack`); `fit_film` and
`fit_spectrum` free some of its scalars and keep the others. A scalar is named by the path
of its leaf (`jax.tree_util.tree_flatten_with_path`, written as `jax.tree_util.keystr`
without the leading dot), then its position inside a non-scalar leaf, then the part of a
complex one:

* a constant `Film`: its fields, ``"thickness"``, ``"eta_film"``, ``"eta_base"``,
  ``"kappa_base"``, ``"eta_outer"`` (the names the fits always had);
* a `Stack`: ``"thickness[i]"`` (layer i, layer 0 facing the outer medium; ``"thickness"``
  is ``"thickness[0]"``), a constant layer index ``"eta[i]"``, ``"eta_base"``,
  ``"eta_outer"``; a complex constant n + iκ is two scalars, ``"eta_base.real"`` and
  ``"eta_base.imag"``;
* an index model's leaves below its field: a `FormulaIndex`'s coefficients
  ``"eta[1].coefficients[0]"`` (for `cauchy` A; ``[1]`` is B, ``[3]`` C), a
  `ConstantIndex`'s ``"eta_film.n"`` / ``"eta_film.k"``, a table's ``"eta_base.n[17]"``;
  in a dispersive `Film` the same below ``eta_film`` / ``eta_base`` / ``eta_outer``
  (``"eta_film.coefficients[0]"``);
* the patch fit's roughness: ``"alpha"``.

`ParamMap` is the static half (the tree structure, the leaves' shapes, which scalars are
free): hashable, a `jax.jit` static argument. The values travel as the flat tuple of leaves
(`leaves`), so new values never recompile, and `ParamMap.rebuild` puts the free values back
into the tree with no positional unpacking of fields. A small leaf is rebuilt element by
element (no scatter), so derivatives with respect to the free scalars never flow through
the fixed ones.

Example:
    >>> from thinfilm_jax.core.stack import Stack
    >>> from thinfilm_jax.optics.index import cauchy
    >>> s = Stack([250.0, 80.0], (cauchy(1.45, 0.0035), 2.0), 3.9 + 0.02j)
    >>> [n for n in scalar_names(s) if not n.startswith("eta[0].coefficients[2")]
    ['thickness[0]', 'thickness[1]', 'eta[0].coefficients[0]', 'eta[0].coefficients[1]', \
'eta[0].coefficients[3]', 'eta[0].coefficients[4]', 'eta[1]', 'eta_base.real', \
'eta_base.imag', 'eta_outer']
"""

from __future__ import annotations

import re
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.film import Film
from ..core.stack import Stack

__all__ = ["ParamMap", "default_box", "resolve", "scalar_names", "scalar_table", "value_of"]

_PATH = re.compile(r"^[A-Za-z_]\w*(\[\d+\]|\.[A-Za-z_]\w*)*$")
#: a leaf with at most this many scalars is rebuilt element by element, larger by scatter
_STACKED = 16


class Entry(NamedTuple):
    """One real scalar: leaf `leaf` of the flattened (material, α), flat position `flat`
    inside it, `part` "" (a real leaf), "real" or "imag" (a complex one)."""

    leaf: int
    flat: int
    part: str


def is_path_name(name: str) -> bool:
    """True for a name of the path grammar (``eta[1].coefficients[0]``, ``thickness[2]``)."""
    return isinstance(name, str) and bool(_PATH.match(name)) and ("[" in name or "." in name)


def _leaves_with_names(material):
    out = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(material)[0]:
        out.append((jax.tree_util.keystr(path).lstrip("."), leaf))
    return out


def scalar_table(material, with_alpha: bool = False) -> dict[str, Entry]:
    """{name: `Entry`} of every real scalar of `material` (module docstring), in leaf order;
    "alpha" last (the leaf after the material's) when `with_alpha`."""
    table = {}
    leaves = _leaves_with_names(material)
    for i, (name, leaf) in enumerate(leaves):
        shape = np.shape(leaf)
        cplx = bool(np.iscomplexobj(leaf))
        parts = ("real", "imag") if cplx else ("",)
        for j in range(int(np.prod(shape, dtype=int))):
            pos = "".join(f"[{p}]" for p in np.unravel_index(j, shape)) if shape else ""
            for part in parts:
                table[name + pos + (f".{part}" if part else "")] = Entry(i, j, part)
    if with_alpha:
        table["alpha"] = Entry(len(leaves), 0, "")
    return table


def scalar_names(material, with_alpha: bool = False) -> list[str]:
    """The names of `scalar_table`, in order."""
    return list(scalar_table(material, with_alpha))


def resolve(name: str, table: dict, material) -> str:
    """The table's name for `name`: ``"thickness"`` is layer 0 of a `Stack`
    (``"thickness[0]"``) and ``"thickness[0]"`` the thickness of a `Film`; else `name`."""
    if isinstance(material, Stack) and name == "thickness":
        return "thickness[0]"
    if isinstance(material, Film) and name == "thickness[0]":
        return "thickness"
    return name


def describe(table: dict) -> list[str]:
    """The names of `table` for a message: a long leaf's scalars shortened to a range."""
    out, seen = [], {}
    for name, e in table.items():
        seen.setdefault((e.leaf, e.part), []).append(name)
    for names in seen.values():
        out.extend(names) if len(names) <= 4 else out.append(f"{names[0]} … {names[-1]}")
    return out


def layer_of(name: str, material) -> int | None:
    """The layer whose thickness `name` (a table name) is, or None."""
    if isinstance(material, Film):
        return 0 if name == "thickness" else None
    m = re.fullmatch(r"thickness\[(\d+)\]", name)
    return int(m.group(1)) if m else None


def _index_slots(material) -> list[tuple[str, Any]]:
    if isinstance(material, Stack):
        return [(f"eta[{i}]", e) for i, e in enumerate(material.eta)] + [
            ("eta_base", material.eta_base), ("eta_outer", material.eta_outer)]
    return [(k, getattr(material, k)) for k in ("eta_film", "eta_base", "eta_outer")]


def default_box(name: str, value: float, material, defaults: dict) -> tuple[float, float]:
    """The box of a free scalar when no bound names it.

    * a name of `defaults` (the `Film` fields, "alpha"): that box;
    * a layer thickness ``"thickness[i]"``: the box of ``"thickness"``;
    * the real part (n) of a constant index (``"eta[i]"``, ``"eta_base.real"``, a
      `ConstantIndex`'s ``.n``): the box of ``"eta_film"`` (1, 4) when it holds the value,
      else (n/2, 2n); its imaginary part (κ, ``.imag``, ``.k``): the box of ``"kappa_base"``
      (0, 10);
    * any other model parameter (a dispersion coefficient, a table value) of initial value
      v: [v − w, v + w] with w = max(|v|/4, 0.05), e.g. a Cauchy A = 1.45 in [1.09, 1.81].
    """
    if name in defaults:
        return defaults[name]
    if layer_of(name, material) is not None:
        return defaults["thickness"]
    for slot, eta in _index_slots(material):
        if not name.startswith(slot):
            continue
        rest = name[len(slot):]
        constant = not callable(eta) or type(eta).__name__ == "ConstantIndex"
        if constant and rest in ("", ".real", ".n"):
            lo, hi = defaults["eta_film"]
            return (lo, hi) if lo <= value <= hi else (value / 2.0, value * 2.0)
        if constant and rest in (".imag", ".k"):
            return defaults["kappa_base"]
    w = max(abs(value) / 4.0, 0.05)
    return (value - w, value + w)


def leaves(material, alpha, dtype) -> tuple:
    """The flat leaves of (material, α) as arrays: real ones in `dtype`, complex ones in the
    matching complex dtype (α last; None when there is no α)."""
    cdt = jnp.complex128 if jnp.dtype(dtype) == jnp.float64 else jnp.complex64
    out = []
    for leaf in jax.tree_util.tree_leaves(material):
        a = jnp.asarray(leaf)
        out.append(a.astype(cdt if jnp.iscomplexobj(a) else dtype))
    out.append(jnp.asarray(1.0 if alpha is None else alpha, dtype))
    return tuple(out)


def value_of(material, alpha, name: str):
    """The value of the scalar `name` of (material, α) (a table name or an alias)."""
    if name == "alpha":
        return alpha
    table = scalar_table(material)
    e = table[resolve(name, table, material)]
    leaf = jnp.asarray(jax.tree_util.tree_leaves(material)[e.leaf]).reshape(-1)[e.flat]
    return {"": leaf, "real": jnp.real(leaf), "imag": jnp.imag(leaf)}[e.part]


class ParamMap(NamedTuple):
    """Static description of the free scalars of (material, α): hashable (a jit static
    argument); the values are the `leaves` tuple."""

    treedef: Any  # of the material
    shapes: tuple  # of every leaf, α last
    entries: tuple  # the free scalars' `Entry`s, in the order of `free`

    @classmethod
    def of(cls, material, entries) -> ParamMap:
        ls, treedef = jax.tree_util.tree_flatten(material)
        return cls(treedef, tuple(np.shape(v) for v in ls) + ((),), tuple(entries))

    def host_values(self, material, alpha=None) -> np.ndarray:
        """The free scalars (p,) of the concrete (material, α), on the host (float64)."""
        host = [np.asarray(v) for v in jax.tree_util.tree_leaves(material)]
        host.append(np.asarray(1.0 if alpha is None else alpha))
        out = []
        for e in self.entries:
            v = host[e.leaf].reshape(-1)[e.flat]
            out.append(float({"": np.real(v), "real": np.real(v), "imag": np.imag(v)}[e.part]))
        return np.asarray(out)

    def rebuild(self, x_free, base):
        """(material, α) with the free scalars from `x_free` (p,) and the rest from `base`."""
        ls = list(base)
        groups: dict[int, list] = {}
        for k, e in enumerate(self.entries):
            groups.setdefault(e.leaf, []).append((k, e))
        for i, items in groups.items():
            b = ls[i]
            size = int(np.prod(b.shape, dtype=int))
            if jnp.iscomplexobj(b):
                parts = {"real": jnp.real(b).reshape(-1), "imag": jnp.imag(b).reshape(-1)}
            else:
                parts = {"": b.reshape(-1)}
            for part, flat in parts.items():
                mine = {e.flat: x_free[k].astype(flat.dtype) for k, e in items
                        if e.part == part}
                if not mine:
                    continue
                if size <= _STACKED:  # element by element: no derivative through fixed ones
                    flat = jnp.stack([mine.get(j, flat[j]) for j in range(size)])
                else:
                    for j, v in mine.items():
                        flat = flat.at[j].set(v)
                parts[part] = flat
            if jnp.iscomplexobj(b):
                ls[i] = jax.lax.complex(parts["real"], parts["imag"]).reshape(b.shape)
            else:
                ls[i] = parts[""].reshape(b.shape)
        return jax.tree_util.tree_unflatten(self.treedef, ls[:-1]), ls[-1]
