r"""Car paint in the form measured paints ship (X-Rite AxF "CPA2"-style), under a clear coat.

The paint (`CarPaint`, a pytree; Kneiphof & Klein 2022, "Real-time image-based lighting of
metallic and pearlescent car paints", Computers & Graphics 105, 36–45, render this form of
material) is a *brightness* BRDF times a *colour table*, both seen through a smooth clear coat:

$$ f_b(\omega_i', \omega_o') = \frac{a}{\pi} + \sum_l s_l\,
   \frac{D_l(h')\,G_{2,l}(\omega_i', \omega_o')\,F_l(\langle h', \omega_i'\rangle)}
        {4\,\langle n,\omega_i'\rangle\langle n,\omega_o'\rangle}, \qquad
   f_j(\omega_i, \omega_o) = \frac{T(\theta_i)\,T(\theta_o)}{\eta_c^2}\,
   f_b(\omega_i', \omega_o')\;\chi_j(\theta_h', \theta_d'), $$

* D_l: GGX of width α_l (`ndf.ggx`); G₂: height-correlated Smith (`masking`, Heitz 2014,
  Eq. 99); F_l: Schlick's F₀_l + (1 − F₀_l)(1 − ⟨h',ω_i'⟩)⁵ (`optics.fresnel.fresnel_schlick`);
  a ≥ 0 the Lambert weight, s_l ≥ 0 the lobe weights. (X-Rite's CPA2 decoder writes its lobes
  with the Beckmann NDF and the Cook–Torrance V-cavity G, as the Unity HDRP AxF shader
  evaluates them; the lobes here are the library's GGX ones.)
* χ_j(θ_h, θ_d): the colour table, (n_h, n_d, 3) values on uniform grids of θ_h = ∠(n, h) and
  θ_d = ∠(h, ω_i) over [0, π/2] (end points included), read bilinearly; evaluated at the
  directions inside the coat.
* The coat: a smooth dielectric of index η_c ≥ 1 (η_c = 1: no coat). ω_i', ω_o' are ω_i, ω_o
  refracted into it (sin θ = η_c sin θ'), T = 1 − F with F the exact unpolarised Fresnel
  reflectance of air | η_c (`coat_reflectance`; the same from either side).

The coat factor T_i T_o/η_c², derived. Radiance L from outside enters as L' = T_i η_c² L (the
radiance of a ray grows by η² across an interface: L/η² is invariant); the base reflects
L_r' = ∫ f_b L' cos θ_i' dω_i'; leaving, L_o = T_o L_r'/η_c². So L_o = ∫ T_i T_o f_b L cos θ_i'
dω_i', and with the étendue of refraction η_c² cos θ_i' dω_i' = cos θ_i dω_i (Snell's law:
η² cos θ' dω' is conserved) this is ∫ (T_i T_o f_b/η_c²) L cos θ_i dω_i: the η_c² of entering
and the 1/η_c² of leaving cancel, and the 1/η_c² left is the solid-angle factor. The value is
reciprocal (T_i T_o and f_b are). Energy: the coat's mirror reflects F(θ_o) of a uniform unit
light (`coat_reflectance`, the delta term kept *outside* the BRDF value), and the paint adds
T_o ∫_cone T_i f_b χ cos θ_i' dω_i' ≤ T_o (for χ ≤ 1 and an f_b of albedo ≤ 1), so the white
furnace gives ≤ F + T = 1 (tests/brdf/test_carpaint.py). Single scattering: light the coat
reflects back down onto the base (inside the cone and under total internal reflection) is
left out, as in the AxF model.

Directional albedo (`lobe_albedo`, `paint_patch_nodes`). With colour 1, lobe l reflects
A_l(θ_o) = T_o ∫_cone T(θ_i) s_l ρ_l F_l cos θ_i' dω_i' of a uniform unit light: inside the coat
the light comes only from the refraction cone cos θ_i' ≥ c_min = √(1 − 1/η_c²). The integral
is `microfacet.patch_quadrature`'s half-vector rule (inverse-CDF variable β of GGX, horizon-
clustered inner nodes, Gauss–Jacobi azimuths) at the view θ_o' with its inner limit moved from
the horizon to the cone: for a half-vector azimuth φ_h, ⟨n,ω_i'⟩ = R cos(2θ_h − δ) ≥ c_min for
θ_h ≤ θ_max with tan θ_max = (sin θ_o' cos φ_h + √(R² − c²_min))/(cos θ_o' + c_min) =
(cos θ_o' − c_min)/(√(R² − c²_min) − sin θ_o' cos φ_h) (R, δ as in `microfacet`; c_min = 0 gives
its horizon); T(θ_i) ∝ √(cos θ_i' − c_min) near the cone edge, which the horizon-clustered
inner nodes (1 − s ∝ (1 − x)²) make smooth. The Lambert term: a/η_c² T_o ∫_0^1 T(c) 2c dc by
Gauss–Legendre in c = cos θ_i.

Pigments (colour tables from the library's own optics, the three default observer bands):

* `pearlescent_colour(film)`: χ_j = `rgb_reflectance`(film, cos θ_d)_j, the flake a thin film
  met at θ_d (a mica platelet coated with TiO₂ in a binder: η₁ ≈ 1.5, η₂ ≈ 2.5–2.7 (anatase
  to rutile), η₃ ≈ 1.56; layer thicknesses of tens to ≈ 150 nm give the silver-to-green
  interference series, Pfaff & Reynders 1999, Chem. Rev. 99, 1963; Maile, Pfaff & Reynders
  2005, Prog. Org. Coat. 54, 150);
* `metallic_colour(eta, kappa)`: the bare flake of a conductor under the binder,
  `spectral.reflectance.bare_bands` (aluminium: η ≈ 0.96, κ ≈ 6.69 at 550 nm, Rakić 1995,
  Appl. Opt. 34, 4755, as refractiveindex.info tabulates it);
* `plain_colour(rgb)`: a constant table.

Negative band values (the default bands are colour-matching functions with negative lobes)
are clipped to 0 in the pigment tables (so a table is a valid χ ≥ 0).

Example (a one-lobe paint without a coat is the library's GGX material; with a coat the
value stays reciprocal and the white furnace stays ≤ 1):
    >>> import numpy as np
    >>> from thinfilm_jax.brdf import carpaint as C, material as M
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> wi = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    >>> wo = np.array([-np.sin(0.7), 0.1, np.cos(0.7)]); wo = wo / np.linalg.norm(wo)
    >>> bare = C.car_paint(0.0, [1.0], [0.3], [1.0], C.plain_colour([1.0, 1.0, 1.0]), 1.0)
    >>> ggx = M.Material(M.ggx_lobe(0.3), M.no_fresnel(), M.no_diffuse())
    >>> bool(np.allclose(C.paint_brdf(bare, wi, wo, n), M.brdf_value(ggx, wi, wo, n),
    ...                  rtol=1e-13, atol=0))
    True
    >>> paint = C.PAINTS["metallic"]()
    >>> f = C.paint_brdf(paint, wi, wo, n)
    >>> f.shape, bool(np.allclose(f, C.paint_brdf(paint, wo, wi, n), rtol=1e-12, atol=0))
    ((3,), True)
    >>> c = np.cos(np.array([0.0, 1.0, 1.5]))
    >>> total = C.coat_reflectance(paint, c) + C.lobe_albedo(paint, c).sum(-1)
    >>> bool(np.all(total <= 1))
    True
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..optics.fresnel import fresnel_schlick, safe_sqrt
from ..spectral.reflectance import bare_bands, rgb_reflectance
from ..spectral.spectra import DEFAULT_OBSERVER
from . import masking as _masking
from .material import check_direction
from .microfacet import composite_gauss_legendre
from . import microfacet as _mf
from . import ndf as _ndf

__all__ = ["CarPaint", "car_paint", "check_paint", "paint_colour", "paint_brightness",
           "paint_brdf", "brightness_and_colour", "coat_reflectance", "coat_transmittance",
           "refract_in", "lobe_albedo",
           "paint_patch_nodes", "DEFAULT_PAINT_QUADRATURE", "DEFAULT_DIFFUSE_QUADRATURE",
           "pearlescent_colour", "metallic_colour", "plain_colour", "PAINTS",
           "metallic_paint", "pearlescent_paint", "plain_paint", "AL_ETA", "AL_KAPPA"]

#: (n_u, n_φ) of the half-vector rule of each lobe in `lobe_albedo` / `paint_patch_nodes`
DEFAULT_PAINT_QUADRATURE = (64, 64)
#: (n_c, n_φ) of the product rule of the Lambert term (c = cos θ_i ∈ [0, 1], φ ∈ [0, π])
DEFAULT_DIFFUSE_QUADRATURE = (32, 32)
#: aluminium at 550 nm (Rakić 1995, Appl. Opt. 34, 4755; refractiveindex.info)
AL_ETA = 0.96
#: its extinction coefficient κ (same source)
AL_KAPPA = 6.69


class CarPaint(NamedTuple):
    """An AxF-CPA2-style car paint (a pytree; every leaf an array; module docstring).

    diffuse (): a ≥ 0, the Lambert weight a/π of the brightness; lobe_weight, lobe_alpha,
    lobe_f0 (L,): s_l ≥ 0, GGX α_l ∈ (0, 1], Schlick F₀_l ∈ [0, 1]; colour (n_h, n_d, 3): the
    table χ over θ_h, θ_d ∈ [0, π/2] (uniform grids, end points included), ≥ 0; coat_ior ():
    η_c ≥ 1 (1: no coat)."""

    diffuse: Array
    lobe_weight: Array
    lobe_alpha: Array
    lobe_f0: Array
    colour: Array
    coat_ior: Array


# ----------------------------------------------------------------------------- checks
def _leaf_dtype(*xs):
    """The widest floating dtype among the array arguments (Python numbers and integer arrays
    adapt; none: the default float), promoted outside JAX's strict mode and canonicalised
    (float64 host arrays give float32 unless 64-bit JAX is enabled, without a warning)."""
    dts = [np.dtype(x.dtype) for x in xs if hasattr(x, "dtype")]
    dts = [d for d in dts if np.issubdtype(d, np.floating)]
    return jax.dtypes.canonicalize_dtype(np.result_type(*dts) if dts else jnp.result_type(float))


def check_paint(paint) -> CarPaint:
    """`paint`, after checking its shapes (always) and values (concrete leaves; traced ones are
    not checked): a ValueError (TypeError for a non-`CarPaint`) naming the argument."""
    if not isinstance(paint, CarPaint):
        raise TypeError(f"paint must be a CarPaint, got {type(paint).__name__}")
    shapes = {k: np.shape(v) for k, v in paint._asdict().items()}
    for k in ("diffuse", "coat_ior"):
        if shapes[k] != ():
            raise ValueError(f"{k} must be a scalar (shape ()), got shape {shapes[k]}")
    nl = shapes["lobe_weight"]
    if len(nl) != 1:
        raise ValueError(f"lobe_weight must have shape (L,), got {nl}")
    for k in ("lobe_alpha", "lobe_f0"):
        if shapes[k] != nl:
            raise ValueError(f"{k} must have the shape of lobe_weight {nl}, got {shapes[k]}")
    cs = shapes["colour"]
    if len(cs) != 3 or cs[2] != 3 or cs[0] < 2 or cs[1] < 2:
        raise ValueError(f"colour must have shape (n_h, n_d, 3) with n_h, n_d >= 2, got {cs}")
    for k, v in paint._asdict().items():
        V.check_real(k, v)
    V.check_range("diffuse", paint.diffuse, 0.0, why=" (Lambert weight a >= 0)")
    V.check_range("lobe_weight", paint.lobe_weight, 0.0, why=" (lobe weights s_l >= 0)")
    V.check_range("lobe_alpha", paint.lobe_alpha, 0.0, 1.0, lo_open=True,
                  why=" (GGX roughness)")
    V.check_range("lobe_f0", paint.lobe_f0, 0.0, 1.0, why=" (Schlick F0)")
    V.check_range("colour", paint.colour, 0.0, why=" (colour table >= 0)")
    V.check_range("coat_ior", paint.coat_ior, 1.0, why=" (clear-coat IOR; 1 = no coat)")
    return paint


def car_paint(diffuse, lobe_weight, lobe_alpha, lobe_f0, colour, coat_ior=1.5) -> CarPaint:
    """A checked `CarPaint` (module docstring). Scalars for the lobe arguments mean one lobe;
    lists become arrays; the leaves share one floating dtype (the inputs' precision)."""
    args = {"diffuse": diffuse, "lobe_weight": lobe_weight, "lobe_alpha": lobe_alpha,
            "lobe_f0": lobe_f0, "colour": colour, "coat_ior": coat_ior}
    args = {k: V.check_real(k, V.as_array(k, v)) for k, v in args.items()}
    dt = _leaf_dtype(*args.values())
    out = {k: jnp.asarray(v, dt) for k, v in args.items()}
    for k in ("lobe_weight", "lobe_alpha", "lobe_f0"):
        if out[k].ndim == 0:
            out[k] = out[k][None]
    return check_paint(CarPaint(**out))


def _directions(paint, wi, wo, n):
    check_paint(paint)
    wi, wo, n = (check_direction(k, v) for k, v in (("wi", wi), ("wo", wo), ("n", n)))
    V.check_broadcast([("wi", wi), ("wo", wo), ("n", n)])
    dt = _leaf_dtype(wi, wo, n, paint.coat_ior)
    paint = CarPaint(*(jnp.asarray(x, dt) for x in paint))
    wi, wo, n = jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (wi, wo, n)))
    return paint, wi, wo, n


