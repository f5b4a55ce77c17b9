r"""Uneven light, over-exposure and too few pads (SPEC §14): `fit_photo`'s smooth light field
and its flags of what it cannot explain, on photographs rendered independently of its model
(`benchmarks.photo_scenes`).

``python -m benchmarks.photo_light --out figures`` writes figures/photo_light.json
and photo_light.md (``--size``: the photographs' side, default 160).

**Scenarios** (fixed seed):

* *uneven light*: the oxide wafer of `photo_scenes.oxide_thickness` (SiO₂ on Si), a 16-bit
  linear TIFF by the Nikon (known camera, D65), lit by a lamp off to one side (inverse-square
  falloff with the cosine of incidence, from a point at (−0.6, 0.3) of the frame's width, 1.2
  widths above the wafer) through a lens vignetting as cos⁴ of the field angle (a 35° half
  diagonal), the product scaled to 1 at its peak and 0.55 in the darkest corner (`light_field`;
  not in the fit's family). Bare-Si terrace as reference. Fitted with
  ``illumination="uniform"`` and ``"smooth"``; the same wafer evenly lit as the baseline.
* *over-exposed JPEG*: the soap film of `photo_scenes.soap_thickness` as an 8-bit sRGB JPEG
  (quality 90, D50) exposed 1.6 × the study's exposure, so that bright fringes clip.
* *pads*: the oxide wafer by the Nikon, ``camera="unknown"``, anchored by four terraces
  against all six.

Per row: median |error|, the share within 15 nm (the right fringe order), the share wrong, the
share of the wrong flagged `ambiguous`, the share of the right flagged, reduced χ² (mean and
robust), the fit's time and pixels per second.

Example (the light field's range):
    >>> from benchmarks.photo_light import light_field
    >>> f = light_field(64)
    >>> round(float(f.max()), 6), round(float(f.min()), 6)
    (1.0, 0.55)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from .photo_scenes import (SOAP_RANGE, apply_table, camera_table, encode_srgb8, oxide_thickness,
                           reflectance_table, sensor, soap_thickness, templates, write_image,
                           xyz_table, xyz_to_srgb)

NIKON = "Nikon 5100 (NPL)"
SEED = 20261206
CORNER = 0.55  # the darkest corner's light / the peak's
OXIDE_EXPOSURE = 1.6  # as photo_study's oxide photographs
SOAP_EXPOSURE, SOAP_LIGHT, SOAP_WB = 7.0 * 1.6, "D50", (1.08, 1.0, 0.93)
FOUR_PADS = (0, 1, 3, 4)
RIGHT_NM = 15.0


def light_field(n: int, corner: float = CORNER) -> np.ndarray:
    """(n, n) the light reaching the sensor relative to its peak: a lamp at (−0.6, 0.3, 1.2)
    (frame widths; the frame is the unit square, y down), E ∝ cos θ / r², times cos⁴ of the
    lens's field angle (35° at the corners), mapped affinely in log so that the peak is 1
    and the darkest pixel `corner`."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    dx, dy, dz = x + 0.6, y - 0.3, 1.2
    r2 = dx * dx + dy * dy + dz * dz
    lamp = dz / r2 ** 1.5
    rr = np.hypot(x - 0.5, y - 0.5) / np.hypot(0.5, 0.5)
    vig = np.cos(np.arctan(rr * np.tan(np.deg2rad(35.0)))) ** 4
    f = np.log(lamp * vig)
    f = (f - f.max()) / (f.max() - f.min()) * -np.log(corner)
    return np.exp(f)


def render(n: int, folder) -> dict:
    """The scenarios' photographs in `folder`: {key: path}, the truth maps and the pads."""
    rng = np.random.default_rng(SEED)
    folder = Path(folder)
    tpl = templates()
    oxide, pads = oxide_thickness(n)
    d_g, lam, r = reflectance_table(tpl["oxide"], 901.0, 380.0, 780.0)
    raw, _ = camera_table(r, lam, NIKON, "D65")
    colours = OXIDE_EXPOSURE * apply_table(d_g, raw, oxide)
    paths = {}
    for key, field in (("even", 1.0), ("uneven", light_field(n)[..., None])):
        v = sensor(colours * field, rng)
        paths[key] = write_image(folder / f"oxide_{key}.tif",
                                 np.round(v * 65535).astype(np.uint16))
    soap = soap_thickness(n)
    d_g, lam, r = reflectance_table(tpl["soap"], SOAP_RANGE[1] + 1.0, 360.0, 830.0)
    xyz_t, white = xyz_table(r, lam, SOAP_LIGHT)
    xyz = sensor(SOAP_EXPOSURE * apply_table(d_g, xyz_t, soap), rng)
    v = np.clip(np.asarray(SOAP_WB) * xyz_to_srgb(xyz, white), 0.0, 1.0)
    paths["soap_over"] = write_image(folder / "soap_over.jpg", encode_srgb8(v), quality=90)
    return {"paths": paths, "oxide": oxide, "soap": soap, "pads": pads}


