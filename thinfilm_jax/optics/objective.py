r"""Reflectance seen through a microscope objective (SPEC §14).

A Köhler-illuminated objective of numerical aperture NA fills its pupil uniformly: the
specimen is lit by a cone of incidence angles $0 \le \theta \le \theta_{\max}$,
$\sin\theta_{\max} = \mathrm{NA}/\eta_1$ ($\eta_1$ the ambient index, ``eta_outer``: 1 for a
dry objective, the oil for an immersion one), each pupil point carrying the same power, and
the same objective collects the reflected cone. A point at pupil radius ρ ∝ sin θ lights
the specimen at θ; equal power per pupil area ($2\pi\rho\,d\rho \propto \sin\theta\cos\theta
\,d\theta$) makes the measured reflectance the average

$$ \bar R(\mathrm{NA}) = \frac{\int_0^{\theta_{\max}} R(\theta)\sin\theta\cos\theta\,d\theta}
   {\int_0^{\theta_{\max}} \sin\theta\cos\theta\,d\theta}
   = \frac{1}{u_{\max}}\int_0^{u_{\max}} R\,du,\qquad u = \sin^2\theta,\
   u_{\max} = (\mathrm{NA}/\eta_1)^2, $$

of the exact stack reflectance (`optics.stack`), s and p averaged for unpolarised light
(an azimuthal average of a linearly polarised lamp gives the same: the s and p fractions
average to ½ over the azimuth). This is the model of the flake-contrast literature (e.g.
Blake et al., Appl. Phys. Lett. 91, 063124 (2007), who found the NA's effect on graphene's
contrast small below NA ≈ 0.5; Casiraghi et al., Nano Lett. 7, 2711 (2007)).

**Quadrature.** With $c = \cos\theta$ ($du = -2c\,dc$) the average is
$\frac{2}{u_{\max}}\int_{c_{\min}}^{1} R(c)\,c\,dc$, $c_{\min} = \sqrt{1 - u_{\max}}$,
computed by an n-point Gauss–Legendre rule on $[c_{\min}, 1]$:

$$ c_i = 1 - h\,\frac{1 - t_i}{2},\quad h = 1 - c_{\min} = \frac{u_{\max}}{1 + c_{\min}},
   \qquad \bar R = \frac{\sum_i w_i c_i R(c_i)}{\sum_i w_i c_i} $$

($t_i, w_i$ the Legendre nodes and weights on [−1, 1]; the denominator is the rule applied to
$\int c\,dc = h(1 + c_{\min})/2$, which it integrates exactly, so the normalisation changes
nothing but makes $\bar R$ a convex combination of the $R(c_i)$: $0 \le \bar R \le 1$).
Why $c$ and not $u$: in $u$ the integrand has the branch point of $\cos\theta = \sqrt{1-u}$ at
$u = 1$, just beyond the interval when NA → η₁ (Gauss–Legendre then converges slowly); in
$c$ every wavenumber $q_k = \sqrt{\varepsilon_k - \eta_1^2 + \eta_1^2 c^2}$ is analytic on
the interval for layers denser than the ambient (branch points at imaginary c), so the rule
converges geometrically up to NA = η₁. The integrand oscillates with the layers' phases
$4\pi d_k q_k/\lambda$, which change over the cone by
$\Phi = \sum_k 4\pi d_k\,|q_k(\theta = 0) - q_k(\theta_{\max})|/\lambda$ (`phase_change`);
the node count follows it and the distance of the nearest branch point (`branch_rho`:
media less dense than an immersion oil), n = 32 + ⌈2Φ⌉ + ⌈23/ln ρ⌉ (`auto_nodes`).
Measured against a 4000-node rule (graphene on SiO₂ on Si, λ = 400/550/800 nm) with the
first two terms alone (the third only adds nodes): ≤ 4e-14 up to 1 µm of oxide, ≤ 1e-8 up
to 10 µm (Φ = 109 rad, 251 nodes) for NA ≤ 0.95, 3e-7 at NA = η₁ with 10 µm. 32 nodes alone
give 3e-10 at 1 µm and NA 0.95, 1.4e-6 at 2 µm. Under oil (η₁ = 1.515, NA 1.4) above a
1.46 layer, 32 nodes are off by 4e-5; the third term brings it to 9e-10 (tested).

**Limits.** NA = 0 gives $h = 0$, every $c_i = 1$ and $\bar R = R(\theta = 0)$ exactly; the
formula has no singularity there ($h = u_{\max}/(1 + c_{\min})$, no division by NA), so
gradients with respect to NA are finite (0 at NA = 0: $\bar R$ is even in NA). At NA = η₁
(grazing rays) $c_{\min} = \sqrt{1 - u_{\max}}$ has an infinite derivative: it is written
with a double-where (value 0, derivative 0 there), so the gradient is finite but drops the
term through $c_{\min}$ at that one point.

Example (a bare glass surface: the average of the Fresnel reflectance over the cone rises
with the NA; at NA = 0 it is ((n − 1)/(n + 1))² = 0.04):
    >>> from thinfilm_jax.core.stack import Stack
    >>> glass = Stack([0.0], (1.5,), 1.5)
    >>> [round(float(objective_reflectance(glass, 550.0, na)), 6) for na in (0.0, 0.9)]
    [0.04, 0.053761]
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..core.stack import Stack
from .fresnel import complex_dtype
from .index import index_at, is_index_model
from .stack import POLARISATIONS, stack_reflectance, stack_reflectance_traced

#: The fewest Gauss–Legendre nodes in cos θ of `objective_reflectance`, and the count it
#: uses when the stack is traced (module docstring: ≤ 1e-8 for a phase change over the cone
#: Φ ≲ 12 rad, about 1 µm of oxide at 400 nm and NA 0.95).
DEFAULT_NODES = 32
#: The most nodes the automatic rule takes (Φ ≈ 500 rad: 40 µm of oxide at 400 nm, NA 0.95).
MAX_NODES = 1024


def auto_nodes(phase_change, branch_rho=np.inf) -> int:
    """The node count for a phase change Φ (rad) of the layers over the cone and the
    Bernstein-ellipse parameter ρ of the nearest branch point (`branch_rho`):
    ``DEFAULT_NODES + ⌈2Φ⌉ + ⌈23 / ln ρ⌉`` (the last term: ρ^(−n) = 1e-10, a margin
    over the ρ^(−2n) of the theory for the oscillating factor), at most
    `MAX_NODES` (also when a branch point lies on the interval, ρ ≤ 1.001: total internal
    reflection inside the cone). Measured ≤ 1e-8 against 4000-node rules
    (tests/optics/test_objective.py, docs/how-to/microscope.md)."""
    phi = float(np.max(phase_change, initial=0.0))
    rho = float(np.min(branch_rho, initial=np.inf))
    if rho <= 1.001:
        return MAX_NODES
    extra = 0.0 if np.isinf(rho) else np.ceil(23.0 / np.log(rho))
    return int(min(MAX_NODES, DEFAULT_NODES + np.ceil(2.0 * phi) + extra))


@functools.lru_cache(maxsize=None)
def _legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    t, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (1.0 - t), w  # τ_i = (1 − t_i)/2 ∈ (0, 1): c_i = 1 − h τ_i


def _as_stack(x) -> Stack:
    """A checked `Film` (constant indices) or `Stack` as a `Stack` (a `Film` is its one-layer
    stack: the same values to 1e-12, SPEC §12)."""
    if isinstance(x, Film):
        return Stack.from_film(x.real_base())
    return x._replace(thickness=jnp.asarray(x.thickness))


def phase_change(x, wavelength, na) -> np.ndarray:
    r"""The change of the layers' round-trip phases over the objective's cone (rad), concrete
    inputs: $\Phi = \sum_k 4\pi d_k\,|q_k(0) - q_k(\theta_{\max})|/\lambda$ with
    $q_k(\theta) = \sqrt{\varepsilon_k - \eta_1^2\sin^2\theta}$, so
    $q_k(\theta_{\max}) = \sqrt{\varepsilon_k - \mathrm{NA}^2}$; broadcast shape of the
    batch, `wavelength` and `na`. What the quadrature's node count follows (`auto_nodes`)."""
    stack = _as_stack(x)
    lam = np.asarray(wavelength, float)
    d = np.asarray(stack.thickness, float)
    na2 = np.square(np.asarray(na, float))
    phi = 0.0
    for k, e in enumerate(stack.eta):
        eps = np.square(np.asarray(index_at(e, lam) if is_index_model(e) else e, complex))
        dq = np.abs(np.sqrt(eps) - np.sqrt(eps - na2))
        phi = phi + 4.0 * np.pi * d[..., k] * dq / lam
    return np.asarray(phi)


