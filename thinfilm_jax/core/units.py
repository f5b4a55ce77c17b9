"""Spectral units: photon energy ↔ vacuum wavelength, and the wavelength units that data
files name (SPEC §14).

$E\\,[\\mathrm{eV}] = hc / \\lambda$ with $hc$ = 1239.84198 eV nm (CODATA 2018: h and c
exact, e exact, so hc/e = 1239.841984… eV nm). J.A. Woollam's WVASE and CompleteEASE
convert with hc = 1240 exactly (their oscillator tables reproduce to 3e-7 with 1240 and to
1.6e-3 with 1239.84: `optics.oscillators`); a round trip through one constant is exact
whichever it is.

Example:
    >>> [round(float(to_nanometres(v, u)), 4) for v, u in ((2.0, "eV"), (0.5, "µm"), (5000, "A"))]
    [619.921, 500.0, 500.0]
"""

from __future__ import annotations

import numpy as np

__all__ = ["HC_EV_NM", "unit_name", "to_nanometres"]

#: hc in eV nm (CODATA 2018)
HC_EV_NM = 1239.84198

#: the spelling of each wavelength unit in data files → its canonical name
UNIT_NAMES = {
    "nm": "nm", "nanometers": "nm", "nanometres": "nm",
    "ev": "eV",
    "µm": "um", "μm": "um", "um": "um", "micron": "um", "microns": "um",
    "a": "A", "å": "A", "angstrom": "A", "angstroms": "A",
    "cm-1": "cm-1", "1/cm": "cm-1",
}


def unit_name(token: str) -> str | None:
    """The canonical unit ("nm", "eV", "um", "A", "cm-1") a file's token names, else None
    (case-insensitive; ``(nm)`` and ``[nm]`` count)."""
    t = token.strip().strip("()[]").strip().lower()
    return UNIT_NAMES.get(t)


def to_nanometres(values, unit: str):
    """Vacuum wavelengths in nm from `values` in `unit` (a `unit_name` spelling): nm as is,
    eV → hc/E, µm × 1000, Å / 10, cm⁻¹ → 10⁷ / ν̃ (NumPy, float64)."""
    u = unit_name(unit) or unit
    v = np.asarray(values, float)
    if u == "nm":
        return v
    if u == "eV":
        return HC_EV_NM / v
    if u == "um":
        return v * 1000.0
    if u == "A":
        return v / 10.0
    if u == "cm-1":
        return 1.0e7 / v
    raise ValueError(f"unknown wavelength unit {unit!r}; expected one of "
                     f"{sorted(set(UNIT_NAMES.values()))}")
