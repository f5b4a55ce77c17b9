"""Layer 3, the surface: GGX/Beckmann microfacet distributions, Smith masking, albedo and the
patch quadratures (`microfacet`); the classic lobes written once: normal distributions (`ndf`),
masking–shadowing (`masking`), diffuse terms (`diffuse`) and their composition with a Fresnel
term into band values (`material`). Imports `core`, `optics`, `spectral`."""
