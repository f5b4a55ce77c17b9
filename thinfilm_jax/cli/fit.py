"""``thinfilm-jax fit OBSERVATIONS [--out PATH] [--overwrite]``: fit a film to observations.

Everything the fit needs is read from the observations file (CSV or JSON); the result is
written atomically as JSON, by default next to the input as ``<stem>.fit.json``, and an
existing result is never replaced unless ``--overwrite`` is given.

Two kinds of observations (chosen by the columns / keys present):

**Patch colours** (`thinfilm_jax.fit.film_fit.fit_film`): band radiances of a patch under uniform
light at several view angles, as `patch_radiance` returns them.

* CSV: columns ``theta_o_deg,R,G,B`` (``X,Y,Z`` with ``observer = cie_1931_2``), one row
  per view angle; optional column ``sigma`` (standard deviation of that row's bands).
* JSON: ``{"theta_o_deg": [...], "observed": [[R, G, B], ...], ...settings}``; optional
  ``"sigma"`` (scalar or same shape as ``observed``).
* required setting: ``alpha`` (GGX α; the initial guess if ``"alpha"`` is free).

**Reflectance spectra** (`thinfilm_jax.fit.film_fit.fit_spectrum`): unpolarised R(λ) at one or more
angles of incidence.

* CSV: columns ``wavelength_nm,R`` and, for several angles, ``theta_deg`` (long format:
  one row per (angle, wavelength); every angle must have the same wavelengths); a single
  angle may instead be given as the setting ``theta_deg = 0``; with neither, normal
  incidence (0°, what most reflectometers measure) is assumed and said so.
* JSON: ``{"wavelength_nm": [...], "theta_deg": [...], "R": [[...], ...]}`` (R has one
  row per angle); optional ``"sigma"``.

**Raw spectrometer spectra** (SPEC §14; ``fit_spectrum(..., envelope=k)``): a text export of
a spectrometer, ``.xy``, ``.txt``, ``.dat`` or ``.tsv`` (two columns, or an OceanView /
SpectraSuite export: `thinfilm_jax.fit.spectrum_file.read_spectrum`; rows with NaN are
dropped), fitted at normal incidence as g(λ)·R(λ) + b(λ) with ``--envelope K`` (default 2
for these files; also the setting ``envelope`` of a CSV / JSON spectrum). The material
comes from the command line (``--eta-film 1.33 --eta-base 1`` for a soap film in air),
``--wavelength-range LO HI`` keeps part of the band, ``--thickness-range LO HI`` sets the
thickness box (default 0–2000 nm) and ``--background FILE`` subtracts a known offset (a dark
or no-film spectrum on the same wavelengths; then only g is fitted).

**Settings** (JSON keys, or CSV comment lines ``# key = value`` above the header, the
value JSON or a bare word / comma list; a ``# key = value`` line below the header is an
error, not silently ignored). Files are UTF-8 (a byte-order mark is allowed; UTF-16 with a
byte-order mark is read too).

* ``initial``: ``{"thickness": nm, "eta_film": ..., "eta_base": ..., "kappa_base": 0,
  "eta_outer": 1}``; ``eta_film`` and ``eta_base`` are required (fixed values or initial
  guesses), thickness defaults to 500 nm, κ₃ to 0, η₁ to 1. Each index (``eta_film``,
  ``eta_base``, ``eta_outer``) is a number (it stays a number) or a material (SPEC §12,
  `thinfilm_jax.optics.materials.refractive_index`): a bundled name (``"SiO2"``, ``"Si"``,
  ``"Si3N4"``, ...) or the path of a refractiveindex.info YAML or a CSV file; an unknown
  name is an error that lists the bundled ones.
* ``layers``: a layer stack instead of one film (`Stack`), ``"SiO2:250,Si3N4:80"`` (or a
  list ``["SiO2:250", "Si3N4:80"]``): ``material:thickness_nm`` per layer, layer 0 (facing
  the outer medium) first, each material a name, a file or a number; ``initial`` then
  gives ``eta_base`` (and ``eta_outer``, ``kappa_base`` for a numeric base) only.
* ``free``: parameters to fit (default ``thickness``): `Film` fields, and ``alpha`` for
  patches; with ``layers`` ``thickness[i]`` (layer i; ``thickness`` is layer 0); a
  material's own parameters by path, e.g. ``eta_film.coefficients[0]``
  (`thinfilm_jax.fit.params`).
* optional: ``method`` (default ``reference``), ``refine_method``, ``observer``
  (``stiles_burch_1959_10`` or ``cie_1931_2``), ``bounds`` (``{"thickness": [0, 2000]}``),
  ``solver``, ``n_starts``, ``n_solves``, ``max_steps``, ``quadrature`` (``[16, 16]``),
  ``absolute_sigma``.

Example CSV::

    # alpha = 0.25
    # initial = {"thickness": 400, "eta_film": 1.3, "eta_base": 2.0, "kappa_base": 0.5}
    # free = thickness, eta_film
    theta_o_deg,R,G,B
    0,0.04368,0.09424,0.04756
    10,0.04123,0.09212,0.04942
    ...

The output may not be the input file itself nor a directory (checked before fitting); it is
written atomically, so an interrupted run (Ctrl-C) leaves no partial file.

**Command-line overrides** (`add_arguments`): ``--eta-film``, ``--eta-base``,
``--eta-outer`` (a number, a bundled material name or a file), ``--kappa-base``,
``--thickness``, ``--layers "SiO2:250,Si3N4:80"`` and ``--free thickness[0] thickness[1]``
replace the file's settings; a bad value (an unknown material, a malformed layer list) is a
usage error (exit status 2) naming the option, before anything is fitted.

The output JSON holds the input path, the kind, the settings used (materials as given:
numbers, names or paths) and the `FitResult` summary (`FitResult.to_dict`: the fitted film
or stack (thicknesses and index names), α, free parameters with standard errors,
correlation matrix, degenerate pairs, loss, convergence, residuals).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from ..interop.index_text import parse_index, parse_layers  # the one parser (fit, render)
from .fit_files import (INDEX_KEYS, INITIAL_DEFAULTS, INITIAL_KEYS, NOTES, RAW_DEFAULT_ENVELOPE,
                         RAW_SUFFIXES, SETTINGS, _array, _fail, _in_range, _index_setting,
                         _number, material_of, read_csv, read_observations, read_text)

__all__ = [
    "RAW_SUFFIXES",
    "NOTES",
    "read_text",
    "read_csv",
    "read_observations",
    "check_output",
    "add_arguments",
    "run_fit_cli",
]

#: Help text for the ``fit`` sub-command (argparse, RawDescriptionHelpFormatter).
FIT_HELP = """\
Fit film thickness, IORs and roughness to observations read from CSV or JSON and write the
result as JSON (default: <stem>.fit.json next to the input; never overwritten without
--overwrite).

