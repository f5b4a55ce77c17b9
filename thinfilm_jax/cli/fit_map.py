"""``thinfilm-jax fit-map IMAGE ...``: a thickness map (optionally η₂) from an image
(`thinfilm_jax.fit.thickness_map.fit_patch_map`).

IMAGE holds the linear band radiances (H, W, J) of a film under uniform light, as
`patch_radiance` / `render_patch_map` give them (Stiles–Burch RGB bands by default; X, Y, Z
with ``--observer cie_1931_2``): a ``.npy`` array, or an ``.exr`` / ``.hdr`` file read with
OpenImageIO (its first three channels, linear). The view angle is one number
(``--theta-o`` degrees) or a per-pixel ``.npy`` map (H, W) in degrees (``--theta-o-map``).

Writes into ``--out`` (default ``fit_map``), each file atomically (Ctrl-C leaves no partial
file): ``thickness_map.npy`` (H, W) nm, ``thickness_map.png`` (colour map with a colour bar
in nm) and ``fit_map.json`` (the settings, the thickness range, the residuals' percentiles,
the reduced χ² and the misfit warnings, pixels per second warm and the compilation time
separately (the warm-up batch's time minus its warm cost); with ``--free thickness
eta_film`` also ``eta_film_map.npy``).

With ``--camera`` the image is a photograph instead: `thinfilm_jax.cli.fit_photo` (encodings,
cameras, lights, reference regions; its own outputs).

``--gltf DIR`` also writes the map as a complete glTF 2.0 asset, a sphere carrying the film
(`thinfilm_jax.interop.gltf_file.write_gltf`, SPEC §10): ``DIR/fit_map.gltf`` with its mesh in
``DIR/fit_map.bin`` and a material with `KHR_materials_iridescence` (η₂ as `iridescenceIor`,
minimum and maximum covering the map, factor 1), `KHR_materials_ior` (η₃) and
`roughnessFactor` √α, and the
`iridescenceThicknessTexture` ``DIR/fit_map_thickness.png`` (G channel, linear, 8-bit or
``--gltf-bits 16``; it gives back the map to (max − min)/(2(2ᵇ − 1)) nm). What glTF cannot
hold is a usage error before the fit: κ₃ > 0 (glTF's metals are a Schlick tint, its
dielectrics a real IOR; fit with ``--kappa-base 0`` or leave out ``--gltf``), η₁ ≠ 1, and a
fitted η₂ map (``--free eta_film``: the extension has one `iridescenceIor`). A dispersive
material (``--eta-film water``) is written with its index at ``--gltf-wavelength`` (550 nm),
recorded in the material's ``extras.thinfilm_jax`` (the colour this costs: docs/how-to/gltf.md).
The same ``--gltf`` works for a photograph (``--camera``, `thinfilm_jax.cli.fit_photo`).

Each index (``--eta-film``, ``--eta-base``, ``--eta-outer``) is a number (it stays a
number) or a material (SPEC §12): a bundled name (``SiO2``, ``Si``, ``Si3N4``, ...) or a
refractiveindex.info YAML / CSV file; an unknown name or a number out of range is a usage
error (exit status 2) that lists the bundled names. A material is an index model: the map
model must take dispersive indices (`fit_patch_map` says so with a one-line error where it
does not).

Example::

    thinfilm-jax fit-map wedge.npy --theta-o 20 --alpha 0.2 --eta-film 1.46 \\
        --eta-base 3.9 --kappa-base 0.02 --smoothness 50 --out wedge_fit
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..core.methods import names as method_names
from ._output import gltf_line

__all__ = ["IndexArg", "add_parser"]

#: the parser's numeric options are checked by `_checks.check_args` (usage errors); the
#: indices by `_index_arg` (they may be materials, so they are stored under other names)
#: index option → (attribute of the parsed value, lowest value of a number, lowest excluded)
INDEX_OPTIONS = {"--eta-film": ("eta_film_index", 1.0, False),
                 "--eta-base": ("eta_base_index", 0.0, True),
                 "--eta-outer": ("eta_outer_index", 1.0, False)}


class IndexArg(NamedTuple):
    """An index option as given (`text`) and as parsed (`value`: a number or an index
    model)."""

    text: str
    value: Any

    @property
    def number(self) -> bool:
        return not callable(self.value)


def _index_arg(lo: float, lo_open: bool):
    """argparse type of an index option: a number in range or a material (`IndexArg`)."""
    import argparse

    from ..interop.index_text import parse_index

    def parse(text: str) -> IndexArg:
        try:
            v = parse_index(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        if not callable(v):
            n = v.real
            if (n <= lo if lo_open else n < lo) or v.imag < 0:
                rng = f"{'(' if lo_open else '['}{lo}, inf)"
                raise argparse.ArgumentTypeError(f"must be a number in {rng} (κ >= 0) or a "
                                                 f"material, got {text}")
        return IndexArg(text, v)

    parse.__name__ = "index"  # argparse's "invalid index value" message
    return parse


def add_parser(sub) -> None:
    """Register ``fit-map`` on the ``thinfilm-jax`` sub-parsers.

    Example (the defaults a minimal command line gets):
        >>> from thinfilm_jax.cli.main import build_parser
        >>> args = build_parser().parse_args(["fit-map", "wedge.npy", "--theta-o", "20",
        ...                                   "--alpha", "0.2", "--eta-film", "1.33",
        ...                                   "--eta-base", "1.0"])
        >>> args.free, args.method, args.grid, args.func is run_fit_map_cli
        (['thickness'], 'filtered', 201, True)
        >>> args.eta_film_index.value, args.eta_outer_index.value
        (1.33, 1.0)
    """
    import argparse

    p = sub.add_parser("fit-map", help="fit a per-pixel thickness map to an image",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("image", help="(H, W, 3) linear band radiances: .npy, .exr or .hdr; or a "
                                 "photograph with --camera (PNG, JPEG, TIFF, EXR, RAW)")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--theta-o", dest="theta_o", type=float, metavar="DEG",
                      help="view angle of every pixel, degrees [0, 90]")
    view.add_argument("--theta-o-map", dest="theta_o_map", metavar="FILE.npy",
                      help="per-pixel view angles (H, W), degrees")
    p.add_argument("--alpha", type=float,
                   help="GGX roughness α in (0, 1] (band images: required; photographs: "
                        "a rough film under uniform light, default a mirror view)")
    mat = " (a number, a bundled material such as SiO2, Si, or a .yml / .csv file)"
    p.add_argument("--eta-film", dest="eta_film_index", type=_index_arg(1.0, False),
                   required=True, metavar="N|NAME|FILE",
                   help="film IOR η₂ (fixed, or the initial value with --free ... eta_film)"
                        + mat)
    p.add_argument("--eta-base", dest="eta_base_index", type=_index_arg(0.0, True),
                   required=True, metavar="N|NAME|FILE",
                   help="base IOR η₃ (1.0: a free-standing soap film)" + mat)
    p.add_argument("--kappa-base", dest="kappa_base", type=float, default=0.0,
                   help="base absorption κ₃ of a numeric --eta-base (0)")
    p.add_argument("--eta-outer", dest="eta_outer_index", type=_index_arg(1.0, False),
                   default=IndexArg("1.0", 1.0), metavar="N|NAME|FILE",
                   help="outer IOR η₁ (1)" + mat)
    p.add_argument("--free", nargs="+", choices=["thickness", "eta_film"],
                   default=["thickness"], help="fitted fields (default: thickness)")
    p.add_argument("--smoothness", type=float, metavar="NM",
                   help="τ of the neighbour prior, nm (default: independent pixels)")
    p.add_argument("--sigma", type=float, default=0.01,
                   help="noise standard deviation of the image, absolute (0.01)")
    p.add_argument("--thickness-range", dest="thickness_range", type=float, nargs=2,
                   metavar=("LO", "HI"), default=[0.0, 2000.0],
                   help="thickness box, nm (0 2000)")
    p.add_argument("--grid", type=int, default=201, help="thickness grid of the screen (201)")
    p.add_argument("--method", choices=method_names("patch"), default="filtered",
                   help="map model, a patch_radiance method (default filtered: real time; reference: exact)")
    p.add_argument("--observer", choices=["stiles_burch_1959_10", "cie_1931_2"],
                   default="stiles_burch_1959_10")
    p.add_argument("--chunk", type=int, default=2048, help="pixels per batch (2048)")
    p.add_argument("--out", default="fit_map", help="output folder (default: fit_map)")
    p.add_argument("--devices", type=int, metavar="K",
                   help="split each batch across the first K devices (default: one device)")
    p.add_argument("--gltf", metavar="DIR",
                   help="also write a glTF asset: DIR/fit_map.gltf, fit_map.bin and the "
                        "thickness texture fit_map_thickness.png (KHR_materials_iridescence)")
    p.add_argument("--gltf-bits", dest="gltf_bits", type=int, choices=[8, 16], default=8,
                   help="bits of the glTF thickness texture (8)")
    p.add_argument("--gltf-wavelength", dest="gltf_wavelength", type=float, default=550.0,
                   metavar="NM",
                   help="wavelength at which a material's dispersive index is written as "
                        "glTF's one constant IOR (550)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from .fit_photo import add_arguments

    add_arguments(p)
    p.set_defaults(func=run_fit_map_cli, usage_error=p.error)


def _load_image(path: Path) -> np.ndarray:
    if not path.is_file():
        raise ValueError(f"IMAGE {path}: no such file")
    if path.suffix.lower() == ".npy":
        try:
            a = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ValueError(f"IMAGE {path}: not a readable .npy array ({e})") from None
    elif path.suffix.lower() in (".exr", ".hdr"):
        from ..shading.envmap import _read_image  # OpenImageIO, linear float

        a = _read_image(path, f"IMAGE {path}")
    else:
        raise ValueError(f"IMAGE {path}: expected .npy, .exr or .hdr")
    if a.ndim != 3 or a.shape[-1] != 3:
        raise ValueError(f"IMAGE {path}: expected an (H, W, 3) array, got shape {a.shape}")
    return a


def _load_theta(args, shape) -> np.ndarray:
    if args.theta_o is not None:
        deg = np.full(shape, args.theta_o, float)
    else:
        path = Path(args.theta_o_map)
        if not path.is_file():
            raise ValueError(f"--theta-o-map {path}: no such file")
        try:
            deg = np.asarray(np.load(path, allow_pickle=False), float)
        except (OSError, ValueError) as e:
            raise ValueError(f"--theta-o-map {path}: not a readable .npy array ({e})") from None
        if deg.shape != shape:
            raise ValueError(f"--theta-o-map: shape {deg.shape} does not match the image's "
                             f"{shape}")
    if not np.all(np.isfinite(deg)) or np.any((deg < 0) | (deg > 90)):
        raise ValueError("--theta-o / --theta-o-map: view angles must be finite degrees in "
                         "[0, 90]")
    return np.deg2rad(deg)


def _gltf_problem(args) -> str | None:
    """Why the film of `args` cannot be written as a glTF material (None: it can)."""
    if "eta_film" in args.free:
        return ("glTF holds one iridescenceIor, not the eta_film map of --free eta_film "
                "(fit the thickness alone)")
    gltf = Path(args.gltf)
    if gltf.exists() and not gltf.is_dir():
        return f"{gltf} exists and is not a folder"
    from ..interop.gltf import film_to_gltf

    wl = args.gltf_wavelength
    if not (np.isfinite(wl) and wl > 0):
        return f"--gltf-wavelength must be a wavelength > 0 nm, got {wl:g}"
    try:  # the film's scalar fields, as the written material will hold them
        film_to_gltf(_film(args, 0.0), wavelength_nm=wl)
    except ValueError as e:
        hint = (" — give a non-absorbing --eta-base (--kappa-base 0) or leave out --gltf"
                if "absorbing base" in str(e) else "")
        return f"{e}{hint}"
    return None


def _index_json(arg: IndexArg):
    """An index option for the JSON summary: a real number, {"n", "k"} of a complex one, or
    the material as given (a name or a path)."""
    if not arg.number:
        return arg.text
    v = complex(arg.value)
    return v.real if v.imag == 0 else {"n": v.real, "k": v.imag}


def _film(args, thickness):
    """The `Film` of the command line's indices (numbers or index models) at `thickness`."""
    from ..core.film import Film

    return Film(thickness, args.eta_film_index.value, args.eta_base_index.value,
                args.kappa_base, args.eta_outer_index.value)


