r"""Microfacet BRDF pieces (GGX / Beckmann, height-correlated Smith) and the light-patch quadrature.

Conventions: surface normal n = +z, view direction ω_o = (sin θ_o, 0, cos θ_o), roughness α is
the NDF width parameter (0 < α ≤ 1), h = normalize(ω_i + ω_o), c = ⟨ω_o, h⟩ = ⟨ω_i, h⟩.

NDFs (Walter et al. 2007), both normalised so that ∫ D(h) cos θ_h dω_h = 1:

    GGX:       D(h) = α² / (π cos⁴θ_h (α² + tan²θ_h)²) = α² / (π (sin²θ_h + α² cos²θ_h)²)
    Beckmann:  D(h) = exp(−tan²θ_h / α²) / (π α² cos⁴θ_h)

Smith Λ (Walter 2007; Heitz 2014, "Understanding the masking-shadowing function"):

    GGX:       Λ(ω) = (−1 + sqrt(1 + α² tan²θ)) / 2
    Beckmann:  Λ(ω) = (erf(a) − 1)/2 + exp(−a²)/(2 a √π),   a = 1/(α tan θ)

Everything is evaluated through L(θ) := cos θ · Λ(θ), which is finite on [0, π/2]
(GGX: L = (sqrt(α² + (1 − α²) cos²θ) − cos θ)/2), so nothing is 0/0 at grazing angles.
Height-correlated Smith masking-shadowing (Heitz 2014, Eq. 99):

    G₂(ω_i, ω_o) = 1 / (1 + Λ(ω_i) + Λ(ω_o)) = cos_i cos_o / (cos_i cos_o + cos_o L_i + cos_i L_o)

for cos_i, cos_o > 0 (else 0). BRDF without Fresnel term (Kneiphof et al. 2019, Eq. 1, 10):

    ρ̃(ω_i, ω_o) = D(h) G₂(ω_i, ω_o) / (4 cos_i cos_o)
               = D(h) / (4 (cos_i cos_o + cos_o L_i + cos_i L_o)).

Patch integral under a uniform light (Kneiphof et al. 2019, Eq. 12), for any f of c:

    L[f](θ_o, α) = ∫_{H²} ρ̃(ω_i, ω_o) cos_i f(⟨h, ω_i⟩) dω_i
                 = ∫ D(h) cos θ_h · [G₂ ⟨o,h⟩ / (cos θ_h cos θ_o)] · f(c) dω_h,

with ω_i = 2⟨o,h⟩h − ω_o, dω_i = 4⟨o,h⟩ dω_h, integrand 0 where cos_i ≤ 0.  The albedo of the
prefiltered (split-sum) BRDF is A(θ_o, α) = L[1] ≤ 1.

Quadrature (`patch_quadrature`).  Write h by (θ_h, φ_h) and use the inverse-CDF variable
β = atan(tan θ_h / α), in which D cos θ_h dω_h = (du/dβ) dβ dφ_h / 2π with u the CDF of the NDF
(GGX: u = sin²β, i.e. tan²θ_h = α² u/(1 − u); Beckmann: u = 1 − exp(−tan²β)).  Since
cos_i = 2⟨o,h⟩ cos θ_h − cos θ_o = sin θ_o sin 2θ_h cos φ_h + cos θ_o cos 2θ_h = R cos(2θ_h − δ),
R = sqrt(sin²θ_o cos²φ_h + cos²θ_o), tan δ = tan θ_o cos φ_h, the valid half vectors for a given
φ_h are exactly 0 ≤ θ_h < θ_max(φ_h) = π/4 + δ/2 (equivalently, for given θ_h the valid azimuths
are |φ_h| < φ*, cos φ* = −cot θ_o cot 2θ_h).  θ_max(φ_h) is analytic (no kinks), so the
integral is done as an outer azimuth rule over φ_h ∈ (0, π) (mirror symmetry y → −y, weights
doubled) and an inner Gauss–Legendre rule over β ∈ [0, β_max(φ_h)].  The azimuth rule is split at
φ_h = π/2 and uses, on each half, Gauss–Jacobi(−1/2, 0) in x = |cos φ_h| (nodes uniform-like near
φ_h = 0, π where the integrand is even, clustered at π/2 where θ_max(φ_h) steepens into a step as
θ_o → π/2; the nearest complex singularity is at Im φ_h = asinh(cot θ_o)).  For GGX the inner
nodes are β = β_max sin(πs/2), clustering at the horizon to resolve the heavy tail near θ_h = π/2.
All of it is written with sin/cos of β and of γ = π/2 − β, so values and gradients are finite for
θ_o ∈ [0, π/2] (both ends included) and α ∈ (0, 1].  Convergence is geometric in n_u and n_phi
(measured: error of L[cos 40c] at θ_o = 70°, α = 0.5 is 2e-2, 2e-4, 4e-9, 2e-12 for
n_u = n_phi = 16, 24, 32, 40); near θ_o = π/2 and for small α it is slower but still geometric.

The "kinked" design (split the θ_h range at π/4 ∓ θ_o/2 and integrate φ_h ∈ [0, φ*(θ_h)]) was
tried first: φ*(θ_h) = arccos(−cot θ_o cot 2θ_h) has square-root end points and a pole at
θ_h = π/2 just outside the second piece, which limits it to ≳ 1e-4 at n = 32 for the case above.

Example (the albedo A(θ_o, α) = L[1] ≤ 1; a near-mirror reflects all of a uniform light, A → 1):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax.brdf.microfacet import albedo
    >>> a = albedo(jnp.array([0.0, 0.0, 1.2]), jnp.array([1e-3, 0.5, 0.5]), quadrature=(16, 16))
    >>> [round(float(x), 3) for x in a]
    [1.0, 0.688, 0.726]
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import masking as _masking
from . import ndf as _ndf

__all__ = [
    "PatchQuadrature",
    "normal_distribution",
    "DEFAULT_QUADRATURE",
    "NDFS",
    "smith_lambda",
    "smith_g1",
    "smith_g2",
    "brdf_no_fresnel",
    "patch_quadrature",
    "light_moments",
    "albedo",
    "lobe_moments_normal_view",
    "splitsum_light_moments",
    "view_direction",
    "sample_patch_mc",
]

NDFS = ("ggx", "beckmann")
DEFAULT_QUADRATURE = (48, 48)  # (n_u, n_phi) of `patch_quadrature`: converged to ~1e-12 (tests)


class PatchQuadrature(NamedTuple):
    """Nodes of L[f] ≈ Σ weight · f(cos_hi); Σ weight = A(θ_o, α).

    For `patch_quadrature` the nodes cover the half space y ≥ 0 only (weights doubled)."""

    cos_hi: jax.Array  # (N,)   c = ⟨h, ω_i⟩
    weight: jax.Array  # (N,)   non-negative
    wi: jax.Array  # (N, 3) light direction ω_i


# ----------------------------------------------------------------------------- helpers
def _check_ndf(ndf):
    if not isinstance(ndf, str) or ndf not in NDFS:
        raise ValueError(f"ndf must be one of {NDFS}, got {ndf!r}")


def _check_orders(quadrature):
    """Quadrature orders as plain ints: n_u >= 1, n_phi >= 2 (ValueError naming them)."""
    from ..core import _validate as V

    return V.check_quadrature(quadrature)


def _check_view(theta_o, alpha, *, traced=True):
    """θ_o ∈ [0, π/2] (radians), α ∈ (0, 1]; concrete values always, traced ones inside
    `thinfilm_jax.checked` if `traced`."""
    from ..core import _validate as V

    if traced or V.is_concrete(theta_o):
        theta_o = V.check_angle("theta_o", theta_o)
    if traced or V.is_concrete(alpha):
        alpha = V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    return theta_o, alpha


def _asfloat(*xs):
    dt = jnp.result_type(*xs)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.result_type(float)
    return tuple(jnp.asarray(x, dt) for x in xs)


_clamp01 = _ndf.clamp01  # [0, 1] with the full one-sided gradient at the ends


def _view_cos_sin(theta_o):
    """(cos θ_o, sin θ_o) for θ_o ∈ [0, π/2]; cos clamped at 0 (float32 π/2 rounds past π/2).

    No clip on sin: jnp.clip at the tie sin 0 = 0 would halve the gradient at θ_o = 0."""
    c = jnp.cos(theta_o)
    return jnp.where(c >= 0, c, 0), jnp.sin(theta_o)


_exp_cut = _ndf.exp_cut  # exponent above which exp(−x) underflows in a dtype


def _lambda_cos(cos, alpha, ndf):
    """L = cos θ · Λ(θ) for cos θ ∈ [0, 1]; finite (L(0) = α/2 GGX, α/(2√π) Beckmann).

    The formulas live in `masking` (`lambda_cos_ggx`, `lambda_cos_beckmann`)."""
    return _masking.lambda_cos(cos, alpha, ndf)


def _g2_denominator(ci, co, alpha, ndf):
    """cos_i cos_o / G₂ = cos_i cos_o + cos_o L_i + cos_i L_o (> 0 unless cos_i = cos_o = 0)."""
    return ci * co + co * _lambda_cos(ci, alpha, ndf) + ci * _lambda_cos(co, alpha, ndf)


def _g2_over_cos_o(ci, co, alpha, ndf):
    """G₂ / cos_o = cos_i / (cos_i cos_o + cos_o L_i + cos_i L_o), finite at cos_o = 0."""
    den = _g2_denominator(ci, co, alpha, ndf)
    ok = den > 0
    return jnp.where(ok, ci / jnp.where(ok, den, 1), 0)


def _beta_pdf(sb, cb, ndf):
    """du/dβ of the NDF CDF u in β = atan(tan θ_h / α) (D cos θ_h dω_h = (du/dβ) dβ dφ_h / 2π)."""
    if ndf == "ggx":  # u = sin²β
        return 2 * sb * cb
    ok = sb * sb < _exp_cut(sb.dtype) * cb * cb  # u = 1 − exp(−tan²β)
    cs = jnp.where(ok, cb, 1)
    t = jnp.where(ok, sb, 0) / cs
    return jnp.where(ok, 2 * t / (cs * cs) * jnp.exp(-t * t), 0)


def _half_vector_trig(sb, cb, alpha):
    """(cos θ_h, sin θ_h, tan θ_h) from sin β, cos β, where tan θ_h = α tan β."""
    r = jnp.sqrt(cb * cb + alpha * alpha * sb * sb)
    ok = cb > 0
    return cb / r, alpha * sb / r, jnp.where(ok, alpha * sb / jnp.where(ok, cb, 1), 0)


@functools.lru_cache(maxsize=None)
def _gl01(n):
    """Gauss–Legendre on [0, 1]: nodes s, 1 − s and weights (host float64)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return (1 + x) / 2, (1 - x) / 2, w / 2