patch colours: CSV columns theta_o_deg,R,G,B [,sigma] (X,Y,Z with observer=cie_1931_2), or
  JSON {"theta_o_deg": [...], "observed": [[R,G,B], ...]}; setting alpha required.
spectra: CSV columns wavelength_nm,R [,theta_deg] (long format), or
  JSON {"wavelength_nm": [...], "theta_deg": [...], "R": [[...], ...]}.
settings: JSON keys or CSV comment lines '# key = value' above the header (UTF-8):
  initial = {"thickness": 400, "eta_film": 1.3, "eta_base": 2.0, "kappa_base": 0.5}
  free = thickness, eta_film     (Film fields and, for patches, alpha; default thickness)
  method = reference | filtered | ...   refine_method, observer, bounds, solver,
  n_starts, n_solves, max_steps, quadrature, absolute_sigma (optional).
materials: an index is a number, a bundled name (SiO2, Si, Si3N4, ...) or a .yml/.csv
  file; layers = SiO2:250,Si3N4:80 (a stack, layer 0 on top) with free = thickness[0],
  thickness[1]. The options below override the file's settings."""



def _settings(path, obs, kind):
    unknown = [k for k in obs if k not in SETTINGS and k not in
               ("theta_o_deg", "observed", "wavelength_nm", "R", NOTES)]
    if unknown:
        _fail(path, f"unknown key(s) {unknown}; settings are {list(SETTINGS)}")
    init = obs.get("initial")
    layers = obs.get("layers")
    if not isinstance(init, dict):
        _fail(path, "missing setting 'initial' (an object with at least eta_film and eta_base, "
                    "e.g. {\"eta_film\": 1.3, \"eta_base\": 2.0, \"kappa_base\": 0.5})")
    bad = [k for k in init if k not in INITIAL_KEYS]
    if bad:
        _fail(path, f"initial: unknown field(s) {bad}; expected {list(INITIAL_KEYS)}")
    film = {}
    if layers is not None:
        for k in ("thickness", "eta_film"):
            if k in init:
                _fail(path, f"initial.{k} does not apply with layers (each layer gives its "
                            f"material and thickness)")
        try:
            film["layers"] = parse_layers(layers)
        except ValueError as e:
            _fail(path, f"layers: {e}")
    for k in INITIAL_KEYS:
        if layers is not None and k in ("thickness", "eta_film"):
            continue
        if k in init:
            film[k] = (_index_setting(path, f"initial.{k}", init[k]) if k in INDEX_KEYS
                       else _number(path, f"initial.{k}", init[k]))
        elif k in INITIAL_DEFAULTS:
            film[k] = INITIAL_DEFAULTS[k]
        else:
            _fail(path, f"initial: missing field {k!r}")
    free = obs.get("free", ["thickness"])
    free = [free] if isinstance(free, str) else free
    if not (isinstance(free, list) and all(isinstance(k, str) for k in free)):
        _fail(path, f"free must be a list of parameter names, got {free!r}")
    kw = {"free": tuple(free)}
    for k in ("method", "refine_method", "observer", "solver"):
        if obs.get(k) is not None:
            kw[k] = str(obs[k])
    for k in ("n_starts", "n_solves", "max_steps"):
        if k in obs:
            v = obs[k]
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                _fail(path, f"{k} must be a positive integer, got {v!r}")
            kw[k] = v
    if "quadrature" in obs:
        q = obs["quadrature"]
        q = [q, q] if isinstance(q, int) else q
        if not (isinstance(q, list) and len(q) == 2 and all(isinstance(v, int) and v >= 2
                                                             for v in q)):
            _fail(path, f"quadrature must be an int or a pair of ints >= 2, got {q!r}")
        if kind != "patch":
            _fail(path, "quadrature applies to patch fits only")
        kw["quadrature"] = tuple(q)
    if "absolute_sigma" in obs:
        if not isinstance(obs["absolute_sigma"], bool):
            _fail(path, f"absolute_sigma must be true or false, got {obs['absolute_sigma']!r}")
        kw["absolute_sigma"] = obs["absolute_sigma"]
    if "bounds" in obs:
        b = obs["bounds"]
        if not isinstance(b, dict):
            _fail(path, f"bounds must be an object {{name: [lo, hi]}}, got {b!r}")
        kw["bounds"] = {k: tuple(_number(path, f"bounds.{k}", t) for t in v)
                        if isinstance(v, list) and len(v) == 2
                        else _fail(path, f"bounds.{k} must be [lo, hi], got {v!r}")
                        for k, v in b.items()}
    if obs.get("envelope") is not None:
        e = obs["envelope"]
        if not (isinstance(e, int) and not isinstance(e, bool) and e >= 0):
            _fail(path, f"envelope must be an integer >= 0 (the degree of the lamp "
                        f"polynomials), got {e!r}")
        if kind != "spectrum":
            _fail(path, "envelope applies to spectra only")
        kw["envelope"] = e
    if kind == "spectrum":
        for k in ("method", "refine_method", "observer"):
            if k in kw:
                _fail(path, f"setting {k!r} applies to patch fits only")
    return film, kw


