r"""Belcour & Barla 2017 series form of the Airy reflectance (SPEC §3, K 4).

Per polarisation, with R₁₂ = |r₁₂|², R₂₃ = |r₂₃|², T₁₂₁ = 1 − R₁₂, φ₂ = arg r₂₁ + arg r₂₃:

$$ R = C_0 + 2\sum_{m\ge1} C_m\cos(m\Phi),\quad \Phi = 2\pi D/\lambda + \varphi_2,\quad
   C_0 = R_{12} + R_*,\ R_* = \frac{T_{121}^2 R_{23}}{1 - R_{12}R_{23}},\
   C_m = (R_* - T_{121})\left(\sqrt{R_{12}R_{23}}\right)^m. $$

We keep the product z = r₂₁ r₂₃ = −r₁₂ r₂₃ instead of (√(R₁₂R₂₃), φ₂): since
|z| = √(R₁₂R₂₃) and arg z = φ₂, C_m e^{imφ₂} = (R_* − T₁₂₁) z^m exactly. This removes the
√ and arg singularities at R₁₂ = 0 (η₂ = η₁) or R₂₃ = 0 from values and gradients.

The series equals §2 when the 1|2 interface transmits (η₁ ≤ η₂ sin-wise). Under total
internal reflection at 1|2 (η₁ > η₂, grazing) T₁₂₁ = 0 and the series gives R = 1, while
the exact Airy sum keeps frustrated transmission through very thin films: a documented
limitation of the series (SPEC §3).

Example (the series converges to the exact Airy reflectance; M = 0 leaves C₀):
    >>> from thinfilm_jax import Film, airy_reflectance
    >>> from thinfilm_jax.optics.series import series_reflectance, series_terms
    >>> film = Film(600.0, 1.3, 2.0, 0.5)
    >>> st = series_terms(film, 0.8)
    >>> r = series_reflectance(st, 550.0, 60).mean(axis=0)  # (R_s + R_p)/2
    >>> bool(abs(r - airy_reflectance(film, 0.8, 550.0)) < 1e-12)
    True
    >>> bool(abs(series_reflectance(st, 550.0, 0) - st.c0).max() == 0)
    True
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from ..core import _validate as V
from .turns import sincos_turns
from ..core.film import Film
from .fresnel import as_complex, film_interfaces, safe_div, sqrt_upper_parts

__all__ = [
    "SeriesTerms",
    "series_terms",
    "series_reflectance",
    "fourier_band_reflectance",
    "FusedTerms",
    "fused_terms",
]


class SeriesTerms(NamedTuple):
    """BB17 terms of one film at one angle. Leading axis of c0, amp, z is (s, p)."""

    c0: Array  # C₀ = R₁₂ + R*
    amp: Array  # R* − T₁₂₁, so that C_m = amp·|z|^m
    z: Array  # r₂₁ r₂₃ (real on the dielectric path); |z| = √(R₁₂R₂₃), arg z = φ₂
    opd: Array  # D = 2 η₂ d cos θ₂ (nm), shared by s and p

    @property
    def phi2(self) -> Array:
        """φ₂ = arg r₂₁ + arg r₂₃ (0 where z = 0, with a finite gradient)."""
        zc = as_complex(self.z)
        zero = zc == 0
        return jnp.where(zero, 0.0, jnp.angle(jnp.where(zero, 1.0, zc)))

    def cm(self, m: int) -> Array:
        """C_m = (R* − T₁₂₁) (√(R₁₂R₂₃))^m, m ≥ 1."""
        az2 = jnp.real(self.z) ** 2 + jnp.imag(self.z) ** 2
        return self.amp * az2 ** (m / 2)


def series_terms(film: Film, cos_theta, *, arithmetic: str = "complex") -> SeriesTerms:
    """C₀, R* − T₁₂₁, z = r₂₁r₂₃ and D of `film` at cos θ₁ (inputs pre-broadcast).

    Concrete inputs are checked like `airy_reflectance`'s (film domain, cos θ₁ ∈ [0, 1],
    `arithmetic` "real" or "complex", κ₃ = 0 on the dielectric path); traced ones are not.
    """
    V.check_choice("arithmetic", arithmetic, ("real", "complex"))
    if all(V.is_concrete(x) for x in (*film, cos_theta)):
        from .airy import choose_arithmetic

        film = V.check_film(film)
        cos_theta = V.check_cos_theta(cos_theta)
        V.check_broadcast([("film", jnp.zeros(film.shape)), ("cos_theta", cos_theta)])
        choose_arithmetic(film, arithmetic)
    ifc = film_interfaces(film, cos_theta, arithmetic=arithmetic)
    r12, r23 = ifc.r12, ifc.r23
    R12 = jnp.real(r12) ** 2 + jnp.imag(r12) ** 2
    R23 = jnp.real(r23) ** 2 + jnp.imag(r23) ** 2
    # T₁₂₁ and T₂₃ clamped at 0 against rounding (|r| = 1 under TIR), and the denominator
    # written as 1 − R₁₂R₂₃ = T₁₂₁ + R₁₂T₂₃ ≥ T₁₂₁, so that R* ≤ T₁₂₁ stays bounded. Under TIR at
    # 1|2 with an evanescent film (|r₁₂| = |r₂₃| = 1) the naive 1 − R₁₂R₂₃ is a rounding residue
    # (possibly ~1e-33 when XLA contracts it into an FMA) and T²R₂₃/(1 − R₁₂R₂₃) blew up to O(1).
    # TIR at 1|2 (evanescent film, Im q₂ > 0): T₁₂₁ = 0 exactly and there are no interference
    # terms (z := 0). Without this, rounding in T (1e-7 in float32) multiplies |z|^m, and |z|
    # exceeds 1 there (|r₂₃| > 1 for an evanescent wave on an absorbing base): O(1) errors.
    evanescent = jnp.imag(ifc.q2) > 0
    T = jnp.where(evanescent, 0.0, jnp.maximum(1.0 - R12, 0.0))
    T23 = jnp.maximum(1.0 - R23, 0.0)
    # the denominator is 0 only when both interfaces reflect totally: then R* = 0 (T = 0).
    rstar = safe_div(T * T * R23, T + R12 * T23)
    z = jnp.where(evanescent, jnp.zeros_like(r12), -r12 * r23)
    opd = 2.0 * film.thickness * jnp.real(ifc.q2)
    return SeriesTerms(R12 + rstar, rstar - T, z, opd)


def series_reflectance(terms: SeriesTerms, wavelength, terms_m: int) -> Array:
    """Truncated series R_M(λ) per polarisation (leading axis 2), M = `terms_m`."""
    e = jax.lax.complex(*sincos_turns(terms.opd / wavelength))  # phase 2πD/λ, in turns
    ze = as_complex(terms.z) * e
    zm = jnp.ones_like(ze)
    acc = jnp.zeros_like(terms.c0)
    for _ in range(terms_m):
        zm = zm * ze
        acc = acc + jnp.real(zm)
    return terms.c0 + 2.0 * terms.amp * acc


def fourier_band_reflectance(terms: SeriesTerms, shat, terms_m: int, shat0, *,
                             partial_sums: bool = False) -> Array:
    r"""Band reflectance (K 4 / K 29) per polarisation, leading axis 2, trailing axis bands.

    $$ R_j = C_0\hat S_j(0) + \sum_{m=1}^{M} C_m\left[e^{im\varphi_2}\hat S_j(-mD)
       + e^{-im\varphi_2}\hat S_j(mD)\right]
       = C_0\hat S_j(0) + 2(R_*-T_{121})\sum_m \operatorname{Re}\,z^m\hat S_j(-mD), $$

    using Ŝ_j(mD) = conj Ŝ_j(−mD) for real sensitivities.

    Args:
        terms: `SeriesTerms` (the mean-direction terms C*, φ₂* for K 29).
        shat: callable m ↦ Ŝ_j(−m μ_D[, m²σ_D²]) with shape (*batch, n_bands), complex.
        terms_m: M.
        shat0: Ŝ_j(0), shape (n_bands,).
        partial_sums: return every partial sum M' = 0 … M stacked on a new leading axis
            (one evaluation of the whole M sweep; the last entry is the M-term value).
    """
    z = as_complex(terms.z[..., None])
    # ranks aligned explicitly: (2, *batch, 1) against (*batch, J) and (J,)
    c0 = terms.c0[..., None] * jnp.reshape(shat0, (1,) * terms.c0.ndim + (-1,))
    amp = 2.0 * terms.amp[..., None]
    acc = jnp.zeros_like(c0)
    sums = [c0]
    zm = jnp.ones_like(z)
    for m in range(1, terms_m + 1):
        zm = zm * z
        acc = acc + jnp.real(zm * shat(m)[None])
        if partial_sums:
            sums.append(c0 + amp * acc)
    return jnp.stack(sums) if partial_sums else c0 + amp * acc


# ----------------------------------------------------------------------------- fused
def _complex_div(nr, ni, dr, di):
    """(nr + i ni) / (dr + i di) on real parts, 0 where the denominator is 0: the arithmetic
    of `fresnel.safe_div` (scaled by 1/(|Re| + |Im|), one shared reciprocal), double-where."""
    zero = (dr == 0) & (di == 0)
    dr = jnp.where(zero, 1.0, dr)
    k = 1.0 / (jnp.abs(dr) + jnp.abs(di))
    dr, di = dr * k, di * k
    k = k / (dr * dr + di * di)
    return (jnp.where(zero, 0.0, (nr * dr + ni * di) * k),
            jnp.where(zero, 0.0, (ni * dr - nr * di) * k))


class FusedTerms(NamedTuple):
    """`SeriesTerms` written for one fused loop: each polarisation its own array (no stacked
    axis, which XLA would materialise) and z on real parts. Tuples are (s, p)."""

    c0: tuple  # C₀ per polarisation
    amp: tuple  # R* − T₁₂₁
    z_re: tuple  # Re z, z = r₂₁ r₂₃
    z_im: tuple  # Im z (zeros on the dielectric path)
    opd: Array  # D = 2 d Re q₂ (nm)


def fused_terms(film: Film, cos_theta, *, arithmetic: str = "complex") -> FusedTerms:
    """`series_terms` (the same arithmetic, operation for operation) on real parts, for the
    real-time kernels: every output is an elementwise function of the inputs, which XLA fuses
    into the kernel's single loop. No validation (traced inputs of the kernels)."""
    eta1, eta2, eta3, kappa3, d = (film.eta_outer, film.eta_film, film.eta_base,
                                   film.kappa_base, film.thickness)
    c = jnp.asarray(cos_theta)
    s2 = eta1**2 * (1.0 - c) * (1.0 + c)
    q1 = eta1 * c
    eps1, eps2 = eta1**2, eta2**2
    zero = jnp.zeros_like(s2 + eps2)
    if arithmetic == "real":
        from .fresnel import safe_sqrt

        q2r, q2i = safe_sqrt(eps2 - s2), zero
        q3r, q3i = safe_sqrt(eta3**2 - s2), zero
        e3r, e3i = eta3**2, zero
    elif arithmetic == "complex":
        # q₂ = √(η₂² − s²) on the upper branch: real or imaginary (`fresnel.sqrt_upper` of a
        # real argument); q₃ = √(ε₃ − s²) with ε₃ = (η₃ + iκ₃)²
        q2r, q2i = sqrt_upper_parts(eps2 - s2, zero)
        e3r, e3i = eta3 * eta3 - kappa3 * kappa3, 2.0 * eta3 * kappa3
        q3r, q3i = sqrt_upper_parts(e3r - s2, e3i + zero)
    else:
        raise ValueError(f"unknown arithmetic {arithmetic!r}; expected 'real' or 'complex'")
    # r^s_ab = (q_a − q_b)/(q_a + q_b), r^p_ab = (ε_b q_a − ε_a q_b)/(ε_b q_a + ε_a q_b)
    if arithmetic == "real":  # real amplitudes, `fresnel.safe_div`'s real division
        def _cdiv(nr, ni, dr, di):  # noqa: F811  (the imaginary parts are zeros here)
            dz = dr == 0
            return jnp.where(dz, 0.0, nr / jnp.where(dz, 1.0, dr)), zero
    else:
        _cdiv = _complex_div
    r12 = (_cdiv(q1 - q2r, -q2i, q1 + q2r, q2i),
           _cdiv(eps2 * q1 - eps1 * q2r, -eps1 * q2i, eps2 * q1 + eps1 * q2r, eps1 * q2i))
    e3q2 = (e3r * q2r - e3i * q2i, e3r * q2i + e3i * q2r)
    r23 = (_cdiv(q2r - q3r, q2i - q3i, q2r + q3r, q2i + q3i),
           _cdiv(e3q2[0] - eps2 * q3r, e3q2[1] - eps2 * q3i,
                 e3q2[0] + eps2 * q3r, e3q2[1] + eps2 * q3i))
    evanescent = q2i > 0
    c0, amp, zr, zi = [], [], [], []
    for (a12, b12), (a23, b23) in zip(r12, r23):
        R12 = a12 * a12 + b12 * b12
        R23 = a23 * a23 + b23 * b23
        # as `series_terms`: T₁₂₁, T₂₃ clamped at 0, TIR at 1|2 (evanescent film) exact
        T = jnp.where(evanescent, 0.0, jnp.maximum(1.0 - R12, 0.0))
        T23 = jnp.maximum(1.0 - R23, 0.0)
        den = T + R12 * T23
        dz = den == 0
        rstar = jnp.where(dz, 0.0, T * T * R23 / jnp.where(dz, 1.0, den))
        c0.append(R12 + rstar)
        amp.append(rstar - T)
        zr.append(jnp.where(evanescent, 0.0, -(a12 * a23 - b12 * b23)))
        zi.append(jnp.where(evanescent, 0.0, -(a12 * b23 + b12 * a23)))
    return FusedTerms(tuple(c0), tuple(amp), tuple(zr), tuple(zi), 2.0 * d * q2r)
