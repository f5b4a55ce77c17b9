"""Layer 4, the real-time film models: Kneiphof et al. 2019's filtered reflectance
(`filtered`, K 20–29), this library's improved model (`improved`), the fused per-point
kernels (`kernels`) and the knobs they share (`options`). Imports the layers below."""

from . import filtered, improved, improved_table, kernels, options
from .filtered import *  # noqa: F403 (its __all__)
from .improved import *  # noqa: F403 (its __all__)
from .improved_table import *  # noqa: F403 (its __all__)
from .kernels import *  # noqa: F403 (its __all__)
from .options import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *filtered.__all__,
    *improved.__all__,
    *improved_table.__all__,
    *kernels.__all__,
    *options.__all__,
]
