"""`ModelOptions`: the static knobs that travel together through every forward model.

One small, hashable record (a `NamedTuple` of Python strings and ints, never arrays), so that
it is a `jax.jit` static argument as it stands and one object carries the same choices through
`patch_radiance`, `envmap_radiance`, the kernels and the fits. The vocabulary is the
library's: each name means one thing everywhere.

| field | values | meaning |
|---|---|---|
| ``terms`` | int ≥ 0 | M, Fourier orders of the real-time methods (BB17 K 4, K 29) |
| ``shat`` | "auto" · "exact" · "lut" · "gaussian" | source of the band spectrum Ŝ_j(μ, σ²) (SPEC §5) |
| ``ndf`` | "ggx" · "beckmann" | microfacet normal distribution (the IBL methods: GGX) |
| ``quadrature`` | (n_u ≥ 1, n_φ ≥ 2) | orders of the half-vector patch quadrature |
| ``arithmetic`` | "auto" · "real" · "complex" | Fresnel arithmetic (a scene specialisation) |
| ``layer`` | "auto" · "film" · "bare" | "bare": no film (d = 0), the outer|base Fresnel only |
| ``bins`` | int ≥ 1 (3) | K, the equal-probability bins of cos θ₁ of `method="improved"` |
| ``light_spread`` | bool (False) | `improved` under a map: bins' spreads follow the light |
| ``bin_reads`` | int ≥ 1 (1) | `improved` under a map: prefiltered reads per bin |

The last three belong to `improved` (`realtime.improved.ImprovedOptions`, checked there;
``options.improved`` gives them as one record): `ModelOptions` is the combined object users
pass, each method reads the fields it owns.

``shat="auto"`` (the default) is each entry point's own default: "exact" under uniform
light (`patch_radiance`, the fits) and "lut" under a map (`envmap_radiance`: the
prefiltered map's table), so that ``ModelOptions(bins=2)`` changes K only, and an options
object equal to the default gives the default's program (`checked(shat_auto=...)`).
``arithmetic="auto"`` picks the real (dielectric) path when the concrete film allows it
(κ₃ = 0, η₂, η₃ ≥ η₁) and the complex one otherwise or under `jit`, where the caller forces
``"real"`` to specialise (see `airy.choose_arithmetic`); ``layer="auto"`` likewise picks the
bare interface when every thickness is concretely 0 (`reflectance.choose_layer`). The
specialisations change no result beyond rounding, except that a bare film gets the exact
R₁₃ Ŝ_j(0) where the Fourier methods would truncate at M terms. The observer is not a field: it is
the keyword ``observer=`` of every public function (SPEC §8).

``bins`` trades accuracy for cost in `improved`: each bin adds ≈ 100 ns a point under a map,
≈ 0.6× `filtered`'s whole point (docs/studies/performance.md, "Where `improved`'s cost lies";
the costs of K = 2 and 3 are the presets' below), with the error falling as K grows
(docs/studies/improved.md, "Choosing K"). Each K builds its own (θ_o, α) table once
(≈ 15 s on a 2-core CPU, then cached next to the compiled programs).
``light_spread=True`` also reads each bin's light-weighted spread of the incidence cosine
from the prefiltered second moments (`methods.improved.bin_radiance_parts`): ≈ 1.18× the cost of
`improved` under a map for ≈ 6 % lower mean ΔE₀₀ over the small-sources study's renders
(docs/studies/improved.md, "Choosing K"); under uniform light it changes nothing.
``bin_reads=g`` gives each of `improved`'s K bins g prefiltered reads instead of one (the
g·K kernels fitted to the lobe, `improved.bin_table(reads=g)`; `methods.improved.bin_radiance_parts`
pools them): narrower kernels that follow each bin's part of the lobe, for maps of many
small bright sources. It costs ≈ 55 ns a read a point on a 2-core CPU (g = 3: ≈ 2× the
default); its measured errors are in docs/studies/improved.md, "Choosing K". Under uniform
light it changes nothing.

Three named quality settings of `improved` (`ModelOptions.preset(name)`, the render CLI's
``--quality``): cost a shading point under a map against `filtered`'s (float32, 2¹⁸ points of
absorbing films, jitted, a 2-core CPU: figures/method_cost.md, the one table of costs;
through the public call at 2²⁰ points on a dielectric film, figures/presets_bench.json: 1.50×,
2.30×, 5.57×; docs/studies/performance.md) and the error over the 18 renders of the
small-sources study (the worst ratio of mean ΔE₀₀ to `filtered`'s, and how many renders stay
above 3 mean ΔE₀₀: figures/improved_bins.md; docs/studies/improved.md, "Choosing K"):

| preset | options | cost ÷ `filtered` | worst ΔE₀₀ ratio / renders > 3 |
|---|---|---|---|
| "fast" | ``bins=2`` | 1.69× | 0.84 / 5 |
| "default" | ``ModelOptions()`` (K = 3) | 2.56× | 0.70 / 2 |
| "accurate" | ``bin_reads=3`` (K = 3) | 5.66× | 0.56 / 0 |

Under uniform light (`patch_radiance`) only K acts: "fast" is about 1.6× less accurate
than "default" there, and "accurate" is "default" (docs/improved.md).

Example:
    >>> from thinfilm_jax import ModelOptions
    >>> ModelOptions(terms=3, shat="lut").terms
    3
    >>> ModelOptions.preset("fast").bins, ModelOptions.preset("default") == ModelOptions()
    (2, True)
"""

