"""`read_spectrum`: a spectrometer's text export → (wavelength_nm, values) (SPEC §14).

Two layouts are read:

* **two-column text**: one ``wavelength value`` pair per line, separated by a comma, a tab,
  a semicolon or spaces (``.xy``, ``.csv``, ``.txt``); lines before the first numeric pair
  (a header: column names, units, comments) are skipped, as are blank lines and ``#``
  comments anywhere; a third or later column (a dark or reference column some programs
  add) is ignored.
* **OceanView / SpectraSuite** text exports (Ocean Optics / Ocean Insight): a header block
  (``Data from ... Node``, ``Date:``, ``Integration Time (sec):``, ...) ending with the line
  ``>>>>>Begin Spectral Data<<<<<`` (``>>>>>Begin Processed Spectral Data<<<<<`` in
  SpectraSuite), then tab-separated pairs, optionally closed by
  ``>>>>>End Spectral Data<<<<<``. Everything above the marker is header, whatever it holds.

Decimal commas (``512,3`` in a file separated by tabs or semicolons) are not guessed: a
comma is a separator.

Checks (ValueError naming the field): every wavelength and value finite (a NaN or inf
value names its line; ``nonfinite="drop"`` drops such rows instead, as spectrometers
write NaN for masked pixels), wavelengths positive and strictly increasing, and at least
`MIN_POINTS` points.

Example:
    >>> import pathlib, tempfile
    >>> text = "Integration Time (sec): 0.1\\n>>>>>Begin Spectral Data<<<<<\\n500.1\\t12.5\\n" \\
    ...        "500.5\\t13.0\\n501.0\\t12.8\\n501.4\\t12.9\\n501.9\\t13.3\\n502.3\\t13.1\\n"
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     p = pathlib.Path(tmp, "s.txt"); _ = p.write_text(text)
    ...     lam, val = read_spectrum(p)
    >>> lam[:2].tolist(), val[:2].tolist()
    ([500.1, 500.5], [12.5, 13.0])
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

__all__ = ["MIN_POINTS", "read_spectrum"]

#: fewest points a spectrum may have
MIN_POINTS = 6
_BEGIN = re.compile(r"^>+\s*begin\b.*spectral data\s*<+\s*$", re.IGNORECASE)
_END = re.compile(r"^>+\s*end\b.*<+\s*$", re.IGNORECASE)
_SPLIT = re.compile(r"[,;\t ]+")


def _pair(line):
    """(λ, value) of a data line, or None when its first two fields are not numbers."""
    cells = [c for c in _SPLIT.split(line.strip()) if c]
    if len(cells) < 2:
        return None
    try:
        return float(cells[0]), float(cells[1])
    except ValueError:
        return None


def read_spectrum(path, *, nonfinite: str = "raise") -> tuple[np.ndarray, np.ndarray]:
    """Read a spectrum exported as text (module docstring).

    Args:
        path: the file (UTF-8, optional byte-order mark; Latin-1 is tried when it is not
            UTF-8, as some spectrometer software writes µ and ° that way).
        nonfinite: "raise" (default): a NaN / inf wavelength or value is a ValueError
            naming its line; "drop": such rows are left out.

    Returns:
        (wavelength_nm (n,), values (n,)) float64 arrays.
    """
    if nonfinite not in ("raise", "drop"):
        raise ValueError(f"nonfinite must be 'raise' or 'drop', got {nonfinite!r}")
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ValueError(f"path: cannot read {path}: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    lines = text.splitlines()
    start = next((i + 1 for i, s in enumerate(lines) if _BEGIN.match(s.strip())), 0)
    rows, linenos = [], []
    for i in range(start, len(lines)):
        s = lines[i].strip()
        if not s or s.startswith("#"):
            continue
        if _END.match(s):
            break
        pair = _pair(s)
        if pair is None:
            if rows:
                raise ValueError(f"values: line {i + 1} of {path.name} is not a "
                                 f"'wavelength value' pair: {s[:60]!r}")
            continue  # still in the header
        rows.append(pair)
        linenos.append(i + 1)
    if not rows:
        raise ValueError(f"path: {path.name} holds no 'wavelength value' pairs")
    a = np.asarray(rows, float)
    lam, val = a[:, 0], a[:, 1]
    bad = ~(np.isfinite(lam) & np.isfinite(val))
    if np.any(bad):
        if nonfinite == "raise":
            i = int(np.argmax(bad))
            field = "wavelength" if not np.isfinite(lam[i]) else "values"
            raise ValueError(f"{field}: non-finite entry (NaN/inf) on line {linenos[i]} of "
                             f"{path.name}; pass nonfinite='drop' to leave such rows out")
        lam, val = lam[~bad], val[~bad]
    if lam.size < MIN_POINTS:
        raise ValueError(f"values: {path.name} holds {lam.size} points; a spectrum needs at "
                         f"least {MIN_POINTS}")
    if np.any(lam <= 0):
        raise ValueError(f"wavelength: {lam[lam <= 0][0]!r} nm in {path.name} is not positive")
    steps = np.diff(lam)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise ValueError(f"wavelength: not strictly increasing in {path.name}: {lam[i]!r} then "
                         f"{lam[i + 1]!r} nm")
    return lam, val
