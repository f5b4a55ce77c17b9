r"""A `Film` to and from OpenPBR Surface `thin_film_*` parameters.

Source: the OpenPBR Surface specification v1.1.1 (2026-04-17; AcademySoftwareFoundation/OpenPBR,
`index.html` "Thin-film iridescence", and its MaterialX `reference/open_pbr_surface.mtlx`,
nodedef version 1.1.1):

| OpenPBR (default)                        | `Film`                                        |
|------------------------------------------|-----------------------------------------------|
| `thin_film_thickness` (0.5) in **µm**     | d = 1000 × thickness nm (the .mtlx: × 1000)  |
| `thin_film_ior` (1.4, range (0, ∞))       | η₂                                            |
| `specular_ior` (1.5), `base_metalness` = 0 | η₃, κ₃ = 0                                  |
| ambient medium, `coat_weight` = 0         | η₁ = 1                                        |
| `thin_film_weight` (0, coverage)          | the returned weight                           |

The specification recommends Belcour & Barla 2017 for the film (as glTF's extension does) and
leaves the metal case open: its metals are the Schlick "F82-tint" model with no complex IOR, so
a metallic base (`base_metalness` > 0) needs ``eta_base=``/``kappa_base=`` from the caller
(only `base_metalness` = 1; a partial mix is a ValueError), as in `interop.gltf`. Also a
ValueError, never dropped: κ₃ > 0 or η₁ ≠ 1 on export; `coat_weight` > 0 (the film then sits
under the coat, a second layer), `specular_weight` ≠ 1 or `specular_color` ≠ white (they scale
the base Fresnel: no single η₃), unknown parameter names, non-finite values, values outside
the specification's ranges, and IORs below 1 (allowed by OpenPBR, outside this library's
domain, SPEC §1).

Round trip: every field is exact except the thickness, whose nm → µm → nm scaling by 1000 is
exact to 1 ulp (bit-exact for 194 of 200 random thicknesses, tests/interop/test_interop.py).

Example:
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.interop.openpbr import film_from_openpbr, film_to_openpbr
    >>> params = film_to_openpbr(Film(500.0, 1.4, 1.5))
    >>> params["thin_film_thickness"], params["thin_film_weight"]
    (0.5, 1.0)
    >>> film_from_openpbr(params)
    (Film(thickness=500.0, eta_film=1.4, eta_base=1.5, kappa_base=0.0, eta_outer=1.0), 1.0)
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..core import _validate as V
from ..core.film import Film
from .gltf import _number  # a finite JSON number in range: one check for both formats

__all__ = ["DEFAULTS", "film_from_openpbr", "film_to_openpbr"]

SPEC_VERSION = "1.1.1"
#: Defaults of the parameters read here (OpenPBR v1.1.1 parameter tables / .mtlx nodedef).
DEFAULTS = {"thin_film_weight": 0.0, "thin_film_thickness": 0.5, "thin_film_ior": 1.4,
            "specular_ior": 1.5, "base_metalness": 0.0, "coat_weight": 0.0,
            "specular_weight": 1.0, "specular_color": (1.0, 1.0, 1.0)}
#: Every parameter of the v1.1.1 nodedef (others are accepted and do not affect the film).
PARAMETERS = (
    "base_weight", "base_color", "base_diffuse_roughness", "base_metalness", "specular_weight",
    "specular_color", "specular_roughness", "specular_ior", "specular_roughness_anisotropy",
    "transmission_weight", "transmission_color", "transmission_depth", "transmission_scatter",
    "transmission_scatter_anisotropy", "transmission_dispersion_scale",
    "transmission_dispersion_abbe_number", "subsurface_weight", "subsurface_color",
    "subsurface_radius", "subsurface_radius_scale", "subsurface_scatter_anisotropy",
    "fuzz_weight", "fuzz_color", "fuzz_roughness", "coat_weight", "coat_color",
    "coat_roughness", "coat_roughness_anisotropy", "coat_ior", "coat_darkening",
    "thin_film_weight", "thin_film_thickness", "thin_film_ior", "emission_luminance",
    "emission_color", "geometry_opacity", "geometry_thin_walled", "geometry_normal",
    "geometry_coat_normal", "geometry_tangent", "geometry_coat_tangent")
#: µm → nm
NM_PER_UM = 1000.0


def film_from_openpbr(params, *, eta_base=None, kappa_base=None) -> tuple[Film, float]:
    """(`Film`, `thin_film_weight`) of OpenPBR Surface parameters (a dict of name → value;
    missing names take the v1.1.1 defaults). `eta_base`/`kappa_base`: the base of a metal
    (`base_metalness` = 1), which OpenPBR describes by F82-tint only. ValueError: see module."""
    if not isinstance(params, Mapping):
        raise ValueError(f"params must be a dict of OpenPBR parameters, got "
                         f"{type(params).__name__}")
    unknown = set(params) - set(PARAMETERS)
    if unknown:
        raise ValueError(f"unknown OpenPBR parameter(s) {sorted(unknown)} (v{SPEC_VERSION})")
    p = {**DEFAULTS, **params}
    weight = _number("thin_film_weight", p["thin_film_weight"], 0.0, 1.0)
    d = NM_PER_UM * _number("thin_film_thickness", p["thin_film_thickness"], 0.0)
    eta2 = _number("thin_film_ior", p["thin_film_ior"], 1.0)
    if _number("coat_weight", p["coat_weight"], 0.0, 1.0) != 0:
        raise ValueError("coat_weight > 0 puts the film under a coat (a second layer, outer "
                         "index coat_ior): one Film cannot hold it")
    if _number("specular_weight", p["specular_weight"], 0.0) != 1:
        raise ValueError("specular_weight != 1 scales the base Fresnel: no single eta_base")
    colour = np.asarray(p["specular_color"], float)
    if colour.shape != (3,) or not np.all(colour == 1.0):
        raise ValueError("specular_color other than (1, 1, 1) tints the base Fresnel: no "
                         "single eta_base")
    metalness = _number("base_metalness", p["base_metalness"], 0.0, 1.0)
    if metalness == 1:
        if eta_base is None:
            raise ValueError("a metallic base (base_metalness = 1) is OpenPBR's F82-tint "
                             "Schlick model, no eta + i kappa: pass eta_base= and kappa_base=")
        return Film(d, eta2, _number("eta_base", eta_base, 0.0),
                    _number("kappa_base", 0.0 if kappa_base is None else kappa_base, 0.0),
                    1.0), weight
    if metalness > 0:
        raise ValueError(f"base_metalness = {metalness} mixes a metal and a dielectric base: "
                         f"one Film cannot hold it")
    if eta_base is not None or kappa_base is not None:
        raise ValueError("eta_base=/kappa_base= are for metallic bases; a dielectric base is "
                         "specular_ior")
    return Film(d, eta2, _number("specular_ior", p["specular_ior"], 1.0), 0.0, 1.0), weight


def film_to_openpbr(film: Film, weight=1.0) -> dict:
    """OpenPBR Surface parameters {thin_film_weight, thin_film_thickness (µm), thin_film_ior,
    specular_ior, base_metalness = 0} of a one-valued `film`. κ₃ > 0 or η₁ ≠ 1 → ValueError."""
    film = V.check_film(film)
    vals = {}
    for k, v in film._asdict().items():
        a = np.asarray(v)
        if a.size != 1:
            raise ValueError(f"film.{k} must be one value, got shape {a.shape}")
        vals[k] = float(a.reshape(()))
    if vals["kappa_base"] != 0:
        raise ValueError(f"OpenPBR metals are F82-tint, not eta + i kappa: cannot hold "
                         f"kappa_base = {vals['kappa_base']!r}")
    if vals["eta_outer"] != 1:
        raise ValueError(f"the film must sit under the ambient medium (eta_outer = 1); got "
                         f"{vals['eta_outer']!r}")
    return {"thin_film_weight": _number("weight", weight, 0.0, 1.0),
            "thin_film_thickness": vals["thickness"] / NM_PER_UM,
            "thin_film_ior": vals["eta_film"], "specular_ior": vals["eta_base"],
            "base_metalness": 0.0}
