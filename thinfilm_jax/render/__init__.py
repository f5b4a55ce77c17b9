"""Layer 8 (after `interop`, before `cli`): what users run to see a film, beyond the library's
functions. One concern per module:

* `figure7` — Figure 7 of Kneiphof et al. 2019 (``thinfilm-jax figure7``, ``make figure7``).
* `scene` — one's own film or stack on a sphere, and a soap bubble (``thinfilm-jax render``).
* `study_scenes` — the sphere renders of Kneiphof et al. 2019, Figures 3–6, and the car
  paints (``thinfilm-jax render --scene fig4|fig3|varying|carpaint``).
* `plot` — figures on matplotlib's Agg canvas without pyplot's global state; matplotlib is
  the optional ``[plots]`` extra, imported when a figure is drawn.

Nothing in the layers below imports this package. The research studies and benchmarks that
measure the library are not part of it: they live in the repository's ``benchmarks/`` folder
(``python -m benchmarks.bench`` from a clone).
"""

from . import bubble, figure7, plot, scene, scene_material, study_scenes
from .bubble import *  # noqa: F403 (its __all__)
from .figure7 import *  # noqa: F403 (its __all__)
from .plot import *  # noqa: F403 (its __all__)
from .scene import *  # noqa: F403 (its __all__)
from .scene_material import *  # noqa: F403 (its __all__)
from .study_scenes import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *bubble.__all__,
    *figure7.__all__,
    *plot.__all__,
    *scene.__all__,
    *scene_material.__all__,
    *study_scenes.__all__,
]
