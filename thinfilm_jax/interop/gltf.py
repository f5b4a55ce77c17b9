r"""A `Film` to and from a glTF 2.0 material with `KHR_materials_iridescence` (SPEC §10).

Sources: the ratified extension (KhronosGroup/glTF, `extensions/2.0/Khronos/
KHR_materials_iridescence/README.md` and `schema/material.KHR_materials_iridescence.schema.json`),
`KHR_materials_ior` (`ior`, default 1.5, minimum 1) and the core
`material.pbrMetallicRoughness.schema.json` (`metallicFactor`, default **1.0**).

Mapping (SPEC §1 notation):

| glTF                                   | `Film`                                              |
|----------------------------------------|-----------------------------------------------------|
| `iridescenceIor` (1.3; draft spelling `iridescenceIOR`) | η₂                                   |
| `iridescenceThicknessMaximum` (400 nm) | d, when there is no thickness texture               |
| mix(`…Minimum` (100), `…Maximum`, texture G) | d per texel (`thickness_from_texture`)        |
| `KHR_materials_ior.ior` (1.5), `metallicFactor` = 0 | η₃, κ₃ = 0                             |
| outside medium (air)                   | η₁ = 1                                              |
| `iridescenceFactor` (0) × texture R     | the returned factor (`iridescence_mix`)             |

What glTF cannot hold is a `ValueError`, never dropped: κ₃ > 0 and η₁ ≠ 1 on export; on
import a metallic base (`metallicFactor` > 0 — also when `pbrMetallicRoughness` is omitted,
glTF's default is 1 — whose Fresnel is the Schlick tint `baseColor`, not an η₃ + iκ₃) unless
the caller supplies ``eta_base=``/``kappa_base=``, a partly metallic base, and
`KHR_materials_specular` (it scales F₀: no single η₃). The schema's ranges are checked
(factor in [0, 1], IOR ≥ 1, thicknesses ≥ 0, finite numbers; unknown fields rejected). The
extension allows `iridescenceThicknessMinimum` > `…Maximum` (README: "MAY be greater"): it is
read as written, an inverted mapping.

Thickness maps travel as an `iridescenceThicknessTexture` PNG written with OpenImageIO
(`write_thickness_texture`: G channel, R = B = 0, linear — a gAMA 1.0 chunk —, minimum and
maximum covering the map so that no code is wasted; 8-bit by default, 16-bit on request).
Read back (`read_thickness_texture`) the map is reproduced to the PNG quantisation,
|Δd| ≤ (max − min)/(2(2ᵇ − 1)) (tests/interop/test_interop.py).

Example (the round trip is exact; JSON keeps every float64):
    >>> import json
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.interop.gltf import film_from_gltf, film_to_gltf
    >>> material = film_to_gltf(Film(350.0, 1.33, 1.52), factor=0.8)
    >>> material["extensions"]["KHR_materials_iridescence"]["iridescenceThicknessMaximum"]
    350.0
    >>> film_from_gltf(json.loads(json.dumps(material)))
    (Film(thickness=350.0, eta_film=1.33, eta_base=1.52, kappa_base=0.0, eta_outer=1.0), 0.8)
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core._io import atomic_write, write_json
from ..core.film import Film

EXTENSION = "KHR_materials_iridescence"
IOR_EXTENSION = "KHR_materials_ior"
#: The schema's defaults (material.KHR_materials_iridescence.schema.json).
DEFAULTS = {"iridescenceFactor": 0.0, "iridescenceIor": 1.3,
            "iridescenceThicknessMinimum": 100.0, "iridescenceThicknessMaximum": 400.0}
FIELDS = (*DEFAULTS, "iridescenceIOR", "iridescenceTexture", "iridescenceThicknessTexture",
          "extensions", "extras")
#: `KHR_materials_ior` default (its schema) and glTF's default `metallicFactor`.
DEFAULT_IOR, DEFAULT_METALLIC = 1.5, 1.0


def mix(x, y, a):
    """GLSL mix(x, y, a) = x(1 − a) + y·a (exact at a = 0 and a = 1)."""
    return x * (1.0 - a) + y * a


def thickness_from_texture(g, minimum=DEFAULTS["iridescenceThicknessMinimum"],
                           maximum=DEFAULTS["iridescenceThicknessMaximum"]):
    """d = mix(`iridescenceThicknessMinimum`, `…Maximum`, texture.g) in nm (the README)."""
    return mix(minimum, maximum, g)


def iridescence_mix(f_base, f_iridescence, factor):
    """F = mix(F_schlick, F_iridescence, iridescence) with iridescence = `iridescenceFactor` ×
    texture.r: the extension's blend (README, implementation notes; for a metal base the
    ratified notes blend the conductor Fresnel with the same weight). Broadcasts; JAX-traceable.

    Example:
        >>> float(iridescence_mix(0.04, 0.2, 0.25))
        0.08
    """
    return mix(jnp.asarray(f_base), jnp.asarray(f_iridescence), jnp.asarray(factor))


def _number(where: str, value, lo=None, hi=None) -> float:
    """A finite JSON number in [lo, hi], as a Python float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{where} must be finite, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ValueError(f"{where} must lie in [{lo}, {hi if hi is not None else 'inf'}], "
                         f"got {value!r}")
    return value


