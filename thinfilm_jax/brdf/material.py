r"""`Material`: one specular microfacet lobe × one Fresnel term + one diffuse term, as band values.

    f_j(ω_i, ω_o) = D(h) V(ω_i, ω_o) F_j(⟨h,ω_i⟩) + f_diffuse,j(ω_i, ω_o),
    V = G/(4⟨n,ω_i⟩⟨n,ω_o⟩),

h = normalize(ω_i + ω_o), 0 unless ⟨n,ω_i⟩, ⟨n,ω_o⟩ > 0; J = 3 bands of the observer (SPEC §1:
unit-area bands, so a flat reflectance R gives R in every band). The pieces come from `ndf`
(D), `masking` (G, V) and `diffuse`; the Fresnel terms from the existing optics:

Fresnel kinds, F_j(c) at c = ⟨h,ω_i⟩:

* "one": 1 (the white furnace);
* "schlick": `optics.fresnel.fresnel_schlick(f0, c)`, f0 a number or bands (..., J);
* "dielectric", "conductor": the exact unpolarised R of the bare interface η₁ | η + iκ
  (`spectral.reflectance.bare_bands`, i.e. `optics.fresnel.film_interfaces` with no film);
* "film": the exact band reflectance of a `Film` at c, `spectral.reflectance.rgb_reflectance`
  (method "spectral" or "fourier").

Specular NDFs (`ndf`): "ggx", "beckmann", "ggx_aniso", "blinn_phong", "ashikhmin_shirley",
"none"; maskings (`masking.MASKINGS`): "smith_correlated", "smith_separable" (Smith Λ of GGX,
Beckmann, anisotropic GGX, and for Blinn–Phong the Beckmann Λ at Walter's α = √(2/(s + 2)), an
approximation that is not the Λ of that D: for rough lobes it gains energy at grazing views,
directional albedo with F = 1 of 1.40 at s = 0 and 1.014 at s = 10, θ_o = 1.5, ≤ 1 from s = 20
on, tests/brdf/test_brdf_material.py), "v_cavity", "ashikhmin_shirley", "implicit" (any NDF).
The "ashikhmin_shirley" NDF of a `Material` is the paper's p(h) (`ndf.ashikhmin_shirley_pdf`,
normalised on dω_h, a factor κ = √((n_u+1)(n_v+1)/((n_u+2)(n_v+2))) below the projected-area NDF `ndf.ashikhmin_shirley`), so
that `ashikhmin_shirley_lobe` with its default masking "ashikhmin_shirley" is Ashikhmin &
Shirley's 2000 specular BRDF as published (their Eq. 4):
√((n_u+1)(n_v+1))/(8π) ⟨n,h⟩^{e(φ_h)} F/(⟨h,ω_o⟩ max(c_i, c_o)).
Diffuse kinds: "none", "lambert", "oren_nayar", "ashikhmin_shirley" (coupled to the specular
layer through R_s = F_j(1), their Eq. 5).

The parameters are pytree leaves (`jax.grad` with respect to a `Material` gives a `Material` of
gradients); the names are static aux data (`jit` specialises on them). The constructors and
`brdf_value` check concrete inputs and raise a `ValueError` naming the argument; traced values
(inside `jit`, `vmap`, `grad`) are not checked.

Example (a rough gold-like conductor: a GGX lobe with Schlick Fresnel over Lambert; the value
is symmetric in ω_i ↔ ω_o):
    >>> import numpy as np
    >>> from thinfilm_jax.brdf import material as M
    >>> mat = M.Material(M.ggx_lobe(0.3), M.schlick_fresnel([1.0, 0.78, 0.34]),
    ...                  M.lambert_diffuse(0.1))
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> wi = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    >>> wo = np.array([-np.sin(0.7), 0.0, np.cos(0.7)])
    >>> f = M.brdf_value(mat, wi, wo, n)
    >>> f.shape, bool(np.allclose(f, M.brdf_value(mat, wo, wi, n), rtol=1e-14, atol=0))
    ((3,), True)
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core._pytree import pytree_dataclass
from ..core.film import Film
from ..optics.fresnel import fresnel_schlick
from ..spectral.reflectance import RGB_METHODS as FILM_METHODS
from ..spectral.reflectance import bare_bands, rgb_reflectance
from ..spectral.spectra import DEFAULT_OBSERVER, get_observer
from . import diffuse as _diffuse
from . import masking as _masking
from . import ndf as _ndf

__all__ = ["NDFS", "MASKINGS", "FRESNELS", "DIFFUSES", "Specular", "Fresnel", "Diffuse",
           "Material", "brdf_value", "ggx_lobe", "beckmann_lobe", "ggx_aniso_lobe",
           "blinn_phong_lobe", "ashikhmin_shirley_lobe", "no_specular", "no_fresnel",
           "schlick_fresnel", "dielectric_fresnel", "conductor_fresnel", "film_fresnel",
           "no_diffuse", "lambert_diffuse", "oren_nayar_diffuse", "ashikhmin_shirley_diffuse"]

NDFS = ("ggx", "beckmann", "ggx_aniso", "blinn_phong", "ashikhmin_shirley", "none")
ROUGHNESS_NDFS = ("ggx", "beckmann", "ggx_aniso")  # shape = α ∈ (0, 1]
EXPONENT_NDFS = ("blinn_phong", "ashikhmin_shirley")  # shape = exponent ≥ 0
ANISOTROPIC_NDFS = ("ggx_aniso", "ashikhmin_shirley")  # need a tangent t
SMITH_NDFS = ("ggx", "beckmann", "ggx_aniso", "blinn_phong")  # a Smith Λ exists
MASKINGS = _masking.MASKINGS
FRESNELS = ("one", "schlick", "dielectric", "conductor", "film")
DIFFUSES = _diffuse.DIFFUSES
#: |‖v‖ − 1| and |⟨t, n⟩| allowed for the direction arguments of `brdf_value`
UNIT_TOL = 1e-6


class Specular:
    """A microfacet specular lobe: `ndf` and `masking` names (static) and the NDF's widths along
    t and b, `shape_x`, `shape_y` (α for GGX/Beckmann, exponents n_u, n_v for Blinn–Phong and
    Ashikhmin–Shirley; isotropic NDFs read `shape_x`). Build it with the `*_lobe` constructors."""

    ndf: str
    masking: str
    shape_x: object = 1.0
    shape_y: object = 1.0


class Fresnel:
    """A Fresnel term: `kind` (static, `FRESNELS`), `f0` (Schlick), `film` (a `Film`; for
    "dielectric"/"conductor" a bare one, thickness 0 and η₂ = η₁), and for "film" the static
    `method`/`terms` of `rgb_reflectance`; `observer` names the bands."""

    kind: str
    f0: object = None
    film: object = None
    method: str = "spectral"
    terms: int = 2
    observer: str = DEFAULT_OBSERVER


class Diffuse:
    """A diffuse term: `kind` (static, `DIFFUSES`), `albedo` (a number or bands (..., J)) and the
    Oren–Nayar slope deviation `sigma` (radians)."""

    kind: str
    albedo: object = 0.0
    sigma: object = 0.0


class Material:
    """One specular lobe × one Fresnel term + one diffuse term (a pytree)."""

    specular: Specular
    fresnel: Fresnel
    diffuse: Diffuse


Specular = pytree_dataclass(Specular, ["shape_x", "shape_y"], ["ndf", "masking"])
Fresnel = pytree_dataclass(Fresnel, ["f0", "film"], ["kind", "method", "terms", "observer"])
Diffuse = pytree_dataclass(Diffuse, ["albedo", "sigma"], ["kind"])
Material = pytree_dataclass(Material, ["specular", "fresnel", "diffuse"], [])


# ----------------------------------------------------------------------------- checks
def _check_specular(s):
    if not isinstance(s, Specular):
        raise TypeError(f"specular must be a Specular, got {type(s).__name__}")
    V.check_choice("ndf", s.ndf, NDFS)
    V.check_choice("masking", s.masking, MASKINGS)
    if s.masking.startswith("smith") and s.ndf not in SMITH_NDFS + ("none",):
        raise ValueError(f"masking {s.masking!r} needs a Smith Λ, which ndf {s.ndf!r} does not "
                         f"have in closed form; use 'v_cavity', 'ashikhmin_shirley' or "
                         f"'implicit'")
    if s.ndf in ROUGHNESS_NDFS:
        for k in ("shape_x", "shape_y"):
            V.check_range(f"{s.ndf} alpha ({k})", getattr(s, k), 0.0, 1.0, lo_open=True,
                          why=" (roughness)")
    elif s.ndf in EXPONENT_NDFS:
        for k in ("shape_x", "shape_y"):
            V.check_range(f"{s.ndf} exponent ({k})", getattr(s, k), 0.0, why=" (>= 0)")
    return s


def _check_fresnel(f):
    if not isinstance(f, Fresnel):
        raise TypeError(f"fresnel must be a Fresnel, got {type(f).__name__}")
    V.check_choice("fresnel", f.kind, FRESNELS)
    V.check_choice("observer", f.observer, ("stiles_burch_1959_10", "cie_1931_2"))
    if f.kind == "schlick":
        V.check_range("f0", f.f0, 0.0, 1.0)
    if f.kind in ("dielectric", "conductor", "film"):
        V.check_film(f.film, "film" if f.kind == "film" else f.kind)
    if f.kind == "film":
        V.check_choice("method", f.method, FILM_METHODS)
        V.check_int("terms", f.terms, 0)
    return f


def _check_diffuse(d):
    if not isinstance(d, Diffuse):
        raise TypeError(f"diffuse must be a Diffuse, got {type(d).__name__}")
    V.check_choice("diffuse", d.kind, DIFFUSES)
    if d.kind != "none":
        V.check_range("albedo", d.albedo, 0.0, 1.0)
    if d.kind == "oren_nayar":
        V.check_range("sigma", d.sigma, 0.0, why=" (radians, slope deviation)")
    return d


def check_direction(name, v):
    """`v` (..., 3) checked: finite, and unit vectors (to `UNIT_TOL`) where concrete."""
    v = V.check_finite(name, v)
    if np.ndim(v) < 1 or np.shape(v)[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3); got {np.shape(v)}")
    if V.is_concrete(v):
        norm = np.linalg.norm(np.asarray(v, float), axis=-1)
        if np.any(np.abs(norm - 1) > UNIT_TOL):
            bad = norm[np.abs(norm - 1) > UNIT_TOL].flat[0]
            raise ValueError(f"{name} must be a unit vector (|‖{name}‖ − 1| ≤ {UNIT_TOL}); got "
                             f"norm {bad!r}")
    return v


# ----------------------------------------------------------------------------- constructors
def _spec(ndf, masking, x, y):
    return _check_specular(Specular(ndf, masking, V.as_array("shape", x), V.as_array("shape", y)))


def ggx_lobe(alpha, masking: str = "smith_correlated") -> Specular:
    """GGX lobe of roughness α ∈ (0, 1] (`ndf.ggx`)."""
    return _spec("ggx", masking, alpha, alpha)


def beckmann_lobe(alpha, masking: str = "smith_correlated") -> Specular:
    """Beckmann lobe of roughness α ∈ (0, 1] (`ndf.beckmann`)."""
    return _spec("beckmann", masking, alpha, alpha)


def ggx_aniso_lobe(alpha_x, alpha_y, masking: str = "smith_correlated") -> Specular:
    """Anisotropic GGX lobe, α_x along the tangent t, α_y along b = n × t (`ndf.ggx_aniso`)."""
    return _spec("ggx_aniso", masking, alpha_x, alpha_y)


def blinn_phong_lobe(exponent, masking: str = "v_cavity") -> Specular:
    """Normalised Blinn–Phong lobe of exponent s ≥ 0 (`ndf.blinn_phong`); Cook–Torrance's
    V-cavity masking by default."""
    return _spec("blinn_phong", masking, exponent, exponent)


def ashikhmin_shirley_lobe(n_u, n_v, masking: str = "ashikhmin_shirley") -> Specular:
    """Ashikhmin–Shirley 2000 anisotropic Phong lobe, exponents n_u along t and n_v along b; with
    the default masking this is their specular BRDF (their Eq. 4)."""
    return _spec("ashikhmin_shirley", masking, n_u, n_v)


def no_specular() -> Specular:
    """No specular lobe (a purely diffuse material)."""
    return Specular("none", "implicit", 1.0, 1.0)


def no_fresnel() -> Fresnel:
    """F = 1 in every band (the white furnace)."""
    return Fresnel("one")


def schlick_fresnel(f0) -> Fresnel:
    """Schlick's F = F₀ + (1 − F₀)(1 − c)⁵, F₀ ∈ [0, 1] a number or bands (..., J)."""
    return _check_fresnel(Fresnel("schlick", f0=V.as_array("f0", f0)))


