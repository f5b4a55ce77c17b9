"""Reading ellipsometric data files: `read_ellipsometry` (SPEC §14).

Two layouts, told apart by their rows:

* **WVASE / CompleteEASE exports** (``.dat``): header lines (a comment, a line such as
  ``VASEmethod[...]``, and the wavelength unit alone on a line: ``nm``, ``eV``, ``µm`` /
  ``um``, ``A`` / ``Å``, ``1/cm``), then one row per point ``E  λ  angle  ψ  Δ  σψ  σΔ``
  (WVASE's ``E`` rows). Rows of other kinds (``dPolE``, ``uR``, ``T``, ``R``, …:
  depolarisation, intensities) are skipped. CompleteEASE writes the same six numbers
  without the ``E``; a file with no ``E`` row is read from such rows of numbers.
* **Tab- or space-separated text** ``λ  angle  ψ  Δ`` (the refellips / WVASE text exports,
  e.g. ``nm AOI Psi Delta``): header lines, then rows of 4 (or 6, with σψ σΔ) numbers.

The wavelength unit is named by the header (`_header_unit`: a line holding only the unit,
a line starting with it, or a ``(unit)`` token; default nm when the header names none);
wavelengths are returned in nm (`core.units.to_nanometres`: eV → hc/E with
hc = 1239.84198 eV nm). Angles, ψ and Δ are in degrees, as the files write them; Δ is
returned as written (WVASE's are folded into [0°, 180°], other programs' may run to 360°:
`fit_ellipsometry` folds both model and data). **σψ, σΔ are NaN where the file has none**
(the text layout): six arrays of one shape either way, `EllipsometryData.has_sigma` tells.

Bad input is a `ValueError` naming the file, the line and the field: no data rows, a row of
5 numbers or with a word among its numbers, NaN or inf, ψ outside [0°, 90°], an angle
outside [0°, 90°), a wavelength ≤ 0, a negative σ.

Text is UTF-8 (a byte-order mark is allowed), UTF-16 with a byte-order mark, or else
Latin-1 (WVASE writes "µm" as the Windows byte 0xB5).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .units import to_nanometres, unit_name

__all__ = ["EllipsometryData", "read_ellipsometry"]

_FIELDS = ("wavelength", "angle", "psi", "delta", "sigma_psi", "sigma_delta")


class EllipsometryData(NamedTuple):
    """ψ, Δ data: wavelength (nm), angle of incidence (°), ψ (°), Δ (°), σψ (°), σΔ (°), each a
    1-D float64 array, one entry per measured point, in file order (σ NaN when the file has
    none)."""

    wavelength: np.ndarray
    angle: np.ndarray
    psi: np.ndarray
    delta: np.ndarray
    sigma_psi: np.ndarray
    sigma_delta: np.ndarray

    @property
    def has_sigma(self) -> bool:
        """True when the file gave σψ and σΔ for every point."""
        return bool(np.all(np.isfinite(self.sigma_psi)) and np.all(np.isfinite(self.sigma_delta)))


def _text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ValueError(f"{path}: cannot read the file ({e.strerror or e})") from None
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _numbers(tokens, where):
    """floats of `tokens`, or None when one is not a number; ValueError for NaN/inf."""
    try:
        vals = [float(t) for t in tokens]
    except ValueError:
        return None
    for name, v in zip(_FIELDS, vals):
        if not math.isfinite(v):
            raise ValueError(f"{where}: {name} is {v} (values must be finite)")
    return vals


def _row(vals, where):
    """The six fields of one data row of 4 or ≥ 6 numbers (σ NaN for 4)."""
    if len(vals) == 4:
        return vals + [math.nan, math.nan]
    if len(vals) >= 6:
        return vals[:6]
    raise ValueError(f"{where}: {len(vals)} numbers; expected 4 (λ, angle, ψ, Δ) or 6 "
                     f"(with σψ, σΔ)")


def _header_unit(tokens):
    """The wavelength unit a header line names: the line's only token (WVASE's unit line),
    or its first token unless that is "A" (``nm AOI Psi Delta``; a comment such as "A film"
    names none), or a ``(unit)`` / ``[unit]`` token (``Wavelength (eV)``)."""
    if len(tokens) == 1:
        return unit_name(tokens[0])
    first = unit_name(tokens[0])
    if first and first != "A":
        return first
    return next((unit_name(t) for t in tokens[1:] if t[:1] in "([" and unit_name(t)), None)


def read_ellipsometry(path) -> EllipsometryData:
    """Read ψ, Δ data from a WVASE / CompleteEASE ``.dat`` export or a tab-separated text
    file (module docstring) → `EllipsometryData` (wavelength in nm; angles, ψ, Δ, σ in °).

    Example (a two-point WVASE export in eV):
        >>> import pathlib, tempfile
        >>> text = "sample\\neV\\nE 2.0 70 12.5 100.0 0.01 0.05\\nE 3.0 70 20.0 120.0 0.01 0.05\\n"
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     p = pathlib.Path(tmp, "s.dat"); _ = p.write_text(text)
        ...     d = read_ellipsometry(p)
        >>> d.wavelength.round(3).tolist(), d.psi.tolist(), d.has_sigma
        ([619.921, 413.281], [12.5, 20.0], True)
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    unit, e_rows, plain_rows, started = None, [], [], False
    for lineno, line in enumerate(_text(path).splitlines(), 1):
        tokens = line.replace(",", " ").split()
        if not tokens:
            continue
        where = f"{path}, line {lineno}"
        if tokens[0] == "E":
            vals = _numbers(tokens[1:], where)
            if vals is None:
                raise ValueError(f"{where}: an 'E' row must hold numbers (λ, angle, ψ, Δ, σψ, "
                                 f"σΔ); got {line.strip()!r}")
            e_rows.append((where, _row(vals, where)))
            started = True
            continue
        vals = _numbers(tokens, where)
        if vals is not None and len(vals) >= 4:
            plain_rows.append((where, _row(vals, where)))
            started = True
            continue
        if vals is not None and started:
            raise ValueError(f"{where}: {len(vals)} numbers; expected 4 (λ, angle, ψ, Δ) or 6")
        if not started and unit is None:
            unit = _header_unit(tokens)
    rows = e_rows or plain_rows
    if not rows:
        raise ValueError(f"{path}: no ψ, Δ data rows (WVASE 'E' rows 'E λ angle ψ Δ σψ σΔ', "
                         f"or rows of 4 or 6 numbers 'λ angle ψ Δ [σψ σΔ]')")
    for where, (lam, angle, psi, _, s_psi, s_delta) in rows:
        if lam <= 0:
            raise ValueError(f"{where}: wavelength {lam} must be > 0")
        if not 0.0 <= angle < 90.0:
            raise ValueError(f"{where}: angle {angle}° lies outside [0°, 90°)")
        if not 0.0 <= psi <= 90.0:
            raise ValueError(f"{where}: psi {psi}° lies outside [0°, 90°]")
        if s_psi < 0 or s_delta < 0:
            raise ValueError(f"{where}: sigma_psi, sigma_delta must be ≥ 0; got {s_psi}, "
                             f"{s_delta}")
    a = np.asarray([r for _, r in rows], float)
    return EllipsometryData(to_nanometres(a[:, 0], unit or "nm"), *(a[:, i].copy()
                                                                     for i in range(1, 6)))