# ----------------------------------------------------------------------------- coat
_dot = _ndf.dot


def _cos_inside(c, eta):
    """cos θ' = √(c² + η² − 1)/η of the refracted ray (c = cos θ > 0 outside, η ≥ 1)."""
    return jnp.sqrt(c * c + (eta * eta - 1)) / eta


def _fresnel_coat(c, ct, eta):
    """Unpolarised F of air | η at cos θ = c ≥ 0 outside, cos θ_t = ct inside (real Fresnel
    equations, Born & Wolf §1.5.2); 0 at η = 1 (the 0/0 of c = ct = 0 too)."""
    den_s, den_p = c + eta * ct, eta * c + ct
    ok = den_s > 0
    ds, dp = jnp.where(ok, den_s, 1), jnp.where(ok, den_p, 1)
    rs, rp = (c - eta * ct) / ds, (eta * c - ct) / dp
    return jnp.where(ok, 0.5 * (rs * rs + rp * rp), 0)


def _coat(c, eta):
    """(cos θ', F) of outside cosines c (> 0 where used; guarded to 1 elsewhere by callers)."""
    ct = _cos_inside(c, eta)
    return ct, _fresnel_coat(c, ct, eta)


def coat_reflectance(paint: CarPaint, cos_o) -> Array:
    """F(θ_o) of the smooth coat, the weight of its mirror term L_coat = F(θ_o) L(ω_r) (exact
    unpolarised Fresnel of air | η_c; 0 at η_c = 1 and for cos θ_o < 0). Any shape."""
    check_paint(paint)
    cos_o = V.check_finite("cos_o", cos_o)
    dt = _leaf_dtype(cos_o, paint.coat_ior)
    c, eta = jnp.asarray(cos_o, dt), jnp.asarray(paint.coat_ior, dt)
    cc = _ndf.clamp01(c)
    ct = safe_sqrt(cc * cc + (eta * eta - 1)) / eta
    return jnp.where(c >= 0, _fresnel_coat(cc, ct, eta), 0)


