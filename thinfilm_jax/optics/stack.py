r"""Exact reflectance and transmittance of a stack of N coherent layers (SPEC §12).

Media 0 (outer, lossless), 1 … N (the layers of `Stack`, layer 0 of ``Stack.eta`` is medium
1) and N + 1 (the semi-infinite base). Each medium has the normal wavenumber
$q_k = \eta_k\cos\theta_k = \sqrt{\varepsilon_k - \eta_0^2\sin^2\theta_0}$ on the branch
$\operatorname{Im} q_k \ge 0$ (`fresnel.sqrt_upper`; waves decay in absorbing and
evanescent media) and the interface amplitudes $r_j = r_{j,j+1}$ of `fresnel.interface_amplitudes`
(s: $(q_j - q_{j+1})/(q_j + q_{j+1})$; p: $(\varepsilon_{j+1} q_j - \varepsilon_j q_{j+1})/
(\varepsilon_{j+1} q_j + \varepsilon_j q_{j+1})$, the `tmm` convention). Layer k of thickness
$d_k$ has the one-way phase $\beta_k = 2\pi d_k q_k/\lambda$.

**Reflection: the Airy (impedance) recursion from the base upward** (Born & Wolf §1.6.5;
Heavens 1955, ch. 4). $\Gamma_j$ is the reflection amplitude seen from medium j at its
interface with j + 1:

$$ \Gamma_N = r_N,\qquad
   \Gamma_{j} = \frac{r_j + \Gamma_{j+1}E_{j+1}}{1 + r_j\,\Gamma_{j+1}E_{j+1}},\quad
   E_k = e^{2i\beta_k},\qquad r = \Gamma_0,\quad R = |\Gamma_0|^2 . $$

For N = 1 this is the one-film formula of `airy` (SPEC §2).

**Transmission.** The forward amplitude just below interface j is the one above it times
$\tau_j = t_j/(1 + r_j\Gamma_{j+1}E_{j+1})$; across layer k it gains $e^{i\beta_k}$. With
the tangential field that is continuous across an interface (E for s, H for p) the interface
transmission is $t_j = 1 + r_j$ for both polarisations (p in its H form is s with the
admittance $Y = q/\varepsilon$ in place of $Y = q$, and $r_p$ above is its reflection
amplitude), so

$$ t = \prod_{j=0}^{N}\frac{1 + r_j}{1 + r_j\Gamma_{j+1}E_{j+1}}\ \prod_{k=1}^{N} e^{i\beta_k}
   \quad (E_{N+1}\Gamma_{N+1} = 0),\qquad
   T = |t|^2\,\frac{\operatorname{Re} Y_{N+1}}{Y_0},\quad Y^s = q,\ Y^p = q/\varepsilon . $$

This is the Poynting flux into the base over the incident one, `tmm`'s
$\operatorname{Re}(n\cos\theta)$ (s) and $\operatorname{Re}(n\,\overline{\cos\theta})$ (p)
factors for its E-field $t_p$. The factor $|1 + r_0|^2 / Y_0 = 4 Y_0/|Y_0 + Y_1|^2$ is
written in that form, so that grazing incidence ($Y_0 = 0$) gives T = 0, not 0/0.

**Why it cannot overflow.** Every propagation factor has $|E_k| = e^{-4\pi d_k\operatorname{Im}
q_k/\lambda} \le 1$ and $|e^{i\beta_k}| \le 1$ because $\operatorname{Im} q_k \ge 0$: a thick
absorbing layer drives $E_k$ to 0 (an underflow, harmless), so $\Gamma$ above it becomes that
interface's Fresnel amplitude (a 10 µm metal layer is the bulk metal) and $t \to 0$. No
factor $e^{-i\beta}$ (which grows as $e^{+2\pi d\operatorname{Im} q/\lambda}$) ever appears,
unlike the raw product of 2 × 2 transfer matrices, whose entries overflow in float32 beyond
a few hundred nm of metal and whose ratio loses every digit long before. The denominators
$1 + r_j\Gamma_{j+1}E_{j+1}$ vanish only at the exact grazing corners handled by `safe_div`'s
double-where (limit 0).

**Arithmetic.** Interface amplitudes depend on the angle (and on λ only for dispersive
media): the media are stacked on one leading axis and their wavenumbers and amplitudes
formed in one vectorised program on that shape, whatever N. Only the phases and the
recursion run per (angle, wavelength): the layers are a `jax.lax.scan` whose step forms
the phase factor once (`sincos_turns` in turns, an `optimization_barrier` so that XLA does
not recompute it in each consumer) and then the recursion for both polarisations (stacked
on a leading axis) as one complex elementwise program, the division written on (Re, Im)
parts. Measured on 64 angles × 100 wavelengths, float64, 2 CPU cores: R of 8 / 16 / 80
layers in 0.4 / 0.8 / 3.8 ms warm, compiled in 0.8 / 1.3 / ~2 s; the unrolled Python loop
(``layers="loop"``) compiles in 1.6 / 3.4 s at 8 / 16 layers (growing with N) and runs
3× slower warm. `benchmarks/stack_bench.py` times it against its peers.

Example (a quarter-wave MgF₂ layer on glass at 550 nm, normal incidence:
R = ((n_s − n²)/(n_s + n²))² = 0.0126):
    >>> from thinfilm_jax.core.stack import Stack
    >>> s = Stack([550.0 / (4 * 1.38)], (1.38,), 1.52)
    >>> round(float(stack_reflectance(s, 1.0, 550.0)), 6)
    0.012601
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.stack import Stack
from .turns import sincos_turns
from .fresnel import complex_dtype, interface_amplitudes, sin2_outer, sqrt_upper
from .index import index_at, is_index_model

__all__ = [
    "POLARISATIONS",
    "check_stack",
    "check_index",
    "stack_reflectance",
    "stack_transmittance",
    "stack_reflectance_traced",
    "stack_amplitudes",
    "stack_amplitudes_traced",
]

POLARISATIONS = ("s", "p", "unpolarised")

_LAYERS = ("auto", "loop", "scan")


# ----------------------------------------------------------------------------------------
# validation


def check_stack(stack, name: str = "stack") -> Stack:
    """Validate a `Stack` (concrete values; traced values pass through unchecked) and return
    it with `thickness` an array of ≥ 1 dimension whose last axis has ``len(eta)`` entries.

    Raises ValueError naming the field: a negative or non-finite thickness, a thickness whose
    last axis is not the number of layers, a non-finite index, an index with κ = Im η < 0 or
    Re η < 0 (or η = 0), and an absorbing outer medium (its κ must be 0: the incident wave
    is defined there).
    """
    if not isinstance(stack, Stack):
        raise TypeError(f"{name} must be a thinfilm_jax Stack, got {type(stack).__name__}")
    if not isinstance(stack.eta, (tuple, list)):
        raise TypeError(f"{name}.eta must be a tuple of the N layer indices, got "
                        f"{type(stack.eta).__name__}")
    n = len(stack.eta)
    d = V.check_range(f"{name}.thickness", V.as_array(f"{name}.thickness", stack.thickness),
                      0.0, why=" (nm, d >= 0)")
    if jnp.ndim(d) == 0 or jnp.shape(d)[-1] != n:
        raise ValueError(f"{name}.thickness must hold the N = len({name}.eta) = {n} layer "
                         f"thicknesses on its last axis; got shape {jnp.shape(d)}")
    for i, e in enumerate(stack.eta):
        check_index(f"{name}.eta[{i}]", e)
    check_index(f"{name}.eta_base", stack.eta_base)
    check_index(f"{name}.eta_outer", stack.eta_outer, lossless=True)
    return Stack(d, tuple(stack.eta), stack.eta_base, stack.eta_outer)


def check_index(name: str, eta, *, lossless: bool = False):
    """A constant index (number or array, real or complex n + iκ): finite, n ≥ 0, κ ≥ 0,
    η ≠ 0 (κ = 0 too if `lossless`). Index models and traced values are returned unchecked
    (a model checks its own wavelength range; its values are checked by `check_index_values`)."""
    if is_index_model(eta):
        return eta
    eta = V.as_array(name, eta)
    if V.is_concrete(eta):
        check_index_values(name, eta, lossless=lossless)
    return eta


def check_index_values(name: str, eta, *, lossless: bool = False) -> None:
    """The range checks of `check_index` on concrete index values (no-op when traced)."""
    if not V.is_concrete(eta):
        return
    v = np.asarray(eta)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite; got NaN or inf in {name}")
    re, im = np.real(v), np.imag(v)
    if np.any(im < 0):
        raise ValueError(f"{name} must have kappa = Im(eta) >= 0 (absorption, the n + ik "
                         f"convention); got {complex(v[im < 0].flat[0])!r}")
    if lossless and np.any(im != 0):
        raise ValueError(f"{name} must be lossless (kappa = 0: the incident wave is defined "
                         f"there); got {complex(v[im != 0].flat[0])!r}")
    if np.any(re < 0) or np.any(v == 0):
        bad = v[(re < 0) | (v == 0)].flat[0]
        raise ValueError(f"{name} must have Re(eta) >= 0 and eta != 0; got {bad!r}")


def _check_args(stack, cos_theta, wavelength, polarisation, layers):
    V.check_choice("polarisation", polarisation, POLARISATIONS)
    V.check_choice("layers", layers, _LAYERS)
    stack = check_stack(stack)
    cos_theta = V.check_cos_theta(cos_theta)
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    # every index at the wavelengths, outside the compiled core: a model raises here on a
    # wavelength outside its range (concrete inputs), and its values are range-checked
    cache: dict[int, Array] = {}

    def at(name, e):
        if not is_index_model(e):
            return e
        if id(e) not in cache:  # a material used by several layers is evaluated once
            cache[id(e)] = index_at(e, wavelength)
            check_index_values(name, cache[id(e)])
        return cache[id(e)]

    etas = (at("stack.eta_outer", stack.eta_outer),
            *(at(f"stack.eta[{i}]", e) for i, e in enumerate(stack.eta)),
            at("stack.eta_base", stack.eta_base))
    check_index_values("stack.eta_outer", etas[0], lossless=True)
    V.check_broadcast([("stack.thickness[..., 0]", jnp.zeros(jnp.shape(stack.thickness)[:-1])),
                       ("cos_theta", cos_theta), ("wavelength", wavelength),
                       *((f"index {i}", jnp.zeros(jnp.shape(e))) for i, e in enumerate(etas))])
    pols = ("s", "p") if polarisation == "unpolarised" else (polarisation,)
    layers = "scan" if layers == "auto" else layers
    return stack.thickness, etas, cos_theta, wavelength, pols, layers


# ----------------------------------------------------------------------------------------
# public functions


def stack_reflectance(stack: Stack, cos_theta, wavelength, polarisation: str = "unpolarised",
                      *, layers: str = "auto") -> Array:
    """Reflectance R of `stack` (SPEC §12, exact; the recursion of the module docstring).

    Args:
        stack: `Stack`; ``thickness[..., :]`` (nm) has the N layers on its last axis, its
            leading axes broadcast (NumPy rules) with `cos_theta`, `wavelength` and array
            indices. Indices: numbers (n or n + iκ, κ ≥ 0), arrays or index models
            (evaluated at `wavelength`); the outer medium is lossless.
        cos_theta: cos θ₀ ∈ [0, 1] in the outer medium (rounding excursions clamped).
        wavelength: λ in nm (> 0).
        polarisation: "s", "p" or "unpolarised" (½(R_s + R_p)).
        layers: "auto" (= "scan": a `jax.lax.scan` over layers) or "loop" (a Python loop,
            unrolled): how the layers are traced, same values to rounding ("loop" compiles
            longer, growing with N, and runs slower: module docstring).

    Returns:
        R with the broadcast shape, real dtype following the inputs (float32 → float32).
    """
    d, etas, c, lam, pols, layers = _check_args(stack, cos_theta, wavelength, polarisation, layers)
    return _stack_jit(d, etas, pols, layers, c, lam, want="R")


def stack_transmittance(stack: Stack, cos_theta, wavelength, polarisation: str = "unpolarised",
                        *, layers: str = "auto") -> Array:
    """Transmittance T of `stack`: the fraction of the incident power carried into the base
    (Poynting flux normal to the layers; arguments as `stack_reflectance`). A lossless stack
    on a lossless base has R + T = 1; absorption in the layers or the base' evanescence
    (total internal reflection) makes R + T < 1 or T = 0."""
    d, etas, c, lam, pols, layers = _check_args(stack, cos_theta, wavelength, polarisation, layers)
    return _stack_jit(d, etas, pols, layers, c, lam, want="T")


def stack_reflectance_traced(stack: Stack, cos_theta, wavelength,
                             polarisation: str = "unpolarised", *, layers: str = "scan") -> Array:
    """`stack_reflectance` without the input checks: trace-safe (every field may be traced)
    for callers that validated at their own boundary (`spectral`, `shading`, `fit`)."""
    return _stack_jit(*_traced_args(stack, wavelength, polarisation, layers), cos_theta,
                      wavelength, want="R")


def stack_transmittance_traced(stack: Stack, cos_theta, wavelength,
                               polarisation: str = "unpolarised", *,
                               layers: str = "scan") -> Array:
    """`stack_transmittance` without the input checks (as `stack_reflectance_traced`)."""
    return _stack_jit(*_traced_args(stack, wavelength, polarisation, layers), cos_theta,
                      wavelength, want="T")


def stack_amplitudes(stack: Stack, cos_theta, wavelength, *, layers: str = "auto") -> Array:
    r"""The complex reflection amplitudes $(r_s, r_p) = \Gamma_0$ of `stack` (the recursion of
    the module docstring; arguments as `stack_reflectance`), stacked on a leading axis of
    size 2: ``out[0]`` = r_s, ``out[1]`` = r_p, complex dtype following the inputs.

    Conventions (those of `fresnel.interface_amplitudes`, the `tmm` ones): time dependence
    $e^{-i\omega t}$ with κ ≥ 0 absorbing, and r_p = −r_s at normal incidence. $R_s =
    |r_s|^2$ and $R_p = |r_p|^2$ are `stack_reflectance`'s; the phases are what
    ellipsometry reads (`optics.ellipsometry`: ρ = r_p / r_s)."""
    d, etas, c, lam, _, layers = _check_args(stack, cos_theta, wavelength, "unpolarised",
                                             layers)
    return _stack_jit(d, etas, ("s", "p"), layers, c, lam, want="r")


def stack_amplitudes_traced(stack: Stack, cos_theta, wavelength, *,
                            layers: str = "scan") -> Array:
    """`stack_amplitudes` without the input checks (trace-safe, as
    `stack_reflectance_traced`): (r_s, r_p) on a leading axis of size 2."""
    return _stack_jit(*_traced_args(stack, wavelength, "unpolarised", layers), cos_theta,
                      wavelength, want="r")


def _traced_args(stack, wavelength, polarisation, layers):
    seen: dict[int, Array] = {}  # one evaluation per model object (outside jit: per material)

    def at(e):
        if not is_index_model(e):
            return e
        if id(e) not in seen:
            seen[id(e)] = index_at(e, wavelength)
        return seen[id(e)]

    etas = tuple(at(e) for e in (stack.eta_outer, *stack.eta, stack.eta_base))
    pols = ("s", "p") if polarisation == "unpolarised" else (polarisation,)
    layers = "scan" if layers == "auto" else layers
    return jnp.asarray(stack.thickness), etas, pols, layers


# ----------------------------------------------------------------------------------------
# the recursion on (Re, Im) pairs


def _abs2(z):
    return jnp.real(z) ** 2 + jnp.imag(z) ** 2


def _cdiv(num, den):
    """num/den for complex arrays on (re, im), 0 where den = 0 (double-where). No rescaling:
    |den| = |1 + r Γ E| stays O(1) here (|r Γ E| is bounded by the passivity of the layers),
    so |den|² neither overflows nor underflows. One complex output (XLA fuses it whole)."""
    dr, di = jnp.real(den), jnp.imag(den)
    m = dr * dr + di * di
    zero = m == 0
    k = jnp.where(zero, 0.0, 1.0 / jnp.where(zero, 1.0, m))
    nr, ni = jnp.real(num), jnp.imag(num)
    return jax.lax.complex((nr * dr + ni * di) * k, (ni * dr - nr * di) * k)


def _phase(d, q, lam, turns):
    """exp(2πi · turns · d q / λ) on (re, im): `sincos_turns` of the real part, the modulus
    e^{−2π turns d Im q / λ} ≤ 1 (Im q ≥ 0)."""
    c, s = sincos_turns(turns * d * jnp.real(q) / lam)
    g = jnp.exp((-2.0 * math.pi) * (turns * d * jnp.imag(q) / lam))
    return jax.lax.complex(g * c, g * s)


def _step(carry, x, lam, want_t):
    """One interface j (from the base upward): Γ_j from Γ_{j+1}, and the transmission
    product gains (1 + r_{j+1}) e^{iβ_{j+1}} / (1 + r_j Γ_{j+1} E_{j+1}). Polarisations on
    the leading axis of the carry and of the amplitudes r = r_j, t = 1 + r_{j+1}."""
    gam, prod = carry
    d, q, r, t = x
    if want_t:
        h = _phase(d, q, lam, 1.0)  # e^{iβ}
        h = jax.lax.optimization_barrier(h)  # formed once, not in every consumer fusion
        e = h * h
    else:
        # E = e^{2iβ} directly (the rounding of `airy`: turns 2 d Re q / λ)
        e = jax.lax.optimization_barrier(_phase(d, q, lam, 2.0))
    ge = gam * e[None]
    den = 1.0 + r * ge
    gam_new = _cdiv(r + ge, den)
    if want_t:
        prod = prod * _cdiv(h[None] * t, den)
    return (gam_new, prod), None


@functools.partial(jax.jit, static_argnames=("pols", "layers", "want"))
def _stack_jit(thickness, etas, pols, layers, cos_theta, wavelength, want):
    # precision from the arrays given (Python numbers are weakly typed: they follow)
    strong = [x for x in (thickness, cos_theta, wavelength, *etas)
              if not getattr(jnp.asarray(x), "weak_type", False)]
    cdt = complex_dtype(*strong) if strong else complex_dtype(1.0)
    rdt = jnp.finfo(cdt).dtype
    d = jnp.asarray(thickness, rdt)
    c = jnp.asarray(cos_theta, rdt)
    lam = jnp.asarray(wavelength, rdt)
    n = len(etas) - 2
    shape = jnp.broadcast_shapes(jnp.shape(d)[:-1], c.shape, lam.shape,
                                 *(jnp.shape(e) for e in etas))
    nd = len(shape)

    def lift(x):  # leading unit axes up to the output rank (no implicit rank promotion)
        return jnp.reshape(x, (1,) * (nd - jnp.ndim(x)) + jnp.shape(x))

    c, lam = lift(c), lift(lam)
    # media 0 … N+1 on a leading axis (one vectorised program whatever N: compile time
    # does not grow with the number of layers)
    eta = jnp.stack(jnp.broadcast_arrays(*(lift(jnp.asarray(e, cdt)) for e in etas)))
    eps = eta * eta
    n0 = jnp.real(eta[0])
    s2 = sin2_outer(n0, c)
    q = sqrt_upper(eps - jax.lax.complex(s2, jnp.zeros_like(s2))[None])
    q0 = n0 * c  # q₀ = η₀ cos θ₀, exact (lossless outer medium)
    q0 = jnp.broadcast_to(jax.lax.complex(q0, jnp.zeros_like(q0)), q.shape[1:])
    q = jnp.concatenate([q0[None], q[1:]])
    eps = jnp.broadcast_to(eps, (n + 2, *q.shape[1:]))
    # interface amplitudes r_j (s, p), j = 0 … N, on the (angle [, λ]) shape: (2, N+1, …)
    r = interface_amplitudes(q[:-1], q[1:], eps[:-1], eps[1:])
    ip = [("s", "p").index(p) for p in pols]

    want_t = want == "T"
    r = r[ip[0]:ip[0] + len(ip)]  # the polarisations asked for: (P, N+1, …)
    gam = jnp.broadcast_to(r[:, n], (len(ip), *shape))
    prod = jnp.ones((len(ip), *shape) if want_t else (), cdt)
    if n:
        # layer k = j + 1 below interface j, for j = 0 … N−1 on axis 0
        dl = jnp.moveaxis(d, -1, 0)
        dl = jnp.reshape(dl, (n,) + (1,) * (nd - dl.ndim + 1) + dl.shape[1:])
        xs = (dl, q[1:n + 1], jnp.moveaxis(r[:, :n], 1, 0), jnp.moveaxis(1.0 + r[:, 1:], 1, 0))
        step = functools.partial(_step, lam=lam, want_t=want_t)
        carry = (gam, prod)
        if layers == "loop":
            for j in reversed(range(n)):
                carry, _ = step(carry, jax.tree.map(lambda x, j=j: x[j], xs))
        else:
            carry, _ = jax.lax.scan(step, carry, xs, reverse=True)
        gam, prod = carry

    if want == "r":  # the complex amplitudes Γ₀ (P, …) themselves (`stack_amplitudes`)
        return jnp.broadcast_to(gam, (len(ip), *shape))
    vals = []
    for k, i in enumerate(ip):
        if want == "R":
            vals.append(_abs2(gam[k]))
            continue
        # T = |prod|² · 4 Y₀ Re Y_{N+1} / |Y₀ + Y₁|² (s: Y = q; p: Y = q/ε, ε₀ real)
        qb, eb = q[n + 1], eps[n + 1]
        if i == 0:
            num = 4.0 * jnp.real(q[0]) * jnp.real(qb)
            den = _abs2(q[0] + q[1])
        else:
            re_yb = jnp.real(qb * jnp.conj(eb)) / _abs2(eb)
            num = 4.0 * jnp.real(q[0]) * jnp.real(eps[0]) * _abs2(eps[1]) * re_yb
            den = _abs2(eps[1] * q[0] + eps[0] * q[1])
        zden = den == 0
        fac = jnp.where(zden, 0.0, num / jnp.where(zden, 1.0, den))
        vals.append(fac * _abs2(prod[k]))
    out = vals[0] if len(vals) == 1 else 0.5 * (vals[0] + vals[1])
    return jnp.broadcast_to(out, shape)
