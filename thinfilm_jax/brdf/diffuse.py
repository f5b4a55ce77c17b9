r"""Diffuse BRDF terms, pure and broadcasting, in dot-product form (c_i = ⟨n,ω_i⟩, c_o = ⟨n,ω_o⟩).

Every term is 0 unless c_i, c_o > 0 and broadcasts a band axis through `albedo` (e.g. (..., J)
against cosines (..., 1)). All are reciprocal (symmetric in ω_i ↔ ω_o).

* Lambert:  f = ρ/π.
* Oren–Nayar, qualitative model (Oren & Nayar 1994, "Generalization of Lambert's reflectance
  model", Eq. 30; σ the standard deviation of the facet slope angle, in radians):
  f = ρ/π (A + B max(0, cos(φ_i − φ_o)) sin α tan β),  α = max(θ_i, θ_o), β = min(θ_i, θ_o),
  A = 1 − σ²/(2(σ² + 0.33)),  B = 0.45 σ²/(σ² + 0.09).
  Since sin θ_i sin θ_o cos(φ_i − φ_o) = ⟨ω_i,ω_o⟩ − c_i c_o and sin α tan β = sin θ_i sin θ_o /
  cos β with cos β = max(c_i, c_o):  f = ρ/π (A + B max(0, ⟨ω_i,ω_o⟩ − c_i c_o)/max(c_i, c_o)).
  σ = 0 is Lambert.
* Ashikhmin–Shirley 2000 (Eq. 5), the diffuse term energy-coupled to a specular layer of normal
  reflectance R_s:  f = 28 R_d/(23π) (1 − R_s)(1 − (1 − c_i/2)⁵)(1 − (1 − c_o/2)⁵).

Example (Oren–Nayar at σ = 0 is Lambert; at σ > 0 it brightens backscatter, ω_i = ω_o):
    >>> import numpy as np
    >>> from thinfilm_jax.brdf import diffuse
    >>> w = np.array([np.sin(1.0), 0.0, np.cos(1.0)])
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> bool(diffuse.oren_nayar(0.5, 0.0, w, w, n) == diffuse.lambert(0.5, w, w, n))
    True
    >>> round(float(diffuse.oren_nayar(0.5, 0.5, w, w, n) / diffuse.lambert(0.5, w, w, n)), 4)
    1.2181
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .ndf import _float

__all__ = ["DIFFUSES", "lambert", "oren_nayar", "oren_nayar_ab", "ashikhmin_shirley"]

DIFFUSES = ("none", "lambert", "oren_nayar", "ashikhmin_shirley")


def _cosines(wi, wo, n):
    wi, wo, n = _float(wi, wo, n)
    ci, co = jnp.sum(wi * n, axis=-1), jnp.sum(wo * n, axis=-1)
    return wi, wo, ci, co, (ci > 0) & (co > 0)


def lambert(albedo, wi, wo, n):
    """ρ/π where c_i, c_o > 0, else 0; shape broadcast(albedo, cosines)."""
    _, _, _, _, up = _cosines(wi, wo, n)
    (albedo,) = _float(albedo)
    return jnp.where(up, albedo / np.pi, 0)


def oren_nayar_ab(sigma):
    """Oren & Nayar 1994 Eq. 30 coefficients A = 1 − σ²/(2(σ² + 0.33)), B = 0.45σ²/(σ² + 0.09)."""
    (sigma,) = _float(sigma)
    s2 = sigma * sigma
    return 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


def oren_nayar(albedo, sigma, wi, wo, n):
    """Oren–Nayar qualitative model ρ/π (A + B max(0, ⟨ω_i,ω_o⟩ − c_i c_o)/max(c_i, c_o)).

    σ ≥ 0 in radians; wi, wo, n unit vectors (..., 3)."""
    wi, wo, ci, co, up = _cosines(wi, wo, n)
    (albedo, sigma) = _float(albedo, sigma)
    a, b = oren_nayar_ab(sigma)
    proj = jnp.sum(wi * wo, axis=-1) - ci * co  # sin θ_i sin θ_o cos(φ_i − φ_o)
    big = jnp.where(up, jnp.maximum(ci, co), 1)
    f = albedo / np.pi * (a + b * jnp.maximum(proj, 0) / big)
    return jnp.where(up, f, 0)


def _fresnel_like(c):
    m = 1 - c / 2
    m2 = m * m
    return 1 - m2 * m2 * m


def ashikhmin_shirley(albedo, specular_normal, wi, wo, n):
    """Ashikhmin–Shirley 2000 Eq. 5: 28 R_d/(23π) (1 − R_s)(1 − (1 − c_i/2)⁵)(1 − (1 − c_o/2)⁵).

    `albedo` = R_d, `specular_normal` = R_s (the specular layer's reflectance at normal
    incidence), both broadcasting (e.g. bands (..., J))."""
    _, _, ci, co, up = _cosines(wi, wo, n)
    albedo, rs = _float(albedo, specular_normal)
    ci, co = jnp.where(up, ci, 0), jnp.where(up, co, 0)
    f = 28 / (23 * np.pi) * albedo * (1 - rs) * (_fresnel_like(ci) * _fresnel_like(co))
    return jnp.where(up, f, 0)