def coat_transmittance(paint: CarPaint, cos_theta) -> Array:
    """T = 1 − F(θ) of the coat (0 for cos θ < 0)."""
    f = coat_reflectance(paint, cos_theta)
    return jnp.where(jnp.asarray(cos_theta) >= 0, 1 - f, 0)


def refract_in(w, n, eta):
    """ω' = ω/η + (cos θ' − cos θ/η) n: unit ω (outside, ⟨n,ω⟩ > 0) refracted into the coat
    (a direction pointing away from the base; exactly ω at η = 1)."""
    c = _dot(w, n)
    ct = _cos_inside(c, eta)
    return w / eta + (ct - c / eta)[..., None] * n


# ----------------------------------------------------------------------------- evaluation
def _angle(a, b):
    """∠(a, b) = atan2(|a × b|, ⟨a,b⟩), finite gradient where a ∥ b (double-where)."""
    x = jnp.cross(a, b)
    return jnp.arctan2(safe_sqrt(_dot(x, x)), _dot(a, b))


def _frame(paint, wi, wo, n):
    """Everything the value needs, guarded: up mask, outside/inside cosines, F_i, F_o, the
    inside half vector's cos θ_h', ⟨h',ω_i'⟩ and the angles θ_h', θ_d'."""
    eta = paint.coat_ior
    ci, co = _dot(wi, n), _dot(wo, n)
    up = (ci > 0) & (co > 0)
    cis = jnp.where(up, _ndf.clamp01(ci), 1)
    cos_ = jnp.where(up, _ndf.clamp01(co), 1)
    cti, fi = _coat(cis, eta)
    cto, fo = _coat(cos_, eta)
    wi_in = wi / eta + (cti - cis / eta)[..., None] * n
    wo_in = wo / eta + (cto - cos_ / eta)[..., None] * n
    h, ok = _ndf.half_vector(wi_in, wo_in, up)
    nh = jnp.where(ok, _ndf.clamp01(_dot(n, h)), 1)
    dh = jnp.where(ok, _ndf.clamp01(_dot(wi_in, h)), 1)
    th = jnp.where(ok, _angle(n, jnp.where(ok[..., None], h, n)), 0)
    td = jnp.where(ok, _angle(jnp.where(ok[..., None], wi_in, n),
                              jnp.where(ok[..., None], h, n)), 0)
    return dict(up=up, cti=cti, cto=cto, fi=fi, fo=fo, nh=nh, dh=dh, th=th, td=td)