from __future__ import annotations

from typing import NamedTuple

from ..core import _validate as V
from .filtered import SHAT_SOURCES
from .improved import DEFAULT_BINS, ImprovedOptions
from ..brdf.microfacet import DEFAULT_QUADRATURE, NDFS
from ..spectral.reflectance import LAYERS

__all__ = ["PRESETS", "ModelOptions", "check_options"]

ARITHMETIC_CHOICES = ("auto", "real", "complex")
#: the named quality settings of `improved` (module docstring): fields that differ from
#: `ModelOptions()`
PRESETS = {"fast": dict(bins=2), "default": {}, "accurate": dict(bin_reads=3)}
SHAT_CHOICES = ("auto",) + SHAT_SOURCES


class ModelOptions(NamedTuple):
    """Static model knobs (hashable; see the module docstring for the vocabulary)."""

    terms: int = 2
    shat: str = "auto"
    ndf: str = "ggx"
    quadrature: tuple[int, int] = DEFAULT_QUADRATURE
    arithmetic: str = "auto"
    layer: str = "auto"
    bins: int = DEFAULT_BINS
    light_spread: bool = False
    bin_reads: int = 1

    @classmethod
    def preset(cls, name: str) -> ModelOptions:
        """The named quality setting of `improved` (`PRESETS`, costs and errors in the
        module docstring): "fast" (K = 2 bins), "default" (= `ModelOptions()`, K = 3) or
        "accurate" (K = 3 with three prefiltered reads a bin). ValueError for another name."""
        V.check_choice("preset", name, tuple(PRESETS))
        return cls(**PRESETS[name])

    def checked(self, shat_auto: str = "exact") -> ModelOptions:
        """The same options validated (ValueError naming the field) and normalised;
        ``shat="auto"`` becomes `shat_auto`, the caller's default Ŝ source."""
        V.check_choice("shat", self.shat, SHAT_CHOICES)
        V.check_choice("ndf", self.ndf, NDFS)
        V.check_choice("arithmetic", self.arithmetic, ARITHMETIC_CHOICES)
        V.check_choice("layer", self.layer, LAYERS)
        improved = self.improved.checked()  # the fields `improved` owns, checked there
        return self._replace(shat=shat_auto if self.shat == "auto" else self.shat,
                             terms=V.check_int("terms", self.terms, 0),
                             quadrature=V.check_quadrature(self.quadrature),
                             bins=improved.bins, bin_reads=improved.bin_reads)

    @property
    def improved(self) -> ImprovedOptions:
        """The options of `method="improved"` (`realtime.improved.ImprovedOptions`):
        ``bins``, ``bin_reads`` and ``light_spread``."""
        return ImprovedOptions(self.bins, self.bin_reads, self.light_spread)


def check_options(options, shat_auto: str = "exact") -> ModelOptions:
    """`options` as a validated `ModelOptions` (TypeError for anything else), ``shat="auto"``
    resolved to `shat_auto` (`ModelOptions.checked`)."""
    if not isinstance(options, ModelOptions):
        raise TypeError(f"options must be a thinfilm_jax.ModelOptions, got "
                        f"{type(options).__name__}")
    return options.checked(shat_auto)