def branch_rho(x, wavelength, na) -> np.ndarray:
    r"""The Bernstein-ellipse parameter ρ ≥ 1 of the nearest branch point of the integrand
    in cos θ (concrete inputs): medium k's wavenumber $\sqrt{\varepsilon_k - \eta_1^2
    + \eta_1^2 c^2}$ branches at $c^2 = 1 - \varepsilon_k/\eta_1^2$; with the interval
    $[c_{\min}, 1]$ mapped onto [−1, 1] ($t$), $\rho = |t + \sqrt{t^2 - 1}|$ (the branch
    with ρ ≥ 1). Gauss–Legendre's error falls as $\rho^{-2n}$; ρ → 1 when a medium less
    dense than the ambient nears total internal reflection inside the cone (an immersion
    objective above a low-index layer). Broadcast shape of `wavelength` and `na`."""
    stack = _as_stack(x)
    lam = np.asarray(wavelength, float)

    def at(e):
        return np.asarray(index_at(e, lam) if is_index_model(e) else e, complex)

    eta1 = np.real(at(stack.eta_outer))
    u = np.square(np.asarray(na, float) / eta1)
    c_min = np.sqrt(np.clip(1.0 - u, 0.0, None))
    mid, half = 0.5 * (1.0 + c_min), np.maximum(0.5 * (1.0 - c_min), 1e-300)
    rho = np.full(np.broadcast_shapes(np.shape(u), np.shape(lam)), np.inf)
    d = np.asarray(stack.thickness, float)
    # a layer of zero thickness changes nothing (its two interfaces cancel): skipped
    media = [e for k, e in enumerate(stack.eta) if np.any(d[..., k] != 0)]
    for e in (*media, stack.eta_base):
        cb = np.sqrt(1.0 - np.square(at(e)) / eta1**2 + 0j)
        for root in (cb, -cb):
            with np.errstate(over="ignore", invalid="ignore"):  # NA → 0: t → ∞, ρ → ∞
                t = (root - mid) / half
                w = t + np.sqrt(t * t - 1.0 + 0j)
                r = np.maximum(np.abs(w), 1.0 / np.maximum(np.abs(w), 1e-300))
            r = np.where(np.isfinite(r), r, np.inf)
            rho = np.minimum(rho, np.broadcast_to(r, rho.shape))
    return rho


