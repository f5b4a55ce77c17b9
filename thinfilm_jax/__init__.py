"""thinfilm_jax: differentiable thin-film iridescence on microfacet surfaces.

Exact spectral reference (Airy), Belcour & Barla 2017 Fourier-domain band integration,
Kneiphof et al. 2019 filtered reflectance for rough surfaces, and a uniform-lighting patch
integrator. Conventions (docs/SPEC.md): nm, radians, GGX α, colour bands of unit area.

The public face is this file; the package is grouped in layers, each importing only those
before it: `core` (the `Film` and `Stack` pytrees, the method registry, input checks, file
output, compilation cache, sharding) → `optics` (interface amplitudes, exact Airy R, layer
stacks, index models and bundled materials, BB17 series terms, the D distribution) →
`spectral` (observers and Ŝ, band reflectances, the Ŝ(μ,σ²) table, the RGB basis of maps,
colorimetry, glTF's iridescence) → `brdf` (normal distributions, masking, diffuse terms,
`Material`, patch quadrature) → `realtime` (K 29, the improved model, per-point kernels) →
`shading` (uniform-light patch, environment maps, prefiltering, suns, the exact and
real-time IBL) → `fit` (optimistix fits, thickness maps) → `interop` (glTF,
OpenPBR, the text forms of indices and layers) → `render` (Figure 7, the scenes of
`thinfilm-jax render`, figures without pyplot; nothing below imports it) → `cli`. The
research studies and benchmarks live outside the package, in the repository's `benchmarks/`.

Example (SPEC §4: the Fourier path K 4 converges to the exact spectral bands, which share its
λ quadrature):
    >>> import numpy as np
    >>> import thinfilm_jax as tf
    >>> film = tf.Film(600.0, 1.3, 2.0, 0.5)  # the film of Kneiphof et al. 2019, Figure 7
    >>> exact = tf.rgb_reflectance(film, 0.8)  # method="spectral"
    >>> exact.shape
    (3,)
    >>> def error(m):  # M Fourier orders against the exact bands
    ...     fourier = tf.rgb_reflectance(film, 0.8, method="fourier", terms=m)
    ...     return float(np.abs(fourier - exact).max())
    >>> 1e-6 < error(2) < 1e-4, error(12) < 1e-12  # M = 2 (the papers'), M = 12
    (True, True)
"""

