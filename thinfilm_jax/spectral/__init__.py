"""Layer 2, from wavelengths to colour bands: observers and the sensitivity Ŝ (`spectra`), band
reflectances exact (films and stacks) and Fourier, and the band-centroid films of the
real-time methods (`reflectance`), the Gaussian-filtered Ŝ(μ, σ²) table (`lut`), the
RGB-to-spectrum basis of environment maps (`uplift`), glTF's iridescence (`khr`) and the one
bands ↔ Rec. 709 / sRGB conversion and CIEDE2000 convention (`colorimetry`). Imports `core`,
`optics`."""

from . import camera, colorimetry, khr, lut, reflectance, spectra, uplift
from .camera import *  # noqa: F403 (its __all__)
from .colorimetry import *  # noqa: F403 (its __all__)
from .khr import *  # noqa: F403 (its __all__)
from .lut import *  # noqa: F403 (its __all__)
from .reflectance import *  # noqa: F403 (its __all__)
from .spectra import *  # noqa: F403 (its __all__)
from .uplift import *  # noqa: F403 (its __all__)

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *camera.__all__,
    *colorimetry.__all__,
    *khr.__all__,
    *lut.__all__,
    *reflectance.__all__,
    *spectra.__all__,
    *uplift.__all__,
]
