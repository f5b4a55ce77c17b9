"""Layer 5, light: the uniform-light patch (`patch`, SPEC §7), environment maps (`envmap`),
their prefiltering for the real-time methods (`prefilter`), suns split from a map
(`sources`), the exact image-based-lighting integral (`ibl_reference`) and
`envmap_radiance` (`ibl`, SPEC §9); one module per method (`methods`), looked up in the
registry (`core.methods`). Imports the layers below."""

from . import (
    carpaint_ibl,
    colour_table,
    compare,
    envmap,
    ibl,
    ibl_adaptive,
    ibl_integrand,
    ibl_reference,
    material_ibl,
    material_patch,
    patch,
    prefilter,
    sources,
)
from .carpaint_ibl import *  # noqa: F403 (its __all__)
from .colour_table import *  # noqa: F403 (its __all__)
from .compare import *  # noqa: F403 (its __all__)
from .envmap import *  # noqa: F403 (its __all__)
from .ibl import *  # noqa: F403 (its __all__)
from .ibl_adaptive import *  # noqa: F403 (its __all__)
from .ibl_integrand import *  # noqa: F403 (its __all__)
from .ibl_reference import *  # noqa: F403 (its __all__)
from .material_ibl import *  # noqa: F403 (its __all__)
from .material_patch import *  # noqa: F403 (its __all__)
from .patch import *  # noqa: F403 (its __all__)
from .prefilter import *  # noqa: F403 (its __all__)
from .sources import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *carpaint_ibl.__all__,
    *colour_table.__all__,
    *compare.__all__,
    *envmap.__all__,
    *ibl.__all__,
    *ibl_adaptive.__all__,
    *ibl_integrand.__all__,
    *ibl_reference.__all__,
    *material_ibl.__all__,
    *material_patch.__all__,
    *patch.__all__,
    *prefilter.__all__,
    *sources.__all__,
]
