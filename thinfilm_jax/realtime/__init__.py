"""Layer 4, the real-time film models: Kneiphof et al. 2019's filtered reflectance
(`filtered`, K 20–29), this library's improved model (`improved`), the fused per-point
kernels (`kernels`) and the knobs they share (`options`). Imports the layers below."""

from .filtered import SHAT_SOURCES, filtered_bands, split_by_light
from .improved import (
    BinLight,
    ImprovedOptions,
    lookup_bins,
    lookup_lobe,
    lookup_reads,
    bin_bands,
    scan_bins,
    improved_bins,
    improved_bands,
    improved_kernel,
)
from .improved_table import BinTable, bin_table, prefilter_kernel, DEFAULT_BINS
from .kernels import ideal_kernel, filtered_kernel, lobe_moments
from .options import PRESETS, ModelOptions, check_options

__all__ = [
    "SHAT_SOURCES",
    "filtered_bands",
    "split_by_light",
    "BinLight",
    "ImprovedOptions",
    "lookup_bins",
    "lookup_lobe",
    "lookup_reads",
    "bin_bands",
    "scan_bins",
    "improved_bins",
    "improved_bands",
    "improved_kernel",
    "BinTable",
    "bin_table",
    "prefilter_kernel",
    "DEFAULT_BINS",
    "ideal_kernel",
    "filtered_kernel",
    "lobe_moments",
    "PRESETS",
    "ModelOptions",
    "check_options",
]
