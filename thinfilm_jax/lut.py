r"""Lookup table of the Gaussian-filtered sensitivity Ŝ_j(μ, σ²) (K 18, SPEC §5).

The exact filtered transform (`spectra.sensitivity_ft(mu, sigma2=...)`) costs one complex
exponential per tabulated wavelength; a real-time shader reads a 2D table instead. Ŝ(μ, ·)
oscillates in μ with the period of the band's wavelengths (≈ 400–700 nm), which a plain
table must resolve. We store the *demodulated* envelope

$$ E_j(\mu, \sigma) = \hat S_j(\mu, \sigma^2)\, e^{+2\pi i \mu \bar\nu_j} $$

(ν̄_j: the band's |S|-weighted mean frequency), which varies on the scale of the inverse
bandwidth (≳ 1 µm), and multiply the carrier e^{−2πiμν̄_j} back analytically at lookup.
Interpolation is bicubic Catmull–Rom on a uniform (|μ|, σ) grid, C¹ and differentiable.
Symmetries fill the borders exactly: Ŝ(−μ, σ²) = conj Ŝ(μ, σ²) and the table is even in σ.

Range and behaviour outside it (documented, never garbage):
* σ ∈ [0, σ_max], σ_max = 1000 nm by default: there |Ŝ| ≤ e^{−2π²σ²/λ_max²} < 1e-12, so
  σ > σ_max is clamped to σ_max (a value < 1e-12).
* |μ| ≤ μ_max, by default the observer's alias-free optical path λ_min²/(2Δλ)
  (15.2 µm for the 5-nm Stiles & Burch table, 64.8 µm for CIE 1931 at 1 nm). Beyond it the
  tabulated quadrature itself aliases, and the table returns 0, the limit of a continuous
  band (coherent interference averages out); `alias_free_path` gives the bound.
The LUT's error against the exact quadrature is measured by `lut_max_error` (tests and
README state it).

Example (the default table, its accuracy against the exact quadrature, 0 beyond μ_max):
    >>> import numpy as np
    >>> from thinfilm_jax.lut import build_shat_lut, lookup
    >>> from thinfilm_jax.spectra import shat_host
    >>> lut = build_shat_lut()
    >>> lut.table.shape  # (n_mu + 3, n_sigma + 3, J)
    (613, 131, 3)
    >>> err = np.abs(np.asarray(lookup(lut, 1234.5, 30.0)) - shat_host(1234.5, 30.0**2))
    >>> bool(err.max() < 1e-4)  # measured 1.9e-5
    True
    >>> np.asarray(lookup(lut, 2e4, 0.0)).tolist()  # μ = 20 µm > μ_max = 15.2 µm
    [0j, 0j, 0j]
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from . import _validate as V
from .fresnel import complex_dtype
from .spectra import DEFAULT_OBSERVER, get_observer, shat_host


class ShatLUT(NamedTuple):
    """Demodulated table of Ŝ_j(μ, σ²) on a uniform (|μ|, σ) grid (a pytree of arrays).

    table: (n_mu + 3, n_sigma + 3, J) complex, one padding row/column before and two after.
    carrier: (J,) ν̄_j in 1/nm. mu_max, sigma_max: grid extents (nm).
    """

    table: Array
    carrier: Array
    mu_max: Array
    sigma_max: Array


def alias_free_path(observer: str = DEFAULT_OBSERVER) -> float:
    """λ_min² / (2 max Δλ): the optical path beyond which the tabulated quadrature aliases."""
    lam = get_observer(observer).wavelengths
    return float(lam.min() ** 2 / (2.0 * np.diff(lam).max()))


@functools.cache
def _build(observer, d_mu, n_sigma, sigma_max, mu_max):
    obs = get_observer(observer)
    mu_max = alias_free_path(observer) if mu_max is None else float(mu_max)
    n_mu = int(np.ceil(mu_max / d_mu)) + 1
    mu_max = (n_mu - 1) * d_mu
    d_sig = sigma_max / (n_sigma - 1)
    mu = np.arange(-1, n_mu + 2) * d_mu
    sig = np.abs(np.arange(-1, n_sigma + 2) * d_sig)  # even in σ: row −1 equals row +1
    w = np.abs(obs.weights)
    carrier = (w / obs.wavelengths[:, None]).sum(0) / w.sum(0)
    vals = np.stack([shat_host(mu, s * s, obs) for s in sig], axis=1)  # (μ, σ, J)
    table = vals * np.exp(2j * np.pi * mu[:, None, None] * carrier)
    return table, carrier, mu_max, sigma_max


def build_shat_lut(observer: str = DEFAULT_OBSERVER, *, d_mu: float = 25.0,
                   n_sigma: int = 128, sigma_max: float = 1000.0, mu_max: float | None = None,
                   dtype=jnp.float64) -> ShatLUT:
    """Tabulate Ŝ_j(μ, σ²) once on the host; `dtype` float32 gives a complex64 table.

    Default resolution: Δμ = 25 nm, 128 σ samples on [0, 1000] nm (error in README).
    """
    get_observer(observer)  # validates the name (plain or cross-band, see uplift)
    d_mu = float(V.check_range("d_mu", d_mu, 0.0, lo_open=True, why=" (nm)"))
    n_sigma = V.check_int("n_sigma", n_sigma, 2)
    sigma_max = float(V.check_range("sigma_max", sigma_max, 0.0, lo_open=True, why=" (nm)"))
    if mu_max is not None:
        mu_max = float(V.check_range("mu_max", mu_max, 0.0, lo_open=True, why=" (nm)"))
    table, carrier, mmax, smax = _build(observer, float(d_mu), int(n_sigma), float(sigma_max),
                                        mu_max)
    cdt = complex_dtype(jnp.zeros((), dtype))
    return ShatLUT(jnp.asarray(table, cdt), jnp.asarray(carrier, dtype),
                   jnp.asarray(mmax, dtype), jnp.asarray(smax, dtype))


def _catmull_rom(f):
    f2, f3 = f * f, f * f * f
    return jnp.stack([(-f3 + 2 * f2 - f) / 2, (3 * f3 - 5 * f2 + 2) / 2,
                      (-3 * f3 + 4 * f2 + f) / 2, (f3 - f2) / 2], axis=-1)


def lookup(lut: ShatLUT, mu, sigma, *, interpolation: str = "cubic") -> Array:
    """Ŝ_j(μ, σ²) from the table, shape broadcast(mu, sigma) + (J,), complex.

    Args:
        mu: mean optical path μ (nm), any sign.
        sigma: standard deviation σ ≥ 0 (nm), not the variance.
        interpolation: "cubic" (Catmull–Rom in (|μ|, σ), C¹) or "linear" (bilinear, C⁰,
            4 taps instead of 16; the real-time read of `improved`, within 2e-3 of exact Ŝ
            at the default resolution, tests/test_improved.py).
    The demodulated envelope is interpolated, the carrier e^{−2πi|μ|/λ_c} is exact; Ŝ(−μ) =
    conj Ŝ(μ); 0 beyond μ_max; σ clamped at σ_max.
    """
    n_mu = lut.table.shape[0] - 3
    n_sig = lut.table.shape[1] - 3
    mu, sigma = jnp.broadcast_arrays(jnp.asarray(mu), jnp.asarray(sigma))
    a = jnp.abs(mu)
    inside = a <= lut.mu_max
    tm = jnp.minimum(a, lut.mu_max) / lut.mu_max * (n_mu - 1)
    ts = jnp.minimum(sigma, lut.sigma_max) / lut.sigma_max * (n_sig - 1)
    fm = jnp.clip(jnp.floor(tm), 0, n_mu - 2)
    fs = jnp.clip(jnp.floor(ts), 0, n_sig - 2)
    im, is_ = fm.astype(jnp.int32), fs.astype(jnp.int32)
    t, cdt = lut.table, lut.table.dtype
    if interpolation == "cubic":
        wm, ws = _catmull_rom(tm - fm).astype(cdt), _catmull_rom(ts - fs).astype(cdt)
        off = jnp.arange(4, dtype=jnp.int32)
        patch = t[(im[..., None] + off)[..., :, None], (is_[..., None] + off)[..., None, :]]
        env = jnp.einsum("...a,...b,...abj->...j", wm, ws, patch,
                         precision=jax.lax.Precision.HIGHEST)
    elif interpolation == "linear":
        u, v = (tm - fm)[..., None].astype(cdt), (ts - fs)[..., None].astype(cdt)
        im, is_ = im + 1, is_ + 1  # row/column 0 is the cubic stencil's padding
        env = ((t[im, is_] * (1 - u) + t[im + 1, is_] * u) * (1 - v)
               + (t[im, is_ + 1] * (1 - u) + t[im + 1, is_ + 1] * u) * v)
    else:
        raise ValueError(f"unknown interpolation {interpolation!r}; expected 'cubic' or "
                         f"'linear'")
    carrier = jnp.reshape(lut.carrier, (1,) * a.ndim + (-1,))  # ranks aligned explicitly
    arg = (-2.0 * jnp.pi) * a[..., None] * carrier
    val = env * jax.lax.complex(jnp.cos(arg), jnp.sin(arg))
    val = jnp.where((mu < 0)[..., None], jnp.conj(val), val)
    return jnp.where(inside[..., None], val, jnp.zeros((), val.dtype))


def lut_max_error(observer: str = DEFAULT_OBSERVER, n: int = 20000, seed: int = 0,
                  **build_kw) -> float:
    """max |LUT − exact| over `n` random (μ, σ) inside the table's range (float64)."""
    lut = build_shat_lut(observer, **build_kw)
    rng = np.random.default_rng(seed)
    mu = rng.uniform(-float(lut.mu_max), float(lut.mu_max), n)
    sig = rng.uniform(0, float(lut.sigma_max), n) * rng.choice([0.0, 0.1, 1.0], n)
    exact = shat_host(mu, sig**2, observer)
    return float(np.abs(np.asarray(lookup(lut, mu, sig)) - exact).max())
