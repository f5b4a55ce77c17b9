"""The one registry of shading and reflectance methods, with what each one models.

Every entry point that takes ``method=`` (`rgb_reflectance`, `patch_radiance`,
`envmap_radiance`), the command line and the studies read their method names from here, and
`require` turns a material the method cannot model into a `ValueError` that names the method
and what it lacks (SPEC §12). Adding a method is one `Method` row.

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
    >>> METHODS["filtered"].stacks, METHODS["reference"].stacks, METHODS["ideal"].stacks
    (False, True, True)
"""

from __future__ import annotations

from typing import NamedTuple


class Method(NamedTuple):
    """One method: its name, where it is offered and what it models."""

    name: str
    where: tuple[str, ...]
    exact: bool
    dispersion: str  # "exact" | "bands" | ""
    stacks: bool
    summary: str


_ROWS = (
    Method("spectral", ("rgb",), True, "exact", True,
           "the exact bands: the Airy (or stack) reflectance integrated over the observer's λ"),
    Method("fourier", ("rgb",), False, "bands", False,
           "BB17's Fourier-domain sum after M orders (K 4)"),
    Method("reference", ("patch", "envmap"), True, "exact", True,
           "converged quadrature of the exact spectral reflectance"),
    Method("mc", ("envmap",), True, "exact", True,
           "importance-sampled Monte Carlo of the exact reflectance"),
    Method("ideal", ("patch", "envmap"), False, "exact", True,
           "BB17 at h = n times the split-sum albedo (a Stack or dispersive film: its exact "
           "bands at h = n, tabulated over cos θ under a map)"),
    Method("filtered_gt_moments", ("patch",), False, "bands", False,
           "K 29 with the true light moments (Figure 7 (b), (f))"),
    Method("filtered_gt_opd", ("patch",), False, "bands", False,
           "K 29 with the true moments of D (Figure 7 (c), (g))"),
    Method("filtered", ("patch", "envmap"), False, "bands", False,
           "K 29 with split-sum / prefiltered light moments (Kneiphof 2019)"),
    Method("improved", ("patch", "envmap"), False, "bands", False,
           "K 29 per equal-probability bin of cos θ₁ (this library)"),
    Method("khr", ("rgb", "patch", "envmap"), False, "", False,
           "glTF KHR_materials_iridescence's F_iridescence (linear Rec. 709)"),
    Method("colour_table", ("envmap",), False, "", False,
           "Kneiphof & Klein 2022 prefiltered colour table of one material and map"),
)

#: name → `Method`, in the order the entry points list them.
METHODS: dict[str, Method] = {m.name: m for m in _ROWS}


def names(where: str) -> tuple[str, ...]:
    """The method names an entry point offers ("rgb", "patch" or "envmap"), in order."""
    return tuple(m.name for m in _ROWS if where in m.where)


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