def _real_dtype(*xs):
    """The real dtype of the strongly typed inputs (Python numbers follow them)."""
    strong = [x for x in xs if not getattr(jnp.asarray(x), "weak_type", False)]
    return jnp.finfo(complex_dtype(*strong) if strong else complex_dtype(1.0)).dtype


def _check_na(na, eta1):
    """`na` finite, ≥ 0 and ≤ η₁ (concrete values; traced ones inside `checked`)."""
    na = V.check_range("na", na, 0.0, why=" (numerical aperture)")
    if V.is_concrete(na) and V.is_concrete(eta1):
        v, e = np.asarray(na, float), np.asarray(eta1, float)
        bad = v > e * (1.0 + 4.0 * np.finfo(float).eps)
        if np.any(bad):
            first = np.broadcast_to(v, np.broadcast_shapes(v.shape, e.shape))[bad].flat[0]
            raise ValueError(f"na must lie in [0, eta_outer] (NA = eta_outer sin(theta_max) "
                             f"cannot exceed the ambient index {float(e.min()):g}); got "
                             f"{first!r}")
    return na


def objective_reflectance(x, wavelength, na, *, polarisation: str = "unpolarised",
                          nodes: int | None = None) -> Array:
    r"""Reflectance of `x` seen through a Köhler-illuminated objective of numerical aperture
    `na` (SPEC §14): $\bar R = \frac{1}{u_{\max}}\int_0^{u_{\max}} R\,d(\sin^2\theta)$,
    $u_{\max} = (\mathrm{NA}/\eta_1)^2$ (module docstring), by the exact stack recursion
    at `nodes` Gauss–Legendre angles in cos θ.

    Args:
        x: a `Film` (constant or dispersive indices) or a `Stack`; its batch axes (a `Film`'s
            field shape, a `Stack`'s ``thickness[..., :-1]``) broadcast with `wavelength`
            and `na`. Index models are evaluated at each wavelength; the ambient
            ``eta_outer`` = η₁ is lossless (an immersion oil may be a model).
        wavelength: λ in nm (> 0).
        na: numerical aperture, 0 ≤ NA ≤ η₁ (NA = 0: normal incidence exactly).
        polarisation: "unpolarised" (½(R_s + R_p) at each angle), "s" or "p".
        nodes: Gauss–Legendre nodes (≥ 1). None (default): `auto_nodes` of `phase_change`
            and `branch_rho` (≥ `DEFAULT_NODES`, more for thick layers and for media near
            total internal reflection under an immersion objective; ≤ 1e-8 measured)
            when `x`, `wavelength` and `na` are concrete, `DEFAULT_NODES` when any is traced
            (inside `jax.grad` with respect to the thickness, for instance: enough to 1e-8
            for Φ ≲ 12 rad; pass `nodes` for thicker stacks under a transformation).

    Returns:
        $\bar R$ with the broadcast shape of the batch, `wavelength` and `na`; real dtype
        following the inputs.

    Raises:
        ValueError: `na` negative, NaN, or above η₁; bad `x`, `wavelength`, `polarisation`
            or `nodes` (named).
    """
    V.check_choice("polarisation", polarisation, POLARISATIONS)
    if nodes is not None:
        nodes = V.check_int("nodes", nodes, 1)
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    w_concrete = wavelength if V.is_concrete(wavelength) else None
    stack = _as_stack(V.check_material(x, "x", wavelengths=w_concrete))
    if is_index_model(stack.eta_outer):
        eta1 = stack.eta_outer(wavelength)
    else:
        eta1 = V.as_array("x.eta_outer", stack.eta_outer)
    if V.is_concrete(eta1) and np.any(np.imag(np.asarray(eta1)) != 0):
        raise ValueError("x.eta_outer must be lossless (kappa = 0): the objective's cone is "
                         "defined in the ambient medium")
    na = _check_na(na, jnp.real(eta1) if not V.is_concrete(eta1) else np.real(eta1))
    V.check_broadcast([("x (batch)", np.zeros(np.shape(stack.thickness)[:-1])),
                       ("wavelength", wavelength), ("na", na)])
    if nodes is None:
        concrete = all(V.is_concrete(v) for v in jax.tree.leaves((stack, wavelength, na)))
        nodes = (auto_nodes(phase_change(stack, wavelength, na),
                            branch_rho(stack, wavelength, na)) if concrete else DEFAULT_NODES)
    c, wts, lam = _nodes(stack, wavelength, na, nodes)
    # the public stack code checks every index value at every wavelength (κ ≥ 0, finite)
    r = stack_reflectance(_expand(stack), c, lam, polarisation)
    return _average(r, c, wts)


