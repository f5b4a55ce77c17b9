"""Command line: ``thinfilm-jax figure7 | render | fit | fit-map | fit-ellips | bench`` (also
``python -m thinfilm_jax``). The research studies and benchmarks are not in the installed
package: they live in the repository's ``benchmarks/`` folder (``python -m benchmarks.bench``
from a clone, ``make bench``); ``thinfilm-jax bench`` hands its arguments to that command when
it finds the clone (`_bench`), and says so when it does not."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from ._checks import _add_device_options, _devices, _enable_x64

__all__ = ["OWN_SCENE_OPTIONS", "build_parser", "main"]


def _figure7(args) -> int:
    devices = _devices(args)
    _enable_x64()
    from ..render.figure7 import Figure7Config, run_figure7

    fields = {f.name for f in dataclasses.fields(Figure7Config)}
    cfg = Figure7Config(**{k: tuple(v) if isinstance(v, list) else v
                           for k, v in vars(args).items() if k in fields and v is not None})
    summary = run_figure7(cfg, out_dir=args.out, progress=not args.quiet, devices=devices,
                          timing_path=args.timing)
    print(f"wrote {args.out}/figure7.png, figure7_error.png, figure7.json, figure7.npz "
          f"in {summary['timing']['compute_seconds']:.1f} s"
          + (f" (timing: {args.timing})" if args.timing else ""))
    print(f"{'row/method':40s} {'ΔE mean':>8s} {'ΔE p95':>8s} {'ΔE max':>8s}")
    for k, v in summary["errors_vs_reference"].items():
        print(f"{k:40s} {v['dE2000_mean']:8.3f} {v['dE2000_p95']:8.3f} {v['dE2000_max']:8.3f}")
    return 0


def find_benchmarks():
    """The `benchmarks` package of the clone this library runs from (an editable install:
    the folder beside `thinfilm_jax/`) or of the current folder; ImportError saying where the
    studies live when neither has it (an installed wheel holds no studies)."""
    import importlib
    from pathlib import Path

    for root in (Path(__file__).resolve().parents[2], Path.cwd()):
        if (root / "benchmarks" / "__init__.py").is_file():
            if str(root) not in sys.path:
                sys.path.insert(0, str(root))
            return importlib.import_module("benchmarks")
    raise ImportError("thinfilm-jax bench runs the studies of the repository's benchmarks/ "
                      "folder, which the installed package does not hold: from a clone, "
                      "`pip install -e '.[bench,plots]'` and `python -m benchmarks.bench`")


def _bench(argv: list[str]) -> int:
    """``thinfilm-jax bench ARGS``: ``python -m benchmarks.bench ARGS`` of the clone (its
    options are its own, ``--help`` included); exit status 2 and one line when there is no
    clone to run."""
    try:
        find_benchmarks()
    except ImportError as e:
        print(f"thinfilm-jax bench: error: {e}", file=sys.stderr)
        return 2
    from benchmarks.bench import main as bench_main

    return bench_main(argv)


# the own scenes' options: argparse destination and the scenes that take each (the study
# scenes take none of them)
OWN_SCENE_OPTIONS = {
    "--thickness": ("thickness", ("sphere",)),
    "--eta-film": ("film_index", ("sphere", "bubble")),
    "--eta-base": ("base_index", ("sphere",)),
    "--layers": ("layers", ("sphere",)),
    "--alpha": ("alpha", ("sphere",)),
    "--thickness-range": ("thickness_range", ("bubble",)),
    "--elevation": ("elevation", ("sphere", "bubble")),
    "--bin-reads": ("bin_reads", ("sphere",)),
    "--light-spread": ("light_spread", ("sphere",)),
    "--quality": ("quality", ("sphere",)),
}


def _given(args, options) -> list[str]:
    """The `render` options among `options` that the command line gave (a flag: set)."""
    dest = {"--method": "method", **{k: v[0] for k, v in OWN_SCENE_OPTIONS.items()}}
    return [k for k in options if getattr(args, dest[k]) not in (None, False)]


def _render(args) -> int:
    """`thinfilm-jax render`: one's own scene (sphere, bubble; `render.scene`) or the study
    scenes (`render.study_scenes`). Options that do not fit the scene are usage errors."""
    from ..render.scene import OWN_SCENES, default_out_dir

    scenes = args.scene or ["sphere"]
    own = [s for s in scenes if s in OWN_SCENES]
    fail = args.render_parser.error
    if own and (len(scenes) > 1):
        fail(f"--scene {own[0]} renders one scene alone; got {scenes}")
    if not own:
        given = _given(args, OWN_SCENE_OPTIONS)
        if given:
            fail(f"options of --scene sphere / bubble only: {', '.join(given)} (got --scene "
                 f"{' '.join(scenes)})")
    out = args.out if args.out is not None else str(default_out_dir())
    devices = _devices(args)
    _enable_x64()
    if own:
        return _render_scene(args, own[0], out, fail)
    from pathlib import Path

    from ..render.study_scenes import RenderConfig, run_render, summary_table

    kw = {k: tuple(v) for k, v in (("envmaps", args.envmap), ("scenes", scenes),
                                   ("methods", args.method), ("alphas", args.alphas)) if v}
    if args.alphas and not all(0 < a <= 1 for a in args.alphas):
        raise ValueError(f"--alphas must lie in (0, 1], got {args.alphas}")
    cfg = RenderConfig(resolution=args.resolution or 64, exposure=args.exposure,
                       observer=args.observer, ldr_srgb=args.ldr_srgb, **kw)
    summary = run_render(cfg, out_dir=out, progress=not args.quiet, devices=devices)
    files = [Path(out) / f"ibl_{s}.png" for s in cfg.scenes]
    files += [Path(out) / "ibl_render.json", Path(out) / "ibl_render.npz"]
    print("wrote " + ", ".join(str(f) for f in files))
    print(summary_table(summary))
    return 0


def _render_scene(args, scene: str, out: str, fail) -> int:
    """--scene sphere | bubble (`render.scene.render_scene`)."""
    from pathlib import Path

    from ..render.scene import SceneConfig, format_summary, make_material, render_scene

    if args.envmap and len(args.envmap) > 1:
        fail(f"--scene {scene} renders under one map; got {len(args.envmap)} --envmap")
    kw = dict(scene=scene, resolution=args.resolution or 128, exposure=args.exposure,
              observer=args.observer, ldr_srgb=args.ldr_srgb, elevation_deg=args.elevation)
    if args.envmap:
        kw["envmap"] = args.envmap[0]
    if scene == "sphere":
        if _given(args, ["--thickness-range"]):
            fail("--thickness-range applies to --scene bubble (use --thickness)")
        if args.layers is not None and (args.thickness is not None
                                        or args.film_index is not None):
            fail("--layers replaces --thickness and --eta-film (give one or the other)")
        kw["material"] = make_material(
            600.0 if args.thickness is None else args.thickness,
            1.2 if args.film_index is None else args.film_index,
            2.0 if args.base_index is None else args.base_index, layers=args.layers)
        if args.alpha is not None:
            kw["alpha"] = args.alpha
        if args.method:
            kw["methods"] = tuple(args.method)
        if args.bin_reads is not None:
            kw["bin_reads"] = args.bin_reads
        kw["light_spread"] = args.light_spread
        if args.quality is not None:
            kw["quality"] = args.quality
    else:
        given = _given(args, ["--method"] + [k for k, (_, takes) in OWN_SCENE_OPTIONS.items()
                                             if "bubble" not in takes])
        if given:
            fail(f"not an option of --scene bubble: {', '.join(given)} (a free-standing film, "
                 "air on both sides, mirror-smooth, exact; it takes --eta-film and "
                 "--thickness-range)")
        if args.film_index is not None:
            kw["eta_film"] = args.film_index
        if args.thickness_range is not None:
            kw["thickness_top"], kw["thickness_bottom"] = args.thickness_range
    try:
        cfg = SceneConfig(**kw)
    except ValueError as e:  # a method that cannot model the material: usage
        fail(str(e))
    summary = render_scene(cfg, out_dir=out, progress=not args.quiet)
    print(f"wrote {len(summary['files'])} files into {out}: "
          + ", ".join(Path(f).name for f in summary["files"]))
    print(format_summary(summary))
    print(f"total {summary['total_seconds']:.1f} s")
    return 0


def _fit(args) -> int:
    _enable_x64()
    from .fit import run_fit_cli

    return run_fit_cli(args)


def _index_arg(option: str):
    """argparse type of an index option (`interop.index_text.parse_index`): a usage error
    (exit 2) names the bundled materials."""
    def parse(text):
        from ..interop.index_text import parse_index

        try:
            return parse_index(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    parse.__name__ = option  # argparse's "invalid <name> value" if it ever shows
    return parse


def _layers_arg(text):
    """argparse type of --layers: [(index, thickness nm)] (`interop.index_text.parse_layers`)."""
    from ..interop.index_text import parse_layers

    try:
        return parse_layers(text, indices=True)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _add_render_parser(sub) -> None:
    """The ``render`` sub-command: one's own scene (`render.scene`) or the study scenes
    (`render.study_scenes`)."""
    from ..shading.envmap import SHIPPED
    from ..render.study_scenes import envmap_methods

    rd = sub.add_parser("render", help="a film or stack on a sphere, a soap bubble, or the "
                        "study scenes (Kneiphof Figs. 3-6), under an environment map",
                        description="Render one's own film or layer stack on a sphere (--scene "
                                    "sphere, the default: one linear EXR and one sRGB PNG per "
                                    "method, ΔE₀₀ maps against the reference, composite.png, "
                                    "render.npz, render.json), a soap bubble (--scene bubble), "
                                    "or the study scenes fig4/fig3/varying/carpaint (ibl_<scene>"
                                    ".png, ibl_render.json, ibl_render.npz) into --out "
                                    "(default: a new folder render-YYYYmmdd-HHMMSS; SPEC §9, "
                                    "§12). See docs/how-to/render.md.")
    rd.add_argument("--envmap", action="append", metavar="PATH_OR_NAME",
                    help=f"a .hdr/.exr file or a shipped map {sorted(SHIPPED)} (sphere, "
                         "bubble: one, default venice_sunset; study scenes: repeatable, "
                         "default the four shipped maps)")
    rd.add_argument("--ldr-srgb", dest="ldr_srgb", action="store_true",
                    help="read 8-/16-bit map files (PNG, JPEG) as sRGB, decoded to relative "
                         "radiance (white = 1); without it they are refused: display values "
                         "are not radiance")
    rd.add_argument("--scene", action="append",
                    choices=["sphere", "bubble", "fig4", "fig3", "varying", "carpaint"],
                    help="sphere (default): your film or stack (--thickness, --eta-film, "
                         "--eta-base, --layers, --alpha); bubble: a free-standing water film "
                         "thin at the top, thick at the bottom (--eta-film, "
                         "--thickness-range); study scenes (repeatable): fig4: α=0.25, "
                         "d=600 nm, η₂=1.2, η₃=2.0; fig3: roughness sweep, η₂=1.3, "
                         "η₃=2.0+0.5i, d=650 nm; varying: thickness texture; carpaint: the "
                         "example car paints, exact reference vs Kneiphof & Klein 2022's "
                         "colour table")
    rd.add_argument("--thickness", type=float, help="sphere: film thickness, nm (600)")
    rd.add_argument("--eta-film", dest="film_index", type=_index_arg("--eta-film"),
                    metavar="N|N+Kj|NAME|FILE",
                    help="film index: a number, a bundled material name (SiO2, Si3N4, "
                         "water, ...), or a refractiveindex.info .yml / .csv file (sphere: "
                         "1.2; bubble: water)")
    rd.add_argument("--eta-base", dest="base_index", type=_index_arg("--eta-base"),
                    metavar="N|N+Kj|NAME|FILE",
                    help="sphere: base index, e.g. 2.0+0.5j, Si, Au, or a file (2.0)")
    rd.add_argument("--layers", type=_layers_arg, metavar="MAT:NM[,MAT:NM...]",
                    help="sphere: a layer stack instead of one film, layer 0 facing the air, "
                         "e.g. \"SiO2:250,Si3N4:80\" on --eta-base Si (stacks and dispersive "
                         "films need an exact method: reference, mc)")
    rd.add_argument("--alpha", type=float, help="sphere: GGX roughness α in (0, 1] (0.25)")
    rd.add_argument("--thickness-range", dest="thickness_range", type=float, nargs=2,
                    metavar=("TOP", "BOTTOM"), help="bubble: film thickness at the top and "
                    "the bottom, nm (30 1200); d = top + (bottom - top)·sqrt(ψ/π)")
    rd.add_argument("--elevation", type=float, help="sphere, bubble: camera elevation above "
                    "the horizon, degrees (sphere 15, bubble 30)")
    rd.add_argument("--method", action="append",
                    choices=envmap_methods(),
                    help="methods, in columns (repeatable; sphere default: reference, "
                         "improved; study scenes: reference, ideal, filtered, improved)")
    rd.add_argument("--bin-reads", dest="bin_reads", type=int, metavar="G",
                    help="sphere, method improved: prefiltered reads per bin (1; 3 for maps "
                         "of many small lights: ≈ 2× the cost, docs/studies/improved.md)")
    rd.add_argument("--light-spread", dest="light_spread", action="store_true",
                    help="sphere, method improved: each bin's spread follows its light")
    rd.add_argument("--quality", choices=("fast", "default", "accurate"),
                    help="sphere, method improved: ModelOptions.preset (fast: K = 2 bins, "
                         "1.5× filtered's cost; default: K = 3, 2.3×; accurate: 3 reads a "
                         "bin, 4.6×)")
    rd.add_argument("--alphas", type=float, nargs="+", help="α of the fig3 sweep "
                    "(0.05 0.15 0.3 0.6)")
    rd.add_argument("--resolution", type=int, help="pixels per image side (sphere, bubble: "
                    "128; study scenes: 64)")
    rd.add_argument("--exposure", type=float, help="display exposure (default: the "
                    "reference's 99th-percentile luminance to 0.9)")
    rd.add_argument("--observer", choices=["stiles_burch_1959_10", "cie_1931_2"],
                    default="stiles_burch_1959_10")
    rd.add_argument("--out", help="output folder (default: a new folder "
                    "render-YYYYmmdd-HHMMSS in the current directory)")
    rd.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_device_options(rd)
    rd.set_defaults(func=_render, render_parser=rd)


def build_parser() -> argparse.ArgumentParser:
    """The ``thinfilm-jax`` parser; a sub-command's unset options stay None (the study's defaults
    apply, SPEC §7).

    Example:
        >>> args = build_parser().parse_args(["figure7", "--resolution", "32"])
        >>> args.command, args.resolution, args.out, args.thickness
        ('figure7', 32, 'figures', None)
    """
    from .. import __version__

    p = argparse.ArgumentParser(prog="thinfilm-jax", description=__doc__)
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    f7 = sub.add_parser("figure7", help="reproduce Figure 7 of Kneiphof et al. 2019",
                        description="Render the eight panels (a)-(h) and the ΔE error maps into "
                                    "--out (figure7.png, figure7_error.png, figure7.json, "
                                    "figure7.npz). Defaults follow SPEC §7.")
    f7.add_argument("--out", default="figures", help="output folder (default: figures)")
    f7.add_argument("--resolution", type=int, help="pixels per panel side (default 64; paper 256)")
    f7.add_argument("--eta-film", dest="eta_film", type=float, help="film IOR η₂ (1.3)")
    f7.add_argument("--eta-base", dest="eta_base", type=float, help="base IOR η₃ (2.0)")
    f7.add_argument("--kappa-base", dest="kappa_base", type=float, help="base κ₃ (0.5)")
    f7.add_argument("--thickness", type=float, help="film thickness of row (a)-(d), nm (600)")
    f7.add_argument("--alpha", type=float, help="GGX α of row (e)-(h) (0.25)")
    f7.add_argument("--thickness-max", dest="thickness_max", type=float,
                    help="largest thickness of row (e)-(h), nm (1000)")
    f7.add_argument("--observer", choices=["stiles_burch_1959_10", "cie_1931_2"])
    f7.add_argument("--terms", type=int, help="Fourier orders M of the real-time methods (2)")
    f7.add_argument("--quadrature", type=int, nargs=2, metavar=("N_U", "N_PHI"),
                    help="half-vector quadrature orders (n_u, n_phi) (32 32)")
    f7.add_argument("--shat", choices=["exact", "lut", "gaussian"],
                    help="filtered Ŝ source of K 29 (exact)")
    f7.add_argument("--exposure", type=float, help="display exposure for all panels (2.0)")
    f7.add_argument("--quiet", action="store_true", help="no progress bar")
    f7.add_argument("--timing", metavar="PATH", help="also write the run's times, device and "
                    "load average to PATH as JSON (`make bench`: figures/figure7_timing.json); "
                    "--out holds the results only, the same on every run")
    _add_device_options(f7)
    f7.set_defaults(func=_figure7)

    _add_render_parser(sub)
    # listed for --help; `main` hands everything after "bench" to the clone's command
    sub.add_parser("bench", add_help=False, help="the studies of a clone's benchmarks/ folder "
                   "(python -m benchmarks.bench; --help lists its options)")

    from . import fit as fit_cli

    ft = sub.add_parser("fit", help="fit film parameters to observed patch colours or spectra",
                        description=fit_cli.__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    fit_cli.add_arguments(ft)
    ft.set_defaults(func=_fit)

    from . import fit_map as fit_map_cli

    fit_map_cli.add_parser(sub)
    from . import fit_ellips as fit_ellips_cli

    fit_ellips_cli.add_parser(sub)
    return p


def main(argv=None) -> int:
    from ._checks import check_args, run_command

    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:
        return _bench(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    check_args(parser, args)  # out-of-range options: usage error before any work
    from ..core.compilation_cache import enable_compilation_cache

    enable_compilation_cache()  # opt out: THINFILM_JAX_NO_CACHE=1
    return run_command(args)  # Ctrl-C and bad input found later: one line, no traceback


if __name__ == "__main__":
    sys.exit(main())