def _brightness(paint, g):
    """f_b T_i T_o/η² (…) from the frame `g`, 0 below either horizon."""
    a, s, al, f0 = paint.diffuse, paint.lobe_weight, paint.lobe_alpha, paint.lobe_f0
    ci, co = g["cti"][..., None], g["cto"][..., None]
    d = _ndf.ggx(g["nh"][..., None], al)
    vis = _masking.visibility_smith_correlated(
        ci, co, _masking.lambda_cos_ggx(ci, al), _masking.lambda_cos_ggx(co, al))
    f = fresnel_schlick(f0, g["dh"][..., None])
    fb = a / np.pi + jnp.sum(s * d * vis * f, axis=-1)
    eta = paint.coat_ior
    t = (1 - g["fi"]) * (1 - g["fo"]) / (eta * eta)
    return jnp.where(g["up"], t * fb, 0)


def _colour(table, th, td):
    """Bilinear χ(θ_h, θ_d) on the uniform grids over [0, π/2] (…, 3)."""
    nh_, nd_ = table.shape[0], table.shape[1]
    x = jnp.clip(th * (2 / np.pi), 0, 1) * (nh_ - 1)
    y = jnp.clip(td * (2 / np.pi), 0, 1) * (nd_ - 1)
    i0 = jnp.clip(jnp.floor(x), 0, nh_ - 2).astype(jnp.int32)
    j0 = jnp.clip(jnp.floor(y), 0, nd_ - 2).astype(jnp.int32)
    fx = (x - i0.astype(x.dtype))[..., None]
    fy = (y - j0.astype(y.dtype))[..., None]
    top = table[i0, j0] * (1 - fy) + table[i0, j0 + 1] * fy
    bot = table[i0 + 1, j0] * (1 - fy) + table[i0 + 1, j0 + 1] * fy
    return top * (1 - fx) + bot * fx


