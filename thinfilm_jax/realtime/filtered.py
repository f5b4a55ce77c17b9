r"""Filtered band reflectance for a Gaussian distribution of the optical path (K 19, K 29).

$$ \int p_R R_j \approx C_0^* + \sum_{m=1}^{M} C_m^*\left[e^{im\varphi_2^*}\hat S_j(-m\mu_D, m^2\sigma_D^2)
   + e^{-im\varphi_2^*}\hat S_j(m\mu_D, m^2\sigma_D^2)\right], $$

with C*_m, φ₂* the BB17 terms at the mean light direction (cos θ₁*, K 22) and Ŝ the
Gaussian-filtered sensitivity, either exact (`shat="exact"`, SPEC §5 quadrature) or from
the LUT (`shat="lut"`, `lut.ShatLUT`). Kneiphof et al. use M = 2.

Example (σ_D = 0 is the BB17 Fourier sum K 4; a spread σ_D of many wavelengths averages the
interference out, leaving the same C₀ in every band):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.realtime.filtered import filtered_bands
    >>> from thinfilm_jax.optics.opd import OPDMoments, opd_of_cos
    >>> from thinfilm_jax.spectral.reflectance import fourier_bands
    >>> film, c, obs = Film(600.0, 1.3, 2.0, 0.5), 0.8, "stiles_burch_1959_10"
    >>> sharp = filtered_bands(film, c, OPDMoments(opd_of_cos(film, c), 0.0), obs)
    >>> bool(np.allclose(sharp, fourier_bands(film, c, obs, terms=2)))
    True
    >>> wide = filtered_bands(film, c, OPDMoments(opd_of_cos(film, c), 1e4), obs)
    >>> bool(np.ptp(np.asarray(wide)) < 1e-9)
    True
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array

from ..core.film import Film
from ..optics.opd import OPDMoments
from ..optics.series import fourier_band_reflectance, fused_terms, series_terms
from ..spectral.lut import ShatLUT, carrier_parts, read_parts
from ..spectral.spectra import sensitivity_ft, shat_at_zero

__all__ = ["SHAT_SOURCES", "filtered_bands", "split_by_light"]

SHAT_SOURCES = ("exact", "lut", "gaussian")
UNROLLED_READS = ("cubic", "linear_mu")  # ≥ 8 taps: one loop for all orders (`_read_orders`)


def filtered_bands(film: Film, cos_mean, opd: OPDMoments, observer: str, *, terms: int = 2,
                   shat: str = "exact", lut: ShatLUT | None = None,
                   arithmetic: str = "complex", interpolation: str = "cubic",
                   shat0: Array | None = None, light: Array | None = None) -> Array:
    """K 29 band reflectance (..., J) for broadcast inputs (no validation; see patch.py).

    `shat0`: Ŝ_j(0) (J,) of the C₀ term when `lut` holds bands that no observer name gives
    (a light's colour folded into the cross bands, `sources.with_film_tables`); then
    `observer` is not read.

    `light` (..., K) with shat="lut" and a cross-band `observer` (`uplift`, J·K bands j·k):
    returns Σ_k R_jk light_k (..., J), the band radiance under RGB light (SPEC §9), reading
    the table one light channel at a time (K reads of J bands, which XLA fuses into the
    kernel's loop; one read of J·K bands per tap does not fuse and moves ~8× the bytes);
    `lut` may then be the table already split per channel (`split_by_light`).

    `interpolation` is the LUT read (`lut.lookup`: "cubic", "linear_mu" or "linear") when
    shat="lut". With ``opd.std=None``
    the path is known to be exact (σ_D = 0, the `ideal` kernel): the LUT is read at σ = 0
    only."""
    if shat == "lut":
        if light is not None:
            return _lut_bands_under_light(film, cos_mean, opd, observer, terms, lut,
                                          arithmetic, interpolation, light)
        return _lut_bands(film, cos_mean, opd, observer, terms, lut, arithmetic,
                          interpolation, shat0)
    if light is not None:
        raise ValueError("filtered_bands: light= needs shat='lut' (the cross-band table)")
    st = series_terms(film, cos_mean, arithmetic=arithmetic)
    dtype = jnp.result_type(cos_mean, float)
    mean, std = opd
    std = jnp.zeros_like(mean) if std is None else std

    def shat_m(m):
        return sensitivity_ft(-m * mean, observer, sigma2=(m * std) ** 2, shat=shat)

    s0 = shat_at_zero(observer, dtype, "gaussian" if shat == "gaussian" else "exact")
    return jnp.mean(fourier_band_reflectance(st, shat_m, terms, s0), axis=0)


def _lut_bands_under_light(film, cos_mean, opd, observer, terms, lut, arithmetic,
                           interpolation, light):
    """Σ_k light_k R_jk: the cross-band table (bands j·k, k fastest) read one light channel
    k at a time, in place (`lut.read_parts(channel=(k, K))`: no copy of the table per call),
    one J-band K 29 per channel (`_read_orders`) on the film terms computed once. A tuple of
    per-channel tables (`split_by_light`) is read as given."""
    n_light = light.shape[-1]
    s0 = shat_at_zero(observer, jnp.result_type(cos_mean, float), "exact")
    ft = fused_terms(film, cos_mean, arithmetic=arithmetic)
    split = isinstance(lut, tuple) and not isinstance(lut, ShatLUT)
    out = None
    for k in range(n_light):
        r = _read_orders(ft, s0[k::n_light], terms, opd, lut[k] if split else lut,
                         interpolation, None if split else (k, n_light))
        r = r * light[..., k:k + 1]
        out = r if out is None else out + r
    return out


def split_by_light(lut: ShatLUT, n_light: int = 3) -> tuple[ShatLUT, ...]:
    """The cross-band table (bands j·k, light channel k fastest) as one J-band table per
    light channel k. Each is a strided copy of the table; `filtered_bands(light=...)` reads
    the cross-band table in place instead (`lut.read_parts(channel=...)`), and takes such a
    tuple as `lut` too."""
    return tuple(ShatLUT(lut.table[..., k::n_light], lut.carrier[k::n_light], lut.mu_max,
                         lut.sigma_max) for k in range(n_light))


def _read_orders(ft, s0, terms, opd, lut, interpolation, channel=None):
    r"""C₀ Ŝ_j(0) + Σ_m Re(W_m conj Ŝ_j(mμ_D, m²σ_D²)), W_m = Σ_{s,p} (R* − T₁₂₁) z^m.

    Reads of 4 taps (bilinear, or σ = 0) are the steps of a `lax.scan` over m (z^m
    carried), which XLA compiles into one loop per order: unrolled, two such reads (and the
    K bins of `improved`) fuse into one loop that XLA's CPU backend compiles to slow code
    (`ideal_kernel` 1.7× slower, `improved_kernel` 3×: figures/kernel_bench.md). The 16-tap
    bicubic and 8-tap "linear_mu" reads are unrolled: one loop of both orders is as fast as
    two, or faster (under a map's light; the 8-tap read in the scan loop cost 1.3× the
    unrolled 16-tap one); so is a light channel's read of a cross-band table (`channel`
    given: `improved`'s bins under a map, 4 taps, 1.09× faster unrolled, while its
    uniform-light bins are as fast either way); unrolled, the carrier of order m is the
    m-th power of order 1's,
    e^{−2πi mμ ν̄_j} = (e^{−2πi μ ν̄_j})^m, one `sincos_turns` per band instead of M
    (equal to rounding). The same sum either way. `ft`: `series.fused_terms` at the mean
    cosine; `channel`: light channel (k, K) of a cross-band `lut` (`lut.read_parts`)."""
    c0 = 0.5 * (ft.c0[0] + ft.c0[1])
    mean, std = opd
    shape = jnp.broadcast_shapes(c0.shape, mean.shape, *(() if std is None else (std.shape,)))
    # the sum's dtype: the film terms' and the table's (a float32 film under a float64 map
    # reads float64 values, and the scan's carry must hold them from its first step)
    dtype = c0.dtype if lut is None else jnp.result_type(c0.dtype,
                                                          jnp.finfo(lut.table.dtype).dtype)
    out = jnp.broadcast_to(c0[..., None] * jnp.reshape(s0, (1,) * c0.ndim + (-1,)),
                           shape + s0.shape[-1:]).astype(dtype)

    def order(carry, m, carrier=None):  # carry: the sum so far and z^(m−1) per polarisation
        out, pr, pi = carry
        pr, pi = (tuple(a * c - b * d for a, b, c, d in zip(pr, pi, ft.z_re, ft.z_im)),
                  tuple(a * d + b * c for a, b, c, d in zip(pr, pi, ft.z_re, ft.z_im)))
        wr = ft.amp[0] * pr[0] + ft.amp[1] * pr[1]
        wi = ft.amp[0] * pi[0] + ft.amp[1] * pi[1]
        sr, si = read_parts(lut, m * mean, None if std is None else m * std,
                            interpolation=interpolation, channel=channel, carrier=carrier)
        return (out + (wr[..., None] * sr + wi[..., None] * si), pr, pi), None

    one, zero = jnp.ones(shape, c0.dtype), jnp.zeros(shape, c0.dtype)  # z^0: the film's
    carry = (out, (one, one), (zero, zero))
    if std is not None and (interpolation in UNROLLED_READS or channel is not None):
        first = carrier_parts(lut, mean, channel)
        car = first
        for m in range(1, terms + 1):
            if m > 1:  # (c + is)(c₁ + is₁)
                car = (car[0] * first[0] - car[1] * first[1],
                       car[0] * first[1] + car[1] * first[0])
            carry, _ = order(carry, m, car)
        return carry[0]
    ms = jnp.arange(1, terms + 1, dtype=mean.dtype)
    return jax.lax.scan(order, carry, ms)[0][0]


def _lut_bands(film, cos_mean, opd, observer, terms, lut, arithmetic, interpolation,
               shat0=None):
    r"""K 29 with Ŝ from the LUT on real parts (`series.fused_terms`, then `_read_orders`).

    The polarisation mean is taken before the bands: with W_m = Σ_{s,p} (R* − T₁₂₁) z^m
    (complex, per shading point) and Ŝ(−mμ) = conj Ŝ(mμ),

    $$ R_j = \tfrac12\sum_{s,p} C_0\,\hat S_j(0) + \sum_{m=1}^{M}
       \operatorname{Re}\big(W_m\,\overline{\hat S_j(m\mu_D, m^2\sigma_D^2)}\big), $$

    the same sum as `series.fourier_band_reflectance` (half the band work)."""
    dtype = jnp.result_type(cos_mean, float)
    s0 = shat_at_zero(observer, dtype, "exact") if shat0 is None else shat0.astype(dtype)
    return _read_orders(fused_terms(film, cos_mean, arithmetic=arithmetic), s0, terms, opd,
                        lut, interpolation)
