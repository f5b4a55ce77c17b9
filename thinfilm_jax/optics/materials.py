"""Bundled materials and index files: `refractive_index(source)` → an index model (SPEC §12).

`source` is

* a number, real or complex (n + iκ, κ ≥ 0): `ConstantIndex`;
* an index model: returned as is;
* a bundled material name (`MATERIALS`, case-insensitive): "SiO2", "Si", "Si3N4", "TiO2",
  "Al2O3", "MgF2", "water", "Al", "Ag", "Au", "Cu", "Cr", and the 2D materials "graphene"
  and "MoS2" (one layer's index; `MONOLAYER_NM` gives one layer's thickness);
* a path to a refractiveindex.info YAML file (``.yml``/``.yaml``: `DATA` entries of type
  ``tabulated nk``, ``tabulated n``, ``tabulated k`` and ``formula 1``–``formula 9``,
  wavelengths in µm, ``wavelength_range`` (or the older ``range``) in µm); n and κ from two
  entries (a formula and ``tabulated k``) make a `CompositeIndex`;
* a path to a CSV file (``.csv``) whose header names its columns: ``wavelength_nm`` or
  ``wavelength_um``, ``n``, optionally ``k``; lines starting with ``#`` are comments.

A malformed file, an unknown name (the message lists the bundled ones), κ < 0 or wavelengths
that do not increase strictly is a `ValueError` naming the problem and the file.

`MATERIALS` is the one place a bundled material is added: its name, its citation, its
wavelength range (nm) and its source, either a table in ``thinfilm_jax/data/materials/``
(provenance and licences in that folder's README.md) or a published dispersion formula
(refractiveindex.info numbering, `FormulaIndex`). Every bundled material covers at least
360–830 nm, the range of the colour bands (SPEC §1).
"""

from __future__ import annotations

import csv
import functools
import importlib.resources
import numbers
import os
import re
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from .index import (
    CompositeIndex,
    ConstantIndex,
    FormulaIndex,
    IndexModel,
    TabulatedIndex,
    check_table,
)


class BundledMaterial(NamedTuple):
    """A bundled material: `source` is a file in ``thinfilm_jax/data/materials/`` (a CSV
    with columns ``wavelength_nm,n,k``) or ``"formula N"`` with `coefficients` (λ in µm)."""

    citation: str
    wavelength_range: tuple[float, float]  # nm
    source: str
    coefficients: tuple[float, ...] | None = None
    note: str = ""


_RAKIC = ("A. D. Rakić, A. B. Djurišić, J. M. Elazar and M. L. Majewski, \"Optical properties "
          "of metallic films for vertical-cavity optoelectronic devices\", Appl. Opt. 37, "
          "5271–5283 (1998)")
_RAKIC_NOTE = "Lorentz–Drude model fitted to measurements of evaporated films"