def _mapping(where: str, value) -> Mapping:
    if not isinstance(value, Mapping):
        raise ValueError(f"{where} must be a JSON object, got {type(value).__name__}")
    return value


def _texture_values(where: str, values, present: bool, keyword: str):
    if present and values is None:
        raise ValueError(f"the material has {where}: pass {keyword}= (its sampled channel, "
                         f"values in [0, 1]), or use read_gltf, which reads the image")
    if not present:
        if values is not None:
            raise ValueError(f"{keyword}= was given but the material has no {where}")
        return None
    values = np.asarray(values, float)
    if not np.all(np.isfinite(values)) or np.any((values < 0) | (values > 1)):
        raise ValueError(f"{keyword} must be finite texture values in [0, 1]")
    return values


def _base(material: Mapping, eta_base, kappa_base):
    """(η₃, κ₃) of the material's base (module docstring)."""
    extensions = material.get("extensions", {})
    if "KHR_materials_specular" in extensions:
        raise ValueError("KHR_materials_specular scales the base F0 (specular, specularColor): "
                         "no single eta_base + i kappa_base holds it")
    pbr = _mapping("material.pbrMetallicRoughness", material.get("pbrMetallicRoughness", {}))
    metallic = _number("pbrMetallicRoughness.metallicFactor",
                       pbr.get("metallicFactor", DEFAULT_METALLIC), 0.0, 1.0)
    if metallic > 0 and "metallicRoughnessTexture" in pbr:
        raise ValueError("metalness varies over metallicRoughnessTexture: one Film cannot "
                         "hold it")
    if 0 < metallic < 1:
        raise ValueError(f"metallicFactor = {metallic} mixes a metal and a dielectric base: "
                         f"one Film cannot hold it")
    if metallic == 1:
        if eta_base is None:
            raise ValueError("a metallic base (metallicFactor = 1; glTF's default when "
                             "pbrMetallicRoughness omits it) has a Schlick tint (baseColor), "
                             "no eta + i kappa: pass eta_base= and kappa_base=")
        return (_number("eta_base", eta_base, 0.0),
                _number("kappa_base", 0.0 if kappa_base is None else kappa_base, 0.0))
    if eta_base is not None or kappa_base is not None:
        raise ValueError("eta_base=/kappa_base= are for metallic bases; a dielectric base is "
                         "the material's KHR_materials_ior (default 1.5)")
    ior_ext = _mapping(IOR_EXTENSION, extensions.get(IOR_EXTENSION, {}))
    unknown = set(ior_ext) - {"ior", "extensions", "extras"}
    if unknown:
        raise ValueError(f"unknown {IOR_EXTENSION} field(s) {sorted(unknown)}")
    return _number(f"{IOR_EXTENSION}.ior", ior_ext.get("ior", DEFAULT_IOR), 1.0), 0.0


