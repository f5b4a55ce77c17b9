"""Layer 0, what every other layer stands on: the `Film` and `Stack` pytrees (`film`,
`stack`), what the exact paths take and how it is batched (`material`), the registry of
methods and what each models (`methods`), the checks at the public boundary (`_validate`),
atomic file writes (`files`), JAX's persistent compilation cache (`compilation_cache`) and the
batch sharding over devices (`sharding`). Imports nothing else of the package."""

from ._validate import checked
from . import (
    compilation_cache,
    ellipsometry_data,
    film,
    files,
    image,
    material,
    methods,
    sharding,
    stack,
    units,
)
from .compilation_cache import *  # noqa: F403 (its __all__)
from .ellipsometry_data import *  # noqa: F403 (its __all__)
from .film import *  # noqa: F403 (its __all__)
from .files import *  # noqa: F403 (its __all__)
from .image import *  # noqa: F403 (its __all__)
from .material import *  # noqa: F403 (its __all__)
from .methods import *  # noqa: F403 (its __all__)
from .sharding import *  # noqa: F403 (its __all__)
from .stack import *  # noqa: F403 (its __all__)
from .units import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    "checked",
    *compilation_cache.__all__,
    *ellipsometry_data.__all__,
    *film.__all__,
    *files.__all__,
    *image.__all__,
    *material.__all__,
    *methods.__all__,
    *sharding.__all__,
    *stack.__all__,
    *units.__all__,
]
