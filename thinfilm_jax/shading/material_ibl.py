r"""Any composed `Material` under an environment map (SPEC §9): converged quadrature and MC.

$$ L_j(n, \omega_o) = \sum_t \int_t f_j(\omega_i, \omega_o)\,\langle n,\omega_i\rangle\,
   c_t\, d\omega_i $$

over the texels t of the piecewise-constant map (radiance c_t). How RGB light meets the
material's bands:

* *Spectral Fresnel terms* ("film", "dielectric", "conductor": an exact R(λ) exists) with
  `cross_band=True` (the default): the cross-band form of SPEC §9,
  Σ_k D V ⟨n,ω_i⟩ R_jk(⟨h,ω_i⟩) c_k, with R_jk the bands of the `uplift.cross_band_name`
  observer; tabulated at `n_cos` cosines and interpolated linearly exactly as
  `ibl_reference` does (`reflectance_table`, `interp_table`), so that a GGX + film material with
  height-correlated Smith masking reproduces `envmap_radiance(film, α, ...,
  method="reference", exhaustive=True)` to rounding (same texel nodes, same table);
  `n_cos=None` evaluates R_jk at every node instead.
* *Everything else* (the Schlick or unit Fresnel term, every diffuse term, and the spectral
  kinds with `cross_band=False`): the per-channel (diagonal) product f_j c_j, f_j from
  `brdf_value`.

`method="reference"`: every texel with s × s Gauss–Legendre nodes in (cos θ, φ)
(`ibl_integrand.texel_nodes`, the exhaustive rule's nodes; s = `ibl_reference.auto_subdivisions`
of the lobe's effective α — α for GGX/Beckmann (the smaller of α_x, α_y), Walter's
√(2/(s+2)) for the Phong exponents, 1 for a purely diffuse material — unless given).
`method="mc"`: cosine-weighted sampling of ω_i about n (pdf ⟨n,ω_i⟩/π, any material, no
NDF assumption), nearest-texel radiance (the piecewise-constant map's exact value), a fixed
key; `return_stderr=True` adds the standard error per band.

Example (a Lambert material under a white map is the uniform light: ρ; a GGX + film material
is the film's reference — on this 8 × 16 map the adaptive reference refines every block, so it
is the exhaustive rule):
    >>> import numpy as np
    >>> import thinfilm_jax as tf
    >>> from thinfilm_jax.shading.material_ibl import material_envmap_radiance
    >>> n, v = np.array([0.0, 0.0, 1.0]), np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    >>> lam = tf.Material(tf.no_specular(), tf.no_fresnel(), tf.lambert_diffuse(0.6))
    >>> white = np.ones((8, 16, 3))
    >>> float(np.abs(material_envmap_radiance(lam, n, v, white) - 0.6).max()) < 1e-12
    True
    >>> film = tf.Film(600.0, 1.3, 2.0, 0.5)
    >>> mat = tf.Material(tf.ggx_lobe(0.4), tf.film_fresnel(film), tf.no_diffuse())
    >>> env = np.random.default_rng(0).uniform(0, 2, (8, 16, 3))
    >>> ref = tf.envmap_radiance(film, 0.4, n, v, env)
    >>> float(np.abs(material_envmap_radiance(mat, n, v, env) - ref).max()) < 1e-12
    True
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..brdf import material as M
from ..core import _validate as V
from ..optics.airy import choose_arithmetic
from ..spectral.reflectance import spectral_bands
from ..spectral.spectra import get_observer
from ..spectral.uplift import cross_band_name
from .envmap import EnvMap, load_envmap, lookup_nearest
from .ibl_integrand import interp_table, _local_frame, reflectance_table
from .ibl_reference import exact_rule
from .material_patch import diffuse_only

__all__ = ["material_envmap_radiance", "MATERIAL_ENVMAP_METHODS", "effective_alpha"]

MATERIAL_ENVMAP_METHODS = ("reference", "mc")
SPECTRAL_FRESNELS = ("film", "dielectric", "conductor")
HIGHEST = jax.lax.Precision.HIGHEST


def effective_alpha(material: M.Material) -> float:
    """The lobe width that sets the reference's sub-texel nodes (module docstring)."""
    s = material.specular
    if s.ndf == "none":
        return 1.0
    a = np.asarray([s.shape_x, s.shape_y], float)
    if s.ndf in M.EXPONENT_NDFS:
        a = np.sqrt(2 / (np.max(a) + 2)) if s.ndf == "blinn_phong" else np.sqrt(2 / (a + 2))
    return float(np.min(a))