# ----------------------------------------------------------------------------- main
def _call_kw(kw, options_cls):
    """Settings → keyword arguments of the fit: `free`, `method` stay keywords, the rest
    becomes its `FitOptions` (invalid values raise ValueError, reported as file errors)."""
    call = {k: kw[k] for k in ("free", "method", "envelope") if k in kw}
    call["options"] = options_cls(**{k: v for k, v in kw.items() if k not in call})
    return call


def check_output(path: Path, out: Path, overwrite: bool) -> None:
    """Refuse, before any work, an output that is the input, a directory, below a file, or
    (without `overwrite`) an existing file."""
    if out.exists() or out.is_symlink():
        if out.is_dir():
            raise SystemExit(f"thinfilm-jax fit: --out {out} is a directory; give a file path "
                             f"such as {out / (path.stem + '.fit.json')}")
        if path.exists() and out.exists() and os.path.samefile(path, out):
            raise SystemExit(f"thinfilm-jax fit: --out {out} is the input file; refusing to "
                             f"replace the observations with the result")
        if not overwrite:
            raise SystemExit(f"thinfilm-jax fit: {out} exists; pass --overwrite to replace it")
    for parent in out.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise SystemExit(f"thinfilm-jax fit: --out {out}: {parent} is not a directory")
            if not os.access(parent, os.W_OK | os.X_OK) and parent == out.absolute().parent:
                raise SystemExit(f"thinfilm-jax fit: --out {out}: cannot write in {parent}")
            break