def run_fit_map_cli(args) -> int:
    """Read, check, fit (a warm-up batch first: compile time measured apart), write.

    With ``--gltf`` a film glTF cannot hold (`_gltf_problem`) is a usage error (exit 2)
    before anything is read or fitted.
    """
    from ._checks import _devices, _enable_x64
    from .fit_photo import PHOTO_SUFFIXES, run_photo

    if getattr(args, "camera", None) is not None:
        if args.theta_o_map is not None:
            args.usage_error("argument --theta-o-map: a photograph has one view (--theta-o)")
        if "eta_film" in args.free:
            args.usage_error("a photograph fits the thickness alone (no --free eta_film)")
        if args.gltf is not None:
            problem = _gltf_problem(args)
            if problem is not None:
                args.usage_error(f"argument --gltf: {problem}")
        return run_photo(args)
    if Path(args.image).suffix.lower() in PHOTO_SUFFIXES or args.reference:
        args.usage_error(f"{Path(args.image).name} is a photograph: give --camera (srgb, "
                         f"unknown, a colour-science camera name or a sensitivities CSV)")
    if args.theta_o is None and args.theta_o_map is None:
        args.usage_error("one of the arguments --theta-o --theta-o-map is required")
    if args.alpha is None:
        args.usage_error("the following arguments are required: --alpha")
    if getattr(args, "gltf", None) is not None:
        problem = _gltf_problem(args)
        if problem is not None:
            args.usage_error(f"argument --gltf: {problem}")
    lo, hi = args.thickness_range
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
        raise ValueError(f"--thickness-range must be 0 <= LO < HI, got {lo} {hi}")
    image = _load_image(Path(args.image))
    theta = _load_theta(args, image.shape[:2])
    out = Path(args.out)
    if args.devices is not None:
        _devices(args)
    _enable_x64()
    from ..fit.thickness_map import fit_patch_map
    from ..spectral.spectra import get_observer

    initial = _film(args, 0.5 * (lo + hi))
    kw = dict(alpha=args.alpha, initial=initial, free=tuple(args.free), method=args.method,
              sigma=args.sigma, smoothness_nm=args.smoothness,
              bounds={"thickness": (lo, hi)}, grid=args.grid, observer=args.observer,
              devices=args.devices)
    h, w, _ = image.shape
    n = h * w
    size = min(args.chunk, n)
    # warm-up on the first `size` pixels as a 1 × size image: the same batch shapes, so
    # the full run below reuses its compilation (also checks every input before the work)
    t0 = time.perf_counter()
    fit_patch_map(image.reshape(-1, 3)[:size][None], theta.reshape(-1)[:size][None],
                  chunk=size, **kw)
    warmup_s = time.perf_counter() - t0
    res = fit_patch_map(image, theta, chunk=size, progress=not args.quiet, **kw)
    compile_s = max(warmup_s - size * res.seconds / n, 0.0)  # minus the batch's warm cost
    d = np.asarray(res.thickness)
    loss = np.asarray(res.loss)
    rms = np.sqrt(2 * loss / 3)  # per-band RMS residual in units of σ

    from ..core.files import atomic_write, write_json

    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "thickness_map.npy", lambda tmp: np.save(tmp, d))
    if "eta_film" in args.free:
        eta = np.asarray(res.eta_film)
        atomic_write(out / "eta_film_map.npy", lambda tmp: np.save(tmp, eta))
    title = (f"{Path(args.image).name}: {h}×{w}, α={args.alpha:g}, "
             f"η₂={args.eta_film_index.text},\n"
             f"η₃={args.eta_base_index.text}+{args.kappa_base:g}i, method={args.method}, "
             f"τ={args.smoothness if args.smoothness else 'none'} nm")
    from ._output import save_thickness_png

    save_thickness_png(out / "thickness_map.png", d, title)
    gltf = None
    if getattr(args, "gltf", None) is not None:
        from ._output import write_map_gltf

        gltf = write_map_gltf(args, _film(args, d), args.alpha)
    pct = (5, 25, 50, 75, 95)
    summary = {
        "image": str(args.image), "shape": [h, w],
        "settings": {k: (_index_json(getattr(args, k + "_index")) if k.startswith("eta_")
                         else getattr(args, k)) for k in (
            "theta_o", "theta_o_map", "alpha", "eta_film", "eta_base", "kappa_base",
            "eta_outer", "free", "smoothness", "sigma", "thickness_range", "grid", "method",
            "observer", "chunk", "devices", "gltf", "gltf_bits", "gltf_wavelength")},
        "bands": list(get_observer(args.observer).band_names),
        "thickness_nm": {f"p{q}": float(np.percentile(d, q)) for q in pct}
        | {"min": float(d.min()), "max": float(d.max())},
        "stderr_nm_median": float(np.nanmedian(np.asarray(res.stderr))),
        "residual_rms_over_sigma": {f"p{q}": float(np.percentile(rms, q))
                                    for q in (50, 95)} | {"max": float(rms.max())},
        "reduced_chi2": float(res.reduced_chi2),  # the misfit test (options.misfit_warnings)
        "warnings": list(res.warnings),
        "pixels_per_second_warm": float(res.pixels_per_second),
        "seconds_warm": float(res.seconds),
        "compile_seconds": compile_s,  # warm-up batch time minus its warm cost
        "warmup_seconds": warmup_s,
        "outputs": ["thickness_map.npy", "thickness_map.png", "fit_map.json"]
        + (["eta_film_map.npy"] if "eta_film" in args.free else []),
    }
    if gltf is not None:
        summary["gltf"] = gltf
    if "eta_film" in args.free:
        eta = np.asarray(res.eta_film)
        summary["eta_film"] = {f"p{q}": float(np.percentile(eta, q)) for q in pct}
    write_json(out / "fit_map.json", summary)
    print(f"wrote {out}/thickness_map.png, thickness_map.npy, fit_map.json: {h}×{w} pixels, "
          f"thickness {d.min():.1f}–{d.max():.1f} nm (median {np.median(d):.1f}), residual "
          f"RMS/σ median {np.median(rms):.2f}; {res.pixels_per_second:.0f} pixels/s warm, "
          f"compile {compile_s:.1f} s")
    if gltf is not None:
        print(gltf_line(gltf))
    return 0