@functools.lru_cache(maxsize=None)
def composite_gauss_legendre(n: int):
    """Composite Gauss–Legendre on [0, 1]: ⌈n/8⌉ equal panels of min(n, 8) nodes; (nodes,
    weights), host float64."""
    order = min(n, 8)
    panels = max(1, -(-n // order))
    x, w = np.polynomial.legendre.leggauss(order)
    x, w = (x + 1) / 2, w / 2
    a = np.arange(panels)[:, None]
    return ((a + x[None]) / panels).reshape(-1), np.tile(w / panels, panels)


@functools.lru_cache(maxsize=None)
def _phi_rule(n):
    """Azimuth rule on (0, π) as (cos φ_h, sin φ_h, weight/π), split at φ_h = π/2.

    On each half, ∫ I dφ = ∫_0^1 J(x) (1 − x²)^(−1/2) dx with x = |cos φ_h|; the m-point
    Gauss–Jacobi(−1/2, 0) rule for it is x = 1 − y², y the positive nodes of 2m-point
    Gauss–Legendre (weights doubled), i.e. nodes uniform-like near φ_h = 0, π (where I is even)
    and clustered at φ_h = π/2 (where θ_max(φ_h) steepens as θ_o → π/2)."""
    if n < 2:
        raise ValueError("n_phi must be >= 2")
    cs, ss, ws = [], [], []
    for sign, m in ((1.0, n // 2), (-1.0, n - n // 2)):
        y, w = np.polynomial.legendre.leggauss(2 * m)
        y, w = y[m:], w[m:]  # positive half
        cs.append(sign * (1 - y * y))
        ss.append(y * np.sqrt(2 - y * y))
        ws.append(2 * w / np.sqrt(2 - y * y) / np.pi)
    return np.concatenate(cs), np.concatenate(ss), np.concatenate(ws)


@functools.lru_cache(maxsize=None)
def _inner_rule(n, ndf):
    """Inner rule on [0, 1] as (s, 1 − s, weights); GGX: s = sin(πx/2) clusters at the horizon."""
    if n < 1:
        raise ValueError("n_u must be >= 1")
    x, omx, w = _gl01(n)
    if ndf == "ggx":
        s, t = np.sin(np.pi * x / 2), 2 * np.sin(np.pi * omx / 4) ** 2  # t = 1 − s, no cancellation
        return s, t, w * np.pi / 2 * np.cos(np.pi * x / 2)
    return x, omx, w


# ----------------------------------------------------------------------------- BRDF pieces
@functools.partial(jax.jit, static_argnames=("ndf",))
def normal_distribution(cos_h, alpha, ndf="ggx"):
    """Normal distribution D(h) as a function of cos θ_h (0 for cos θ_h ≤ 0); `ndf.ggx`,
    `ndf.beckmann`."""
    _check_ndf(ndf)
    cos_h, alpha = _asfloat(cos_h, alpha)
    return _ndf.ggx(cos_h, alpha) if ndf == "ggx" else _ndf.beckmann(cos_h, alpha)


@functools.partial(jax.jit, static_argnames=("ndf",))
def smith_lambda(cos_theta, alpha, ndf="ggx"):
    """Smith Λ(ω) from cos θ; +inf (zero gradient) for cos θ ≤ 0, where G → 0."""
    _check_ndf(ndf)
    cos_theta, alpha = _asfloat(cos_theta, alpha)
    pos = cos_theta > 0
    cs = jnp.where(pos, _clamp01(cos_theta), 1)
    return jnp.where(pos, _lambda_cos(cs, alpha, ndf) / cs, jnp.inf)


@functools.partial(jax.jit, static_argnames=("ndf",))
def smith_g1(cos_theta, alpha, ndf="ggx"):
    """Smith masking G₁ = 1 / (1 + Λ) = cos θ / (cos θ + L); 0 for cos θ ≤ 0."""
    _check_ndf(ndf)
    cos_theta, alpha = _asfloat(cos_theta, alpha)
    c = _clamp01(cos_theta)
    return c / (c + _lambda_cos(c, alpha, ndf))


@functools.partial(jax.jit, static_argnames=("ndf",))
def smith_g2(cos_i, cos_o, alpha, ndf="ggx"):
    """Height-correlated Smith G₂ = 1 / (1 + Λ_i + Λ_o); 0 unless cos_i, cos_o > 0."""
    _check_ndf(ndf)
    cos_i, cos_o, alpha = _asfloat(cos_i, cos_o, alpha)
    ci, co = _clamp01(cos_i), _clamp01(cos_o)
    return co * _g2_over_cos_o(ci, co, alpha, ndf)


@functools.partial(jax.jit, static_argnames=("ndf",))
def brdf_no_fresnel(wi, wo, alpha, ndf="ggx"):
    """ρ̃ = D(h) G₂ / (4 cos_i cos_o) for unit vectors (..., 3), n = z; 0 below either horizon."""
    _check_ndf(ndf)
    wi, wo, alpha = _asfloat(wi, wo, alpha)
    ci, co = wi[..., 2], wo[..., 2]
    up = (ci > 0) & (co > 0)
    hs = wi + wo
    nh2 = jnp.sum(hs * hs, axis=-1)
    cos_h = hs[..., 2] / jnp.sqrt(jnp.where(up, nh2, 1))
    ci, co = jnp.where(up, _clamp01(ci), 1), jnp.where(up, _clamp01(co), 1)
    rho = normal_distribution(cos_h, alpha, ndf) / (4 * _g2_denominator(ci, co, alpha, ndf))
    return jnp.where(up, rho, 0)


# ----------------------------------------------------------------------------- patch quadrature
def patch_quadrature(theta_o, alpha, *, quadrature=DEFAULT_QUADRATURE,
                     ndf="ggx") -> PatchQuadrature:
    """Deterministic quadrature of `L[f](θ_o, α)` for scalar θ_o and α; N = n_phi · n_u nodes.

    `quadrature` = (n_u, n_phi), the inner and azimuth orders (static).

    Outer: n_phi azimuth nodes φ_h ∈ (0, π) (`_phi_rule`); inner: n_u nodes in
    β = atan(tan θ_h / α) ∈ [0, β_max(φ_h)] (`_inner_rule`), where cos_i = 0 at
    tan θ_max = (R + sin θ_o cos φ_h)/cos θ_o = cos θ_o/(R − sin θ_o cos φ_h),
    R = sqrt(sin²θ_o cos²φ_h + cos²θ_o).  Node weight (L[f] ≈ Σ weight · f(cos_hi)):
    w_β (du/dβ) · w_φ · (1/2π) · 2 · (G₂/cos θ_o) · ⟨o,h⟩/cos θ_h, nodes on y > 0 only.
    jit/vmap/grad friendly (shapes static in n_u, n_phi); returns `PatchQuadrature`.
    """
    _check_ndf(ndf)
    n_u, n_phi = _check_orders(quadrature)
    return _patch_quadrature(theta_o, alpha, n_u, n_phi, ndf)


@functools.partial(jax.jit, static_argnums=(2, 3, 4))
def _patch_quadrature(theta_o, alpha, n_u, n_phi, ndf):
    theta_o, alpha = _asfloat(theta_o, alpha)
    dt = theta_o.dtype
    k = lambda a: jnp.asarray(a, dt)  # noqa: E731  host constants in the input dtype
    co, so = _view_cos_sin(theta_o)
    cp, sp, wphi = (k(a)[:, None] for a in _phi_rule(n_phi))
    # horizon of ω_i in β and γ = π/2 − β (γ kept separately: cos β = sin γ stays accurate)
    r = jnp.sqrt(so * so * cp * cp + co * co)
    pos = cp >= 0
    num = jnp.where(pos, r + so * cp, 1)  # cancellation-free branch for each sign of cos φ_h
    den = jnp.where(pos, 1, r - so * cp)
    bmax = jnp.where(pos, jnp.arctan2(num, alpha * co), jnp.arctan2(co, alpha * den))
    gmax = jnp.where(pos, jnp.arctan2(alpha * co, num), jnp.arctan2(alpha * den, co))
    s, t, g = _inner_rule(n_u, ndf)
    beta = bmax * k(s)[None, :]  # (n_phi, 1) × (1, n_u): ranks aligned explicitly
    gamma = gmax + bmax * k(t)[None, :]
    sb, cb = jnp.sin(beta), jnp.sin(gamma)
    ch, sh, th = _half_vector_trig(sb, cb, alpha)
    c = so * sh * cp + co * ch  # ⟨o, h⟩
    ci = jnp.maximum(2 * c * ch - co, 0)  # ⟨n, ω_i⟩
    w_beta = bmax * k(g)[None, :] * _beta_pdf(sb, cb, ndf)
    weight = w_beta * wphi * _g2_over_cos_o(ci, co, alpha, ndf) * (so * th * cp + co)
    weight = jnp.maximum(weight, 0)
    h = jnp.stack([sh * cp, sh * sp, ch], axis=-1)
    o = jnp.stack([so, jnp.zeros_like(so), co])
    wi = 2 * c[..., None] * h - o[None, None, :]
    return PatchQuadrature(c.reshape(-1), weight.reshape(-1), wi.reshape(-1, 3))


@jax.jit
def light_moments(quad: PatchQuadrature):
    """Mean μ_ω (3,) and covariance Σ_ω (3, 3) of ω_i under p_R ∝ weight.

    Kneiphof et al. 2019, Eq. 12, 20, 21.

    The nodes of `patch_quadrature` cover y ≥ 0 only; the mirror half is added exactly:
    E[y] = E[xy] = E[yz] = 0.  Leading batch axes are allowed."""
    w, wi = quad.weight, quad.wi
    a = jnp.sum(w, axis=-1)[..., None]
    a = jnp.where(a > 0, a, 1)
    dt = w.dtype
    hi = jax.lax.Precision.HIGHEST
    mean = jnp.einsum("...n,...ni->...i", w, wi, precision=hi) / a * jnp.asarray([1, 0, 1], dt)
    mask = jnp.asarray([[1, 0, 1], [0, 1, 0], [1, 0, 1]], dt)
    second = jnp.einsum("...n,...ni,...nj->...ij", w, wi, wi, precision=hi) / a[..., None] * mask
    cov = second - mean[..., :, None] * mean[..., None, :]
    return mean, (cov + jnp.swapaxes(cov, -1, -2)) / 2


def view_direction(theta_o):
    """ω_o = (sin θ_o, 0, cos θ_o) (..., 3): the view in the frame of this module (n = z)."""
    theta_o = jnp.asarray(theta_o)
    return jnp.stack([jnp.sin(theta_o), jnp.zeros_like(theta_o), jnp.cos(theta_o)], axis=-1)


def _vmapped(fn, *args):
    """Broadcast the float arguments, apply jit(vmap(fn)) over the flattened batch, reshape back.

    The batch is padded (edge values) to a power of two so that few batch shapes get compiled."""
    args = jnp.broadcast_arrays(*_asfloat(*args))
    shape, n = args[0].shape, args[0].size
    m = 1 << max(n - 1, 0).bit_length() if n else 0
    out = fn(*(jnp.pad(a.reshape(-1), (0, m - n), mode="edge") for a in args))
    return jax.tree_util.tree_map(lambda y: y[:n].reshape(shape + y.shape[1:]), out)


@functools.partial(jax.jit, static_argnames=("n_u", "n_phi", "ndf"))
@functools.partial(jax.vmap, in_axes=(0, 0, None, None, None))
def _albedo_flat(theta_o, alpha, n_u, n_phi, ndf):
    return jnp.sum(_patch_quadrature(theta_o, alpha, n_u, n_phi, ndf).weight)


@functools.partial(jax.jit, static_argnames=("n_u", "n_phi", "ndf"))
@functools.partial(jax.vmap, in_axes=(0, None, None, None))
def _normal_view_flat(alpha, n_u, n_phi, ndf):
    q = _patch_quadrature(jnp.zeros_like(alpha), alpha, n_u, n_phi, ndf)
    mean, cov = light_moments(q)
    return mean[2], cov[2, 2] + mean[2] ** 2


def albedo(theta_o, alpha, *, quadrature=DEFAULT_QUADRATURE, ndf="ggx"):
    """A(θ_o, α) = L[1] = Σ weight (broadcasts over θ_o and α; jit + vmap inside).

    θ_o ∈ [0, π/2] radians, α ∈ (0, 1], quadrature (n_u ≥ 1, n_phi ≥ 2) (checked)."""
    _check_ndf(ndf)
    n_u, n_phi = _check_orders(quadrature)
    theta_o, alpha = _check_view(theta_o, alpha)
    return _vmapped(lambda t, a: _albedo_flat(t, a, n_u, n_phi, ndf), theta_o, alpha)


def lobe_moments_normal_view(alpha, *, quadrature=DEFAULT_QUADRATURE, ndf="ggx"):
    """(a, e_z) = (E[⟨ω_i, n⟩], E[⟨ω_i, n⟩²]) of the light lobe p_R at θ_o = 0 (ω_r = n).

    This is the split-sum "ω_o = n = ω_r" kernel of a prefiltered environment map
    (Kneiphof et al. 2019, §3.2)."""
    _check_ndf(ndf)
    n_u, n_phi = _check_orders(quadrature)
    _, alpha = _check_view(0.0, alpha, traced=False)
    return _vmapped(lambda a: _normal_view_flat(a, n_u, n_phi, ndf), alpha)


def splitsum_light_moments(theta_o, alpha, *, quadrature=DEFAULT_QUADRATURE, ndf="ggx"):
    """Split-sum (mean, cov) of ω_i: the normal-view lobe rotated onto ω_r = (−sin θ_o, 0, cos θ_o).

    μ = a ω_r,  Σ = e_t (I − ω_r ω_rᵀ) + e_z ω_r ω_rᵀ − μ μᵀ,  e_t = (1 − e_z)/2.  The rotated lobe
    is not clipped at the horizon (the split-sum approximation)."""
    theta_o, alpha = _check_view(theta_o, alpha, traced=False)
    theta_o, alpha = jnp.broadcast_arrays(*_asfloat(theta_o, alpha))
    a, ez = lobe_moments_normal_view(alpha, quadrature=quadrature, ndf=ndf)
    r = jnp.stack([-jnp.sin(theta_o), jnp.zeros_like(theta_o), jnp.cos(theta_o)], axis=-1)
    rr = r[..., :, None] * r[..., None, :]
    et = (1 - ez) / 2
    mean = a[..., None] * r
    eye = jnp.eye(3, dtype=theta_o.dtype)
    cov = et[..., None, None] * (eye - rr) + ez[..., None, None] * rr
    cov = cov - mean[..., :, None] * mean[..., None, :]
    return mean, cov


@functools.partial(jax.jit, static_argnames=("n_samples", "ndf"))
def sample_patch_mc(key, theta_o, alpha, n_samples, ndf="ggx") -> PatchQuadrature:
    """Unbiased Monte Carlo nodes for L[f]: h ~ D cos θ_h over the full azimuth [0, 2π).

    weight = G₂ ⟨o,h⟩ / (cos θ_h cos θ_o) / n_samples, 0 where cos_i ≤ 0."""
    _check_ndf(ndf)
    theta_o, alpha = _asfloat(theta_o, alpha)
    dt = theta_o.dtype
    ku, kp = jax.random.split(key)
    u = jax.random.uniform(ku, (n_samples,), dt)
    phi = jax.random.uniform(kp, (n_samples,), dt, 0, 2 * np.pi)
    if ndf == "ggx":  # inverse CDF: tan²β = u/(1 − u)
        sb, cb = jnp.sqrt(u), jnp.sqrt(1 - u)
    else:  # tan²β = −log(1 − u)
        tb = jnp.sqrt(-jnp.log1p(-u))
        sb, cb = tb / jnp.sqrt(1 + tb * tb), 1 / jnp.sqrt(1 + tb * tb)
    ch, sh, th = _half_vector_trig(sb, cb, alpha)
    co, so = _view_cos_sin(theta_o)
    cp, sp = jnp.cos(phi), jnp.sin(phi)
    c = so * sh * cp + co * ch
    ci_raw = 2 * c * ch - co
    ci = jnp.maximum(ci_raw, 0)
    w = _g2_over_cos_o(ci, co, alpha, ndf) * (so * th * cp + co) / n_samples
    w = jnp.where(ci_raw > 0, w, 0)
    h = jnp.stack([sh * cp, sh * sp, ch], axis=-1)
    o = jnp.stack([so, jnp.zeros_like(so), co])
    return PatchQuadrature(c, w, 2 * c[:, None] * h - o)