def film_from_gltf(material, *, eta_base=None, kappa_base=None, thickness_g=None,
                   factor_r=None) -> tuple[Film, float | np.ndarray]:
    """(`Film`, iridescence factor) of a glTF material carrying `KHR_materials_iridescence`.

    Args:
        material: one entry of a glTF document's `materials` (a dict, as `json.load` gives).
        eta_base, kappa_base: the base η₃ + iκ₃ of a metallic material (`metallicFactor` = 1),
            which glTF describes by a Schlick tint only; rejected for a dielectric base.
        thickness_g: the sampled G values of `iridescenceThicknessTexture` (required when the
            material has one; the film's thickness is then the array
            mix(minimum, maximum, g)).
        factor_r: the sampled R values of `iridescenceTexture` (required when present; the
            factor is then `iridescenceFactor` × r).

    Returns: ``(Film(d, η₂, η₃, κ₃, 1.0), factor)`` with Python floats (arrays where a
    texture is sampled). Raises ValueError on what the module docstring lists.
    """
    material = _mapping("material", material)
    extensions = _mapping("material.extensions", material.get("extensions", {}))
    if EXTENSION not in extensions:
        raise ValueError(f"the material has no extensions.{EXTENSION}")
    ext = _mapping(f"extensions.{EXTENSION}", extensions[EXTENSION])
    unknown = set(ext) - set(FIELDS)
    if unknown:
        raise ValueError(f"unknown {EXTENSION} field(s) {sorted(unknown)}; the schema has "
                         f"{list(FIELDS)}")
    if "iridescenceIor" in ext and "iridescenceIOR" in ext:
        raise ValueError("both iridescenceIor and the draft spelling iridescenceIOR are given")
    ior = ext.get("iridescenceIor", ext.get("iridescenceIOR", DEFAULTS["iridescenceIor"]))
    eta_film = _number(f"{EXTENSION}.iridescenceIor", ior, 1.0)
    factor = _number(f"{EXTENSION}.iridescenceFactor",
                     ext.get("iridescenceFactor", DEFAULTS["iridescenceFactor"]), 0.0, 1.0)
    lo, hi = (_number(f"{EXTENSION}.{k}", ext.get(k, DEFAULTS[k]), 0.0)
              for k in ("iridescenceThicknessMinimum", "iridescenceThicknessMaximum"))
    g = _texture_values("iridescenceThicknessTexture", thickness_g,
                        "iridescenceThicknessTexture" in ext, "thickness_g")
    r = _texture_values("iridescenceTexture", factor_r, "iridescenceTexture" in ext, "factor_r")
    thickness = hi if g is None else thickness_from_texture(g, lo, hi)
    if r is not None:
        factor = factor * r
    eta3, kappa3 = _base(material, eta_base, kappa_base)
    return Film(thickness, eta_film, eta3, kappa3, 1.0), factor


def _scalar(name: str, x) -> float:
    a = np.asarray(x)
    if a.size != 1:
        raise ValueError(f"film.{name} must be one value for a glTF material, got shape "
                         f"{a.shape} (a thickness map: write_gltf writes it as a texture)")
    return float(a.reshape(()))


def film_to_gltf(film: Film, factor=1.0) -> dict:
    """A glTF material (dict) holding `film` exactly: `KHR_materials_iridescence` (factor, IOR
    η₂, maximum = d, no texture), `KHR_materials_ior` (η₃) and `metallicFactor` 0 (glTF's
    default 1 would make the base a metal). κ₃ > 0, η₁ ≠ 1 or η₃ < 1 → ValueError."""
    film = V.check_film(film)
    d, eta2, eta3, kappa3, eta1 = (_scalar(k, v) for k, v in film._asdict().items())
    if kappa3 != 0:
        raise ValueError(f"glTF cannot hold an absorbing base (kappa_base = {kappa3!r}): its "
                         f"metals are a Schlick tint (baseColor), its dielectrics a real IOR")
    if eta1 != 1:
        raise ValueError(f"glTF's film sits under air (eta_outer = 1); got {eta1!r}")
    if eta3 < 1:
        raise ValueError(f"KHR_materials_ior needs ior >= 1; got eta_base = {eta3!r}")
    factor = _number("factor", factor, 0.0, 1.0)
    return {"pbrMetallicRoughness": {"metallicFactor": 0.0},
            "extensions": {
                EXTENSION: {"iridescenceFactor": factor, "iridescenceIor": eta2,
                            "iridescenceThicknessMaximum": d},
                IOR_EXTENSION: {"ior": eta3}}}


# ------------------------------------------------------------------------------ textures
def write_thickness_texture(path, thickness, *, bits: int = 8) -> tuple[float, float]:
    """Write a thickness map (H, W) in nm as an `iridescenceThicknessTexture` PNG (OpenImageIO).

    G = (d − min)/(max − min) quantised to `bits` (8 or 16), R = B = 0, linear (gAMA 1.0);
    min and max are the map's, so the codes cover it. A constant map writes G = 1 (then
    min = max = d). Returns (minimum, maximum) for the material.
    """
    import OpenImageIO as oiio

    d = np.asarray(thickness, float)
    if d.ndim != 2 or d.size == 0:
        raise ValueError(f"thickness must be a map (H, W), got shape {d.shape}")
    if not np.all(np.isfinite(d)) or np.any(d < 0):
        raise ValueError("thickness must be finite and >= 0 nm")
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits!r}")
    lo, hi = float(d.min()), float(d.max())
    top = 2**bits - 1
    g = np.ones_like(d) if hi == lo else (d - lo) / (hi - lo)
    dtype = np.uint8 if bits == 8 else np.uint16
    rgb = np.zeros(d.shape + (3,), dtype)
    rgb[..., 1] = np.rint(g * top).astype(dtype)

    def write(tmp):
        spec = oiio.ImageSpec(d.shape[1], d.shape[0], 3, "uint8" if bits == 8 else "uint16")
        spec.attribute("oiio:ColorSpace", "lin_rec709_scene")  # linear data: gAMA 1.0
        out = oiio.ImageOutput.create(str(path))
        if out is None or not out.open(tmp, spec):
            raise OSError(f"cannot write {path}: {oiio.geterror()}")
        out.write_image(rgb)
        out.close()

    atomic_write(path, write)
    return lo, hi


