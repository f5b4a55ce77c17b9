r"""Colour bands S_j(λ) from colour-science and their Fourier transforms Ŝ_j (SPEC §1, §4, §5).

Bands are the observer's colour-matching functions, each normalised to unit area with the
trapezoid rule on the observer's own tabulated wavelengths λ_k. Every λ-integral in the
library uses the same quadrature weights

$$ W_{kj} = \frac{t_k S_j(\lambda_k)}{\sum_{k'} t_{k'} S_j(\lambda_{k'})}, \qquad
   \int f(\lambda) S_j(\lambda)\,d\lambda \approx \sum_k W_{kj} f(\lambda_k), $$

(t_k trapezoid weights), so the spectral reference and the Fourier path (K 4) share one
quadrature and SPEC §4's identity holds to rounding. The Fourier transform and its
Gaussian-filtered version (K 18, SPEC §5) are

$$ \hat S_j(x) = \sum_k W_{kj} e^{-2\pi i x/\lambda_k}, \qquad
   \hat S_j(\mu,\sigma^2) = \sum_k W_{kj} e^{-2\pi i \mu/\lambda_k} e^{-2\pi^2\sigma^2/\lambda_k^2}. $$

A cheaper closed form (BB17's Gaussian fit) represents each band as a sum of Gaussians in
frequency ν = 1/λ; its Fourier transform and filtered transform are then analytic
(`gaussian_fit`, `sensitivity_ft(..., shat="gaussian")`). Its error against the
tabulated Ŝ is measured by `gaussian_fit_error` and stated in the README.

Example (unit-area bands: Ŝ_j(0) = 1; a Gaussian spread of the path over many wavelengths
averages Ŝ out):
    >>> import numpy as np
    >>> from thinfilm_jax.spectral.spectra import get_observer, sensitivity_ft
    >>> get_observer("stiles_burch_1959_10").band_names
    ('R', 'G', 'B')
    >>> bool(np.abs(sensitivity_ft(0.0) - 1.0).max() < 1e-12)
    True
    >>> bool(np.abs(sensitivity_ft(1000.0, sigma2=1000.0**2)).max() < 1e-12)
    True
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V

__all__ = [
    "OBSERVERS",
    "DEFAULT_OBSERVER",
    "SHAT_METHODS",
    "Observer",
    "trapezoid_weights",
    "get_observer",
    "sensitivity_ft",
    "shat_host",
    "shat_at_zero",
    "gaussian_fit",
    "gaussian_fit_error",
]

OBSERVERS = {
    "stiles_burch_1959_10": "Stiles & Burch 1959 10 Degree RGB CMFs",
    "cie_1931_2": "CIE 1931 2 Degree Standard Observer",
}
DEFAULT_OBSERVER = "stiles_burch_1959_10"
SHAT_METHODS = ("exact", "gaussian")


@dataclass(frozen=True, eq=False)
class Observer:
    """Host-side (NumPy) tables of one observer.

    Attributes:
        name: short name (a key of `OBSERVERS`).
        wavelengths: λ_k in nm, shape (K,).
        weights: W_kj, shape (K, J); each column sums to 1.
        areas: ∫ S_j dλ of the raw colour-science table, shape (J,).
        band_names: names of the J bands.
    """

    name: str
    wavelengths: np.ndarray
    weights: np.ndarray
    areas: np.ndarray
    band_names: tuple[str, ...]

    @property
    def n_bands(self) -> int:
        return self.weights.shape[1]


def trapezoid_weights(x: np.ndarray) -> np.ndarray:
    """Weights t_k with Σ t_k f(x_k) = trapezoid rule on the nodes x."""
    dx = np.diff(x)
    t = np.zeros_like(x)
    t[:-1] += dx / 2
    t[1:] += dx / 2
    return t


@functools.cache
def get_observer(name: str = DEFAULT_OBSERVER) -> Observer:
    """The `Observer` called `name` (one of `OBSERVERS`), built once from colour-science.

    `uplift.cross_band_name(name)` (e.g. "stiles_burch_1959_10+mallett2019") gives the J·K
    cross bands S_j B_k of image-based lighting (SPEC §9, `uplift`)."""
    from . import uplift

    if isinstance(name, str) and name.endswith(uplift.SEPARATOR + uplift.BASIS):
        base = get_observer(name[: -len(uplift.SEPARATOR + uplift.BASIS)])
        names = tuple(f"{j}·{k}" for j in base.band_names for k in ("r", "g", "b"))
        return Observer(name, base.wavelengths,
                        uplift.cross_band_weights(base.wavelengths, base.weights),
                        base.areas, names)
    V.check_choice("observer", name, OBSERVERS)
    import colour

    cmfs = colour.MSDS_CMFS[OBSERVERS[name]]
    lam = np.asarray(cmfs.wavelengths, float)
    s = np.asarray(cmfs.values, float)
    t = trapezoid_weights(lam)
    areas = t @ s
    weights = t[:, None] * s / areas
    bands = ("R", "G", "B") if name == "stiles_burch_1959_10" else ("X", "Y", "Z")
    return Observer(name, lam, weights, areas, bands)


def _observer(observer) -> Observer:
    return observer if isinstance(observer, Observer) else get_observer(observer)


def sensitivity_ft(x, observer=DEFAULT_OBSERVER, *, sigma2=None, shat: str = "exact"):
    """Ŝ_j(x) (SPEC §4), or the Gaussian-filtered Ŝ_j(x, σ²) (SPEC §5) if `sigma2` is given.

    Args:
        x: optical path (nm), any shape.
        observer: observer name or `Observer`.
        sigma2: variance σ² (nm²) of a Gaussian on x, broadcasting with x; None means 0.
        shat: "exact" (quadrature on the observer's samples) or "gaussian"
            (closed form of the Gaussian fit, `gaussian_fit`).

    Returns:
        complex array of shape broadcast(x, sigma2) + (n_bands,).
    """
    V.check_choice("shat", shat, SHAT_METHODS)
    obs = _observer(observer)
    if V.is_concrete(x):  # traced values (internal calls under jit) are not checked
        x = V.check_finite("x", x)
    if sigma2 is not None and V.is_concrete(sigma2):
        sigma2 = V.check_range("sigma2", sigma2, 0.0, why=" (variance, nm²)")
    x = jnp.asarray(x)
    dtype = jnp.result_type(x, float)
    if shat == "gaussian":
        return _gaussian_ft(x, sigma2, jnp.asarray(gaussian_fit(obs.name), dtype))
    # built from real parts (no implicit real → complex promotion)
    return jax.lax.complex(*_shat_quadrature(jnp, x, sigma2, obs, dtype))


def shat_host(x, sigma2=None, observer=DEFAULT_OBSERVER) -> np.ndarray:
    """`sensitivity_ft(x, observer, sigma2=sigma2)` (tabulated) in host NumPy float64.

    For tables built once on the host (`lut`, `gaussian_fit`) and for references: it also runs
    while a caller is being traced by `jax.jit` (JAX results would be tracers there) and
    whatever `jax_enable_x64` says.
    """
    re, im = _shat_quadrature(np, np.asarray(x, np.float64), sigma2, _observer(observer),
                              np.float64)
    return re + 1j * im


def _shat_quadrature(xp, x, sigma2, obs: Observer, dtype):
    r"""Real and imaginary parts of Σ_k W_kj e^{−2πix/λ_k} e^{−2π²σ²/λ_k²}, x.shape + (J,).

    The one implementation of the Ŝ quadrature (SPEC §4–5): `sensitivity_ft` calls it with
    xp = jax.numpy (traceable, any dtype), `shat_host` with xp = numpy (float64). Shapes are
    aligned explicitly (no implicit rank promotion).
    """
    if sigma2 is not None:
        x, sigma2 = xp.broadcast_arrays(x, xp.asarray(sigma2, dtype))
    inv_lam = xp.asarray(1.0 / obs.wavelengths, dtype).reshape((1,) * x.ndim + (-1,))
    phase = (-2.0 * np.pi) * x[..., None] * inv_lam
    re, im = xp.cos(phase), xp.sin(phase)
    if sigma2 is not None:
        damp = xp.exp((-2.0 * np.pi**2) * sigma2[..., None] * inv_lam**2)
        re, im = damp * re, damp * im
    w = xp.asarray(obs.weights, dtype)
    if xp is np:
        return re @ w, im @ w
    hi = jax.lax.Precision.HIGHEST
    return jnp.matmul(re, w, precision=hi), jnp.matmul(im, w, precision=hi)


def shat_at_zero(observer=DEFAULT_OBSERVER, dtype=jnp.float64, shat: str = "exact") -> Array:
    """Ŝ_j(0) of the C₀ term, shape (n_bands,).

    "exact": Σ_k W_kj (= 1 up to rounding), which keeps SPEC §4's identity exact on the
    shared samples. "gaussian": the exact area of each band, 1 for the unit-area bands (the
    fit's own Ŝ(0) is only approximately right; C₀ must not inherit that fitting error) and
    ∫ S_j B_k dλ for the cross bands of `uplift`.
    """
    obs = _observer(observer)
    if shat == "gaussian" and obs.areas.shape[0] == obs.n_bands:
        return jnp.ones(obs.n_bands, dtype)
    return jnp.asarray(obs.weights.sum(axis=0), dtype)


# ----------------------------------------------------------------------------------------
# Gaussian fit (BB17's closed form): S_j(λ) dλ ≈ Σ_g a_g N(ν; ν_g, s_g²) dν, ν = 1/λ.
# ----------------------------------------------------------------------------------------


def _gaussian_ft(x, sigma2, params, xp=jnp):
    r"""Closed-form Ŝ of a Gaussian mixture in ν, optionally filtered by x ~ N(x, σ²).

    For one component a·N(ν; ν₀, s²): Ŝ(x) = a exp(−2πixν₀ − 2π²s²x²). With
    x ~ N(μ, σ²), E[exp(−A x² + c x)] = (1 + 2Aσ²)^{-1/2} exp((c²σ² + 2cμ − 2Aμ²)/(2(1+2Aσ²)))
    with A = 2π²s², c = −2πiν₀. `xp` = jax.numpy (`sensitivity_ft`) or numpy (the host
    residual of `gaussian_fit`): one implementation of the closed form.
    """
    if sigma2 is not None:
        x, sigma2 = xp.broadcast_arrays(x, xp.asarray(sigma2, params.dtype))
    params = params.reshape((1,) * x.ndim + params.shape)  # ranks aligned explicitly
    a, nu0, s = params[..., 0], params[..., 1], params[..., 2]  # (..., J, G)
    xx = x[..., None, None]
    big_a = 2.0 * np.pi**2 * s**2
    # c = −2πiν₀ is imaginary, c² = −4π²ν₀² real: split the exponent into real parts.
    if sigma2 is None:
        mag = a * xp.exp(-big_a * xx**2)
        arg = -2.0 * np.pi * nu0 * xx
    else:
        s2 = sigma2[..., None, None]
        den = 1.0 + 2.0 * big_a * s2
        mag = a / xp.sqrt(den) * xp.exp((-4.0 * np.pi**2 * nu0**2 * s2 - 2.0 * big_a * xx**2)
                                        / (2.0 * den))
        arg = -2.0 * np.pi * nu0 * xx / den
    re, im = xp.sum(mag * xp.cos(arg), axis=-1), xp.sum(mag * xp.sin(arg), axis=-1)
    return jax.lax.complex(re, im) if xp is jnp else re + 1j * im


@functools.cache
def gaussian_fit(observer: str = DEFAULT_OBSERVER, n_gauss: int = 3) -> np.ndarray:
    """Fit each band as a sum of `n_gauss` Gaussians in ν = 1/λ (host, SciPy, cached).

    The fit minimises the error of the *transform* Ŝ_j(x) against the tabulated one over
    x ∈ [0, 8000] nm (the range the M ≤ 4 Fourier path uses for visible films), starting
    from a greedy fit of the band's density in ν. Returns params (J, n_gauss, 3) holding
    (a, ν₀ [1/nm], s [1/nm]); Σ_g a_g = 1 is not imposed (Ŝ(0) is fitted like any x).
    """
    from scipy.optimize import least_squares

    obs = get_observer(observer)
    nu = 1.0 / obs.wavelengths
    xs = np.linspace(0.0, 8000.0, 801)
    # the tabulated Ŝ on the host: this function may first run while a caller is being traced
    target = shat_host(xs, observer=obs)  # (X, J)
    out = []
    for j in range(obs.n_bands):
        # density in ν: S(λ) |dλ/dν| = S λ²; on the samples, W_kj / t_k * λ²
        t = trapezoid_weights(obs.wavelengths)
        f = obs.weights[:, j] / t * obs.wavelengths**2
        resid = f.copy()
        params = []
        for _ in range(n_gauss):
            k = int(np.argmax(np.abs(resid)))
            p0 = [resid[k] * 1e-4 * np.sqrt(2 * np.pi), nu[k], 1e-4]

            def one(p, r=resid):
                return p[0] * np.exp(-0.5 * ((nu - p[1]) / p[2]) ** 2) / (np.sqrt(2 * np.pi) * p[2]) - r

            p = least_squares(one, p0, x_scale=[1e-3, 1e-4, 1e-5]).x
            params.append(p)
            resid = -one(p)  # what is left
        p0 = np.concatenate(params)

        def ft_resid(p, j=j):
            d = _gaussian_ft(xs, None, p.reshape(1, -1, 3), xp=np)[:, 0] - target[:, j]
            return np.concatenate([d.real, d.imag])

        p = least_squares(ft_resid, p0, x_scale=np.tile([1e-1, 1e-4, 1e-5], n_gauss)).x
        out.append(p.reshape(-1, 3))
    params = np.stack(out)
    params[..., 2] = np.abs(params[..., 2])
    return params


def gaussian_fit_error(observer: str = DEFAULT_OBSERVER, x_max: float = 8000.0) -> np.ndarray:
    """max_x |Ŝ_fit(x) − Ŝ_tab(x)| over x ∈ [0, x_max] nm, per band (shape (J,))."""
    xs = np.linspace(0.0, x_max, 4001)
    tab = np.asarray(sensitivity_ft(xs, observer))
    fit = np.asarray(sensitivity_ft(xs, observer, shat="gaussian"))
    return np.abs(fit - tab).max(axis=0)