@jax.jit
def _colour_jit(paint, wi, wo, n):
    g = _frame(paint, wi, wo, n)
    return jnp.where(g["up"][..., None], _colour(paint.colour, g["th"], g["td"]), 0)


@jax.jit
def _brightness_jit(paint, wi, wo, n):
    return _brightness(paint, _frame(paint, wi, wo, n))


@jax.jit
def brightness_and_colour(paint, wi, wo, n):
    """(`paint_brightness`, `paint_colour`) from one evaluation of the geometry, unchecked
    (for quadratures that call it inside their own jitted loops, e.g. `colour_table`)."""
    g = _frame(paint, wi, wo, n)
    col = jnp.where(g["up"][..., None], _colour(paint.colour, g["th"], g["td"]), 0)
    return _brightness(paint, g), col


@jax.jit
def _brdf_jit(paint, wi, wo, n):
    g = _frame(paint, wi, wo, n)
    return _brightness(paint, g)[..., None] * _colour(paint.colour, g["th"], g["td"])


def paint_colour(paint: CarPaint, wi, wo, n) -> Array:
    """χ_j(θ_h', θ_d') (..., 3) at the directions inside the coat (bilinear in the table);
    0 unless ⟨n,ω_i⟩, ⟨n,ω_o⟩ > 0. wi, wo: unit light and view directions (pointing away from
    the surface), n: unit normal, (..., 3), broadcast."""
    return _colour_jit(*_directions(paint, wi, wo, n))


def paint_brightness(paint: CarPaint, wi, wo, n) -> Array:
    """T(θ_i) T(θ_o) f_b(ω_i', ω_o')/η_c² (...,): the brightness BRDF seen through the coat
    (module docstring); 0 unless ⟨n,ω_i⟩, ⟨n,ω_o⟩ > 0."""
    return _brightness_jit(*_directions(paint, wi, wo, n))


def paint_brdf(paint: CarPaint, wi, wo, n) -> Array:
    """f_j = `paint_brightness` × `paint_colour` (..., 3), reciprocal; the coat's mirror
    reflection is not in it (`coat_reflectance`). jit/vmap/grad safe."""
    return _brdf_jit(*_directions(paint, wi, wo, n))


