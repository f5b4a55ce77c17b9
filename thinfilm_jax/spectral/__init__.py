"""Layer 2, from wavelengths to colour bands: observers and the sensitivity Ŝ (`spectra`), band
reflectances exact (films and stacks) and Fourier, and the band-centroid films of the
real-time methods (`reflectance`), the Gaussian-filtered Ŝ(μ, σ²) table (`lut`), the
RGB-to-spectrum basis of environment maps (`uplift`), glTF's iridescence (`khr`) and the one
bands ↔ Rec. 709 / sRGB conversion and CIEDE2000 convention (`colorimetry`). Imports `core`,
`optics`."""