def add_arguments(parser) -> None:
    """The ``fit`` sub-command's arguments on `parser`: the observations file, ``--out``,
    ``--overwrite`` and the material overrides (module docstring); bad override values are
    `parser.error` usage errors (exit status 2).

    Example:
        >>> import argparse
        >>> p = argparse.ArgumentParser(prog="thinfilm-jax fit")
        >>> add_arguments(p)
        >>> a = p.parse_args(["obs.csv", "--layers", "SiO2:250,Si3N4:80", "--eta-base", "Si",
        ...                   "--free", "thickness[0]", "thickness[1]"])
        >>> a.layers, a.eta_base, a.free
        ('SiO2:250,Si3N4:80', 'Si', ['thickness[0]', 'thickness[1]'])
    """
    parser.add_argument("observations", help="CSV or JSON file of observations")
    parser.add_argument("--out", required=False, help="result JSON path")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing result")
    g = parser.add_argument_group("material (overrides the file's settings)")
    for flag, what in (("--eta-film", "film index η₂"), ("--eta-base", "base index η₃"),
                       ("--eta-outer", "outer index η₁")):
        g.add_argument(flag, metavar="N|NAME|FILE",
                       help=f"{what}: a number, a bundled material (SiO2, Si, Si3N4, ...) or "
                            f"a refractiveindex.info .yml / .csv file")
    g.add_argument("--kappa-base", dest="kappa_base", type=float, metavar="K",
                   help="base absorption κ₃ of a numeric --eta-base")
    g.add_argument("--thickness", type=float, metavar="NM",
                   help="film thickness (the initial guess if free), nm")
    g.add_argument("--layers", metavar="MAT:NM,...",
                   help="a layer stack instead of one film, layer 0 (on top) first, e.g. "
                        "SiO2:250,Si3N4:80")
    g.add_argument("--free", nargs="+", metavar="NAME",
                   help="fitted parameters, e.g. thickness eta_film, or thickness[0] "
                        "thickness[1] with --layers")
    r = parser.add_argument_group("raw spectra (SPEC §14)")
    r.add_argument("--envelope", type=int, metavar="K",
                   help="fit a raw spectrometer signal g(λ)·R(λ) + b(λ), g and b polynomials "
                        f"of degree K (default {RAW_DEFAULT_ENVELOPE} for "
                        f"{'/'.join(RAW_SUFFIXES)} exports)")
    r.add_argument("--wavelength-range", dest="wavelength_range", type=float, nargs=2,
                   metavar=("LO", "HI"), help="fit only LO <= λ <= HI (nm)")
    r.add_argument("--thickness-range", dest="thickness_range", type=float, nargs=2,
                   metavar=("LO", "HI"), help="the thickness box (nm) the fit searches")
    r.add_argument("--background", metavar="FILE",
                   help="a known offset (dark or no-film spectrum) on the same wavelengths, "
                        "subtracted; then only the gain g is fitted")
    parser.set_defaults(usage_error=parser.error)