from .realtime import kernels as kernels
from .core._validate import checked as checked
from .core.compilation_cache import enable_compilation_cache as enable_compilation_cache
from .optics.airy import airy_reflectance as airy_reflectance
from .optics.fresnel import fresnel_schlick as fresnel_schlick
from .optics.fresnel import normal_reflectance as normal_reflectance
from .shading.envmap import SHIPPED as SHIPPED_ENVMAPS
from .shading.envmap import EnvMap as EnvMap
from .shading.envmap import load_envmap as load_envmap
from .core.film import Film as Film
from .core.stack import Stack as Stack
from .core.methods import METHODS as METHODS
from .optics.stack import stack_reflectance as stack_reflectance
from .optics.stack import stack_transmittance as stack_transmittance
from .optics.materials import MATERIALS as MATERIALS
from .optics.materials import refractive_index as refractive_index
from .optics.index import IndexModel as IndexModel
from .optics.index import ConstantIndex as ConstantIndex
from .optics.index import TabulatedIndex as TabulatedIndex
from .optics.index import FormulaIndex as FormulaIndex
from .optics.index import CompositeIndex as CompositeIndex
from .optics.index import cauchy as cauchy
from .optics.index import sellmeier as sellmeier
from .fit.film_fit import FitOptions as FitOptions
from .fit.film_fit import FitResult as FitResult
from .fit.options import MisfitWarning as MisfitWarning
from .fit.film_fit import fit_film as fit_film
from .fit.film_fit import fit_spectrum as fit_spectrum
from .fit.photo import PhotoResult as PhotoResult
from .fit.photo import fit_photo as fit_photo
from .spectral.camera import camera_response as camera_response
from .core.image import read_photo as read_photo
from .interop.gltf import film_from_gltf as film_from_gltf
from .interop.gltf import film_to_gltf as film_to_gltf
from .shading.ibl import ENVMAP_METHODS as ENVMAP_METHODS
from .shading.ibl import envmap_radiance as envmap_radiance
from .spectral.lut import ShatLUT as ShatLUT
from .spectral.lut import build_shat_lut as build_shat_lut
from .brdf.microfacet import albedo as albedo
from .brdf.material import (  # the classic lobes beside the film (brdf/material.py)
    Material as Material, brdf_value as brdf_value, ggx_lobe as ggx_lobe,
    beckmann_lobe as beckmann_lobe, ggx_aniso_lobe as ggx_aniso_lobe,
    blinn_phong_lobe as blinn_phong_lobe, ashikhmin_shirley_lobe as ashikhmin_shirley_lobe,
    no_specular as no_specular, no_fresnel as no_fresnel, schlick_fresnel as schlick_fresnel,
    dielectric_fresnel as dielectric_fresnel, conductor_fresnel as conductor_fresnel,
    film_fresnel as film_fresnel, no_diffuse as no_diffuse, lambert_diffuse as lambert_diffuse,
    oren_nayar_diffuse as oren_nayar_diffuse,
    ashikhmin_shirley_diffuse as ashikhmin_shirley_diffuse,
)
from .optics.opd import OPDMoments as OPDMoments
from .realtime.options import ModelOptions as ModelOptions
from .optics.opd import taylor_opd_moments as taylor_opd_moments
from .shading.patch import PATCH_METHODS as PATCH_METHODS
from .shading.patch import patch_radiance as patch_radiance
from .shading.patch import patch_radiance_mc as patch_radiance_mc
from .shading.material_patch import material_patch_radiance as material_patch_radiance
from .shading.material_ibl import material_envmap_radiance as material_envmap_radiance
from .shading.prefilter import PrefilteredEnvMap as PrefilteredEnvMap
from .shading.prefilter import prefilter_envmap as prefilter_envmap
from .shading.colour_table import ColourTable as ColourTable
from .shading.colour_table import prefilter_colour as prefilter_colour
from .brdf.carpaint import CarPaint as CarPaint
from .brdf.carpaint import car_paint as car_paint
from .brdf.carpaint import PAINTS as PAINTS
from .shading.carpaint_ibl import paint_envmap_radiance as paint_envmap_radiance
from .shading.carpaint_ibl import paint_patch_radiance as paint_patch_radiance
from .spectral.khr import khr_reflectance as khr_reflectance
from .spectral.colorimetry import bands_to_rec709 as bands_to_rec709
from .spectral.colorimetry import rec709_to_bands as rec709_to_bands
from .spectral.reflectance import rgb_reflectance as rgb_reflectance
from .optics.series import SeriesTerms as SeriesTerms
from .shading.sources import Sources as Sources
from .shading.sources import extract_sources as extract_sources
from .optics.series import series_terms as series_terms
from .core.sharding import map_sharded as map_sharded
from .core.sharding import shard_batch as shard_batch
from .spectral.spectra import OBSERVERS as OBSERVERS
from .spectral.spectra import get_observer as get_observer
from .spectral.spectra import sensitivity_ft as sensitivity_ft
# ellipsometry (SPEC §14): ψ, Δ, their files, their fit, oscillator dispersion models
from .optics.ellipsometry import ellipsometry as ellipsometry
from .core.ellipsometry_data import read_ellipsometry as read_ellipsometry
from .fit.ellipsometry_fit import fit_ellipsometry as fit_ellipsometry
from .optics.oscillators import DielectricIndex as DielectricIndex
from .optics.oscillators import lorentz as lorentz
from .optics.oscillators import gaussian as gaussian
from .optics.oscillators import tauc_lorentz as tauc_lorentz
from .optics.effective_medium import EffectiveMedium as EffectiveMedium
# microscope objectives and 2D materials (SPEC §14): optics/objective.py, optics/materials.py
from .optics.objective import objective_reflectance as objective_reflectance
from .optics.materials import MONOLAYER_NM as MONOLAYER_NM

# raw spectrometer spectra (SPEC §14): fit_spectrum(..., envelope=k) and its reader
from .fit.raw_spectrum import Envelope as Envelope
from .fit.spectrum_file import read_spectrum as read_spectrum

__version__ = "0.2.0"
