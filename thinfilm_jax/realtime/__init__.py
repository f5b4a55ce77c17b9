"""Layer 4, the real-time film models: Kneiphof et al. 2019's filtered reflectance
(`filtered`, K 20–29), this library's improved model (`improved`), the fused per-point
kernels (`kernels`) and the knobs they share (`options`). Imports the layers below."""