def objective_reflectance_traced(x, wavelength, na, polarisation: str = "unpolarised",
                                 nodes: int = DEFAULT_NODES) -> Array:
    """`objective_reflectance` without the input checks: trace-safe (every field, λ and NA
    may be traced) for callers that validated at their own boundary (studies, fits). `x`
    a `Stack`, or a `Film` whose indices are numbers (a dispersive `Film`: `as_stack` it)."""
    stack = _as_stack(x)
    c, wts, lam = _nodes(stack, wavelength, na, nodes)
    r = stack_reflectance_traced(_expand(stack), c, lam, polarisation)
    return _average(r, c, wts)


def _expand(stack: Stack) -> Stack:
    """A trailing axis of angles before the layer axis of the thickness, and after every
    array-valued index (index models follow the wavelengths, which carry it)."""
    def idx(e):
        if is_index_model(e) or jnp.ndim(e) == 0:
            return e
        return jnp.asarray(e)[..., None]

    return Stack(jnp.asarray(stack.thickness)[..., None, :], tuple(idx(e) for e in stack.eta),
                 idx(stack.eta_base), idx(stack.eta_outer))


def _nodes(stack: Stack, wavelength, na, nodes: int):
    """(cos θ at the nodes (..., n), the weights w_i (n,), λ (..., 1)), dtype of the inputs."""
    rdt = _real_dtype(stack.thickness, wavelength, na)
    lam = jnp.asarray(wavelength, rdt)
    eta1 = jnp.real(index_at(stack.eta_outer, lam)).astype(rdt)
    s2 = (jnp.asarray(na, rdt) / eta1) ** 2  # u_max = sin²θ_max
    one_minus = 1.0 - s2
    inside = one_minus > 0
    # c_min = sqrt(1 − u_max), double-where at NA = η₁ (finite gradient; module docstring)
    c_min = jnp.where(inside, jnp.sqrt(jnp.where(inside, one_minus, 1.0)), 0.0)
    h = s2 / (1.0 + c_min)  # = 1 − c_min without cancellation at small NA
    tau, w = _legendre(nodes)
    c = 1.0 - h[..., None] * jnp.asarray(tau, rdt)
    return c, jnp.asarray(w, rdt), lam[..., None]


