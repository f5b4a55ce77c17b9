"""Layer 5, light: the uniform-light patch (`patch`, SPEC §7), environment maps (`envmap`),
their prefiltering for the real-time methods (`prefilter`), suns split from a map
(`sources`), the exact image-based-lighting integral (`ibl_reference`) and
`envmap_radiance` (`ibl`, SPEC §9); one module per method (`methods`), looked up in the
registry (`core.methods`). Imports the layers below."""