# ----------------------------------------------------------------------------- the rows
#: (key, label, photograph, truth, fit keywords, reference pad indices)
ROWS = (
    ("even", "oxide, even light, uniform fit", "even", "oxide", {}, (0,)),
    ("uneven-uniform", "oxide, uneven light (55 % corner), uniform fit", "uneven", "oxide",
     {}, (0,)),
    ("uneven-smooth", "oxide, uneven light (55 % corner), smooth fit", "uneven", "oxide",
     {"illumination": "smooth"}, (0,)),
    ("uneven-smooth-noref", "oxide, uneven light, smooth fit, no reference", "uneven",
     "oxide", {"illumination": "smooth"}, ()),
    ("soap-over", "soap, sRGB JPEG q90 over-exposed 1.6 ×", "soap_over", "soap",
     {"camera": "srgb", "encoding": "srgb", "illuminant": SOAP_LIGHT,
      "thickness_range": (0.0, 1600.0)}, ()),
    ("pads-4", "oxide, camera unknown, 4 pads", "even", "oxide", {"camera": "unknown"},
     FOUR_PADS),
    ("pads-6", "oxide, camera unknown, all 6 pads", "even", "oxide", {"camera": "unknown"},
     tuple(range(6))),
)


def score(res, truth, exclude) -> dict:
    """The row's numbers (module docstring) over the fitted pixels outside `exclude`."""
    d = np.asarray(res.thickness)
    ok = np.isfinite(d) & ~exclude
    err = np.abs(d - truth)[ok]
    right = err < RIGHT_NM
    amb = np.asarray(res.ambiguous)[ok]
    return {"median_abs_nm": float(np.median(err)), "within_15nm_pct": 100 * float(right.mean()),
            "wrong_pct": 100 * float((~right).mean()),
            "wrong_flagged_pct": 100 * float(amb[~right].mean()) if (~right).any() else None,
            "right_flagged_pct": 100 * float(amb[right].mean()) if right.any() else None,
            "reduced_chi2": float(res.reduced_chi2), "robust_chi2": float(res.robust_chi2),
            "pixels": int(ok.sum())}


def run(out="figures", size: int = 160, verbose: bool = True) -> dict:
    """Render, fit every row twice (the second call's time: compiled) and write
    ``out/photo_light.{json,md}``; returns the result."""
    import jax

    from thinfilm_jax.fit.photo import fit_photo
    from ._timing import environment, write_report

    if not jax.config.jax_enable_x64:
        raise RuntimeError("the photo light study needs float64: "
                           "jax.config.update('jax_enable_x64', True)")
    tpl = templates()
    rows = []
    with tempfile.TemporaryDirectory(prefix="photo_light-") as folder:
        sc = render(size, folder)
        for key, label, photo, scene, kw, pads in ROWS:
            ref = [sc["pads"][i] for i in pads]
            exclude = np.zeros((size, size), bool)
            for m, _ in ref:
                exclude |= m
            args = {"camera": NIKON, "encoding": "linear", "thickness_range": (0.0, 900.0),
                    **kw}
            for _ in range(2):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    res = fit_photo(str(sc["paths"][photo]), tpl[scene], reference=ref or None,
                                    **args)
                    seconds = time.perf_counter() - t0
            row = {"key": key, "label": label, **score(res, sc[scene], exclude),
                   "seconds": seconds, "pixels_per_s": res.n_pixels / seconds,
                   "warnings": list(res.warnings)}
            rows.append(row)
            if verbose:
                print(f"[photo_light] {key}: median {row['median_abs_nm']:.3g} nm, "
                      f"{row['within_15nm_pct']:.2f} % within 15 nm, wrong flagged "
                      f"{row['wrong_flagged_pct']}, {seconds:.2f} s", file=sys.stderr,
                      flush=True)
    by = {r["key"]: r for r in rows}
    cost = by["uneven-smooth"]["seconds"] / by["uneven-uniform"]["seconds"]
    result = {"size": size, "seed": SEED, "corner": CORNER, "rows": rows,
              "smooth_cost_vs_uniform": cost, "environment": environment()}
    write_report(out, "photo_light", result, markdown)
    return result


def markdown(res: dict) -> str:
    def cell(v, spec=".3g"):
        return "–" if v is None else format(v, spec)

    lines = [f"# Uneven light, over-exposure and too few pads ({res['size']}² photographs, "
             f"seed {res['seed']})", "",
             "`python -m benchmarks.photo_light` (`benchmarks/photo_light.py`).", "",
             "| row | median \\|err\\| nm | within 15 nm % | wrong % | wrong flagged % | "
             "right flagged % | χ²ᵣ (mean / robust) | s |", "|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['label']} | {cell(r['median_abs_nm'])} | "
                     f"{cell(r['within_15nm_pct'], '.2f')} | {cell(r['wrong_pct'], '.2f')} | "
                     f"{cell(r['wrong_flagged_pct'], '.1f')} | "
                     f"{cell(r['right_flagged_pct'], '.1f')} | {cell(r['reduced_chi2'])} / "
                     f"{cell(r['robust_chi2'])} | {r['seconds']:.2f} |")
    lines += ["", f"The smooth fit's time over the uniform fit's on the uneven photograph: "
              f"{res['smooth_cost_vs_uniform']:.2f} × (second calls, compiled).", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    import jax

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="figures")
    ap.add_argument("--size", type=int, default=160)
    a = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    print(markdown(run(a.out, a.size)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
