"""The material of `thinfilm-jax render --scene sphere` (`scene`): a `Film` or a `Stack`
from the parsed command line (`make_material`), its text (`describe`), which methods can
model it (`check_methods`), and its JSON record in ``render.json`` (`material_json`,
`material_from_json`: rendering the record again gives the same images).

Example (a stack of two bundled materials on silicon, as JSON and back):
    >>> from thinfilm_jax.interop.index_text import parse_layers
    >>> m = make_material(layers=parse_layers("SiO2:250,Si3N4:80", indices=True),
    ...                   eta_base=parse_index("Si"))
    >>> describe(m)
    'air | SiO2 250 nm, Si3N4 80 nm | Si'
    >>> describe(material_from_json(material_json(m))) == describe(m)
    True
"""

from __future__ import annotations

import numpy as np

from ..core.film import Film
from ..core.material import is_dispersive
from ..core.methods import require
from ..core.stack import Stack
from ..interop.index_text import parse_index
from ..optics.index import is_index_model
from ..optics.materials import MATERIALS, refractive_index

__all__ = [
    "make_material",
    "describe",
    "check_methods",
    "index_json",
    "index_from_json",
    "material_json",
    "material_from_json",
]


def make_material(thickness=600.0, eta_film=1.2, eta_base=2.0, *, layers=None, eta_outer=1.0):
    """A `Film` (one layer) or a `Stack` (`layers` with two or more) from parsed values.

    A complex base n + iκ becomes `Film(…, n, κ)`; a complex film index or an index model
    anywhere makes the film dispersive (the exact methods' stack code, SPEC §12).
    """
    if layers is not None and len(layers) > 1:
        return Stack([d for _, d in layers], tuple(e for e, _ in layers), eta_base, eta_outer)
    if layers is not None:
        eta_film, thickness = layers[0]
    if isinstance(eta_film, complex):
        eta_film = refractive_index(eta_film)
    models = any(is_index_model(e) for e in (eta_film, eta_base, eta_outer))
    if isinstance(eta_base, complex) and not models:
        return Film(float(thickness), float(eta_film), eta_base.real, eta_base.imag,
                    float(eta_outer))
    if models and not is_index_model(eta_base) and isinstance(eta_base, complex):
        eta_base = refractive_index(eta_base)
    return Film(float(thickness), eta_film, eta_base, 0.0, eta_outer)


def describe(x) -> str:
    """A short text of an index or a material (labels, titles, JSON)."""
    if is_index_model(x):
        return str(getattr(x, "name", "") or type(x).__name__)
    if isinstance(x, complex):
        return f"{x.real:g}{x.imag:+g}i"
    if isinstance(x, Stack):
        layers = ", ".join(f"{describe(e)} {float(d):g} nm"
                           for e, d in zip(x.eta, np.asarray(x.thickness)))
        return f"air | {layers} | {describe(x.eta_base)}"
    if isinstance(x, Film):
        base = (describe(x.eta_base) if is_index_model(x.eta_base) or not float(x.kappa_base)
                else describe(complex(float(x.eta_base), float(x.kappa_base))))
        return (f"air | {describe(x.eta_film)} {float(np.asarray(x.thickness)):g} nm | {base}")
    return f"{float(x):g}"


def check_methods(material, methods) -> None:
    """`core.methods.require` for every method: a method that cannot model `material` is a
    `ValueError` naming the method and what it lacks."""
    for m in methods:
        require(m, dispersive=is_dispersive(material), stack=isinstance(material, Stack))


def index_json(x):
    """An index as JSON: a real number, ``{"n", "k"}`` of a complex or constant one, or the
    name of a bundled material (`MATERIALS`); a model read from a file keeps its name under
    ``"file"`` (it is not re-loadable from the record: give the file again)."""
    from ..optics.index import ConstantIndex

    if isinstance(x, ConstantIndex):
        x = complex(np.asarray(x(550.0)).reshape(()))
    if is_index_model(x):
        return x.name if x.name in MATERIALS else {"file": x.name}
    if isinstance(x, str):
        return x
    v = complex(np.asarray(x).reshape(()))
    return v.real if v.imag == 0 else {"n": v.real, "k": v.imag}


def index_from_json(v):
    """The inverse of `index_json`: a float, a complex or an index model."""
    if isinstance(v, dict) and "file" in v:
        raise ValueError(f"the record names an index read from a file ({v['file']!r}): it "
                         "cannot be re-loaded from the record, give the file again")
    if isinstance(v, dict):
        return complex(v["n"], v["k"]) if v["k"] else float(v["n"])
    if isinstance(v, str):
        return parse_index(v)
    return float(v)


def material_json(x) -> dict:
    """A `Film` or `Stack` of `make_material` as JSON that `material_from_json` reads back:
    its layers as [index, thickness nm] (layer 0 facing the outer medium), base, outer
    medium, and the `describe` text."""
    if isinstance(x, Stack):
        layers = [[index_json(e), float(d)] for e, d in zip(x.eta, np.asarray(x.thickness))]
        base = index_json(x.eta_base)
    else:
        layers = [[index_json(x.eta_film), float(np.asarray(x.thickness))]]
        kappa = float(np.asarray(x.kappa_base))
        base = index_json(x.eta_base if not kappa else
                          complex(float(np.asarray(x.eta_base)), kappa))
    return {"layers": layers, "eta_base": base, "eta_outer": index_json(x.eta_outer),
            "description": describe(x)}


def material_from_json(d: dict):
    """The `Film` or `Stack` that `material_json` recorded."""
    layers = [(index_from_json(e), float(t)) for e, t in d["layers"]]
    return make_material(layers=layers, eta_base=index_from_json(d["eta_base"]),
                         eta_outer=index_from_json(d["eta_outer"]))