#: name → `BundledMaterial`: the bundled materials (add one here, with its table or formula).
MATERIALS: dict[str, BundledMaterial] = {
    "SiO2": BundledMaterial(
        "I. H. Malitson, \"Interspecimen comparison of the refractive index of fused silica\", "
        "J. Opt. Soc. Am. 55, 1205–1209 (1965)",
        (210.0, 6700.0), "formula 1",
        (0.0, 0.6961663, 0.0684043, 0.4079426, 0.1162414, 0.8974794, 9.896161),
        "fused silica at 20 °C; κ = 0"),
    "Si": BundledMaterial(
        "C. Schinke et al., \"Uncertainty analysis for the coefficient of band-to-band "
        "absorption of crystalline silicon\", AIP Advances 5, 067168 (2015)",
        (250.0, 1450.0), "Si-Schinke-2015.csv", None, "crystalline silicon, 300 K"),
    "Si3N4": BundledMaterial(
        "H. R. Philipp, \"Optical properties of silicon nitride\", J. Electrochem. Soc. 120, "
        "295–300 (1973)",
        (207.0, 1240.0), "formula 1", (0.0, 2.8939, 0.13967),
        "amorphous (CVD) silicon nitride, a one-term Sellmeier fit to Philipp's data; κ = 0"),
    "TiO2": BundledMaterial(
        "T. Siefke et al., \"Materials pushing the application limits of wire grid polarizers "
        "further into the deep ultraviolet spectral range\", Adv. Opt. Mater. 4, 1780–1786 "
        "(2016)",
        (200.602492, 1994.510485), "TiO2-Siefke-2016.csv", None,
        "atomic-layer-deposited amorphous TiO2 thin film"),
    "Al2O3": BundledMaterial(
        "I. H. Malitson and M. J. Dodge, \"Refractive index and birefringence of synthetic "
        "sapphire\", J. Opt. Soc. Am. 62, 1405 (1972)",
        (200.0, 5000.0), "formula 1",
        (0.0, 1.4313493, 0.0726631, 0.65054713, 0.1193242, 5.3414021, 18.028251),
        "crystalline sapphire, ordinary ray, 20 °C; κ = 0 (amorphous alumina films are "
        "lower, n ≈ 1.6–1.65)"),
    "MgF2": BundledMaterial(
        "M. J. Dodge, \"Refractive properties of magnesium fluoride\", Appl. Opt. 23, "
        "1980–1985 (1984)",
        (200.0, 7000.0), "formula 1",
        (0.0, 0.48755108, 0.04338408, 0.39875031, 0.09461442, 2.3120353, 23.793604),
        "crystalline MgF2, ordinary ray, 19 °C; κ = 0"),
    "water": BundledMaterial(
        "M. Daimon and A. Masumura, \"Measurement of the refractive index of distilled water "
        "from the near-infrared region to the ultraviolet region\", Appl. Opt. 46, "
        "3811–3820 (2007)",
        (182.0, 1129.0), "formula 2",
        (0.0, 5.684027565e-1, 5.101829712e-3, 1.726177391e-1, 1.821153936e-2,
         2.086189578e-2, 2.620722293e-2, 1.130748688e-1, 1.069792721e1),
        "distilled water at 20.0 °C; κ = 0"),
    "Al": BundledMaterial(_RAKIC, (201.53, 1993.0), "Al-Rakic-1998.csv", None, _RAKIC_NOTE),
    "Ag": BundledMaterial(_RAKIC, (247.97, 1992.4), "Ag-Rakic-1998.csv", None, _RAKIC_NOTE),
    "Au": BundledMaterial(_RAKIC, (247.97, 1998.0), "Au-Rakic-1998.csv", None, _RAKIC_NOTE),
    "Cu": BundledMaterial(_RAKIC, (206.64, 1986.6), "Cu-Rakic-1998.csv", None, _RAKIC_NOTE),
    "Cr": BundledMaterial(_RAKIC, (247.97, 1992.2), "Cr-Rakic-1998.csv", None, _RAKIC_NOTE),
    # 2D materials (SPEC §14): one layer's index, for a film of N × the monolayer thickness
    # (`MONOLAYER_NM`) on thermal oxide
    "graphene": BundledMaterial(
        "J. W. Weber, V. E. Calado and M. C. M. van de Sanden, \"Optical constants of "
        "graphene measured by spectroscopic ellipsometry\", Appl. Phys. Lett. 97, 091904 "
        "(2010)",
        (210.873, 999.007), "graphene-Weber-2010.csv", None,
        "mechanically exfoliated monolayer on 98 nm SiO2 on Si, in-plane index, fitted as a "
        "0.34 nm layer"),
    "MoS2": BundledMaterial(
        "G. A. Ermolaev et al., \"Broadband optical properties of monolayer and bulk MoS2\", "
        "npj 2D Mater. Appl. 4, 21 (2020)",
        (290.0, 2000.0), "MoS2-Ermolaev-2020.csv", None,
        "CVD monolayer on SiO2/Si, in-plane index (Tauc–Lorentz oscillators fitted to "
        "spectroscopic ellipsometry)"),
}

