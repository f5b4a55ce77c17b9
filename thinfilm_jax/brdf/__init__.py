"""Layer 3, the surface: GGX/Beckmann microfacet distributions, Smith masking, albedo and the
patch quadratures (`microfacet`). Imports `core`, `optics`, `spectral`."""
