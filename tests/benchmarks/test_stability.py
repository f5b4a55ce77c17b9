"""Stiff and extreme inputs for every public function, value and gradient, float32 and float64.

Each (function, dtype) pair is ONE vectorised, jitted call over a product grid of extreme
inputs (`benchmarks.stiff.STIFF_*`: d ∈ {0, 1e-6, 500, 1e4, 1e5} nm; η₂ = η₁, η₁ + 1e-12,
4; κ₃ ∈ {0, 1e-12, 50}; θ ∈ {0, 1e-9, 0.7, 1.2, π/2 − 1e-9, π/2}; α ∈ {1e-4, 0.3, 1};
η₁ > η₂ with total internal reflection; σ_D up to 1e9 nm), with the gradient (a VJP with an
all-ones cotangent, i.e. jax.grad of the sum, reverse mode as users call it) w.r.t. every
`Film` field and every other input (compile time dominates this file: one program per
`patch_radiance` variant, the LUT an argument of the compiled call, not a constant in it). The checks live in `benchmarks.stability` so
that the markdown report (`python -m benchmarks.bench` → figures/stability_report.md, or
`python -m benchmarks.stability`) shows exactly what is asserted here:

* every value and every gradient is finite;
* the value lies within its exact range (R ∈ [0, 1], bands within [Σ W⁻, Σ W⁺] — the
  Stiles & Burch bands have negative lobes —, patch radiance within A·[Σ W⁻, Σ W⁺] with
  A = `microfacet.albedo`; truncated series within their truncation bound);
* the value agrees with a reference where one is defined (an 80-bit closed form and tmm for
  Airy, the spectral bands plus the series tail bound for Fourier, the mirror limit
  α → 0 for patches, the host quadrature for Ŝ, exact limits for the LUT and K 29);
* documented limitations hold as documented (BB17 series under TIR at 1|2 gives R = 1).
"""

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, rgb_reflectance
from benchmarks import stability

DTYPES = ("float64", "float32")


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", stability.STABILITY_FUNCTIONS)
def test_stiff_inputs(name, dtype):
    r = stability.stability_check(name, dtype)
    assert r.n_cases > 0
    assert r.nonfinite_value == 0, r.examples
    assert sum(r.nonfinite_grad.values()) == 0, (r.nonfinite_grad, r.examples)
    assert r.bound_violations == 0, (r.bound, r.bound_excess, r.examples)
    assert r.ref_violations == 0, (r.reference, r.ref_error, r.ref_tol, r.examples)
    for d in r.documented:
        assert d["holds"], d


def test_series_under_tir_is_the_documented_limitation():
    """SPEC §3 / series.py: with η₁ > η₂ beyond the critical angle the Fourier path returns
    R_j = Ŝ_j(0) (R = 1), while the exact Airy sum keeps frustrated transmission (here a bare
    1.5|1.0 interface at d = 0 under TIR as well, so both are 1, and a 1.5|2.0 base, where the
    exact value at d = 0 is the bare interface's, far below 1)."""
    theta = 1.2  # 68.8° > asin(1.2/1.5) = 53.1°
    film = Film(np.array([0.0, 1e-6, 500.0]), 1.2, 2.0, 0.5, 1.5)
    c = np.full(3, np.cos(theta))
    fourier = np.asarray(rgb_reflectance(film, c, method="fourier", terms=2))
    spectral = np.asarray(rgb_reflectance(film, c, method="spectral"))
    np.testing.assert_allclose(fourier, 1.0, atol=1e-12)
    assert np.all(spectral[:2] < 0.9)  # frustrated TIR: thin films transmit
    # 500 nm: the evanescent field decays as e^{-4πd√(η₁²sin²θ − η₂²)/λ} ≤ e^{-5.4}
    assert np.abs(spectral[2] - 1.0).max() < 5e-3


def test_report_renders(tmp_path):
    """The markdown report builds from results (one cheap check, both dtypes)."""
    res = [stability.stability_check("opd.taylor_opd_moments", dt) for dt in DTYPES]
    text = stability.stability_markdown(res)
    assert "opd.taylor_opd_moments" in text and "float32" in text
    assert text.count("\n| opd.taylor_opd_moments |") >= 2


def test_float32_results_are_float32():
    """A float32 film gives float32 values (the checks above run on what float32 sees)."""
    f = Film(600.0, 1.3, 2.0, 0.5).astype(jnp.float32)
    assert rgb_reflectance(f, jnp.float32(0.5)).dtype == jnp.float32