# ----------------------------------------------------------------------------- quadrature
def _cone_rule(co, so, alpha, c_min, n_u, n_phi):
    """`microfacet.patch_quadrature`'s half-vector rule at the inside view (cos θ_o', sin θ_o')
    with the inner limit at ⟨n,ω_i'⟩ = c_min (module docstring): (⟨h,ω_i'⟩ (N,), weight (N,)
    ≈ ρ̃ cos θ_i' dω_i' on y ≥ 0 doubled, ω_i' (N, 3))."""
    dt = co.dtype
    cp, sp, wphi = (jnp.asarray(a, dt)[:, None] for a in _mf._phi_rule(n_phi))
    r2 = so * so * cp * cp + co * co
    rs = safe_sqrt(r2 - c_min * c_min)
    pos = cp >= 0
    num = jnp.where(pos, so * cp + rs, co - c_min)
    den = jnp.where(pos, co + c_min, rs - so * cp)
    num = jnp.maximum(num, 0)
    zero = (num == 0) & (den == 0)
    num, den = jnp.where(zero, 1, num), jnp.where(zero, 1, den)
    bmax = jnp.where(zero, 0, jnp.arctan2(num, alpha * den))
    gmax = jnp.where(zero, np.pi / 2, jnp.arctan2(alpha * den, num))
    s, t, g = (jnp.asarray(a, dt)[None, :] for a in _mf._inner_rule(n_u, "ggx"))
    beta = bmax * s
    gamma = gmax + bmax * t
    sb, cb = jnp.sin(beta), jnp.sin(gamma)
    ch, sh, th = _mf._half_vector_trig(sb, cb, alpha)
    c = so * sh * cp + co * ch  # ⟨o', h⟩
    ci = jnp.maximum(2 * c * ch - co, 0)
    w_beta = bmax * g * _mf._beta_pdf(sb, cb, "ggx")
    weight = w_beta * wphi * _mf._g2_over_cos_o(ci, co, alpha, "ggx") * (so * th * cp + co)
    weight = jnp.where(ci > c_min, jnp.maximum(weight, 0), 0)
    h = jnp.stack([sh * cp, sh * sp, ch], axis=-1)
    o = jnp.stack([so, jnp.zeros_like(so), co])
    wi = 2 * c[..., None] * h - o
    return c.reshape(-1), weight.reshape(-1), wi.reshape(-1, 3)


def _nodes_one(paint, cos_o, orders):
    """Nodes of one view (module docstring), frame n = z, ω_o = (sin θ_o, 0, cos θ_o)."""
    n_u, n_phi, n_c, n_pd = orders
    dt = cos_o.dtype
    eta = paint.coat_ior
    up = cos_o > 0
    c_o = jnp.where(up, _ndf.clamp01(cos_o), 1)
    co_in, f_o = _coat(c_o, eta)
    t_o = jnp.where(up, 1 - f_o, 0)
    so_in = safe_sqrt((1 - c_o) * (1 + c_o)) / eta  # sin θ_o' = sin θ_o/η
    c_min = safe_sqrt(eta * eta - 1) / eta
    e2m1 = eta * eta - 1

    def lobe(alpha, s, f0):
        c, w, wi_in = _cone_rule(co_in, so_in, alpha, c_min, n_u, n_phi)
        ci_in = wi_in[:, 2]
        c_out = safe_sqrt(eta * eta * ci_in * ci_in - e2m1)
        ok = c_out > 0
        cso = jnp.where(ok, c_out, 1)
        ct, f_i = _coat(cso, eta)
        t_i = jnp.where(ok, 1 - f_i, 0)
        wi = jnp.concatenate([wi_in[:, :2] * eta, c_out[:, None]], axis=-1)
        return wi, w * s * fresnel_schlick(f0, c) * t_i * t_o

    wl, wt = jax.vmap(lobe)(paint.lobe_alpha, paint.lobe_weight, paint.lobe_f0)
    # Lambert: c = cos θ_i ∈ [0, 1] × φ ∈ [0, π] (doubled), weight a/π T_i T_o/η² c dc dφ
    xc, wc = (jnp.asarray(a, dt) for a in composite_gauss_legendre(n_c))
    xp, wp = (jnp.asarray(a, dt) for a in composite_gauss_legendre(n_pd))
    phi = np.pi * xp
    ct_i, f_i = _coat(xc, eta)
    sc = safe_sqrt((1 - xc) * (1 + xc))
    wid = jnp.stack([sc[:, None] * jnp.cos(phi)[None], sc[:, None] * jnp.sin(phi)[None],
                     jnp.broadcast_to(xc[:, None], (xc.shape[0], phi.shape[0]))], -1)
    wd = ((paint.diffuse / np.pi) * (1 - f_i) * t_o / (eta * eta) * xc * wc)[:, None] \
        * (2 * np.pi * wp)[None]
    return wl, wt, wid.reshape(-1, 3), wd.reshape(-1)


@functools.partial(jax.jit, static_argnums=(2,))
def _nodes_jit(paint, cos_o, orders):
    return jax.lax.map(lambda c: _nodes_one(paint, c, orders), cos_o)