def _no_fresnel_specular(material):
    return dataclasses.replace(material, fresnel=dataclasses.replace(
        M.no_fresnel(), observer=material.fresnel.observer), diffuse=M.no_diffuse())


def _point_terms(material, dirs, n, wo, t, table, cfg):
    """(spectral part (N, J·K) or None, diagonal part (N, J)) of f ⟨n,ω_i⟩ at the nodes."""
    spectral, n_cos, obs, arithmetic = cfg
    ci = jnp.clip(jnp.sum(dirs * n, -1), 0.0, 1.0)
    if spectral:
        dv = M.brdf_value(_no_fresnel_specular(material), dirs, wo, n, t)[..., 0]
        hs = dirs + wo
        hn2 = jnp.sum(hs * hs, -1)
        ok = hn2 > 0
        c = jnp.clip(jnp.sum(hs * dirs, -1) / jnp.sqrt(jnp.where(ok, hn2, 1.0)), 0.0, 1.0)
        if n_cos is None:
            f = material.fresnel
            film = jax.tree.map(lambda x: jnp.asarray(x, dirs.dtype)[..., None], f.film)
            r = spectral_bands(film, c, obs, arithmetic=arithmetic)
        else:
            r = interp_table(table, c)
        spec = (dv * ci)[:, None] * r
        diag = (M.brdf_value(diffuse_only(material), dirs, wo, n, t) if
                material.diffuse.kind != "none" else None)
        return spec, None if diag is None else diag * ci[:, None]
    return None, M.brdf_value(material, dirs, wo, n, t) * ci[:, None]


def _contract(spec, diag, light, j):
    """Σ_n [Σ_k spec_(n, j, k) light_(n, k) + diag_(n, j) light_(n, j)] → (J,)."""
    out = jnp.zeros((j,), light.dtype)
    if spec is not None:
        k = spec.shape[-1] // j
        if k == 1:
            out = out + jnp.sum(spec * light[:, :j], 0)
        else:
            out = out + jnp.einsum("njk,nk->j", spec.reshape(-1, j, k), light, precision=HIGHEST)
    if diag is not None:
        out = out + jnp.sum(diag * light[:, :j], 0)
    return out


def _per_sample(spec, diag, light, j):
    """The per-node terms of `_contract` (N, J), not summed."""
    out = jnp.zeros(light.shape[:1] + (j,), light.dtype)
    if spec is not None:
        k = spec.shape[-1] // j
        out = out + (spec * light[:, :j] if k == 1 else
                     jnp.sum(spec.reshape(-1, j, k) * light[:, None, :], -1))
    if diag is not None:
        out = out + diag * light[:, :j]
    return out


@functools.partial(jax.jit, static_argnums=(6,))
def _ibl_jit(material, normal, view, tangent, radiance, extra, cfg):
    mc, spectral, n_cos, obs, arithmetic, batch, n_samples = cfg
    dtype = normal.dtype
    j = get_observer(material.fresnel.observer).n_bands
    shape = normal.shape[:-1]
    flat = [x.reshape(-1, 3) for x in (normal, view, tangent)]
    table = None
    if spectral and n_cos is not None:
        table = reflectance_table(material.fresnel.film, obs, n_cos, arithmetic, dtype)
    pcfg = (spectral, n_cos, obs, arithmetic)
    if not mc:  # the texel quadrature: extra = its nodes and their light
        dirs, light = extra

        def one(xs):
            n, wo, t = xs
            spec, diag = _point_terms(material, dirs, n, wo, t, table, pcfg)
            return _contract(spec, diag, light, j), jnp.zeros((j,), dtype)

        out, err = jax.lax.map(one, tuple(flat), batch_size=batch)
    else:
        keys = jax.random.split(extra, flat[0].shape[0])

        def one(xs):
            n, wo, t, key = xs
            u = jax.random.uniform(key, (n_samples, 2), dtype)
            tt, bb = _local_frame(n)
            r = jnp.sqrt(u[:, 0])
            phi = 2 * jnp.pi * u[:, 1]
            z = jnp.sqrt(jnp.maximum(1 - u[:, 0], 0.0))
            d = ((r * jnp.cos(phi))[:, None] * tt + (r * jnp.sin(phi))[:, None] * bb
                 + z[:, None] * n)
            d = d / jnp.linalg.norm(d, axis=-1, keepdims=True)
            # f ⟨n,ω⟩ / pdf = π f: the per-sample weight π / ⟨n,ω⟩ on f ⟨n,ω⟩
            ok = z > 0
            w = jnp.where(ok, jnp.pi / jnp.where(ok, z, 1.0), 0.0)
            spec, diag = _point_terms(material, d, n, wo, t, table, pcfg)
            light = w[:, None] * lookup_nearest(radiance, d)

            vals = _per_sample(spec, diag, light, j)
            return (jnp.mean(vals, 0),
                    jnp.std(vals, 0, ddof=1) / jnp.sqrt(jnp.asarray(n_samples, dtype)))

        out, err = jax.lax.map(one, tuple(flat) + (keys,), batch_size=batch)
    up = (jnp.sum(normal * view, -1) > 0)[..., None]
    return (jnp.where(up, out.reshape(shape + (j,)), 0.0),
            jnp.where(up, err.reshape(shape + (j,)), 0.0))