#: name → the thickness (nm) of one layer of a bundled 2D material: graphene 0.335 nm (the
#: interlayer spacing of graphite; Weber et al. 2010 and Blake et al., Appl. Phys. Lett. 91,
#: 063124 (2007) took 0.34 nm), MoS2 0.65 nm (the value commonly taken for a monolayer; the
#: layer pitch of bulk 2H-MoS2 is c/2 = 0.615 nm). N layers are one film of N × this.
MONOLAYER_NM: dict[str, float] = {"graphene": 0.335, "MoS2": 0.65}


def _data_file(name: str):
    return importlib.resources.files("thinfilm_jax") / "data" / "materials" / name


def _lookup(name: str) -> str | None:
    folded = {k.casefold(): k for k in MATERIALS}
    return folded.get(name.casefold())


@functools.lru_cache(maxsize=None)
def _bundled(name: str) -> IndexModel:
    """The bundled material `name`, built once per process. Built concretely
    (`jax.ensure_compile_time_eval`) also when first asked for inside a trace: under `jit` its
    tables' conversions would be staged into that trace and the cache would keep its tracers
    (UnexpectedTracerError in the next transform)."""
    mat = MATERIALS[name]
    with jax.ensure_compile_time_eval():
        if mat.source.startswith("formula "):
            return FormulaIndex(int(mat.source.split()[1]), np.asarray(mat.coefficients),
                                mat.wavelength_range, name=name, citation=mat.citation)
        with importlib.resources.as_file(_data_file(mat.source)) as path:
            return read_csv(path, name=name, citation=mat.citation)


def refractive_index(source) -> IndexModel:
    """An index model from `source`: a number (real or complex), an index model, a bundled
    material name (`MATERIALS`) or a path to a refractiveindex.info YAML or a CSV file (see
    the module docstring).

    >>> import thinfilm_jax.optics.materials as mt
    >>> round(float(mt.refractive_index("SiO2")(587.56).real), 4)
    1.4585
    >>> complex(mt.refractive_index(1.5 + 0.1j)(550.0))
    (1.5+0.1j)
    """
    if isinstance(source, IndexModel):
        return source
    if isinstance(source, (numbers.Number, np.ndarray, np.generic, jax.Array)) \
            and not isinstance(source, bool):
        return ConstantIndex(source)
    if isinstance(source, (str, os.PathLike)):
        if isinstance(source, str):
            key = _lookup(source)
            if key is not None:
                return _bundled(key)
        path = Path(source)
        suffix = path.suffix.lower()
        if path.is_file() and suffix in (".yml", ".yaml"):
            return read_yaml(path)
        if path.is_file() and suffix == ".csv":
            return read_csv(path)
        if path.is_file():
            raise ValueError(f"refractive_index: {str(path)!r} is neither a .yml/.yaml "
                             f"(refractiveindex.info) nor a .csv file")
        raise ValueError(f"refractive_index: unknown material {str(source)!r}: not a bundled "
                         f"material ({', '.join(MATERIALS)}) and not an existing .yml, .yaml "
                         f"or .csv file")
    raise TypeError(f"refractive_index: source must be a number, an index model, a material "
                    f"name or a file path; got {type(source).__name__}")


# --------------------------------------------------------------------------- CSV


_WAVELENGTH_HEADER = re.compile(r"^wavelength\s*(?:[,_(\[]\s*(nm|um|µm|μm|microns?)\s*[)\]]?)?$")


def _column_name(cell: str, where: str, wavelength_unit: str | None) -> str:
    """A header cell as a column name: ``wavelength_nm`` / ``wavelength_um`` (also written
    ``"Wavelength, µm"``, ``wavelength (nm)``: the refellips / WVASE tables), ``n``, ``k``."""
    c = cell.strip().strip('"').strip().lower()
    if c in ("wavelength_nm", "wavelength_um", "n", "k"):
        return c
    m = _WAVELENGTH_HEADER.match(c)
    if not m:
        return c
    unit = m.group(1) or wavelength_unit
    if unit is None:
        raise ValueError(f"{where}: the header names the column {cell.strip()!r} without its "
                         f"unit; write wavelength_nm or wavelength_um, or pass "
                         f"wavelength_unit='nm' or 'um'")
    return "wavelength_nm" if unit == "nm" else "wavelength_um"


