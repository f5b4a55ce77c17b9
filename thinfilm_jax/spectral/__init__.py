"""Layer 2, from wavelengths to colour bands: observers and the sensitivity Ŝ (`spectra`), band
reflectances exact and Fourier (`reflectance`), the Gaussian-filtered Ŝ(μ, σ²) table (`lut`),
the RGB-to-spectrum basis of environment maps (`uplift`) and XYZ/sRGB/CIEDE2000
(`colorimetry`). Imports `core`, `optics`."""