def read_texture_channel(path, channel: int) -> np.ndarray:
    """One channel (0 = R, 1 = G) of an image as values in [0, 1] (its integer codes over
    2ᵇ − 1; grey images: channel 0, as a sampler expands luminance to RGB)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        fmt = str(spec.format)
        raw = inp.read_image(format=spec.format)
    finally:
        inp.close()
    ch = channel if spec.nchannels >= 3 else 0
    codes = np.asarray(raw)[..., ch].astype(float)
    if fmt in ("uint8", "uint16"):
        return codes / (2 ** (8 if fmt == "uint8" else 16) - 1)
    return codes


def read_thickness_texture(path, minimum, maximum) -> np.ndarray:
    """The thickness map (nm) of an `iridescenceThicknessTexture`: mix(min, max, G)."""
    return thickness_from_texture(read_texture_channel(path, 1), minimum, maximum)


def write_gltf(path, film: Film, factor=1.0, *, bits: int = 8) -> dict:
    """Write a glTF 2.0 document (`.gltf` JSON) with one material holding `film`; a thickness
    map (H, W) (every other field one value) goes to ``<stem>_thickness.png`` beside it as the
    `iridescenceThicknessTexture` (`write_thickness_texture`). Returns the document."""
    path = Path(path)
    film = V.check_film(film)
    d = np.asarray(film.thickness)
    material = film_to_gltf(film._replace(thickness=float(d.max()) if d.size else 0.0), factor)
    doc = {"asset": {"version": "2.0", "generator": "thinfilm_jax"},
           "extensionsUsed": [EXTENSION, IOR_EXTENSION], "materials": [material]}
    if d.ndim == 2:
        png = path.with_name(f"{path.stem}_thickness.png")
        lo, hi = write_thickness_texture(png, d, bits=bits)
        material["extensions"][EXTENSION].update({
            "iridescenceThicknessMinimum": lo, "iridescenceThicknessMaximum": hi,
            "iridescenceThicknessTexture": {"index": 0}})
        doc.update(images=[{"uri": png.name}], textures=[{"source": 0}])
    elif d.size != 1:
        raise ValueError(f"film.thickness must be one value or a map (H, W), got {d.shape}")
    write_json(path, doc)
    return doc


def _texture_image(doc: Mapping, base: Path, info) -> Path:
    info = _mapping("textureInfo", info)
    try:
        image = doc["images"][doc["textures"][info["index"]]["source"]]
    except (KeyError, IndexError, TypeError) as e:
        raise ValueError(f"texture {info!r} does not resolve to an image: {e!r}") from None
    uri = image.get("uri")
    if not isinstance(uri, str) or uri.startswith("data:"):
        raise ValueError("only images referenced by a file uri are read (no data: URIs or "
                         "bufferViews)")
    return base / uri


def read_gltf(path, material: int = 0, *, eta_base=None, kappa_base=None):
    """(`Film`, factor) of material `material` of a `.gltf` file, its textures read from
    their files (`film_from_gltf` with the sampled G and R channels)."""
    path = Path(path)
    doc = json.loads(path.read_text(encoding="utf-8"))
    try:
        mat = doc["materials"][material]
    except (KeyError, IndexError, TypeError):
        raise ValueError(f"{path} has no material {material!r}") from None
    ext = _mapping(f"extensions.{EXTENSION}", mat.get("extensions", {}).get(EXTENSION))
    g = r = None
    if "iridescenceThicknessTexture" in ext:
        g = read_texture_channel(
            _texture_image(doc, path.parent, ext["iridescenceThicknessTexture"]), 1)
    if "iridescenceTexture" in ext:
        r = read_texture_channel(_texture_image(doc, path.parent, ext["iridescenceTexture"]), 0)
    return film_from_gltf(mat, eta_base=eta_base, kappa_base=kappa_base, thickness_g=g,
                          factor_r=r)