def dielectric_fresnel(eta, eta_outer=1.0) -> Fresnel:
    """Exact unpolarised Fresnel reflectance of a dielectric of index η under a medium η₁."""
    return _check_fresnel(Fresnel("dielectric", film=Film(0.0, eta_outer, eta, 0.0, eta_outer)))


def conductor_fresnel(eta, kappa, eta_outer=1.0) -> Fresnel:
    """Exact unpolarised Fresnel reflectance of a conductor η + iκ under a medium η₁."""
    return _check_fresnel(Fresnel("conductor", film=Film(0.0, eta_outer, eta, kappa, eta_outer)))


def film_fresnel(film: Film, *, method: str = "spectral", terms: int = 2,
                 observer: str = DEFAULT_OBSERVER) -> Fresnel:
    """Exact (method="spectral") or Fourier (method="fourier", M = terms) band reflectance of a
    thin film at c = ⟨h,ω_i⟩ (`rgb_reflectance`)."""
    f = Fresnel("film", film=film, method=method, terms=terms, observer=observer)
    f = _check_fresnel(f)
    return dataclasses.replace(f, film=V.check_film(film))


def no_diffuse() -> Diffuse:
    """No diffuse term."""
    return Diffuse("none")


def lambert_diffuse(albedo) -> Diffuse:
    """Lambert ρ/π, ρ ∈ [0, 1] a number or bands (..., J)."""
    return _check_diffuse(Diffuse("lambert", V.as_array("albedo", albedo)))