def _orders(quadrature, diffuse_quadrature):
    n_u, n_phi = V.check_quadrature(quadrature)
    n_c, n_pd = V.check_quadrature(diffuse_quadrature, "diffuse_quadrature")
    return n_u, n_phi, n_c, n_pd


def _quadrature_args(paint, cos_o, quadrature, diffuse_quadrature):
    """Checked (paint, cos θ_o, orders) in one floating dtype for the quadratures below."""
    check_paint(paint)
    cos_o = V.check_range("cos_o", cos_o, -1.0, 1.0, ulps=V.ROUNDING_ULPS, clamp=True)
    orders = _orders(quadrature, diffuse_quadrature)
    dt = _leaf_dtype(cos_o, paint.coat_ior)
    return CarPaint(*(jnp.asarray(x, dt) for x in paint)), jnp.asarray(cos_o, dt), orders


def paint_patch_nodes(paint: CarPaint, cos_o, *, quadrature=DEFAULT_PAINT_QUADRATURE,
                      diffuse_quadrature=DEFAULT_DIFFUSE_QUADRATURE):
    """Quadrature of ∫ f(ω_i, ω_o) g(ω_i) cos θ_i dω_i for the paint's brightness, frame n = z,
    ω_o = (sin θ_o, 0, cos θ_o), nodes on y ≥ 0 (weights doubled: the paint is isotropic).

    Returns (wi_lobes (..., L, N, 3), w_lobes (..., L, N), wi_diffuse (..., M, 3),
    w_diffuse (..., M)): outside light directions and weights T_i T_o f_b,l cos θ_i dω_i/η_c²
    (everything but the colour), so that Σ w g(ω_i) ≈ ∫ f_b g cos θ_i dω_i for smooth g, and
    with g = χ_j the patch radiance (`shading.carpaint_ibl.paint_patch_radiance`).
    quadrature = (n_u, n_φ) of each lobe's half-vector rule (N = n_u n_φ);
    diffuse_quadrature = (n_c, n_φ) of the Lambert term's product rule (M = n_c n_φ).
    """
    paint, c, orders = _quadrature_args(paint, cos_o, quadrature, diffuse_quadrature)
    out = _nodes_jit(paint, c.reshape(-1), orders)
    return tuple(o.reshape(c.shape + o.shape[1:]) for o in out)


@functools.partial(jax.jit, static_argnums=(2,))
def _albedo_jit(paint, cos_o, orders):
    def one(c):
        _, wl, _, wd = _nodes_one(paint, c, orders)
        return jnp.concatenate([jnp.sum(wl, -1), jnp.sum(wd)[None]])

    return jax.lax.map(one, cos_o)


def lobe_albedo(paint: CarPaint, cos_o, *, quadrature=DEFAULT_PAINT_QUADRATURE,
                diffuse_quadrature=DEFAULT_DIFFUSE_QUADRATURE) -> Array:
    """Directional albedo (..., L + 1) of each lobe and (last) of the Lambert term, seen through
    the coat with colour 1: ∫ T_i T_o f_b,l cos θ_i dω_i/η_c² (module docstring); 0 for
    cos θ_o ≤ 0. coat_reflectance + Σ lobe_albedo ≤ 1 when the lobes' own albedos are ≤ 1.

    Accuracy (float64, tests/brdf/test_carpaint.py): the default orders agree with a
    brute-force rule over the outside ω_i to 1e-15 (α = 0.15, 0.3) and with (256, 256) to
    ≤ 4e-11 for α ≥ 0.05, θ_o ≤ 1.55, coat or none; 1.4e-8 at α = 0.01 (against (512, 512)).
    """
    paint, c, orders = _quadrature_args(paint, cos_o, quadrature, diffuse_quadrature)
    out = _albedo_jit(paint, c.reshape(-1), orders)
    return out.reshape(c.shape + out.shape[1:])


# ----------------------------------------------------------------------------- pigments
def _grid(n, dt):
    return jnp.linspace(0.0, np.pi / 2, n, dtype=dt)


def _table_from_td(vals, n_h):
    """(n_d, 3) values of θ_d → (n_h, n_d, 3), clipped at 0 (module docstring)."""
    vals = jnp.where(vals > 0, vals, 0)
    return jnp.broadcast_to(vals[None], (n_h,) + vals.shape)