def read_csv(path, *, name: str = "", citation: str = "", interpolation: str = "nk",
             wavelength_unit: str | None = None) -> TabulatedIndex:
    """A `TabulatedIndex` from a CSV file with a header naming its columns:
    ``wavelength_nm`` or ``wavelength_um`` (also ``"Wavelength, µm"`` and the like, as
    refellips and WVASE tables write it; a bare ``Wavelength`` takes `wavelength_unit`),
    ``n`` and optionally ``k`` (any order). UTF-8 with or without a byte-order mark; cells
    may be quoted; a ``k`` column that no row fills is κ = 0. Blank lines and lines starting
    with ``#`` are skipped. `interpolation`:
    "nk" or "epsilon" (`TabulatedIndex`). Errors name the file and the line."""
    path = Path(path)
    where = str(path)
    if wavelength_unit not in (None, "nm", "um"):
        raise ValueError(f"read_csv: wavelength_unit must be 'nm', 'um' or None; got "
                         f"{wavelength_unit!r}")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{where}: cannot read the file ({e})") from None
    header, rows = None, []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in next(csv.reader([s]))]
        if header is None:
            header = [_column_name(c, where, wavelength_unit) for c in cells]
            continue
        try:
            rows.append((lineno, [float(c) for c in cells]))
        except ValueError:
            raise ValueError(f"{where}, line {lineno}: not a number in {s!r}") from None
    if header is None:
        raise ValueError(f"{where}: no header line (expected columns wavelength_nm or "
                         f"wavelength_um, n, optional k)")
    if rows and header[-1] == "k" and all(len(r) == len(header) - 1 for _, r in rows):
        header = header[:-1]  # a k column named but never filled (refellips' air.csv): κ = 0
    for lineno, r in rows:
        if len(r) != len(header):
            raise ValueError(f"{where}, line {lineno}: {len(r)} values for the "
                             f"{len(header)} columns {header}")
    rows = [r for _, r in rows]
    allowed = {"wavelength_nm", "wavelength_um", "n", "k"}
    unknown = [c for c in header if c not in allowed]
    if unknown or len(set(header)) != len(header):
        raise ValueError(f"{where}: header {header}: columns must be wavelength_nm or "
                         f"wavelength_um, n and optionally k, each once")
    wl_cols = [c for c in ("wavelength_nm", "wavelength_um") if c in header]
    if len(wl_cols) != 1 or "n" not in header:
        raise ValueError(f"{where}: header {header} must name one of wavelength_nm / "
                         f"wavelength_um, and n")
    data = np.asarray(rows, float).reshape(len(rows), len(header))
    col = {c: data[:, i] for i, c in enumerate(header)}
    wl = col[wl_cols[0]] * (1000.0 if wl_cols[0] == "wavelength_um" else 1.0)
    wl, n, k = check_table(wl, col["n"], col.get("k"), where=where)
    return TabulatedIndex(wl, n, k, name=name or path.stem, citation=citation,
                          interpolation=interpolation)


# --------------------------------------------------------------------------- YAML


def _floats(text, where: str, what: str) -> np.ndarray:
    if isinstance(text, (int, float)):
        return np.asarray([float(text)])
    if isinstance(text, (list, tuple)):
        items = text
    elif isinstance(text, str):
        items = text.split()
    else:
        raise ValueError(f"{where}: {what} must be numbers separated by spaces; got "
                         f"{type(text).__name__}")
    try:
        return np.asarray([float(v) for v in items])
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {what} holds a value that is not a number") from None


def _table(entry, ncols: int, where: str) -> np.ndarray:
    data = entry.get("data")
    if not isinstance(data, str):
        raise ValueError(f"{where}: a '{entry['type']}' entry needs a 'data' block of rows")
    rows = []
    for i, line in enumerate(data.strip().splitlines(), 1):
        if not line.strip():
            continue
        v = _floats(line, where, f"row {i} of '{entry['type']}'")
        if len(v) != ncols:
            raise ValueError(f"{where}: row {i} of '{entry['type']}' has {len(v)} values; "
                             f"expected {ncols} (wavelength in µm, "
                             f"{'n, k' if ncols == 3 else entry['type'].split()[1]})")
        rows.append(v)
    if not rows:
        raise ValueError(f"{where}: the '{entry['type']}' entry has no rows")
    return np.asarray(rows)


