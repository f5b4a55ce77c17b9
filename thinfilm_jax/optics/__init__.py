"""Layer 1, the wave optics of one film at one angle and wavelength: interface amplitudes
(`fresnel`), the exact Airy reflectance (`airy`), Belcour & Barla 2017's series terms
(`series`) and the optical path difference and its distribution (`opd`). Imports `core`."""
