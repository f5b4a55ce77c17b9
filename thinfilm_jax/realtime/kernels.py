r"""Per-shading-point real-time kernels: what a renderer port copies (K 4, K 20–29).

Every real-time integrator of the library (`patch_radiance`, `envmap_radiance`) and the
benchmarks call these functions; none re-derives them. They are pure, broadcast over
leading axes, trace-safe (no validation: the public integrators validate), and clean in
float32 (every contraction states its precision).

* `ideal_kernel` — BB17 real time, the film at the ideal reflection direction (h = n):
  R_j(cos θ_o) by the truncated Fourier sum (K 4), which is K 29 with σ_D = 0. Multiply by A(θ_o, α) (and, under an
  environment, by the prefiltered radiance) for the `ideal` method.
* `filtered_kernel` — Kneiphof et al. 2019 (K 29) from the mean μ_ω and covariance Σ_ω of
  the light direction: μ_c = ⟨ω_o, μ_ω⟩, σ_c² = ω_oᵀ Σ_ω ω_o (K 20–21); μ_D, σ_D by the
  Taylor chain (K 25–28); C*_m, φ₂* at cos θ₁* = √((1 + μ_c)/2) (K 22); Ŝ(μ, σ²) from the
  LUT, the exact quadrature or the Gaussian fit.
* `improved_kernel` — this library's improved model (`improved`, docs/improved.md): K 29 per
  equal-probability bin of cos θ₁, the bins read from a (θ_o, α) table (`bin_table`);
  `envmap_radiance` calls it through `methods.improved.improved_envmap`.
* `lobe_moments` — exact A(θ_o, α), μ_ω, Σ_ω of p_R ∝ ρ̃ ⟨n, ω_i⟩ (K 12, uniform light) in
  the frame n = z, ω_o = (sin θ_o, 0, cos θ_o), from the half-vector quadrature.

Valid inputs: cos θ_o ∈ [0, 1]; ω_o and μ_ω in one frame (ω_o unit, |μ_ω| ≤ 1), Σ_ω
symmetric positive semi-definite; film fields as `Film` (thickness ≥ 0 nm, η ≥ 1, κ ≥ 0).

Example (an index-matched film, η₂ = η₁, is invisible: the bare 1|3 interface,
((1.5 − 1)/(1.5 + 1))² = 0.04, in every band; K 29 with Σ_ω = 0 and μ_ω the mirror direction
is the ideal kernel):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.realtime.kernels import filtered_kernel, ideal_kernel, lobe_moments
    >>> [round(float(r), 6) for r in ideal_kernel(Film(500.0, 1.0, 1.5), 1.0)]
    [0.04, 0.04, 0.04]
    >>> film, t = Film(600.0, 1.3, 2.0, 0.5), 0.4
    >>> wo = jnp.array([jnp.sin(t), 0.0, jnp.cos(t)])
    >>> wr = jnp.array([-jnp.sin(t), 0.0, jnp.cos(t)])
    >>> k29 = filtered_kernel(film, wo, wr, jnp.zeros((3, 3)), shat="exact")
    >>> bool(jnp.allclose(k29, ideal_kernel(film, jnp.cos(t))))
    True
    >>> a, mean, cov = lobe_moments(0.0, 0.2, quadrature=(16, 16))
    >>> bool(0.0 < a < 1.0), mean.shape, cov.shape
    (True, (3,), (3, 3))
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import Array

from ..core.film import Film
from .filtered import filtered_bands
from .improved import bin_table, improved_kernel  # noqa: F401  (re-exported)
from ..spectral.lut import ShatLUT
from ..brdf.microfacet import DEFAULT_QUADRATURE, light_moments, patch_quadrature
from ..optics.opd import (OPDMoments, cos_incidence_from_projection, opd_of_cos, project_light_moments,
                  taylor_opd_moments)
from ..spectral.reflectance import fourier_bands
from ..spectral.spectra import DEFAULT_OBSERVER

__all__ = ["ideal_kernel", "filtered_kernel", "improved_kernel", "bin_table", "lobe_moments"]


def ideal_kernel(film: Film, cos_o, *, observer=DEFAULT_OBSERVER, terms: int = 2,
                 shat: str = "exact", lut: ShatLUT | None = None,
                 arithmetic: str = "complex", light: Array | None = None) -> Array:
    """R_j(cos θ_o) by K 4 with M = `terms`, shape broadcast(film, cos_o) + (J,).

    Args:
        film: `Film`.
        cos_o: cos θ_o ∈ [0, 1] (the ideal reflection: cos θ₁ = cos θ_o).
        observer: observer name (plain or cross-band, `uplift`).
        terms: M ≥ 0 Fourier orders.
        shat: Ŝ source, as for `filtered_kernel`: "exact" (quadrature on the observer's
            samples), "lut" (the Ŝ(μ, σ²) table read at σ = 0: K 29 with σ_D = 0) or
            "gaussian" (BB17's closed form).
        arithmetic: "complex" (complex η₃ + iκ₃) or "real" (κ₃ = 0 only).
        light: (..., 3) RGB radiance with a cross-band observer and shat="lut": returns
            Σ_k R_jk light_k (..., J) (`filtered.filtered_bands`), the table read per channel.
    """
    if shat == "lut":
        opd = OPDMoments(opd_of_cos(film, cos_o), None)  # σ_D = 0 exactly: the σ = 0 column
        return filtered_bands(film, cos_o, opd, observer, terms=terms, shat="lut", lut=lut,
                              arithmetic=arithmetic, light=light)
    return fourier_bands(film, cos_o, observer, terms=terms, shat=shat, arithmetic=arithmetic)


def filtered_kernel(film: Film, wo, mean, cov, *, observer=DEFAULT_OBSERVER, terms: int = 2,
                    shat: str = "lut", lut: ShatLUT | None = None,
                    arithmetic: str = "complex", light: Array | None = None,
                    interpolation: str = "cubic") -> Array:
    """K 29 band reflectance from light-direction moments, shape (..., J).

    Args:
        film: `Film` (fields broadcast with the leading axes of `wo`).
        wo: view direction ω_o (..., 3), unit, in the frame of `mean` and `cov`.
        mean: μ_ω (..., 3), mean light direction of p_R (|μ_ω| ≤ 1).
        cov: Σ_ω (..., 3, 3), covariance of the light direction.
        shat: "lut" (needs `lut`), "exact" (SPEC §5 quadrature) or "gaussian" (closed form).
        light: (..., 3) RGB radiance with a cross-band observer and shat="lut": returns
            Σ_k R_jk light_k (..., J) (`filtered.filtered_bands`), the table read per channel.
        interpolation: the LUT read with shat="lut" (`lut.lookup`): "cubic" (16 taps), or
            "linear_mu" (8 taps, what `envmap_radiance` reads at frame size) or "linear".
    """
    mu_c, var_c = project_light_moments(wo, mean, cov)
    opd = taylor_opd_moments(film, mu_c, var_c)
    cos_star = cos_incidence_from_projection(mu_c)
    return filtered_bands(film, cos_star, opd, observer, terms=terms, shat=shat, lut=lut,
                          arithmetic=arithmetic, light=light, interpolation=interpolation)


@functools.partial(jax.jit, static_argnames=("quadrature", "ndf"))
def lobe_moments(theta_o, alpha, *, quadrature: tuple[int, int] = DEFAULT_QUADRATURE,
                 ndf: str = "ggx"):
    """(A, μ_ω, Σ_ω) of p_R for broadcast θ_o, α: shapes (...), (..., 3), (..., 3, 3).

    Frame n = z, ω_o = (sin θ_o, 0, cos θ_o); `quadrature` = (n_u, n_φ) of the half-vector
    quadrature (K 12, 20, 21).
    """
    dt = jnp.result_type(theta_o, alpha, float)
    theta_o, alpha = jnp.broadcast_arrays(jnp.asarray(theta_o, dt), jnp.asarray(alpha, dt))
    shape = theta_o.shape

    def one(t, a):
        q = patch_quadrature(t, a, quadrature=quadrature, ndf=ndf)
        m, c = light_moments(q)
        return jnp.sum(q.weight), m, c

    a, m, c = jax.vmap(one)(theta_o.reshape(-1), alpha.reshape(-1))
    return a.reshape(shape), m.reshape(*shape, 3), c.reshape(*shape, 3, 3)
