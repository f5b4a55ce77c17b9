r"""glTF `KHR_materials_iridescence`: the extension's `F_iridescence` as a named method (SPEC §10).

The ratified extension (KhronosGroup/glTF, `extensions/2.0/Khronos/KHR_materials_iridescence/
README.md`, "Implementation Notes → Iridescence Fresnel", non-normative) approximates Belcour &
Barla 2017 (BB17) for real time. This module evaluates that approximation, in linear Rec. 709
RGB, before the `iridescenceFactor` mix, so that it can be measured against the exact film
(`rgb_reflectance(method="spectral")`, SPEC §2, §4). In the notation of SPEC §1 (η₁ outer,
η₂ film, η₃ + iκ₃ base, d in nm):

* Interfaces by Schlick (`optics.fresnel.fresnel_schlick`) from normal-incidence
  reflectances: R₁₂ = F_S(((η₂ − η₁)/(η₂ + η₁))², cos θ₁), T₁₂₁ = 1 − R₁₂, and
  R₂₃ = F_S(((n₃ − η₂)/(n₃ + η₂))², cos θ₂) with the base IOR
  n₃ = Fresnel0ToIor(F₀ + 10⁻⁴) = (1 + √(F₀ + 10⁻⁴))/(1 − √(F₀ + 10⁻⁴)), F₀ the exact
  normal-incidence reflectance of η₃ + iκ₃ against air (`normal_reflectance`): κ₃ enters
  through F₀ only and is then dropped, as the extension does ("assumed to be 0.0").
* cos θ₂ by Snell's law, cos²θ₂ = 1 − (η₁/η₂)² sin²θ₁; total internal reflection in the film
  (cos²θ₂ < 0, only for η₂ < η₁) gives R₁₂ = 1, hence F = 1 (the README returns vec3(1.0)).
* Phases 0 or π by the IOR ordering: φ₁₂ = π if η₂ < η₁, φ₂₁ = π − φ₁₂, φ₂₃ = π if
  n₃ < η₂; φ = φ₂₁ + φ₂₃.
* OPD 𝒟 = 2 η₂ d cos θ₂ (the ratified README and the sample renderer use cos θ₂; an early
  draft printed cos θ₁).
* Fourier sum with M = 2: R₁₂₃ = clamp(R₁₂R₂₃, 10⁻⁵, 0.9999), r₁₂₃ = √R₁₂₃,
  R_s = T₁₂₁² R₂₃ / (1 − R₁₂₃), C₀ = R₁₂ + R_s, C_m = (R_s − T₁₂₁) r₁₂₃^m,

  $$ F = \max\Big(0,\; C_0 + \sum_{m=1}^{2} 2\,C_m\,\mathbf S(m\mathcal D,\, m\varphi)\Big), $$

  with 𝐒 = XYZ→Rec.709 · xyz and xyz the closed-form Fourier transform of a Gaussian fit of
  the CIE 1931 2° functions in wavenumber ν = 1/λ (the README's `evalSensitivity`): per
  Gaussian g of amplitude a_g, centre μ_g (m⁻¹) and "var" v_g (m²), with p = 2π 𝒟·10⁻⁹,
  a_g √(2π v_g) cos(μ_g p + φ) exp(−v_g p²) / 1.0685·10⁻⁷ (x has two Gaussians).

Constants checked rather than trusted (tests/spectral/test_khr.py::test_constants_*): the matrix is
the XYZ→RGB matrix of the Rec. 709 primaries with the D65 white (0.95047, 1, 1.08883) to
≤ 5·10⁻⁸ (its printed 7 decimals); 1.0685·10⁻⁷ m is ∫ȳ dλ = 106.857 nm of CIE 1931 2°
(colour-science's table), so xyz(0) = (1.0005, 1.0002, 1.0011): the fit's areas; the fit
tracks the transform of the tabulated functions to ≤ 0.07 up to 𝒟 = 2 µm and decays too fast
beyond (at 4 µm: 0.000 against −0.060 for x̄).

What the formula is not (measured in tests/spectral/test_khr.py, table in its docstring): C₀ enters
every channel as is (a flat spectrum is RGB (1, 1, 1)), while the m ≥ 1 terms map the
equal-energy-normalised XYZ without adaptation, 𝐒(0, 0) = (1.2054, 0.9483, 0.9100), so d = 0
is neither the Schlick base nor grey: it is C₀ + 2𝐒(0)(C₁ cos φ + C₂ cos 2φ). The clamp
R₁₂₃ ≥ 10⁻⁵ keeps a film matched to the outer medium (η₂ = η₁) from vanishing.

To and from the library's bands (the whites differ: D65 here, the equal-energy mirror there):
the library's one conversion, `colorimetry.rec709_to_bands` and its inverse
`colorimetry.bands_to_rec709` (ITU-R BT.709 primaries, CAT02 von Kries between the two whites;
a flat reflectance R is RGB (R, R, R) and bands (R, R, R)), re-exported here. It reads the
RGB with BT.709's matrix derived from D65's chromaticity (0.3127, 0.3290), which differs from
the extension's printed matrix (white Z = 1.08883) by ≤ 5.2·10⁻⁴: against reading it back
with the printed matrix, `khr`'s outputs move by ≤ 2·10⁻⁵ per band and their ΔE₀₀ to the
exact film by ≤ 0.002 (the films of tests/spectral/test_khr.py). ΔE against the exact film:
`delta_e_to_exact` (CIE 1931 2°) or `colorimetry.delta_e2000_rec709` (any observer), the
convention of every study.

Implementation notes: the base IOR is kept as the ratio (1 + s)/(1 − s), s = √(F₀ + 10⁻⁴),
and R₂₃'s normal reflectance is computed as ((1 + s) − η₂(1 − s))²/((1 + s) + η₂(1 − s))²,
algebraically the README's value, finite for every F₀ (F₀ > 0.9999, where the README's
division gives an infinite or negative IOR, takes the limit n₃ → ∞: s is capped at 1).
Gradients are finite everywhere (double-where square root at cos θ₂ = 0; the clamp and the
phase switches have zero derivative).

Example (a soap-like film on glass; the three channels differ, and the TIR branch is exactly 1):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.spectral.khr import khr_reflectance
    >>> rgb = khr_reflectance(Film(400.0, 1.33, 1.5), 1.0)
    >>> rgb.shape, bool(np.ptp(np.asarray(rgb)) > 0.01)
    ((3,), True)
    >>> np.asarray(khr_reflectance(Film(400.0, 1.0, 1.5, eta_outer=1.5), 0.2)).tolist()
    [1.0, 1.0, 1.0]
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..optics.fresnel import fresnel_schlick, normal_reflectance, safe_sqrt
from .colorimetry import CIE_1931, delta_e2000_rec709, rec709_to_band_matrix
from .colorimetry import bands_to_rec709 as bands_to_rec709  # re-exported (module docstring)
from .colorimetry import rec709_to_bands as rec709_to_bands

__all__ = [
    "XYZ_TO_REC709",
    "FIT_NORM",
    "TERMS",
    "sensitivity_rec709",
    "khr_bands",
    "khr_reflectance",
    "delta_e_to_exact",
    "khr_to_bands",
]

#: XYZ → linear Rec. 709 RGB as printed by the extension (row-major here; the GLSL `mat3` is
#: column-major). Checked against the primaries and D65 in tests/spectral/test_khr.py.
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])

#: The Gaussian fit of `evalSensitivity`: (xyz component, val, pos [1/m], var [m²]); the
#: x component has a second Gaussian. Normalised by `FIT_NORM` [m].
GAUSSIANS = ((0, 5.4856e-13, 1.6810e06, 4.3278e09),
             (1, 4.4201e-13, 1.7953e06, 9.3046e09),
             (2, 5.2481e-13, 2.2084e06, 6.6121e09),
             (0, 9.7470e-14, 2.2399e06, 4.5282e09))
FIT_NORM = 1.0685e-7
#: Guard added to F₀ before Fresnel0ToIor (the README's "guard against 1.0").
F0_GUARD = 1e-4
#: Clamp of R₁₂R₂₃ in the README's compound terms.
R123_MIN, R123_MAX = 1e-5, 0.9999
#: Number of Fourier orders of the extension.
TERMS = 2


@functools.cache
def _sensitivity_tables():
    """Host float64 (rgb weights (4, 3), k [rad/nm], w [1/nm²]) of the fit, the XYZ→Rec.709
    matrix folded in: 𝐒(𝒟, φ) = Σ_g B_g cos(k_g 𝒟 + φ) exp(−w_g 𝒟²), 𝒟 in nm."""
    comp = np.array([g[0] for g in GAUSSIANS])
    val, pos, var = (np.array([g[i] for g in GAUSSIANS]) for i in (1, 2, 3))
    amp = val * np.sqrt(2.0 * np.pi * var) / FIT_NORM
    weights = XYZ_TO_REC709[:, comp].T * amp[:, None]
    scale = 2.0 * np.pi * 1e-9  # phase per nm of OPD
    return weights, pos * scale, var * scale**2


def sensitivity_rec709(opd, shift) -> Array:
    """𝐒(𝒟, φ): the extension's `evalSensitivity` in linear Rec. 709, shape (..., 3).

    `opd` in nm and `shift` (rad) broadcast; float64 constants cast to their dtype."""
    opd, shift = jnp.asarray(opd), jnp.asarray(shift)
    dtype = jnp.result_type(opd, shift, float)
    opd, shift = jnp.broadcast_arrays(opd, shift)
    weights, k, w = (jnp.asarray(t, dtype) for t in _sensitivity_tables())
    lead = (1,) * opd.ndim  # explicit ranks: no implicit rank promotion
    k, w = k.reshape(lead + k.shape), w.reshape(lead + w.shape)
    x = opd[..., None]
    terms = jnp.cos(k * x + shift[..., None]) * jnp.exp(-w * (x * x))
    return jnp.matmul(terms, weights, precision=jax.lax.Precision.HIGHEST)


def khr_bands(film: Film, cos_theta) -> Array:
    """`F_iridescence` (..., 3) of a broadcast film at cos θ₁ (no validation; see module)."""
    c = jnp.asarray(cos_theta)
    dtype = jnp.result_type(c, *film, float)
    eta1, eta2, eta3, kappa3, d = (jnp.asarray(x, dtype) for x in (
        film.eta_outer, film.eta_film, film.eta_base, film.kappa_base, film.thickness))
    c = jnp.asarray(c, dtype)
    pi = jnp.asarray(math.pi, dtype)
    # first interface, Snell's law and total internal reflection in the film
    r0 = ((eta2 - eta1) / (eta2 + eta1)) ** 2
    cos2_sq = 1.0 - (eta1 / eta2) ** 2 * ((1.0 - c) * (1.0 + c))
    tir = cos2_sq < 0
    cos2 = safe_sqrt(cos2_sq)
    r12 = jnp.where(tir, 1.0, fresnel_schlick(r0, c))
    t121 = 1.0 - r12
    # second interface: base IOR n₃ = (1 + s)/(1 − s) from F₀ against air, κ₃ dropped
    s = jnp.minimum(jnp.sqrt(normal_reflectance(eta3, kappa3) + F0_GUARD), 1.0)
    num, den = (1.0 + s) - eta2 * (1.0 - s), (1.0 + s) + eta2 * (1.0 - s)
    r23 = fresnel_schlick((num / den) ** 2, cos2)
    # phases 0 or π by the IOR ordering (φ₂₁ = π − φ₁₂; n₃ < η₂ ⇔ num < 0)
    phi = pi * ((eta2 >= eta1).astype(dtype) + (num < 0).astype(dtype))
    opd = 2.0 * eta2 * d * cos2
    # the Fourier sum of BB17 truncated at M = 2 with the README's clamp
    r123 = jnp.clip(r12 * r23, R123_MIN, R123_MAX)
    rs = t121 * t121 * r23 / (1.0 - r123)
    out = (r12 + rs)[..., None]
    cm = rs - t121
    amp = jnp.sqrt(r123)
    for m in range(1, TERMS + 1):
        cm = cm * amp
        out = out + (2.0 * cm)[..., None] * sensitivity_rec709(m * opd, m * phi)
    return jnp.maximum(out, 0.0)


def khr_reflectance(film: Film, cos_theta) -> Array:
    """glTF `KHR_materials_iridescence` `F_iridescence` of `film` at cos θ₁, shape
    broadcast(film, cos_theta) + (3,), linear Rec. 709 RGB, before the `iridescenceFactor`
    mix (SPEC §10; the formula and its departures from the exact film: module docstring).
    Same as ``rgb_reflectance(film, cos_theta, method="khr")``.

    Example (broadcasting over angles):
        >>> from thinfilm_jax import Film
        >>> khr_reflectance(Film(500.0, 1.5, 1.5), [1.0, 0.5]).shape
        (2, 3)
    """
    film = V.check_film(film)
    cos_theta = V.check_cos_theta(cos_theta)
    V.check_broadcast([("film", jnp.zeros(film.shape)), ("cos_theta", cos_theta)])
    return _khr_jit(film, cos_theta)


@jax.jit
def _khr_jit(film, cos_theta):
    leaves, tree = jax.tree.flatten((film, cos_theta))
    return khr_bands(*jax.tree.unflatten(tree, jnp.broadcast_arrays(*leaves)))


def delta_e_to_exact(khr_rgb, exact_xyz_bands) -> np.ndarray:
    """CIEDE2000 between `khr` output (..., 3) and the exact CIE 1931 2° bands (..., 3) of
    ``rgb_reflectance(film, c, method="spectral", observer="cie_1931_2")`` (host, NumPy).

    The two have different whites: the exact bands take the perfect mirror (equal-energy
    light) as white, the extension maps a flat reflectance to RGB (1, 1, 1), i.e. D65. This is
    ``colorimetry.delta_e2000_rec709(khr_rgb, exact_xyz_bands, "cie_1931_2")``, the library's
    one convention (SPEC §7): the RGB taken to the bands by `rec709_to_bands` (CAT02 from D65
    to the equal-energy white), both compared in CIELAB with the mirror as white, so a flat
    reflectance R gives ΔE = 0.

    Example (a perfect mirror in both conventions):
        >>> float(delta_e_to_exact(np.ones(3), np.ones(3))) < 1e-9
        True
    """
    return delta_e2000_rec709(khr_rgb, exact_xyz_bands, CIE_1931)


def khr_to_bands(rgb, observer: str) -> Array:
    """`colorimetry.rec709_to_bands` on a JAX array (…, 3): `khr`'s linear Rec. 709 in the
    observer's bands, the space every method of `patch_radiance` and `envmap_radiance`
    returns (its 3×3 matrix a constant of the trace; HIGHEST precision)."""
    m = jnp.asarray(rec709_to_band_matrix(observer), rgb.dtype)
    return jnp.matmul(rgb, m.T, precision=jax.lax.Precision.HIGHEST)
