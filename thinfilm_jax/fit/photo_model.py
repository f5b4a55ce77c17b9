r"""The pixel model of `fit_photo` (SPEC §13, §14): the camera colours s(d) of the template's
layer, their table and its cubic Hermite interpolant, and the pipeline's refine stage on it.

s_j(d) = Σ_k w_kj R̄(λ_k, d), R̄ the template's exact reflectance (SPEC §2, §12: the stack
recursion) averaged over the view's cosines (`_geometry`: the mirror view, the SPEC §7 patch
quadrature of a rough surface under uniform light, or a microscope objective's cone of
numerical aperture `na`, SPEC §14, `optics.objective.cone_nodes`), w the camera's weights
under the light (`spectral.camera`). A pixel's prediction is g C s(d) (gains and matrix:
`fit.photo_screen`); between the table's grid points s(d) is the cubic Hermite interpolant
(error h⁴ s⁗/384: below 1e-9 at 1 nm steps). `_refine_all` is stage 3 of `fit.pixelwise`
(`pixelwise.refine_pixel`) on the censored residuals of `photo_screen.residual`.

Example (bare silicon of constant index 3.9 reads R = (2.9 / 4.9)² in every channel: the
camera's weights are white-balanced, a white reflector reads 1):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.spectral.camera import camera_response
    >>> from thinfilm_jax.fit.photo_model import photo_colours
    >>> s = photo_colours(Film(0.0, 1.46, 3.9), [0.0], camera=camera_response("srgb", "D65"))
    >>> np.round(s, 4).tolist(), round((2.9 / 4.9) ** 2, 4)
    ([[0.3503, 0.3503, 0.3503]], 0.3503)
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..brdf.microfacet import patch_quadrature
from ..core import _validate as V
from ..core.material import as_stack
from ..core.stack import Stack
from ..optics.stack import stack_reflectance_traced
from ..spectral.camera import Camera, camera_response
from .map_quality import neighbours
from .photo_screen import bucket, chunks, pad_to, residual
from .pixelwise import refine_pixel

__all__ = ["photo_colours", "render_photo"]

_HI = jax.lax.Precision.HIGHEST
#: the patch quadrature of a rough film: against (48, 48), 1.3e-6 (oxide on Si) and 9.4e-7
#: (soap) of the largest colour over 0–2000 nm at α = 0.3, θ_o = 0.4 (measured), far below
#: the model floor, at 1/16 of the cost
_QUADRATURE = (12, 12)


def _layer_stack(template, layer: int) -> Stack:
    stack = as_stack(template)
    if not 0 <= layer < stack.n_layers:
        raise ValueError(f"layer must index the template's {stack.n_layers} layer(s), "
                         f"got {layer}")
    return stack


def _geometry(theta_o, alpha, na=None, stack=None, layer=0, wavelengths=None, hi=None):
    """(cosines (N,), weights (N,)) at which the reflectance is averaged: the mirror view,
    the SPEC §7 patch quadrature of a rough surface under uniform light, or a microscope
    objective's cone of numerical aperture `na` (SPEC §14, `optics.objective.cone_nodes`:
    uniform in the pupil, nodes enough for the layer at `hi` nm)."""
    if na is not None:
        from ..optics.objective import cone_nodes

        d = np.array(np.asarray(stack.thickness, float))
        d[..., layer] = float(hi) if hi is not None else d[..., layer]
        return cone_nodes(stack, wavelengths, na, thickness_max=d)
    if alpha is None:
        return np.asarray([np.cos(theta_o)]), np.asarray([1.0])
    quad = patch_quadrature(jnp.float64(theta_o), jnp.float64(alpha), quadrature=_QUADRATURE)
    return np.asarray(quad.cos_hi).ravel(), np.asarray(quad.weight).ravel()


@functools.partial(jax.jit, static_argnames=("layer",))
def _colours(d, stack, layer, cos, qw, lam, weights):
    """(s (G, 3), ds/dd (G, 3)) at thicknesses d (G,) of layer `layer` (module docstring)."""

    def s_of(di):
        st = stack._replace(thickness=jnp.asarray(stack.thickness).at[layer].set(di))
        r = stack_reflectance_traced(st, cos[:, None], lam[None, :])  # (N, K)
        rbar = jnp.matmul(qw, r, precision=_HI)  # (K,)
        return jnp.matmul(rbar, weights, precision=_HI)

    return jax.vmap(lambda di: jax.jvp(s_of, (di,), (jnp.ones_like(di),)))(d)


def photo_colours(template, thickness, *, camera: Camera, theta_o=0.0, alpha=None,
                  layer: int = 0, na=None):
    """The camera colours s(d) (..., 3) of the template with layer `layer` at `thickness`
    (..., nm), white-balanced to the camera's light (a white reflector reads 1); `na`: seen
    through a microscope objective of that numerical aperture (SPEC §14)."""
    stack = _layer_stack(V.check_material(template, "template",
                                          wavelengths=camera.wavelengths), layer)
    d = np.asarray(thickness, float)
    _check_na(na, theta_o, alpha)
    cos, qw = _geometry(float(theta_o), alpha, na, stack, layer, camera.wavelengths,
                        float(np.max(d, initial=0.0)))
    s, _ = _colours(jnp.asarray(d.ravel()), stack, layer, jnp.asarray(cos), jnp.asarray(qw),
                    jnp.asarray(camera.wavelengths), jnp.asarray(camera.weights))
    return np.asarray(s).reshape(*d.shape, -1)


def render_photo(template, thickness, *, camera="srgb", illuminant="D65", theta_o=0.0,
                 alpha=None, layer: int = 0, exposure: float = 1.0,
                 white_balance=(1.0, 1.0, 1.0), na=None) -> np.ndarray:
    """A linear photograph (H, W, 3) of the template with the thickness map `thickness`
    (H, W): exposure · wb_c · s_c(d) of the module docstring (no noise, no encoding). The
    same model `fit_photo` fits: for tests and examples; studies render independently."""
    cam = camera_response(camera, illuminant)
    s = photo_colours(template, thickness, camera=cam, theta_o=theta_o, alpha=alpha,
                      layer=layer, na=na)
    return exposure * np.asarray(white_balance, float) * s


def _hermite(d, lo, h, s, ds):
    """Cubic Hermite interpolant of the table (s, ds) (G, 3) on lo + h·g at d (scalar)."""
    g = s.shape[0]
    u = (d - lo) / h
    fi = jnp.clip(jnp.floor(u), 0, g - 2)
    i = fi.astype(jnp.int32)
    t = u - fi
    t2, t3 = t * t, t * t * t
    h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
    h01, h11 = -2 * t3 + 3 * t2, t3 - t2
    return h00 * s[i] + h10 * h * ds[i] + h01 * s[i + 1] + h11 * h * ds[i + 1]


@functools.partial(jax.jit, static_argnames=("steps", "want_se"))
def _refine(obs, sig, cens, d0, nb, nb_ok, tau, gm, lo_d, hi_d, lo, h, s_tab, ds_tab, levels,
            steps, want_se):
    """Per pixel: `pixelwise.refine_pixel` on [(g C s(d) − o)/σ, (d − d_q)/τ]; returns d, the
    data χ² and the standard error (absolute σ)."""

    def pixel(o, sg, cs, x0, q, ok):
        def data(x):
            pred = jnp.matmul(gm, _hermite(x[0], lo, h, s_tab, ds_tab), precision=_HI)
            return residual(pred, o, sg, cs, levels)

        x, chi, se = refine_pixel(data, x0[None], q, ok, tau, lo_d[None], hi_d[None], steps,
                                  want_se)
        return x[0], chi, se

    return jax.vmap(pixel)(obs, sig, cens, d0, nb, nb_ok)


def _check_na(na, theta_o, alpha):
    """A microscope objective's NA (SPEC §14): a number ≥ 0 (its upper bound, the ambient's
    index, is checked with the stack), seen along the axis (θ_o = 0) of a mirror (α None)."""
    if na is None:
        return
    if np.ndim(na) != 0 or not np.isfinite(float(na)) or float(na) < 0:
        raise ValueError(f"na must be a number ≥ 0 (the objective's numerical aperture), "
                         f"got {na!r}")
    if float(theta_o) != 0.0 or alpha is not None:
        raise ValueError("na (a microscope objective) views along its axis: give theta_o=0 "
                         "and alpha=None with it")


def _host_hermite(d, lo, h, s, ds):
    """`_hermite` on the host for a vector d (P,) → (P, 3)."""
    g = s.shape[0]
    u = (d - lo) / h
    i = np.clip(np.floor(u), 0, g - 2).astype(int)
    t = (u - i)[:, None]
    t2, t3 = t * t, t * t * t
    return ((2 * t3 - 3 * t2 + 1) * s[i] + (t3 - 2 * t2 + t) * h * ds[i]
            + (-2 * t3 + 3 * t2) * s[i + 1] + (t3 - t2) * h * ds[i + 1])


def _refine_all(obs, sig, cens, d0, valid, tau, gm, table, steps, chunk, bar, where=None,
                want_se=False):
    """`_refine` over every pixel in chunks: the neighbour prior (τ finite) needs `valid`
    (H, W) and the fitted pixels' flat indices `where` (their neighbours' current d0)."""
    lo, hi, step, s_tab, ds_tab, levels = table
    n = obs.shape[0]
    if valid is not None:
        h, w = valid.shape
        img = np.zeros(h * w)
        img[where] = d0
        nb, ok = neighbours(img.reshape(h, w), valid)
        nb, ok = nb.reshape(-1, 4)[where], ok.reshape(-1, 4)[where]
    else:
        nb, ok = np.zeros((n, 4)), np.zeros((n, 4), bool)
    consts = (jnp.asarray(min(tau, 1e30)), jnp.asarray(gm), jnp.asarray(lo), jnp.asarray(hi),
              jnp.asarray(lo), jnp.asarray(step), jnp.asarray(s_tab), jnp.asarray(ds_tab),
              jnp.asarray(levels))
    out = []
    size = bucket(n, chunk)
    for s in chunks(n, size):
        m = s.stop - s.start
        r = _refine(*(jnp.asarray(pad_to(a[s], size)) for a in (obs, sig, cens, d0, nb, ok)),
                    *consts, steps=steps, want_se=want_se)
        out.append([np.asarray(v)[:m] for v in r])
        if bar is not None:
            bar.update(m)
    return [np.concatenate(v) for v in zip(*out)]
