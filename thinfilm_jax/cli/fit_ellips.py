"""``thinfilm-jax fit-ellips FILE --layers ... --eta-base ... [--free ...]``: fit a film or a
layer stack to ellipsometric ψ, Δ (`thinfilm_jax.fit.ellipsometry_fit.fit_ellipsometry`,
SPEC §14).

``FILE`` is a WVASE / CompleteEASE ``.dat`` export or ``λ angle ψ Δ`` text
(`thinfilm_jax.core.ellipsometry_data.read_ellipsometry`); its σψ, σΔ columns, where it has
them, weight the fit (reduced χ² = WVASE's MSE²). The material is a stack (``--layers
MAT:NM,...``, layer 0 facing the ambient first) or one film (``--eta-film MAT --thickness
NM``) on ``--eta-base MAT`` under ``--eta-outer`` (default 1); a material is a number, a
bundled name (SiO2, Si, ...) or a table / refractiveindex.info file (the parsers of
``thinfilm-jax fit``, `thinfilm_jax.interop.index_text.parse_index`, `parse_layers`).
``--interpolation epsilon`` interpolates every table in ε = (n + iκ)², WVASE's rule
(`thinfilm_jax.optics.index.TabulatedIndex`); ``--wavelength-unit um`` reads a table whose
header says only ``Wavelength`` (refellips' air.csv).

The result (the fitted material, free parameters with standard errors, residuals, MSE) is
written atomically as JSON, by default ``<stem>.ellips.json`` beside the input, never over an
existing file without ``--overwrite``.

Example::

    thinfilm-jax fit-ellips WVASE_example_2nmSiO2_20nmPNIPAM_MultiWavelength.txt \\
        --layers pnipam.csv:15,silica.csv:2 --eta-base silicon.csv \\
        --interpolation epsilon --free "thickness[0]"
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["add_parser"]


def add_parser(sub) -> None:
    """Register ``fit-ellips`` on the ``thinfilm-jax`` sub-parsers.

    Example:
        >>> from thinfilm_jax.cli.main import build_parser
        >>> a = build_parser().parse_args(["fit-ellips", "si.dat", "--eta-film", "SiO2",
        ...                                "--thickness", "100", "--eta-base", "Si"])
        >>> a.free, a.interpolation, a.eta_outer, a.func is run_fit_ellips_cli
        (['thickness'], 'nk', '1', True)
    """
    import argparse

    p = sub.add_parser("fit-ellips", help="fit a film or stack to ellipsometric psi, Delta",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="WVASE / CompleteEASE .dat export or 'λ angle ψ Δ' text")
    p.add_argument("--layers", metavar="MAT:NM,...",
                   help="the layer stack, layer 0 (facing the ambient) first, e.g. "
                        "pnipam.csv:20,silica.csv:2")
    p.add_argument("--eta-film", dest="eta_film", metavar="N|NAME|FILE",
                   help="one film's material (instead of --layers)")
    p.add_argument("--thickness", type=float, metavar="NM",
                   help="one film's thickness (the initial guess), nm")
    p.add_argument("--eta-base", dest="eta_base", required=True, metavar="N|NAME|FILE",
                   help="the substrate: a number (n or n+kj), a bundled material or a file")
    p.add_argument("--eta-outer", dest="eta_outer", default="1", metavar="N|NAME|FILE",
                   help="the ambient (lossless; default 1)")
    p.add_argument("--free", nargs="+", default=["thickness"], metavar="NAME",
                   help="fitted parameters, e.g. 'thickness[0]' 'thickness[1]' "
                        "(default: thickness, layer 0)")
    p.add_argument("--interpolation", choices=["nk", "epsilon"], default="nk",
                   help="how tables are interpolated: n, k or ε = (n+iκ)² linear in λ "
                        "(epsilon: WVASE's rule)")
    p.add_argument("--wavelength-unit", dest="wavelength_unit", choices=["nm", "um"],
                   help="unit of a table whose header names only 'Wavelength'")
    p.add_argument("--out", help="result JSON (default: <stem>.ellips.json beside the data)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing result")
    p.set_defaults(func=run_fit_ellips_cli, usage_error=p.error)


def _material(args):
    """The `Stack` (``--layers``) or `Film` (``--eta-film``) of the command line; a bad value
    is a usage error naming its option."""
    from ..core.film import Film
    from ..core.stack import Stack
    from ..optics.index import TabulatedIndex
    from ..optics.materials import read_csv
    from ..interop.index_text import parse_index, parse_layers

    def index(text, option):
        path = Path(str(text))
        try:
            if path.suffix.lower() == ".csv" and path.is_file():
                return read_csv(path, interpolation=args.interpolation,
                                wavelength_unit=args.wavelength_unit)
            eta = parse_index(text)
        except ValueError as e:
            args.usage_error(f"argument {option}: {e}")
        if isinstance(eta, TabulatedIndex):
            return eta.with_interpolation(args.interpolation)
        return eta

    if (args.layers is None) == (args.eta_film is None):
        args.usage_error("give either --layers (a stack) or --eta-film with --thickness")
    base, outer = index(args.eta_base, "--eta-base"), index(args.eta_outer, "--eta-outer")
    if args.layers is not None:
        try:
            layers = parse_layers(args.layers)
        except ValueError as e:
            args.usage_error(f"argument --layers: {e}")
        return Stack([d for _, d in layers], tuple(index(m, "--layers") for m, _ in layers),
                     base, outer)
    if args.thickness is None or not (math.isfinite(args.thickness) and args.thickness >= 0):
        args.usage_error("argument --thickness: one film needs its thickness (finite, >= 0 nm)")
    return Film(args.thickness, index(args.eta_film, "--eta-film"), base, 0.0, outer)


def run_fit_ellips_cli(args) -> int:
    """Entry point of ``thinfilm-jax fit-ellips``: read, fit, write the JSON, print a summary."""
    from ..core.files import write_json
    from ..core.ellipsometry_data import read_ellipsometry
    from ..fit.ellipsometry_fit import fit_ellipsometry
    from ..fit.options import material_dict
    from ._checks import _enable_x64
    from .fit import check_output

    _enable_x64()
    path = Path(args.data)
    out = Path(args.out) if args.out else path.with_name(path.stem + ".ellips.json")
    try:
        check_output(path, out, args.overwrite)  # the checks of `fit`, before any work
    except SystemExit as e:
        raise SystemExit(str(e).replace("thinfilm-jax fit:", "thinfilm-jax fit-ellips:")) \
            from None
    initial = _material(args)
    data = read_ellipsometry(path)
    sig = (data.sigma_psi, data.sigma_delta) if data.has_sigma and np.all(
        data.sigma_psi > 0) and np.all(data.sigma_delta > 0) else (None, None)
    res = fit_ellipsometry(data.psi, data.delta, data.wavelength, data.angle, initial=initial,
                           free=tuple(args.free), sigma_psi=sig[0], sigma_delta=sig[1])
    summary = res.to_dict()
    r = np.asarray(res.residuals)
    summary["max_abs_residual_deg"] = {"psi": float(np.max(np.abs(r[0]))),
                                       "delta": float(np.max(np.abs(r[1])))}
    write_json(out, {"input": str(path), "n_points": int(data.psi.size),
                     "sigma_from_file": sig[0] is not None,
                     "initial": material_dict(initial), "interpolation": args.interpolation,
                     "result": summary})
    p, err = summary["params"], summary["stderr"]
    print(f"ellipsometry fit of {path.name} ({data.psi.size} points): "
          + ", ".join(f"{k} = {p[k]:.5g} ± {err[k]:.2g}" for k in p)
          + f"; max |residual| ψ {summary['max_abs_residual_deg']['psi']:.3g}°, "
            f"Δ {summary['max_abs_residual_deg']['delta']:.3g}°"
          + (f"; MSE {math.sqrt(summary['reduced_chi2']):.3g}"
             if summary["reduced_chi2"] is not None else ""))
    for w in summary["warnings"]:
        print(f"warning: {w}")
    print(f"wrote {out}")
    return 0
