"""Layer 3, the surface: GGX/Beckmann microfacet distributions, Smith masking, albedo and the
patch quadratures (`microfacet`); the classic lobes written once: normal distributions (`ndf`),
masking–shadowing (`masking`), diffuse terms (`diffuse`) and their composition with a Fresnel
term into band values (`material`). Imports `core`, `optics`, `spectral`."""

from . import carpaint
from .carpaint import *  # noqa: F403 (its __all__)
from .diffuse import DIFFUSES, lambert, oren_nayar, oren_nayar_ab
from .masking import (
    MASKINGS,
    lambda_cos_ggx,
    lambda_cos_beckmann,
    lambda_cos,
    lambda_cos_ggx_aniso,
    smith_separable,
    smith_correlated,
    v_cavity,
    visibility_smith_separable,
    visibility_smith_correlated,
    visibility_v_cavity,
    visibility_ashikhmin_shirley,
)
from .material import (
    MASKINGS,
    FRESNELS,
    DIFFUSES,
    Specular,
    Fresnel,
    Diffuse,
    Material,
    brdf_value,
    ggx_lobe,
    beckmann_lobe,
    ggx_aniso_lobe,
    blinn_phong_lobe,
    ashikhmin_shirley_lobe,
    no_specular,
    no_fresnel,
    schlick_fresnel,
    dielectric_fresnel,
    conductor_fresnel,
    film_fresnel,
    no_diffuse,
    lambert_diffuse,
    oren_nayar_diffuse,
    ashikhmin_shirley_diffuse,
)
from .microfacet import (
    PatchQuadrature,
    normal_distribution,
    DEFAULT_QUADRATURE,
    smith_lambda,
    smith_g2,
    brdf_no_fresnel,
    patch_quadrature,
    light_moments,
    albedo,
    lobe_moments_normal_view,
    splitsum_light_moments,
    view_direction,
    sample_patch_mc,
)
from .ndf import (
    beckmann,
    ggx,
    ggx_aniso,
    blinn_phong,
    blinn_phong_specular,
    ashikhmin_shirley_pdf,
    walter_alpha,
)

# Left to their modules (ashikhmin_shirley, NDFS and smith_g1 differ between modules):
# NDFS, ashikhmin_shirley, smith_g1.

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    *carpaint.__all__,
    "DIFFUSES", "lambert", "oren_nayar", "oren_nayar_ab",  # diffuse
    "MASKINGS", "lambda_cos_ggx", "lambda_cos_beckmann", "lambda_cos",
    "lambda_cos_ggx_aniso", "smith_separable", "smith_correlated", "v_cavity",
    "visibility_smith_separable", "visibility_smith_correlated", "visibility_v_cavity",
    "visibility_ashikhmin_shirley",  # masking
    "MASKINGS", "FRESNELS", "DIFFUSES", "Specular", "Fresnel", "Diffuse", "Material",
    "brdf_value", "ggx_lobe", "beckmann_lobe", "ggx_aniso_lobe", "blinn_phong_lobe",
    "ashikhmin_shirley_lobe", "no_specular", "no_fresnel", "schlick_fresnel",
    "dielectric_fresnel", "conductor_fresnel", "film_fresnel", "no_diffuse",
    "lambert_diffuse", "oren_nayar_diffuse", "ashikhmin_shirley_diffuse",  # material
    "PatchQuadrature", "normal_distribution", "DEFAULT_QUADRATURE", "smith_lambda",
    "smith_g2", "brdf_no_fresnel", "patch_quadrature", "light_moments", "albedo",
    "lobe_moments_normal_view", "splitsum_light_moments", "view_direction",
    "sample_patch_mc",  # microfacet
    "beckmann", "ggx", "ggx_aniso", "blinn_phong", "blinn_phong_specular",
    "ashikhmin_shirley_pdf", "walter_alpha",  # ndf
]