def _overrides(args, obs) -> None:
    """Apply the command line's material options to the settings `obs` (in place); a bad
    value is a usage error naming its option."""
    def usage(msg):
        err = getattr(args, "usage_error", None)
        if err is None:
            raise SystemExit(f"thinfilm-jax fit: error: {msg}")
        err(msg)

    init = dict(obs.get("initial") or {}) if isinstance(obs.get("initial"), dict) \
        else obs.get("initial")
    given = False
    for k in INDEX_KEYS:
        v = getattr(args, k, None)
        if v is not None:
            try:
                parse_index(v)
            except ValueError as e:
                usage(f"argument --{k.replace('_', '-')}: {e}")
            init = {} if not isinstance(init, dict) else init
            init[k] = v
            given = True
    for k in ("kappa_base", "thickness"):
        v = getattr(args, k, None)
        if v is not None:
            if not (math.isfinite(v) and v >= 0):
                usage(f"argument --{k.replace('_', '-')}: must be finite and >= 0, got {v}")
            init = {} if not isinstance(init, dict) else init
            init[k] = v
            given = True
    layers = getattr(args, "layers", None)
    if layers is not None:
        try:
            parse_layers(layers)
        except ValueError as e:
            usage(f"argument --layers: {e}")
        obs["layers"] = layers
        if isinstance(init, dict):  # the layers give each material and thickness
            for k in ("thickness", "eta_film"):
                if getattr(args, k, None) is not None:
                    usage(f"argument --{k.replace('_', '-')}: does not apply with --layers")
                init.pop(k, None)
        given = True
    if given:
        obs["initial"] = init
    free = getattr(args, "free", None)
    if free is not None:
        obs["free"] = list(free)
    env = getattr(args, "envelope", None)
    if env is not None:
        if env < 0:
            usage(f"argument --envelope: must be >= 0, got {env}")
        obs["envelope"] = env
    tr = getattr(args, "thickness_range", None)
    if tr is not None:
        if not (math.isfinite(tr[0]) and math.isfinite(tr[1]) and 0 <= tr[0] < tr[1]):
            usage(f"argument --thickness-range: need 0 <= LO < HI, got {tr[0]} {tr[1]}")
        obs["bounds"] = {**(obs.get("bounds") or {}), "thickness": [tr[0], tr[1]]}
    wr = getattr(args, "wavelength_range", None)
    if wr is not None and not (math.isfinite(wr[0]) and math.isfinite(wr[1])
                               and 0 < wr[0] < wr[1]):
        usage(f"argument --wavelength-range: need 0 < LO < HI, got {wr[0]} {wr[1]}")