def cone_nodes(stack: Stack, wavelength, na, thickness_max=None):
    """(cos θ at the nodes (n,), normalised weights (n,)) of the objective's cone for callers
    that average a reflectance themselves (`fit.photo` tables): R̄ = Σ weight_i R(cos θ_i),
    the rule of `objective_reflectance` with its automatic node count, for a stack whose
    ambient index is a number (the nodes then do not depend on λ). `thickness_max` (nm, per
    layer or one number) replaces the stack's thicknesses in the node count (a fit's box),
    `wavelength` the concrete wavelengths it must hold at (the shortest sets the count)."""
    if is_index_model(stack.eta_outer) or np.ndim(stack.eta_outer) != 0:
        raise ValueError("na needs an ambient (eta_outer) that is one real number: the cone's "
                         "angles would differ per wavelength")
    eta1 = float(np.real(stack.eta_outer))
    na = float(na)
    if not (np.isfinite(na) and 0.0 <= na <= eta1):
        raise ValueError(f"na must lie in [0, η₁ = {eta1:g}] (the ambient's index), got {na}")
    if thickness_max is not None:
        d = np.broadcast_to(np.asarray(thickness_max, float),
                            np.shape(np.asarray(stack.thickness)))
        stack = stack._replace(thickness=d)
    lam = np.asarray(wavelength, float).ravel()
    n = auto_nodes(phase_change(stack, lam, na), branch_rho(stack, lam, na))
    s2 = (na / eta1) ** 2
    c_min = np.sqrt(max(1.0 - s2, 0.0))
    tau, w = _legendre(n)
    c = 1.0 - s2 / (1.0 + c_min) * tau
    wc = w * c
    return c, wc / wc.sum()


def _average(r, c, w):
    """Σ w_i c_i R_i / Σ w_i c_i over the trailing node axis."""
    wc = w * c
    return jnp.sum(wc * r, axis=-1) / jnp.sum(wc, axis=-1)


__all__ = ["DEFAULT_NODES", "MAX_NODES", "auto_nodes", "branch_rho", "cone_nodes",
           "objective_reflectance",
           "objective_reflectance_traced", "phase_change"]
