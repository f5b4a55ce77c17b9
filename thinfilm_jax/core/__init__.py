"""Layer 0, what every other layer stands on: the `Film` and `Stack` pytrees (`film`,
`stack`), what the exact paths take and how it is batched (`material`), the registry of
methods and what each models (`methods`), the checks at the public boundary (`_validate`),
atomic file writes (`_io`), JAX's persistent compilation cache (`compilation_cache`) and the
batch sharding over devices (`sharding`). Imports nothing else of the package."""

from ._validate import checked
from .compilation_cache import enable_compilation_cache, cached_host_tables
from .ellipsometry_data import EllipsometryData, read_ellipsometry
from .film import Film
from .image import (
    ENCODINGS,
    RAW_SUFFIXES,
    Photo,
    srgb_decoding_derivative,
    estimate_noise,
    read_photo,
    read_mask,
)
from .material import (
    is_dispersive,
    needs_stack,
    as_stack,
    batch_shape,
    point_split,
    first_point,
    expand_batch,
)
from .methods import (
    Method,
    METHODS,
    names,
    implementation,
    register,
    unregister,
    material_path,
    require,
)
from .sharding import batch_mesh, map_sharded, shard_batch, to_host, initialize_distributed
from .stack import Stack
from .units import HC_EV_NM, unit_name, to_nanometres

__all__ = [
    "checked",
    "enable_compilation_cache",
    "cached_host_tables",
    "EllipsometryData",
    "read_ellipsometry",
    "Film",
    "ENCODINGS",
    "RAW_SUFFIXES",
    "Photo",
    "srgb_decoding_derivative",
    "estimate_noise",
    "read_photo",
    "read_mask",
    "is_dispersive",
    "needs_stack",
    "as_stack",
    "batch_shape",
    "point_split",
    "first_point",
    "expand_batch",
    "Method",
    "METHODS",
    "names",
    "implementation",
    "register",
    "unregister",
    "material_path",
    "require",
    "batch_mesh",
    "map_sharded",
    "shard_batch",
    "to_host",
    "initialize_distributed",
    "Stack",
    "HC_EV_NM",
    "unit_name",
    "to_nanometres",
]