def oren_nayar_diffuse(albedo, sigma) -> Diffuse:
    """Oren–Nayar qualitative model, σ ≥ 0 the facet slope deviation in radians."""
    return _check_diffuse(Diffuse("oren_nayar", V.as_array("albedo", albedo),
                                  V.as_array("sigma", sigma)))


def ashikhmin_shirley_diffuse(albedo) -> Diffuse:
    """Ashikhmin–Shirley 2000 diffuse term (their Eq. 5), R_d = albedo, R_s = F_j(1) of the
    material's Fresnel term."""
    return _check_diffuse(Diffuse("ashikhmin_shirley", V.as_array("albedo", albedo)))


# ----------------------------------------------------------------------------- evaluation
_dot = _ndf.dot


def _fresnel_bands(f: Fresnel, c, dtype):
    """F_j(c), shape c.shape + (J,)."""
    j = get_observer(f.observer).n_bands
    ones = jnp.ones(c.shape + (j,), dtype)
    c = _ndf.clamp01(c)
    if f.kind == "one":
        return ones
    if f.kind == "schlick":
        return fresnel_schlick(jnp.asarray(f.f0, dtype), c[..., None]) * ones
    film = jax.tree.map(lambda x: jnp.asarray(x, dtype), f.film)
    if f.kind in ("dielectric", "conductor"):
        return bare_bands(film, c, f.observer, arithmetic="complex") * ones
    return rgb_reflectance(film, c, observer=f.observer, method=f.method, terms=f.terms)


