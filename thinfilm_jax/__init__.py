"""thinfilm_jax: differentiable thin-film iridescence on microfacet surfaces.

Exact spectral reference (Airy), Belcour & Barla 2017 Fourier-domain band integration,
Kneiphof et al. 2019 filtered reflectance for rough surfaces, and a uniform-lighting patch
integrator. See SPEC.md conventions: nm, radians, GGX α, bands of unit area.
"""

from .airy import airy_reflectance as airy_reflectance
from .film import Film as Film
from .reflectance import rgb_reflectance as rgb_reflectance
from .series import SeriesTerms as SeriesTerms
from .series import series_terms as series_terms
from .spectra import OBSERVERS as OBSERVERS
from .spectra import get_observer as get_observer
from .spectra import sensitivity_ft as sensitivity_ft

__version__ = "0.1.0"