def pearlescent_colour(film: Film, n_h: int = 2, n_d: int = 91, *, method: str = "spectral"):
    """χ_j(θ_h, θ_d) = `rgb_reflectance`(film, cos θ_d)_j (n_h, n_d, 3): an interference flake
    (the microfacet) met by the light at θ_d, in the film's outer medium (the binder); the
    default θ_d grid is 1° (91 values), constant in θ_h (n_h = 2 is exact). Negative band
    values are clipped to 0. jit/grad safe in the film."""
    n_h, n_d = V.check_int("n_h", n_h, 2), V.check_int("n_d", n_d, 2)
    film = V.check_film(film)
    if film.shape != ():
        raise ValueError(f"film must be one film (scalar fields), got shape {film.shape}")
    dt = _leaf_dtype(*film)
    c = jnp.cos(_grid(n_d, dt))
    return _table_from_td(rgb_reflectance(film.astype(dt), c, method=method), n_h)


def metallic_colour(eta=AL_ETA, kappa=AL_KAPPA, eta_outer: float = 1.5, n_h: int = 2,
                    n_d: int = 91):
    """χ_j(θ_h, θ_d) = R_j(cos θ_d) of a bare conductor flake η + iκ under the binder η₁ =
    `eta_outer` (`spectral.reflectance.bare_bands`: exact unpolarised Fresnel, flat in λ, so
    the same in the three bands); default aluminium at 550 nm (Rakić 1995). (n_h, n_d, 3)."""
    n_h, n_d = V.check_int("n_h", n_h, 2), V.check_int("n_d", n_d, 2)
    film = V.check_film(Film(0.0, eta_outer, eta, kappa, eta_outer), "flake")
    if film.shape != ():
        raise ValueError(f"eta, kappa, eta_outer must be scalars, got shape {film.shape}")
    dt = _leaf_dtype(*film)
    c = jnp.cos(_grid(n_d, dt))
    film = film.astype(dt)
    return _table_from_td(bare_bands(film, c, DEFAULT_OBSERVER), n_h)


def plain_colour(rgb, n_h: int = 2, n_d: int = 2):
    """A constant table χ ≡ rgb (n_h, n_d, 3), rgb ≥ 0 of shape (3,)."""
    n_h, n_d = V.check_int("n_h", n_h, 2), V.check_int("n_d", n_d, 2)
    rgb = V.check_range("rgb", rgb, 0.0)
    if np.shape(rgb) != (3,):
        raise ValueError(f"rgb must have shape (3,), got {np.shape(rgb)}")
    rgb = jnp.asarray(rgb, _leaf_dtype(rgb))
    return jnp.broadcast_to(rgb, (n_h, n_d, 3))


# ----------------------------------------------------------------------------- examples
def metallic_paint(coat_ior=1.5) -> CarPaint:
    """An aluminium-flake metallic (illustrative values, not a measured paint): a = 0.02, three
    lobes s = (0.3, 0.4, 0.3), α = (0.05, 0.15, 0.4), F₀ = (0.9, 0.8, 0.6) (flake, sparkle and
    haze), colour `metallic_colour()` (Al, Rakić 1995) tinted blue (0.35, 0.5, 0.9), coat η_c =
    1.5 (an automotive clear coat's typical index)."""
    col = metallic_colour() * jnp.asarray([0.35, 0.5, 0.9])
    return car_paint(0.02, [0.3, 0.4, 0.3], [0.05, 0.15, 0.4], [0.9, 0.8, 0.6], col, coat_ior)


def pearlescent_paint(thickness=120.0, coat_ior=1.5) -> CarPaint:
    """A TiO₂-on-mica pearlescent (illustrative lobes): flake film `Film(thickness, 2.6, 1.56,
    0, 1.5)` (TiO₂ η ≈ 2.6 on mica η ≈ 1.56 in a binder η ≈ 1.5; Pfaff & Reynders 1999; 120 nm
    gives a blue–violet interference colour), a = 0.05, two lobes s = (0.6, 0.4), α = (0.1,
    0.3), F₀ = 1 (the colour table carries the film's reflectance), coat η_c = 1.5."""
    col = pearlescent_colour(Film(thickness, 2.6, 1.56, 0.0, 1.5))
    return car_paint(0.05, [0.6, 0.4], [0.1, 0.3], [1.0, 1.0], col, coat_ior)


def plain_paint(coat_ior=1.5) -> CarPaint:
    """A solid (non-effect) red: Lambert a = 0.6 under one broad lobe s = 0.05, α = 0.5,
    F₀ = 0.04, colour (0.8, 0.1, 0.05), coat η_c = 1.5 (illustrative)."""
    return car_paint(0.6, [0.05], [0.5], [0.04], plain_colour([0.8, 0.1, 0.05]), coat_ior)


#: the example paints by name (constructors; parameters in their docstrings)
PAINTS = {"metallic": metallic_paint, "pearlescent": pearlescent_paint, "plain": plain_paint}