def _specular_dv(s: Specular, ci, co, nh, oh, frame):
    """D(h) V(ω_i, ω_o) (before Fresnel) for cosines already guarded (c_i, c_o > 0)."""
    ax, ay = s.shape_x, s.shape_y
    if s.ndf == "none":
        return jnp.zeros_like(ci)
    if s.ndf == "ggx":
        d = _ndf.ggx(nh, ax)
    elif s.ndf == "beckmann":
        d = _ndf.beckmann(nh, ax)
    elif s.ndf == "blinn_phong":
        d = _ndf.blinn_phong(nh, ax)
    else:
        h_t, h_b = frame["h"]
        d = (_ndf.ggx_aniso(h_t, h_b, nh, ax, ay) if s.ndf == "ggx_aniso"
             else _ndf.ashikhmin_shirley_pdf(h_t, h_b, nh, ax, ay))
    m = s.masking
    if m.startswith("smith"):
        if s.ndf == "ggx_aniso":
            (it, ib), (ot, ob) = frame["i"], frame["o"]
            li = _masking.lambda_cos_ggx_aniso(it, ib, ci, ax, ay)
            lo = _masking.lambda_cos_ggx_aniso(ot, ob, co, ax, ay)
        else:
            kind, a = ("beckmann", _ndf.walter_alpha(ax)) if s.ndf == "blinn_phong" \
                else (s.ndf, ax)
            li, lo = _masking.lambda_cos(ci, a, kind), _masking.lambda_cos(co, a, kind)
        vis = (_masking.visibility_smith_correlated if m == "smith_correlated"
               else _masking.visibility_smith_separable)(ci, co, li, lo)
    elif m == "v_cavity":
        vis = _masking.visibility_v_cavity(nh, ci, co, oh)
    elif m == "ashikhmin_shirley":
        vis = _masking.visibility_ashikhmin_shirley(ci, co, oh)
    else:
        vis = 0.25 * jnp.ones_like(ci)
    return d * vis


