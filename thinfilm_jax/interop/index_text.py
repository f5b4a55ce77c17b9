"""Indices and layer stacks written as text: the one parser of the command line (``thinfilm-jax
fit``, ``fit-map``, ``fit-ellips``, ``render``) and of the fits' settings files (SPEC §12).

An index is a number (``1.46``), a complex number n + iκ (``3.9+0.02j``, also ``3.9+0.02i``), a
bundled material name (`thinfilm_jax.optics.materials.MATERIALS`) or the path of a
refractiveindex.info YAML / CSV file (`thinfilm_jax.optics.materials.refractive_index`). A layer
stack is ``"SiO2:250,Si3N4:80"`` (``material:thickness_nm`` per layer, layer 0 facing the outer
medium). A bad value is a `ValueError` that names what is wrong (and the bundled materials).

Example:
    >>> parse_index("1.46"), parse_index(2), parse_index("3.9+0.02j"), parse_index("2.0+0.5i")
    (1.46, 2.0, (3.9+0.02j), (2+0.5j))
    >>> parse_index("SiO2").name
    'SiO2'
    >>> parse_layers("SiO2:250, Si3N4:80")
    [('SiO2', 250.0), ('Si3N4', 80.0)]
    >>> [(e.name, d) for e, d in parse_layers("SiO2:250", indices=True)]
    [('SiO2', 250.0)]
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["parse_index", "parse_layers"]

LAYERS_FORM = "MATERIAL:THICKNESS_NM[,...] (layer 0 first, e.g. 'SiO2:250,Si3N4:80')"


def parse_index(source):
    """An index from text or a number: a number stays a number (a float, or a complex n + iκ
    with κ ≠ 0); a string that is not a number is a bundled material name or the path of a
    refractiveindex.info YAML / CSV file, returned as its index model
    (`thinfilm_jax.optics.materials.refractive_index`). ValueError for anything else (a
    bool, None, a non-finite number, an unknown name or file: the message lists the bundled
    materials)."""
    if isinstance(source, bool) or source is None:
        raise ValueError(f"an index must be a number, a material name or a file, got "
                         f"{source!r}")
    if isinstance(source, int | float):
        v = float(source)
    else:
        text = str(source).strip()
        try:
            v = float(text)
        except ValueError:
            compact = text.replace(" ", "")
            if compact.endswith("i"):  # n+κi, the mathematicians' spelling
                compact = compact[:-1] + "j"
            try:
                v = complex(compact)
            except ValueError:
                from ..optics.materials import refractive_index

                try:
                    return refractive_index(text)
                except (ValueError, TypeError, OSError) as e:
                    raise ValueError(str(e).removeprefix("refractive_index: ")) from None
            if v.imag == 0:
                v = v.real
    if not (math.isfinite(v.real) and math.isfinite(v.imag)):
        raise ValueError(f"an index must be finite, got {source!r}")
    return v


def parse_layers(source, *, indices: bool = False) -> list[tuple[Any, float]]:
    """A layer stack ``"SiO2:250,Si3N4:80"`` (or a list of ``"material:nm"`` strings) →
    [(material, thickness_nm)], layer 0 first: the material as written (a settings file
    records it so), or with ``indices=True`` parsed (`parse_index`). Each material is checked
    either way; ValueError naming the malformed layer."""
    items = source.split(",") if isinstance(source, str) else source
    if not isinstance(items, list | tuple) or not items:
        raise ValueError(f"layers must be {LAYERS_FORM}, got {source!r}")
    out = []
    for i, item in enumerate(items):
        text = str(item).strip()
        mat, sep, d = (t.strip() for t in text.rpartition(":"))
        if not sep or not mat:
            raise ValueError(f"layer {i} {text!r} is not {LAYERS_FORM}")
        try:
            nm = float(d)
        except ValueError:
            raise ValueError(f"layer {i} {text!r}: thickness {d!r} is not a number (nm)") \
                from None
        if not (math.isfinite(nm) and nm >= 0):
            raise ValueError(f"layer {i} {text!r}: thickness must be finite and >= 0 nm")
        try:
            eta = parse_index(mat)
        except ValueError as e:
            raise ValueError(f"layer {i} {text!r}: {e}") from None
        out.append((eta if indices else mat, nm))
    return out
