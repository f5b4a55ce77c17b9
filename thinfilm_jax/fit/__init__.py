"""Layer 6, inverse problems: film parameters from patch radiances (`film_fit`, its starts
and bounds in `options`) and thickness maps from images (`thickness_map`), on one fitting
engine (`engine`: box transform, Levenberg–Marquardt, covariance; optimistix's other
solvers by name). Imports the layers below."""

from . import (
    ellipsometry_fit,
    engine,
    film_fit,
    forward,
    map_models,
    map_quality,
    multistart,
    options,
    params,
    photo,
    photo_flags,
    photo_light,
    photo_model,
    photo_screen,
    pixelwise,
    raw_spectrum,
    results,
    spectrum_file,
    thickness_map,
)
from .ellipsometry_fit import *  # noqa: F403 (its __all__)
from .engine import *  # noqa: F403 (its __all__)
from .film_fit import *  # noqa: F403 (its __all__)
from .forward import *  # noqa: F403 (its __all__)
from .map_models import *  # noqa: F403 (its __all__)
from .map_quality import *  # noqa: F403 (its __all__)
from .multistart import *  # noqa: F403 (its __all__)
from .options import *  # noqa: F403 (its __all__)
from .params import *  # noqa: F403 (its __all__)
from .photo import *  # noqa: F403 (its __all__)
from .photo_flags import *  # noqa: F403 (its __all__)
from .photo_light import *  # noqa: F403 (its __all__)
from .photo_model import *  # noqa: F403 (its __all__)
from .photo_screen import *  # noqa: F403 (its __all__)
from .pixelwise import *  # noqa: F403 (its __all__)
from .raw_spectrum import *  # noqa: F403 (its __all__)
from .results import *  # noqa: F403 (its __all__)
from .spectrum_file import *  # noqa: F403 (its __all__)
from .thickness_map import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *ellipsometry_fit.__all__,
    *engine.__all__,
    *film_fit.__all__,
    *forward.__all__,
    *map_models.__all__,
    *map_quality.__all__,
    *multistart.__all__,
    *options.__all__,
    *params.__all__,
    *photo.__all__,
    *photo_flags.__all__,
    *photo_light.__all__,
    *photo_model.__all__,
    *photo_screen.__all__,
    *pixelwise.__all__,
    *raw_spectrum.__all__,
    *results.__all__,
    *spectrum_file.__all__,
    *thickness_map.__all__,
]