def _diffuse_bands(d: Diffuse, f: Fresnel, wi, wo, n, dtype):
    if d.kind == "none":
        return None
    wi, wo, n = wi[..., None, :], wo[..., None, :], n[..., None, :]  # band axis before xyz
    alb = jnp.asarray(d.albedo, dtype)
    if d.kind == "lambert":
        return _diffuse.lambert(alb, wi, wo, n)
    if d.kind == "oren_nayar":
        return _diffuse.oren_nayar(alb, jnp.asarray(d.sigma, dtype), wi, wo, n)
    rs = _fresnel_bands(f, jnp.ones(wi.shape[:-2], dtype), dtype)
    return _diffuse.ashikhmin_shirley(alb, rs, wi, wo, n)


@jax.jit
def _brdf(material: Material, wi, wo, n, t):
    wi, wo, n = jnp.broadcast_arrays(*_ndf._float(wi, wo, n))
    dtype = wi.dtype
    ci, co = _dot(wi, n), _dot(wo, n)
    up = (ci > 0) & (co > 0)
    h, ok = _ndf.half_vector(wi, wo, up)
    nh = jnp.where(ok, _ndf.clamp01(_dot(n, h)), 1)
    oh = jnp.where(ok, _ndf.clamp01(_dot(wo, h)), 1)
    cis, cos_ = jnp.where(up, _ndf.clamp01(ci), 1), jnp.where(up, _ndf.clamp01(co), 1)
    frame = {}
    if t is not None:
        t = jnp.asarray(t, dtype)
        b = jnp.cross(n, t)
        frame = {"h": (_dot(h, t), _dot(h, b)), "i": (_dot(wi, t), _dot(wi, b)),
                 "o": (_dot(wo, t), _dot(wo, b))}
    s = material.specular
    s = dataclasses.replace(s, shape_x=jnp.asarray(s.shape_x, dtype),
                            shape_y=jnp.asarray(s.shape_y, dtype))
    spec = _specular_dv(s, cis, cos_, nh, oh, frame)
    f = _fresnel_bands(material.fresnel, oh, dtype)
    out = spec[..., None] * f
    diff = _diffuse_bands(material.diffuse, material.fresnel, wi, wo, n, dtype)
    if diff is not None:
        out = out + diff
    return jnp.where(up[..., None], out, 0)


def check_material(material) -> Material:
    """The material, after checking its names and (concrete) parameters (ValueError/TypeError)."""
    if not isinstance(material, Material):
        raise TypeError(f"material must be a Material, got {type(material).__name__}")
    _check_specular(material.specular)
    _check_fresnel(material.fresnel)
    _check_diffuse(material.diffuse)
    return material


def brdf_value(material: Material, wi, wo, n, t=None):
    """Band values f_j(ω_i, ω_o) of `material`, shape broadcast(wi, wo, n, t)[:-1] + (J,).

    Args:
        material: a `Material`.
        wi, wo: unit light and view directions (..., 3), pointing away from the surface.
        n: unit normal (..., 3).
        t: unit tangent ⟂ n (..., 3), the direction of α_x / n_u; required by the anisotropic
            NDFs ("ggx_aniso", "ashikhmin_shirley"), ignored by the others. b = n × t.

    0 where ⟨n,ω_i⟩ ≤ 0 or ⟨n,ω_o⟩ ≤ 0. jit/vmap/grad safe (finite gradients on the closed
    upper hemisphere, h = n included).
    """
    check_material(material)
    wi, wo, n = (check_direction(k, v) for k, v in (("wi", wi), ("wo", wo), ("n", n)))
    shapes = [("wi", wi), ("wo", wo), ("n", n)]
    if material.specular.ndf in ANISOTROPIC_NDFS:
        if t is None:
            raise ValueError(f"ndf {material.specular.ndf!r} is anisotropic: pass a unit tangent "
                             f"t ⟂ n")
    else:
        t = None
    if t is not None:
        t = check_direction("t", t)
        shapes.append(("t", t))
        if V.is_concrete(t) and V.is_concrete(n):
            dots = np.abs(np.sum(np.asarray(t, float) * np.asarray(n, float), axis=-1))
            if np.any(dots > UNIT_TOL):
                raise ValueError(f"t must be perpendicular to n (|⟨t, n⟩| ≤ {UNIT_TOL}); got "
                                 f"|⟨t, n⟩| = {float(dots.max())!r}")
    V.check_broadcast(shapes)
    if t is not None:
        shape = jnp.broadcast_shapes(*(np.shape(v) for _, v in shapes))
        t = jnp.broadcast_to(jnp.asarray(t), shape)
    return _brdf(material, wi, wo, n, t)