def _strip_html(s: str) -> str:
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", s)).strip()


def read_yaml(path) -> IndexModel:
    """An index model from a refractiveindex.info YAML file (``yaml.safe_load``).

    Entries of ``DATA``: ``tabulated nk`` (rows λ n k), ``tabulated n`` (λ n), ``tabulated k``
    (λ k), ``formula 1``–``formula 9`` (``coefficients``, ``wavelength_range`` or ``range``),
    all λ in µm. One entry gives n (and κ if ``tabulated nk``); an n entry and a
    ``tabulated k`` entry give a `CompositeIndex`. The citation is the file's
    ``REFERENCES``."""
    import yaml

    path = Path(path)
    where = str(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{where}: cannot read the file ({e})") from None
    except yaml.YAMLError as e:
        raise ValueError(f"{where}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("DATA"), list) or not doc["DATA"]:
        raise ValueError(f"{where}: a refractiveindex.info file needs a non-empty 'DATA' list")
    citation = _strip_html(str(doc.get("REFERENCES", "")))
    name = path.stem
    n_models, k_models = [], []
    for entry in doc["DATA"]:
        if not isinstance(entry, dict) or not isinstance(entry.get("type"), str):
            raise ValueError(f"{where}: each DATA entry needs a 'type'")
        kind = " ".join(entry["type"].split())
        if kind == "tabulated nk":
            t = _table(entry, 3, where)
            wl, n, k = check_table(t[:, 0] * 1000.0, t[:, 1], t[:, 2], where=where)
            model = TabulatedIndex(wl, n, k, name=name, citation=citation)
            n_models.append(model)
            k_models.append(model)
        elif kind == "tabulated n":
            t = _table(entry, 2, where)
            wl, n, _ = check_table(t[:, 0] * 1000.0, t[:, 1], where=where)
            n_models.append(TabulatedIndex(wl, n, name=name, citation=citation))
        elif kind == "tabulated k":
            t = _table(entry, 2, where)
            wl, _, k = check_table(t[:, 0] * 1000.0, np.zeros(len(t)), t[:, 1], where=where)
            k_models.append(TabulatedIndex(wl, np.zeros_like(k), k, name=name,
                                           citation=citation))
        elif re.fullmatch(r"formula [1-9]", kind):
            if "coefficients" not in entry:
                raise ValueError(f"{where}: the '{kind}' entry has no 'coefficients'")
            coef = _floats(entry["coefficients"], where, f"the coefficients of '{kind}'")
            rng = entry.get("wavelength_range", entry.get("range"))
            if rng is None:
                raise ValueError(f"{where}: the '{kind}' entry has no 'wavelength_range'")
            r = _floats(rng, where, "wavelength_range")
            if len(r) != 2 or not (0 < r[0] < r[1]) or not np.all(np.isfinite(r)):
                raise ValueError(f"{where}: wavelength_range must be two increasing positive "
                                 f"wavelengths in µm; got {rng!r}")
            try:
                model = FormulaIndex(int(kind.split()[1]), coef, tuple(r * 1000.0), name=name,
                                     citation=citation)
            except ValueError as e:
                raise ValueError(f"{where}: {e}") from None
            n_models.append(model)
        else:
            raise ValueError(f"{where}: unsupported DATA type {entry['type']!r} (supported: "
                             f"tabulated nk, tabulated n, tabulated k, formula 1-9)")
    if len(n_models) != 1 or len(k_models) > 1:
        raise ValueError(f"{where}: expected one source of n and at most one of k in DATA; "
                         f"got {len(n_models)} for n and {len(k_models)} for k")
    n_model = n_models[0]
    if not k_models or k_models[0] is n_model:
        return n_model
    return CompositeIndex(n_model, k_models[0], name=name, citation=citation)


__all__ = [
    "MATERIALS", "MONOLAYER_NM", "BundledMaterial", "read_csv", "read_yaml", "refractive_index",
]
