"""Exchange with other formats, the layer after `fit` and before `render`: a `Film` to and
from a glTF 2.0 material with `KHR_materials_iridescence` and its thickness texture (`gltf`),
OpenPBR Surface's `thin_film_*` parameters (`openpbr`), and indices and layer stacks written
as text (`index_text`: the one parser of the command line and the settings files). Imports
`core`, `optics`, `spectral`.

Example (glTF nm and OpenPBR µm describe the same film):
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.interop import gltf, openpbr
    >>> film, factor = gltf.film_from_gltf(gltf.film_to_gltf(Film(400.0, 1.3, 1.5)))
    >>> openpbr.film_to_openpbr(film, factor)["thin_film_thickness"]
    0.4
"""

from . import index_text
from .index_text import *  # noqa: F403 (its __all__)
from .gltf import (
    EXTENSION,
    IOR_EXTENSION,
    EXTRAS,
    KAPPA_FILM_MAX,
    mix,
    iridescence_mix,
    film_from_gltf,
    constant_film,
    constant_index_error,
    film_to_gltf,
    alpha_from_gltf,
    write_thickness_texture,
    read_thickness_texture,
)
from .gltf_file import load_gltf, read_gltf, uv_sphere, write_gltf
from .openpbr import film_from_openpbr, film_to_openpbr

# Left to their modules (glTF's and OpenPBR's DEFAULTS differ):
# DEFAULTS.

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    "EXTENSION", "IOR_EXTENSION", "EXTRAS", "KAPPA_FILM_MAX", "mix", "iridescence_mix",
    "film_from_gltf", "constant_film", "constant_index_error", "film_to_gltf",
    "alpha_from_gltf", "write_thickness_texture", "read_thickness_texture", "uv_sphere",
    "write_gltf", "load_gltf", "read_gltf",  # gltf
    *index_text.__all__,
    "film_from_openpbr", "film_to_openpbr",  # openpbr
]
