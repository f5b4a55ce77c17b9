"""Layer 1, the wave optics at one angle and wavelength: interface amplitudes (`fresnel`), the
exact Airy reflectance of one film (`airy`), N-layer stacks' reflectance and transmittance
(`stack`), refractive-index models (`index`) and the bundled materials (`materials`),
Belcour & Barla 2017's series terms (`series`) and the optical path difference and its
distribution (`opd`). Imports `core`."""

from . import (
    airy,
    effective_medium,
    fresnel,
    index,
    materials,
    objective,
    opd,
    oscillators,
    series,
    stack,
    turns,
)
from .airy import *  # noqa: F403 (its __all__)
from .effective_medium import *  # noqa: F403 (its __all__)
from .fresnel import *  # noqa: F403 (its __all__)
from .index import *  # noqa: F403 (its __all__)
from .materials import *  # noqa: F403 (its __all__)
from .objective import *  # noqa: F403 (its __all__)
from .opd import *  # noqa: F403 (its __all__)
from .oscillators import *  # noqa: F403 (its __all__)
from .series import *  # noqa: F403 (its __all__)
from .stack import *  # noqa: F403 (its __all__)
from .turns import *  # noqa: F403 (its __all__)
from .ellipsometry import (
    check_lossless_ambient,
    ellipsometric_ratio,
    fold_delta,
    psi_delta_traced,
)

# Left to their modules (the function ellipsometry names its module):
# ellipsometry.

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *airy.__all__,
    *effective_medium.__all__,
    "check_lossless_ambient", "ellipsometric_ratio", "fold_delta", "psi_delta_traced",  # ellipsometry
    *fresnel.__all__,
    *index.__all__,
    *materials.__all__,
    *objective.__all__,
    *opd.__all__,
    *oscillators.__all__,
    *series.__all__,
    *stack.__all__,
    *turns.__all__,
]
