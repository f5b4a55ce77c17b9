r"""Ellipsometric angles ψ, Δ of a film or a layer stack (SPEC §14).

An ellipsometer measures the ratio of the p and s reflection amplitudes,

$$ \rho = \frac{r_p}{r_s} = \tan\psi\; e^{i\Delta}, $$

ψ ∈ [0°, 90°] from the moduli, Δ from the phase difference δ_p − δ_s. The amplitudes are
those of the layer-stack code, `optics.stack.stack_amplitudes` (the Airy recursion: no
second transfer-matrix code), so ψ and Δ hold for a `Film` (constant or dispersive: its
one-layer `Stack`) and for a `Stack` of any number of layers, absorbing ones included.

**Conventions: the library against WVASE.** The library's amplitudes (`fresnel`, `stack`,
and `tmm`'s) use the time dependence $e^{-i\omega t}$, so that the index is n + iκ with
κ ≥ 0 absorbing, and the p amplitude $r_p = (\varepsilon_b q_a - \varepsilon_a q_b) /
(\varepsilon_b q_a + \varepsilon_a q_b)$, which is −r_s at normal incidence. J.A.
Woollam's WVASE and CompleteEASE follow the *Nebraska conventions* (R. H. Muller, "Definitions
and conventions in ellipsometry", Surf. Sci. 16, 14 (1969)): Δ = δ_p − δ_s with the time
dependence $e^{+i\omega t}$ (in which an absorbing index is n − iκ), and the same r_p sign
(Δ = 180° at normal incidence and below Brewster's angle of a dielectric, 0° above it).
A complex amplitude of one convention is the complex conjugate of the other's (the same
real field, $\operatorname{Re}(a e^{-i\omega t}) = \operatorname{Re}(\bar a e^{+i\omega t})$),
so

$$ \rho_{\rm WVASE} = \overline{\rho_{\rm library}},\qquad
   \psi = \arctan\frac{|r_p|}{|r_s|},\qquad
   \Delta_{\rm WVASE} = -\arg\rho_{\rm library} \pmod{360°} . $$

This is also refellips' formula (Δ = arg(1/(−ρ)) + π with `tmm`'s ρ). Checked on the data: a
bare silicon substrate (κ > 0) gives arg ρ_library ∈ (180°, 360°) and WVASE's
Δ ∈ (0°, 180°) (171.85° at 300 nm, 45°: TestData_bareSI.txt), the conjugate.

**Reported Δ.** WVASE reflects Δ about 180° (Δ > 180° → 360° − Δ), so Δ ∈ [0°, 180°]:
`ellipsometry` does the same by default (``fold=True``), Δ = |arg ρ| =
atan2(|Im ρ|, Re ρ), the same for both conventions (the fold forgets the sign of sin Δ,
the handedness). ``fold=False`` gives WVASE's unfolded Δ ∈ [0°, 360°).

Example (a bare dielectric: Δ = 180° below Brewster's angle, 0° above it, ψ = 45° at
normal incidence and 0° at Brewster's angle arctan 1.5 = 56.31°):
    >>> import numpy as np
    >>> from thinfilm_jax.core.stack import Stack
    >>> glass = Stack([], (), 1.5)
    >>> psi, delta = ellipsometry(glass, np.cos(np.deg2rad([0.0, 45.0, 70.0])), 633.0)
    >>> np.round(psi, 3).tolist(), np.round(delta, 3).tolist()
    ([45.0, 16.874, 20.636], [180.0, 180.0, 0.0])
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..core.stack import Stack
from .index import index_at, is_index_model
from .stack import stack_amplitudes, stack_amplitudes_traced

__all__ = ["check_lossless_ambient", "ellipsometric_ratio", "ellipsometry", "fold_delta",
           "psi_delta_traced"]


def _as_stack(x) -> Stack:
    """A `Stack` (as is) or the one-layer `Stack` of a `Film` (trace-safe)."""
    if isinstance(x, Stack):
        return x
    if isinstance(x, Film):
        if is_index_model(x.eta_base) and V.is_concrete(x.kappa_base) \
                and np.any(np.asarray(x.kappa_base) != 0):
            raise ValueError("film.kappa_base must be 0 when film.eta_base is an index model "
                             "(the model carries κ)")
        if is_index_model(x.eta_base):
            eb = x.eta_base
        else:  # η₃ + iκ₃ written without Python-complex arithmetic (strict dtype promotion)
            eb, k = jnp.asarray(x.eta_base), jnp.asarray(x.kappa_base)
            if jnp.iscomplexobj(eb):
                eb, k = jnp.real(eb), jnp.imag(eb) + k
            dt = jnp.result_type(eb, k, float)
            eb = jax.lax.complex(*jnp.broadcast_arrays(eb.astype(dt), k.astype(dt)))
        return Stack(jnp.asarray(x.thickness)[..., None], (x.eta_film,), eb, x.eta_outer)
    raise TypeError(f"expected a thinfilm_jax Film or Stack, got {type(x).__name__}")


def check_lossless_ambient(x, wavelength, name: str = "x") -> None:
    """ValueError unless the ambient (`eta_outer`) of `x` is lossless at `wavelength`:
    ellipsometry's incident and reflected waves are defined there (an absorbing ambient has
    no real angle of incidence). Concrete values only (a traced index passes)."""
    eta = index_at(x.eta_outer, wavelength) if is_index_model(x.eta_outer) else x.eta_outer
    if not V.is_concrete(eta):
        return
    k = np.imag(np.asarray(eta))
    if np.any(k != 0):
        raise ValueError(f"{name}.eta_outer must be a lossless ambient (κ = 0) for "
                         f"ellipsometry; got κ = {float(np.max(np.abs(k))):g}")


def _psi_delta(r, fold: bool):
    """(ψ, Δ) in degrees from the library's amplitudes r = (r_s, r_p) on axis 0 (module
    docstring): ψ = atan2(|r_p|, |r_s|); Δ = atan2(|Im ρ|, Re ρ) folded, else
    −arg ρ mod 360°; ρ = r_p conj(r_s) / |r_s|² has the phase of r_p conj(r_s). Double-where
    at ρ = 0 (ψ = 0, Δ undefined: 0 with a zero gradient)."""
    rs, rp = r[0], r[1]
    a_s = jnp.sqrt(jnp.real(rs) ** 2 + jnp.imag(rs) ** 2)
    a_p2 = jnp.real(rp) ** 2 + jnp.imag(rp) ** 2
    zp = a_p2 == 0
    a_p = jnp.where(zp, 0.0, jnp.sqrt(jnp.where(zp, 1.0, a_p2)))
    psi = jnp.degrees(jnp.arctan2(a_p, a_s))
    z = rp * jnp.conj(rs)  # arg z = arg ρ
    x, y = jnp.real(z), jnp.imag(z)
    zero = (x == 0) & (y == 0)
    x1 = jnp.where(zero, 1.0, x)
    if fold:
        ya = jnp.abs(jnp.where(zero, 0.0, y))
        delta = jnp.degrees(jnp.arctan2(ya, x1))
    else:
        delta = jnp.mod(-jnp.degrees(jnp.arctan2(jnp.where(zero, 0.0, y), x1)), 360.0)
    return psi, jnp.where(zero, 0.0, delta)


def psi_delta_traced(x, cos_theta, wavelength, *, fold: bool = True):
    """`ellipsometry` without the input checks: trace-safe (every field may be traced), for
    the fits (`fit.ellipsometry_fit`) that validated at their own boundary."""
    return _psi_delta(stack_amplitudes_traced(_as_stack(x), cos_theta, wavelength), fold)


def ellipsometry(x: Film | Stack, cos_theta, wavelength, *, fold: bool = True) -> tuple[
        Array, Array]:
    """Ellipsometric angles (ψ, Δ) in degrees of `x` in J.A. Woollam's WVASE / CompleteEASE
    convention (module docstring; SPEC §14).

    Args:
        x: a `Film` (constant indices or index models) or a `Stack`; its ambient
            `eta_outer` must be lossless.
        cos_theta: cos θ₀ ∈ [0, 1], the angle of incidence in the ambient (broadcasts with
            `wavelength` and a `Stack`'s batch axes).
        wavelength: λ in nm (> 0), where index models are evaluated.
        fold: Δ reflected about 180° into [0°, 180°] as WVASE reports it (default); False:
            WVASE's Δ = −arg ρ_library in [0°, 360°).

    Returns:
        (ψ, Δ), real arrays of the broadcast shape (dtype following the inputs).
    """
    if not isinstance(x, Film | Stack):
        raise TypeError(f"x must be a thinfilm_jax Film or Stack, got {type(x).__name__}")
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    check_lossless_ambient(x, wavelength)
    if isinstance(x, Film) and not any(is_index_model(getattr(x, k))
                                       for k in ("eta_film", "eta_base", "eta_outer")):
        x = V.check_film(x, "x")
    r = stack_amplitudes(_as_stack(x), cos_theta, wavelength)
    return _psi_delta(r, fold)


def ellipsometric_ratio(x: Film | Stack, cos_theta, wavelength) -> Array:
    """ρ = tan ψ e^{iΔ} in the WVASE (Nebraska) convention, unfolded: the complex conjugate of
    the library's r_p / r_s (module docstring); arguments as `ellipsometry`."""
    if not isinstance(x, Film | Stack):
        raise TypeError(f"x must be a thinfilm_jax Film or Stack, got {type(x).__name__}")
    check_lossless_ambient(x, wavelength)
    r = stack_amplitudes(_as_stack(x), cos_theta, wavelength)
    return jnp.conj(r[1] / r[0])


def fold_delta(delta):
    """Δ (degrees, any real value) reflected into [0°, 180°] as WVASE reports it: Δ mod 360,
    then Δ > 180° → 360° − Δ (NumPy or JAX arrays)."""
    d = jnp.mod(jnp.asarray(delta), 360.0)
    return jnp.where(d > 180.0, 360.0 - d, d)