def material_envmap_radiance(material: M.Material, normal, view, envmap, *, tangent=None,
                             method: str = "reference", cross_band: bool = True,
                             subdivisions: int | None = None, n_cos: int | None = 1024,
                             n_samples: int = 65536, key=None, batch_size: int | None = None,
                             return_stderr: bool = False):
    """Band radiances L_j (..., J) of `material` under `envmap` (SPEC §9), any material.

    Args:
        material: a `brdf.material.Material` (one, shared by every shading point).
        normal, view: unit world vectors (..., 3) (z-up); view points toward the eye.
        envmap: `EnvMap`, an (H, W, 3) array or a path (`load_envmap`).
        tangent: unit tangents ⟂ normal (..., 3) of the anisotropic lobes; default the
            branch-free frame of the normal (Duff et al. 2017).
        method: "reference" (texel quadrature) or "mc" (cosine-weighted Monte Carlo).
        cross_band: R_jk under RGB light for the spectral Fresnel terms (module docstring).
        subdivisions: s × s nodes per texel (reference); None: `auto_subdivisions`.
        n_cos: cosines of the spectral Fresnel table (None: exact at every node).
        n_samples, key: MC sample count per point and PRNG key (default key 0).
        batch_size: shading points evaluated together (default ≈ 2¹⁹ nodes' worth).
        return_stderr: also return the MC standard error (zeros for "reference").

    Shading points with ⟨n, ω_o⟩ ≤ 0 give 0. jit/vmap/grad safe in the material's
    parameters, normal and view (the map size, s and the sample count are static).
    """
    M.check_material(material)
    V.check_choice("method", method, MATERIAL_ENVMAP_METHODS)
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    for name, v in (("normal", normal), ("view", view)):
        if np.shape(v)[-1:] != (3,):
            raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
    shape = V.check_broadcast([("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))]
                              + ([] if tangent is None else
                                 [("tangent", np.zeros(np.shape(tangent)[:-1]))]))
    normal, view = (x if isinstance(x, jax.Array) else np.asarray(x) for x in (normal, view))
    dtype = jnp.result_type(normal, view, float)
    normal = jnp.broadcast_to(jnp.asarray(normal, dtype), shape + (3,))
    view = jnp.broadcast_to(jnp.asarray(view, dtype), shape + (3,))
    tangent = (_local_frame(normal)[0] if tangent is None
               else jnp.broadcast_to(jnp.asarray(tangent, dtype), shape + (3,)))
    f = material.fresnel
    spectral = bool(f.kind in SPECTRAL_FRESNELS and material.specular.ndf != "none")
    obs = cross_band_name(f.observer) if (spectral and cross_band) else f.observer
    arithmetic = choose_arithmetic(f.film, "auto") if spectral else "complex"
    if n_cos is not None:
        n_cos = V.check_int("n_cos", n_cos, 2)
    rad = env.radiance.astype(dtype)
    mc, extra, n_samples, batch = exact_rule(
        method, rad, lambda: effective_alpha(material), int(np.prod(shape)),
        subdivisions=subdivisions, n_samples=n_samples, key=key, batch_size=batch_size)
    cfg = (mc, spectral, n_cos, obs, arithmetic, batch, n_samples)
    out, err = _ibl_jit(material, normal, view, tangent, rad, extra, cfg)
    return (out, err) if return_stderr else out
