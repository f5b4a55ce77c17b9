"""The one registry of shading and reflectance methods, with what each one models.

Every entry point that takes ``method=`` (`rgb_reflectance`, `patch_radiance`,
`envmap_radiance`), the command line and the studies read their method names from here, and
`require` turns a material the method cannot model into a `ValueError` that names the method
and what it lacks (SPEC §12). The registry is executable: a row's ``impl`` is the method
object (or the ``"module:attribute"`` path of it, imported on first use, since the shading
methods live in higher layers) that `spectral.reflectance.rgb_reflectance`,
`shading.patch.patch_radiance` and `shading.ibl.envmap_radiance` call (`implementation`). Adding a method is one module and one
row (docs/how-to/new-method.md); `register` and `unregister` add and remove a row at run time.
`material_path` is the one place that decides how a method reads a material: the one-film
code, the stack code, or a dispersive film at each band's centroid.

Capabilities, per method:

* ``where``: the entry points that offer it ("rgb" = `rgb_reflectance`, "patch" =
  `patch_radiance`, "envmap" = `envmap_radiance`), in the order they list it.
* ``exact``: converges to the physics (the references, Monte Carlo); the others are
  approximations with a measured error (docs/getting-started/methods.md).
* ``dispersion``: "exact" (evaluates every index at each of its own wavelengths), "bands"
  (real-time: the indices of a dispersive single film at each band's centroid wavelength,
  one evaluation per band; docs/studies/materials.md gives the measured ΔE₀₀ per material)
  or "" (constant indices only).
* ``stacks``: models a multi-layer `Stack` (the references exactly; ``ideal`` with the exact
  bands at h = n, tabulated once per homogeneous stack under a map).

Example:
    >>> names("envmap")
    ('reference', 'mc', 'ideal', 'filtered', 'improved', 'khr', 'colour_table')
    >>> names("envmap", exact=False)
    ('ideal', 'filtered', 'improved', 'khr', 'colour_table')
    >>> METHODS["filtered"].stacks, METHODS["reference"].stacks, METHODS["ideal"].stacks
    (False, True, True)
    >>> from thinfilm_jax import Film, ConstantIndex
    >>> material_path(Film(600.0, 1.3, 2.0), "filtered")
    'film'
    >>> material_path(Film(600.0, ConstantIndex(1.3), 2.0), "filtered")
    'bands'
    >>> material_path(Film(600.0, ConstantIndex(1.3), 2.0), "reference")
    'stack'
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any, NamedTuple

from .material import is_dispersive, needs_stack
from .stack import Stack

__all__ = [
    "Method",
    "METHODS",
    "names",
    "MethodNames",
    "implementation",
    "register",
    "unregister",
    "material_path",
    "require",
]


class Method(NamedTuple):
    """One method: its name, where it is offered and what it models."""

    name: str
    where: tuple[str, ...]
    exact: bool
    dispersion: str  # "exact" | "bands" | ""
    stacks: bool
    summary: str
    #: the method object (`shading.methods.ShadingMethod`, or `spectral.reflectance.
    #: BandMethod` for a method of `rgb_reflectance` only), or its "module:attribute" path
    #: (relative to the package)
    impl: Any = None


_ROWS = (
    Method("spectral", ("rgb",), True, "exact", True,
           "the exact bands: the Airy (or stack) reflectance integrated over the observer's λ",
           impl="spectral.reflectance:SPECTRAL"),
    Method("fourier", ("rgb",), False, "bands", False,
           "BB17's Fourier-domain sum after M orders (K 4)",
           impl="spectral.reflectance:FOURIER"),
    Method("reference", ("patch", "envmap"), True, "exact", True,
           "converged quadrature of the exact spectral reflectance",
           impl="shading.methods.reference:REFERENCE"),
    Method("mc", ("envmap",), True, "exact", True,
           "importance-sampled Monte Carlo of the exact reflectance",
           impl="shading.methods.mc:MC"),
    Method("ideal", ("patch", "envmap"), False, "exact", True,
           "BB17 at h = n times the split-sum albedo (a Stack or dispersive film: its exact "
           "bands at h = n, tabulated over cos θ under a map)",
           impl="shading.methods.ideal:IDEAL"),
    Method("filtered_gt_moments", ("patch",), False, "bands", False,
           "K 29 with the true light moments (Figure 7 (b), (f))",
           impl="shading.methods.filtered_gt:GT_MOMENTS"),
    Method("filtered_gt_opd", ("patch",), False, "bands", False,
           "K 29 with the true moments of D (Figure 7 (c), (g))",
           impl="shading.methods.filtered_gt:GT_OPD"),
    Method("filtered", ("patch", "envmap"), False, "bands", False,
           "K 29 with split-sum / prefiltered light moments (Kneiphof 2019)",
           impl="shading.methods.filtered:FILTERED"),
    Method("improved", ("patch", "envmap"), False, "bands", False,
           "K 29 per equal-probability bin of cos θ₁ (this library)",
           impl="shading.methods.improved:IMPROVED"),
    Method("khr", ("rgb", "patch", "envmap"), False, "", False,
           "glTF KHR_materials_iridescence's F_iridescence (linear Rec. 709)",
           impl="shading.methods.khr:KHR"),
    Method("colour_table", ("envmap",), False, "", False,
           "Kneiphof & Klein 2022 prefiltered colour table of one material and map",
           impl="shading.methods.colour_table:COLOUR_TABLE"),
)

#: name → `Method`, in the order the entry points list them (`register` appends).
METHODS: dict[str, Method] = {m.name: m for m in _ROWS}
_RESOLVED: dict[str, Any] = {}


def names(where: str, *, exact: bool | None = None) -> tuple[str, ...]:
    """The method names an entry point offers ("rgb", "patch" or "envmap"), in order;
    ``exact=True`` / ``False`` keeps the exact / the approximate methods only."""
    return tuple(m.name for m in METHODS.values()
                 if where in m.where and (exact is None or m.exact == exact))


class MethodNames(Sequence):
    """The names `names(where, exact=...)` gives, read from the registry at each use: the
    public constants that list an entry point's methods (`ENVMAP_METHODS`, `PATCH_METHODS`,
    `RGB_METHODS`) include a method `register` adds after import. Compares equal to the
    tuple of its names.

    Example:
        >>> MethodNames("rgb") == ("spectral", "fourier", "khr"), "khr" in MethodNames("rgb")
        (True, True)
    """

    def __init__(self, where: str, *, exact: bool | None = None):
        self._where, self._exact = where, exact

    def _names(self) -> tuple[str, ...]:
        return names(self._where, exact=self._exact)

    def __getitem__(self, i):
        return self._names()[i]

    def __len__(self) -> int:
        return len(self._names())

    def __eq__(self, other) -> bool:
        return self._names() == (tuple(other) if isinstance(other, Sequence) else other)

    def __hash__(self) -> int:
        return hash(self._names())

    def __add__(self, other):
        return self._names() + tuple(other)

    def __radd__(self, other):
        return tuple(other) + self._names()

    def __repr__(self) -> str:
        return repr(self._names())


def implementation(method: str):
    """The method object of registry row `method` (its ``impl``, imported on first use)."""
    impl = METHODS[method].impl
    if not isinstance(impl, str):
        return impl
    if method not in _RESOLVED:
        module, attr = impl.split(":")
        # relative to this package, whatever name it was imported under (a study may load an
        # older checkout beside this one under another name: its rows must resolve to its own
        # modules, not to those of the package called thinfilm_jax)
        package = __name__.rpartition(".core.")[0]
        _RESOLVED[method] = getattr(importlib.import_module(f"{package}.{module}"), attr)
    return _RESOLVED[method]


def register(row: Method) -> None:
    """Add `row` to the registry (ValueError if its name is taken); `unregister` removes it."""
    if not isinstance(row, Method):
        raise TypeError(f"row must be a core.methods.Method, got {type(row).__name__}")
    if row.name in METHODS:
        raise ValueError(f"method {row.name!r} is already registered")
    METHODS[row.name] = row


def unregister(name: str) -> None:
    """Remove the row `register` added (a built-in row cannot be removed)."""
    if any(m.name == name for m in _ROWS):
        raise ValueError(f"method {name!r} is built in and cannot be unregistered")
    METHODS.pop(name)
    _RESOLVED.pop(name, None)


def material_path(material, method: str) -> str:
    """How `method` reads `material` (SPEC §12), the one place this is decided: "film" (a
    `Film` of constant indices: the one-film code), "stack" (a `Stack` or dispersive film
    through a method of exact dispersion: the stack code, every index at each wavelength) or
    "bands" (a dispersive single film through a real-time method: the film at each band's
    centroid wavelength, `spectral.reflectance.per_band`). A material the method cannot model
    is the `ValueError` of `require`."""
    if not needs_stack(material):
        return "film"
    require(method, dispersive=is_dispersive(material), stack=isinstance(material, Stack))
    return "stack" if METHODS[method].dispersion == "exact" else "bands"


def require(method: str, *, dispersive: bool = False, stack: bool = False) -> None:
    """Raise a `ValueError` naming `method` and what it lacks when it cannot model a
    dispersive material (`dispersive`) or a multi-layer stack (`stack`)."""
    m = METHODS[method]
    lacks = []
    if stack and not m.stacks:
        lacks.append("layer stacks (a Stack of more than one layer)")
    if dispersive and not m.dispersion:
        lacks.append("dispersive indices (index models)")
    if lacks:
        able = [n for n, r in METHODS.items() if (r.stacks or not stack)
                and (r.dispersion or not dispersive) and set(r.where) & set(m.where)]
        raise ValueError(f"method={method!r} cannot model {' or '.join(lacks)}; methods that "
                         f"can: {able}")
