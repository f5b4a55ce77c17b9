"""The observation files of ``thinfilm-jax fit`` (`cli.fit`): reading CSV, JSON and
spectrometer exports into one dict of observations and settings, with a clear error naming
the file, line and field for anything that cannot be read (UTF-16 without a byte-order mark,
non-finite numbers, ragged rows, unknown settings)."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

from ..interop.index_text import parse_index  # the one parser (fit, render)

__all__ = ["RAW_SUFFIXES", "NOTES", "read_text", "read_csv", "read_json", "read_observations",
           "read_raw", "material_of"]

SETTINGS = ("alpha", "initial", "free", "method", "refine_method", "observer", "bounds",
            "solver", "n_starts", "n_solves", "max_steps", "quadrature", "absolute_sigma",
            "theta_deg", "sigma", "kind", "layers", "envelope")
#: suffixes of spectrometer text exports (`read_spectrum`), fitted as raw spectra
RAW_SUFFIXES = (".xy", ".txt", ".dat", ".tsv")
#: envelope degree of a raw spectrum file when --envelope is not given
RAW_DEFAULT_ENVELOPE = 2
#: what `read_csv` / `read_raw` note for the run to print (not a setting)
NOTES = "_notes"
INITIAL_KEYS = ("thickness", "eta_film", "eta_base", "kappa_base", "eta_outer")
INDEX_KEYS = ("eta_film", "eta_base", "eta_outer")
INITIAL_DEFAULTS = {"thickness": 500.0, "kappa_base": 0.0, "eta_outer": 1.0}
BAND_COLUMNS = {"stiles_burch_1959_10": ("R", "G", "B"), "cie_1931_2": ("X", "Y", "Z")}


def _fail(path, msg):
    raise SystemExit(f"thinfilm-jax fit: {path}: {msg}")


def _number(path, where, text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        _fail(path, f"{where}: {text!r} is not a number")
    if not math.isfinite(v):
        _fail(path, f"{where}: value {text!r} is not finite (NaN/inf)")
    return v


def _parse_setting(text):
    text = text.strip()
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        pass
    if "," in text:
        return [t.strip() for t in text.split(",") if t.strip()]
    return text


# ----------------------------------------------------------------------------- readers
def read_text(path: Path) -> str:
    """The text of `path`: UTF-8 (optional BOM) or UTF-16 with a BOM; else a clear error."""
    try:
        data = path.read_bytes()
    except OSError as e:
        _fail(path, f"cannot read: {e.strerror or e}")
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError as e:
            _fail(path, f"invalid UTF-16 text at byte {e.start}")
    if b"\x00" in data:  # valid UTF-8 in principle, never in a text file
        _fail(path, "holds NUL bytes: looks like UTF-16 without a byte-order mark (or a "
                    "binary file); save it as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        _fail(path, f"not UTF-8 text: byte 0x{data[e.start]:02x} on line {line} cannot be "
                    f"decoded; save the file as UTF-8")


_SETTING_LINE = re.compile(r"^#+\s*([A-Za-z_][A-Za-z0-9_]*)\s*=")


def read_csv(path: Path) -> dict:
    """Observations and settings of a CSV file as the dict a JSON file would give."""
    settings, rows, header = {}, [], None
    for lineno, line in enumerate(read_text(path).splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            if header is not None and _SETTING_LINE.match(s):
                _fail(path, f"line {lineno}: setting {s!r} below the header line; settings "
                            f"('# key = value') must come before the header")
            if "=" in body and header is None:
                key, val = body.split("=", 1)
                settings[key.strip()] = _parse_setting(val)
            continue
        cells = next(csv.reader([s]))
        if header is None:
            header = [c.strip() for c in cells]
            continue
        if len(cells) != len(header):
            _fail(path, f"line {lineno}: {len(cells)} values for {len(header)} columns "
                        f"{header}")
        rows.append((lineno, dict(zip(header, (c.strip() for c in cells)))))
    if header is None:
        _fail(path, "no header line (expected columns theta_o_deg,R,G,B or wavelength_nm,R)")
    if len(set(header)) != len(header):
        _fail(path, f"duplicate column names in header {header}")
    if not rows:
        _fail(path, "no data rows")

    def column(name):
        return [_number(path, f"line {ln}, column {name!r}", r[name]) for ln, r in rows]

    obs = dict(settings)
    if "wavelength_nm" in header:
        for c in ("R",):
            if c not in header:
                _fail(path, f"missing column {c!r} (spectra need wavelength_nm,R[,theta_deg])")
        lam, refl = column("wavelength_nm"), column("R")
        sig = column("sigma") if "sigma" in header else None
        if "theta_deg" in header:
            theta = column("theta_deg")
        elif "theta_deg" not in settings:  # what most reflectometers measure
            theta = [0.0] * len(lam)
            obs[NOTES] = ["no theta_deg column or setting: normal incidence (theta_deg = 0) "
                          "assumed"]
        else:
            t = settings["theta_deg"]
            if isinstance(t, list):
                _fail(path, "setting theta_deg must be one angle when the CSV has no "
                            "theta_deg column")
            theta = [_number(path, "setting theta_deg", t)] * len(lam)
        angles = sorted(set(theta))
        grid = {}
        for i, (t, w) in enumerate(zip(theta, lam)):
            if (t, w) in grid:
                _fail(path, f"line {rows[i][0]}: duplicate (theta_deg, wavelength_nm) = "
                            f"({t}, {w})")
            grid[(t, w)] = i
        lams = sorted({w for t, w in grid if t == angles[0]})
        for t in angles:
            if sorted(w for tt, w in grid if tt == t) != lams:
                _fail(path, f"theta_deg = {t}: the wavelengths differ from those of theta_deg "
                            f"= {angles[0]}; every angle needs the same wavelength_nm values")
        obs.update(kind=settings.get("kind", "spectrum"), wavelength_nm=lams, theta_deg=angles,
                   R=[[refl[grid[(t, w)]] for w in lams] for t in angles])
        if sig is not None:
            obs["sigma"] = [[sig[grid[(t, w)]] for w in lams] for t in angles]
        return obs
    if "theta_o_deg" not in header:
        _fail(path, f"missing column 'theta_o_deg' (patch colours) or 'wavelength_nm' "
                    f"(spectra); header is {header}")
    observer = settings.get("observer", "stiles_burch_1959_10")
    bands = BAND_COLUMNS.get(observer)
    if bands is None:
        _fail(path, f"unknown observer {observer!r}; expected one of {list(BAND_COLUMNS)}")
    for c in bands:
        if c not in header:
            _fail(path, f"missing column {c!r}: observer {observer} needs columns "
                        f"theta_o_deg,{','.join(bands)}")
    cols = [column(c) for c in bands]
    obs.update(kind=settings.get("kind", "patch"), theta_o_deg=column("theta_o_deg"),
               observed=[list(v) for v in zip(*cols)])
    if "sigma" in header:
        s = column("sigma")
        obs["sigma"] = [[v] * len(bands) for v in s]
    return obs


def read_json(path: Path) -> dict:
    try:
        obs = json.loads(read_text(path))
    except json.JSONDecodeError as e:
        _fail(path, f"not valid JSON: {e}")
    if not isinstance(obs, dict):
        _fail(path, "the JSON must be an object with keys theta_o_deg/observed or "
                    "wavelength_nm/R plus settings")
    if "kind" not in obs:
        obs["kind"] = "spectrum" if "wavelength_nm" in obs else "patch"
    return obs


def read_observations(path) -> dict:
    """Read a CSV (``.csv``) or JSON (``.json``) observations file (module docstring).

    Example (patch colours at two view angles, a setting in a comment line):
        >>> import pathlib, tempfile
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     path = pathlib.Path(tmp, "obs.csv")
        ...     _ = path.write_text("# alpha = 0.25\\ntheta_o_deg,R,G,B\\n0,0.12,0.2,0.3\\n"
        ...                         "40,0.2,0.2,0.1\\n")
        ...     obs = read_observations(path)
        >>> obs["kind"], obs["alpha"], obs["theta_o_deg"], obs["observed"][1]
        ('patch', 0.25, [0.0, 40.0], [0.2, 0.2, 0.1])
    """
    path = Path(path)
    if not path.exists():
        _fail(path, "no such file")
    if not path.is_file():
        _fail(path, "not a file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return read_csv(path)
    if suffix == ".json":
        return read_json(path)
    if suffix in RAW_SUFFIXES:
        return read_raw(path)
    _fail(path, f"unknown file type {suffix!r}; expected .csv, .json or a spectrometer "
                f"export ({', '.join(RAW_SUFFIXES)})")


def read_raw(path: Path) -> dict:
    """A spectrometer's text export (`read_spectrum`, NaN rows dropped) as a raw spectrum at
    normal incidence, envelope `RAW_DEFAULT_ENVELOPE` (module docstring)."""
    from ..fit.spectrum_file import read_spectrum

    try:
        lam, val = read_spectrum(path, nonfinite="drop")
    except ValueError as e:
        _fail(path, str(e))
    return {"kind": "spectrum", "wavelength_nm": lam.tolist(), "theta_deg": [0.0],
            "R": [val.tolist()], "envelope": RAW_DEFAULT_ENVELOPE,
            NOTES: ["a spectrometer export: fitted at normal incidence (theta_deg = 0) as a raw "
                    "signal g(λ)·R(λ) + b(λ)"]}


# ----------------------------------------------------------------------------- checks
def _array(path, name, value, ndim):
    import numpy as np

    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        _fail(path, f"{name!r} must be a rectangular array of numbers, got {str(value)[:80]}")
    if a.ndim not in np.atleast_1d(ndim):
        _fail(path, f"{name!r} must be {ndim}-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        _fail(path, f"{name!r} holds a non-finite value (NaN/inf) at index {idx}")
    return a


def _in_range(path, name, a, lo, hi, unit=""):
    import numpy as np

    bad = (a < lo) | (a > hi)
    if np.any(bad):
        _fail(path, f"{name} = {float(a[bad].flat[0])!r} lies outside [{lo}, {hi}]{unit}")


def _index_setting(path, where, value):
    """A file's index value: a number, or a material name / file (checked now)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return _number(path, where, value)
    try:
        parse_index(value)
    except ValueError as e:
        _fail(path, f"{where}: {e}")
    return value


def material_of(desc: dict):
    """The `Film` or `Stack` of a checked settings description (`_settings`): numbers stay
    numbers, names and files become index models."""
    from ..core.film import Film
    from ..core.stack import Stack

    idx = {k: parse_index(desc[k]) for k in INDEX_KEYS if k in desc}
    if "layers" not in desc:
        return Film(desc["thickness"], idx["eta_film"], idx["eta_base"], desc["kappa_base"],
                    idx["eta_outer"])
    base = idx["eta_base"]
    if desc["kappa_base"]:
        if callable(base):
            raise ValueError("initial.kappa_base must be 0 when eta_base is a material (the "
                             "material carries κ)")
        base = complex(base) + 1j * desc["kappa_base"]
    layers = desc["layers"]
    return Stack([d for _, d in layers], tuple(parse_index(m) for m, _ in layers), base,
                 idx["eta_outer"])
