"""``thinfilm-jax fit-map PHOTO --camera NAME ...``: a thickness map from a photograph
(`thinfilm_jax.fit.photo.fit_photo`, SPEC §13).

With ``--camera`` the image is a photograph: PNG, JPEG, TIFF (8 or 16 bit), EXR / HDR, or a
camera RAW file (rawpy), decoded as ``--encoding`` says (srgb, linear, raw; the line printed
first says which was assumed). The camera is a colour-science camera name, a CSV of
sensitivities (header ``wavelength_nm,r,g,b``), ``srgb`` (a colorimetric sRGB image) or
``unknown`` (fitted on ``--reference`` regions); the light is a CIE illuminant name
(``--illuminant``, default D65) or a CSV spectrum (``wavelength_nm,power``). The film is
``--eta-film`` on ``--eta-base`` (numbers or materials: ``--eta-film SiO2 --eta-base Si``),
the unknown thickness its only layer. Exposure and white balance are always fitted.

``--reference MASK.png:THICKNESS_NM`` (repeatable) names regions of known thickness: a mask
image of the photograph's size (nonzero = inside), e.g. the bare substrate at 0 nm.

Writes into ``--out`` (default ``fit_map``), each file atomically and only after the fit
succeeded (a bad input leaves nothing behind): ``thickness.npy``, ``stderr.npy``,
``ambiguous.npy`` (H, W), ``maps.exr`` (channels thickness, stderr, ambiguous), a PNG
``thickness.png`` (the map with a colour bar, ambiguous pixels hatched) and
``fit_photo.json`` (settings, exposure, white balance, camera matrix, reduced χ², residual
summary, warnings, timing). A reduced χ² above 4 means the model does not explain the photo:
the warning is printed and stored, and the exit status stays 0 (the files are written) unless
``--strict``, which makes it exit 3.

``--gltf DIR`` also writes the map as a glTF 2.0 asset (as for band images: ``DIR/fit_map.gltf``,
``.bin``, ``_thickness.png``); a dispersive material (water, TiO2) is written with its index
at ``--gltf-wavelength`` (550 nm), recorded in the material's ``extras``; a mirror fit
(no ``--alpha``) is written with roughness 0; unfitted pixels (outside ``--mask``) take their
nearest fitted pixel's thickness.

Example::

    thinfilm-jax fit-map wafer.tif --camera "Nikon 5100 (NPL)" --encoding linear \\
        --eta-film SiO2 --eta-base Si --reference bare.png:0 --thickness-range 0 1000
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["PHOTO_SUFFIXES", "add_arguments", "run_photo"]

#: photograph suffixes that need --camera (the band-radiance path reads .npy/.exr/.hdr)
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
#: exit status of --strict when the fit warns that the model does not explain the photo
MISFIT_EXIT = 3


def add_arguments(p) -> None:
    """The photograph options of ``fit-map`` (`cli.fit_map.add_parser` calls this).

    Example (what a photograph's command line parses to):
        >>> from thinfilm_jax.cli.main import build_parser
        >>> a = build_parser().parse_args(["fit-map", "wafer.tif", "--camera", "srgb",
        ...                                "--eta-film", "SiO2", "--eta-base", "Si",
        ...                                "--reference", "bare.png:0"])
        >>> a.camera, a.illuminant, a.encoding, a.reference, a.strict
        ('srgb', 'D65', None, ['bare.png:0'], False)
    """
    g = p.add_argument_group("photographs (SPEC §13; --camera selects this mode)")
    g.add_argument("--camera", metavar="NAME|CSV|srgb|unknown",
                   help="the camera: a colour-science name (e.g. 'Nikon 5100 (NPL)'), a CSV "
                        "of sensitivities, srgb (a colorimetric sRGB image) or unknown "
                        "(fitted on --reference regions)")
    g.add_argument("--illuminant", default="D65", metavar="NAME|CSV",
                   help="the light: a CIE illuminant name (D65) or a CSV spectrum")
    g.add_argument("--encoding", choices=["srgb", "linear", "raw"],
                   help="how the pixel values encode light (default: srgb for 8/16-bit "
                        "files, linear for EXR/HDR, raw for camera RAW)")
    g.add_argument("--bit-depth", dest="bit_depth", type=int, choices=[8, 16],
                   help="the bit depth you expect (checked against the file)")
    g.add_argument("--reference", action="append", default=[], metavar="MASK:NM",
                   help="a region of known thickness: MASK.png:THICKNESS_NM (repeatable)")
    g.add_argument("--mask", metavar="MASK.png", help="pixels to fit (default: all)")
    g.add_argument("--illumination", choices=["uniform", "smooth"], default="uniform",
                   help="uniform light, or a smooth light field across the frame (vignetting, "
                        "a lamp off to one side) fitted with the map")
    g.add_argument("--strict", action="store_true",
                   help=f"exit {MISFIT_EXIT} when the model does not explain the photograph")


def _reference(specs) -> list:
    out = []
    for spec in specs:
        path, sep, nm = spec.rpartition(":")
        if not sep or not path:
            raise ValueError(f"--reference {spec!r}: expected MASK.png:THICKNESS_NM")
        try:
            t = float(nm)
        except ValueError:
            raise ValueError(f"--reference {spec!r}: {nm!r} is not a thickness in nm") from None
        if not Path(path).is_file():
            raise ValueError(f"--reference {spec!r}: no such file {path}")
        out.append((path, t))
    return out


def _illuminant(text: str):
    if text.lower().endswith(".csv"):
        path = Path(text)
        if not path.is_file():
            raise ValueError(f"--illuminant {text}: no such file")
        a = np.genfromtxt(path, delimiter=",", names=True)
        names = [n.lower() for n in a.dtype.names]
        if names[:2] != ["wavelength_nm", "power"]:
            raise ValueError(f"--illuminant {text}: the header must be wavelength_nm,power")
        return np.stack([a[a.dtype.names[0]], a[a.dtype.names[1]]], axis=-1)
    return text


def _save_exr(path: Path, maps) -> None:
    import OpenImageIO as oiio

    from ..core.files import atomic_write

    data = np.ascontiguousarray(np.stack(maps, axis=-1).astype(np.float32))

    def write(tmp):
        spec = oiio.ImageSpec(data.shape[1], data.shape[0], data.shape[2], oiio.FLOAT)
        spec.channelnames = ("thickness", "stderr", "ambiguous")
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise OSError(f"cannot write {path}: {oiio.geterror()}")
        out.write_image(data)
        out.close()

    atomic_write(path, write, suffix=".exr")


def photo_title(name: str, res, eta_film: str, eta_base: str, smoothness) -> str:
    """The thickness figure's title: the photograph, camera, light, materials, the neighbour
    prior's τ where one was used, and the reduced χ² as the console says it.

    Example:
        >>> from types import SimpleNamespace as NS
        >>> res = NS(thickness=[[0.0] * 4] * 3, camera="srgb", illuminant="D65",
        ...          chi2_text="reduced chi2 = 1.1 (robust; mean 1.3)", exposure=0.5)
        >>> print(photo_title("w.png", res, "SiO2", "Si", None))
        w.png: 4×3, camera srgb, D65, η₂=SiO2 on η₃=Si
        reduced chi2 = 1.1 (robust; mean 1.3), exposure 0.5; hatched: ambiguous fringe order
    """
    h, w = np.shape(res.thickness)
    prior = f", τ={float(smoothness):g} nm" if smoothness else ""
    return (f"{name}: {w}×{h}, camera {res.camera}, {res.illuminant}, "
            f"η₂={eta_film} on η₃={eta_base}{prior}\n{res.chi2_text}, "
            f"exposure {res.exposure:.3g}; hatched: ambiguous fringe order")


def run_photo(args) -> int:
    """Fit, then write every output (module docstring); returns the exit status."""
    import warnings

    from ._checks import _enable_x64

    image = Path(args.image)
    if not image.is_file():
        raise ValueError(f"PHOTO {image}: no such file")
    reference = _reference(args.reference)
    _enable_x64()
    from ..core.film import Film
    from ..fit.photo import fit_photo

    template = Film(0.0, args.eta_film_index.value, args.eta_base_index.value,
                    args.kappa_base, args.eta_outer_index.value)
    alpha = getattr(args, "alpha", None)
    theta = np.deg2rad(args.theta_o or 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # printed below, from the result
        res = fit_photo(str(image), template, camera=args.camera,
                        illuminant=_illuminant(args.illuminant), encoding=args.encoding,
                        bit_depth=args.bit_depth, reference=reference or None,
                        theta_o=theta, alpha=alpha, thickness_range=tuple(args.thickness_range),
                        smoothness_nm=args.smoothness, mask=args.mask,
                        progress=not args.quiet, illumination=args.illumination)
    print(f"read {res.encoding}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..core.files import atomic_write, write_json

    d, se, amb = res.thickness, res.stderr, res.ambiguous
    for name, a in (("thickness", d), ("stderr", se), ("ambiguous", amb)):
        atomic_write(out / f"{name}.npy", lambda tmp, a=a: np.save(tmp, a))
    _save_exr(out / "maps.exr", (d, se, amb.astype(float)))
    h, w = d.shape
    title = photo_title(image.name, res, args.eta_film_index.text, args.eta_base_index.text,
                        args.smoothness)
    from ._output import save_thickness_png

    save_thickness_png(out / "thickness.png", d, title, amb)
    gltf = None
    if args.gltf is not None:
        from ._output import write_map_gltf

        gltf = write_map_gltf(args, template._replace(thickness=d), alpha)
    summary = {"photo": str(image), "shape": [h, w],
               "settings": {"camera": args.camera, "illuminant": args.illuminant,
                            "encoding": args.encoding, "bit_depth": args.bit_depth,
                            "reference": [f"{p}:{t:g}" for p, t in reference],
                            "mask": args.mask, "eta_film": args.eta_film_index.text,
                            "eta_base": args.eta_base_index.text,
                            "theta_o_deg": args.theta_o or 0.0, "alpha": alpha,
                            "thickness_range": list(args.thickness_range),
                            "smoothness_nm": args.smoothness, "gltf": args.gltf,
                            "gltf_bits": args.gltf_bits,
                            "gltf_wavelength": args.gltf_wavelength,
                            "illumination": args.illumination},
               **res.summary(),
               "outputs": ["thickness.npy", "stderr.npy", "ambiguous.npy", "maps.exr",
                           "thickness.png", "fit_photo.json"]}
    if gltf is not None:
        summary["gltf"] = gltf
    write_json(out / "fit_photo.json", summary)
    ok = np.isfinite(d)
    print(f"wrote {out}/thickness.png, maps.exr, thickness.npy, stderr.npy, ambiguous.npy, "
          f"fit_photo.json: {int(ok.sum())} pixels, thickness {np.nanmin(d):.1f}–"
          f"{np.nanmax(d):.1f} nm, median stderr {np.nanmedian(se):.2f} nm, "
          f"{100 * amb.mean():.1f} % ambiguous; exposure {res.exposure:.4g}, white balance "
          f"{np.round(res.white_balance, 4).tolist()}, {res.chi2_text}; "
          f"{res.pixels_per_second:.0f} pixels/s")
    if gltf is not None:
        from ._output import gltf_line

        print(gltf_line(gltf))
    for note in res.warnings:
        print(f"warning: {note}")
    misfit = any("reduced chi2" in note for note in res.warnings)
    return MISFIT_EXIT if misfit and args.strict else 0
