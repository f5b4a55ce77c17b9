"""Layer 1, the wave optics at one angle and wavelength: interface amplitudes (`fresnel`), the
exact Airy reflectance of one film (`airy`), N-layer stacks' reflectance and transmittance
(`stack`), refractive-index models (`index`) and the bundled materials (`materials`),
Belcour & Barla 2017's series terms (`series`) and the optical path difference and its
distribution (`opd`). Imports `core`."""