def run_fit_cli(args) -> int:
    """Entry point of ``thinfilm-jax fit`` (args.observations, args.out, args.overwrite and
    the material overrides of `add_arguments`, where given)."""
    import numpy as np

    path = Path(args.observations)
    out = Path(args.out) if getattr(args, "out", None) else path.with_name(path.stem + ".fit.json")
    check_output(path, out, getattr(args, "overwrite", False))
    obs = read_observations(path)
    _overrides(args, obs)
    kind = obs.get("kind")
    if kind not in ("patch", "spectrum"):
        _fail(path, f"kind must be 'patch' or 'spectrum', got {kind!r}")
    film_kw, kw = _settings(path, obs, kind)
    for note in obs.get(NOTES, ()):
        print(f"{path.name}: {note}")

    from ..core.files import write_json
    from ..fit.film_fit import FitOptions, fit_film, fit_spectrum

    try:
        initial = material_of(film_kw)
    except ValueError as e:
        _fail(path, str(e))
    if "layers" in film_kw:
        film_kw = {**film_kw, "layers": [{"material": m, "thickness": d}
                                         for m, d in film_kw["layers"]]}
    sigma = obs.get("sigma")
    if sigma is not None:
        sigma = np.asarray(sigma, float) if isinstance(sigma, list) else \
            _number(path, "sigma", sigma)
        if not np.all(np.isfinite(sigma)) or np.any(np.asarray(sigma) <= 0):
            _fail(path, "sigma must be finite and > 0")
    try:
        if kind == "patch":
            for k in ("theta_o_deg", "observed"):
                if k not in obs:
                    _fail(path, f"missing {k!r} (patch observations need theta_o_deg and "
                                f"observed)")
            if "alpha" not in obs:
                _fail(path, "missing setting 'alpha' (GGX roughness in (0, 1])")
            theta = _array(path, "theta_o_deg", obs["theta_o_deg"], 1)
            _in_range(path, "theta_o_deg", theta, 0.0, 90.0, " degrees")
            observed = _array(path, "observed", obs["observed"], 2)
            alpha = _number(path, "alpha", obs["alpha"])
            if not 0.0 < alpha <= 1.0:
                _fail(path, f"alpha = {alpha!r} lies outside (0, 1]")
            res = fit_film(observed, np.deg2rad(theta), alpha=alpha, initial=initial,
                           sigma=sigma, **_call_kw(kw, FitOptions))
            data = {"theta_o_deg": theta.tolist(), "observed": observed.tolist()}
        else:
            for k in ("wavelength_nm", "R"):
                if k not in obs:
                    _fail(path, f"missing {k!r} (spectra need wavelength_nm and R)")
            lam = _array(path, "wavelength_nm", obs["wavelength_nm"], 1)
            if np.any(lam <= 0):
                _fail(path, f"wavelength_nm = {lam[lam <= 0][0]!r} must be > 0 (nm)")
            theta = _array(path, "theta_deg", obs.get("theta_deg", [0.0]), 1)
            _in_range(path, "theta_deg", theta, 0.0, 90.0, " degrees")
            refl = np.atleast_2d(_array(path, "R", obs["R"], (1, 2)))
            background = None
            if getattr(args, "background", None):
                if "envelope" not in kw:
                    _fail(path, "--background applies to raw spectra (give --envelope K)")
                from ..fit.spectrum_file import read_spectrum

                lam_b, background = read_spectrum(Path(args.background), nonfinite="drop")
                if not np.array_equal(lam_b, lam):
                    lam_b = lam_b.tolist()
                    _fail(path, f"--background {args.background}: its wavelengths differ from "
                                f"the spectrum's ({len(lam_b)} vs {lam.size} points)")
            wr = getattr(args, "wavelength_range", None)
            if wr is not None:
                keep = (lam >= wr[0]) & (lam <= wr[1])
                if keep.sum() < 2:
                    _fail(path, f"--wavelength-range {wr[0]:g} {wr[1]:g} keeps "
                                f"{int(keep.sum())} wavelengths")
                lam, refl = lam[keep], refl[:, keep]
                sigma = (sigma[..., keep] if isinstance(sigma, np.ndarray)
                         and sigma.shape[-1] == keep.size else sigma)
                background = None if background is None else background[keep]
            call = _call_kw(kw, FitOptions)
            if background is not None:
                call["background"] = background
            res = fit_spectrum(refl, lam, np.cos(np.deg2rad(theta)), initial=initial,
                               sigma=sigma, **call)
            data = {"wavelength_nm": lam.tolist(), "theta_deg": theta.tolist(),
                    "R": np.atleast_2d(refl).tolist()}
    except (ValueError, TypeError) as e:
        _fail(path, str(e))
    summary = res.to_dict()
    settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in kw.items()}
    if getattr(args, "background", None):
        settings["background"] = str(args.background)
    write_json(out, {"input": str(path), "kind": kind, "initial": film_kw,
                     "settings": settings, "data": data, "result": summary})
    p = summary["params"]
    err = summary["stderr"]
    print(f"{kind} fit of {path.name}: " + ", ".join(f"{k} = {p[k]:.6g} ± {err[k]:.2g}"
                                                    for k in p)
          + f"; loss {summary['loss']:.3g}, converged {summary['converged']}")
    for ru in summary["runner_ups"]:
        print("runner-up minimum: " + ", ".join(f"{k} = {v:.6g}" for k, v in ru["params"].items())
              + f"; loss {ru['loss']:.3g} (Δχ² = {ru['dchi2']:.3g})")
    if summary["ambiguous"]:
        print("AMBIGUOUS: a runner-up minimum (another fringe order) fits almost as well "
              "(Δχ² < 9); the data cannot tell them apart")
    if summary["degenerate"]:
        print("strongly correlated (|corr| > 0.95): "
              + ", ".join(f"{a}/{b}" for a, b in summary["degenerate"]))
    print(f"wrote {out}")
    return 0
