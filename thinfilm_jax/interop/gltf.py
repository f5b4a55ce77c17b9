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
| `roughnessFactor` r (1)                | GGX α = r² (glTF 2.0 specification, Appendix B)     |

What glTF cannot hold is a `ValueError`, never dropped: κ₃ > 0 and η₁ ≠ 1 on export; on
import a metallic base (`metallicFactor` > 0 — also when `pbrMetallicRoughness` is omitted,
glTF's default is 1 — whose Fresnel is the Schlick tint `baseColor`, not an η₃ + iκ₃) unless
the caller supplies ``eta_base=``/``kappa_base=``, a partly metallic base, and
`KHR_materials_specular` (it scales F₀: no single η₃). The schema's ranges are checked
(factor in [0, 1], IOR ≥ 1, thicknesses ≥ 0, finite numbers; unknown fields rejected). The
extension allows `iridescenceThicknessMinimum` > `…Maximum` (README: "MAY be greater"): it is
read as written, an inverted mapping.

A dispersive film (index models, SPEC §12) is written with its indices at one wavelength
(`constant_film`, default `INDEX_WAVELENGTH_NM` = 550 nm), which the material records in
``extras.thinfilm_jax``; its colour cost against the exact film is `constant_index_error`
(docs/how-to/gltf.md: a soap film ΔE₀₀ mean 0.81, TiO₂ on glass 4.9).

Thickness maps travel as an `iridescenceThicknessTexture` PNG written with OpenImageIO
(`write_thickness_texture`: G channel, R = B = 0, linear — a gAMA 1.0 chunk —, minimum and
maximum covering the map so that no code is wasted; 8-bit by default, 16-bit on request).
Read back (`read_thickness_texture`) the map is reproduced to the PNG quantisation,
|Δd| ≤ (max − min)/(2(2ᵇ − 1)) (tests/interop/test_interop.py).

`write_gltf` (in `gltf_file`) writes a complete asset a viewer opens (glTF 2.0 spec. §3–§4): a UV
sphere (`uv_sphere`; POSITION with the min/max the specification requires, NORMAL, TEXCOORD_0
where there is a texture, indices), one node, one scene (``scene: 0``) and the material, as
`.gltf` + `.bin` (+ the PNG) or, for a `.glb` path, one binary container (a JSON and a BIN
chunk, 4-byte aligned, the PNG in a bufferView). The Khronos glTF-Validator reports no error,
warning or unused object on it (tests/interop/test_gltf_asset.py). `read_gltf` and
`load_gltf` read both forms.

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

import math
import numbers
from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.files import atomic_write
from ..core.film import Film
from ..optics.index import is_index_model

__all__ = [
    "EXTENSION",
    "IOR_EXTENSION",
    "DEFAULTS",
    "EXTRAS",
    "KAPPA_FILM_MAX",
    "mix",
    "iridescence_mix",
    "film_from_gltf",
    "constant_film",
    "constant_index_error",
    "film_to_gltf",
    "alpha_from_gltf",
    "write_thickness_texture",
    "read_thickness_texture",
]

EXTENSION = "KHR_materials_iridescence"
IOR_EXTENSION = "KHR_materials_ior"
#: The schema's defaults (material.KHR_materials_iridescence.schema.json).
DEFAULTS = {"iridescenceFactor": 0.0, "iridescenceIor": 1.3,
            "iridescenceThicknessMinimum": 100.0, "iridescenceThicknessMaximum": 400.0}
FIELDS = (*DEFAULTS, "iridescenceIOR", "iridescenceTexture", "iridescenceThicknessTexture",
          "extensions", "extras")
#: `KHR_materials_ior` default (its schema) and glTF's default `metallicFactor`.
DEFAULT_IOR, DEFAULT_METALLIC = 1.5, 1.0
#: the wavelength (nm) at which a dispersive index is written as glTF's one constant IOR
INDEX_WAVELENGTH_NM = 550.0
#: where the written material records it (`material["extras"][EXTRAS]`)
EXTRAS = "thinfilm_jax"
#: the largest κ of a dispersive film index written as a real IOR (recorded in the extras):
#: a 1 µm film loses ≤ 1 − exp(−4πκ·2d/λ) ≈ 0.5 % at 550 nm (TiO₂: κ ≈ 5e-8 at 550 nm)
KAPPA_FILM_MAX = 1e-4


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


def constant_film(film: Film, wavelength_nm=INDEX_WAVELENGTH_NM) -> tuple[Film, dict]:
    """`film` with every index model (SPEC §12) evaluated at `wavelength_nm`: glTF holds one
    constant IOR per interface, so a dispersive film (water, TiO₂, ...) is written as its
    indices at one wavelength. Returns (the constant film, {field: {"name", "n", "k"}} of the
    models evaluated; empty for a film of numbers, which is returned as given).

    The absorption of the base at that wavelength becomes `kappa_base` (and `film_to_gltf`
    refuses it, as any κ₃ > 0). glTF's `iridescenceIor` is real: a film or outer index that
    absorbs more than `KAPPA_FILM_MAX` at that wavelength is a `ValueError`; below it its κ
    is left out of the film and kept in the record. The colour this costs is measured in
    docs/how-to/gltf.md ("Dispersive films") with `constant_index_error`.

    Example:
        >>> from thinfilm_jax import Film, refractive_index
        >>> film, models = constant_film(Film(300.0, refractive_index("water"), 1.0))
        >>> round(float(film.eta_film), 4), models["eta_film"]["name"]
        (1.3347, 'water')
    """
    if not isinstance(film, Film):
        raise TypeError(f"film must be a thinfilm_jax.Film, got {type(film).__name__}")
    names = ("eta_film", "eta_base", "eta_outer")
    models = {k: getattr(film, k) for k in names if is_index_model(getattr(film, k))}
    if not models:
        return film, {}
    wl = _number("wavelength_nm", wavelength_nm, 0.0)
    if wl == 0:
        raise ValueError("wavelength_nm must be > 0 nm, got 0")
    values = {}
    for k, model in models.items():
        try:
            v = complex(np.asarray(model(wl)).reshape(()))
        except ValueError as e:
            raise ValueError(f"film.{k} ({model.name}) at wavelength_nm = {wl:g}: {e}") from None
        if k != "eta_base" and v.imag > KAPPA_FILM_MAX:
            raise ValueError(f"glTF holds a real index: film.{k} ({model.name}) absorbs at "
                             f"{wl:g} nm (kappa = {v.imag:.3g} > {KAPPA_FILM_MAX:g})")
        values[k] = v
    fields = {k: values[k].real for k in values}
    if "eta_base" in values:
        fields["kappa_base"] = float(np.asarray(film.kappa_base)) + values["eta_base"].imag
    return film._replace(**fields), {k: {"name": m.name, "n": values[k].real,
                                         "k": values[k].imag} for k, m in models.items()}


def constant_index_error(film: Film, wavelength_nm=INDEX_WAVELENGTH_NM, *,
                         thickness=np.linspace(0.0, 1000.0, 201),
                         theta_deg=np.linspace(0.0, 80.0, 17)) -> dict:
    """The colour cost of writing a dispersive `film` as its indices at `wavelength_nm`
    (`constant_film`): CIEDE2000 between the exact mirror reflectance of the dispersive film
    and of the constant one (`rgb_reflectance(method="spectral")`, Stiles–Burch bands, the
    mirror as white, SPEC §7) over `thickness` (nm) × view angles `theta_deg`. Returns
    {"mean", "p95", "max", "n"}: the ΔE₀₀ statistics over the grid and its size.

    Example (a film of numbers costs nothing):
        >>> constant_index_error(Film(0.0, 1.33, 1.5), thickness=[300.0], theta_deg=[0.0])
        {'mean': 0.0, 'p95': 0.0, 'max': 0.0, 'n': 1}
    """
    from ..spectral.colorimetry import delta_e2000
    from ..spectral.reflectance import rgb_reflectance

    const, _ = constant_film(film, wavelength_nm)
    d = np.asarray(thickness, float)[:, None]
    cos = np.cos(np.deg2rad(np.asarray(theta_deg, float)))[None, :]
    exact = np.asarray(rgb_reflectance(film._replace(thickness=jnp.asarray(d)),
                                       jnp.asarray(cos), method="spectral"))
    approx = np.asarray(rgb_reflectance(const._replace(thickness=jnp.asarray(d)),
                                        jnp.asarray(cos), method="spectral"))
    de = delta_e2000(approx, exact).reshape(-1)
    return {"mean": float(de.mean()), "p95": float(np.percentile(de, 95)),
            "max": float(de.max()), "n": int(de.size)}


def _scalar(name: str, x) -> float:
    a = np.asarray(x)
    if a.size != 1:
        raise ValueError(f"film.{name} must be one value for a glTF material, got shape "
                         f"{a.shape} (a thickness map: write_gltf writes it as a texture)")
    return float(a.reshape(()))


def _alpha(alpha) -> float:
    """α as a Python float in [0, 1] (glTF's roughnessFactor = √α lies in [0, 1])."""
    a = np.asarray(alpha)
    if a.size != 1 or not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"alpha must be one number (GGX alpha in [0, 1]), got {alpha!r}")
    return _number("alpha (GGX roughness)", float(a.reshape(())), 0.0, 1.0)


def film_to_gltf(film: Film, factor=1.0, *, alpha=None,
                 wavelength_nm=INDEX_WAVELENGTH_NM) -> dict:
    """A glTF material (dict) holding `film` exactly: `KHR_materials_iridescence` (factor, IOR
    η₂, maximum = d, no texture), `KHR_materials_ior` (η₃) and `metallicFactor` 0 (glTF's
    default 1 would make the base a metal). κ₃ > 0, η₁ ≠ 1 or η₃ < 1 → ValueError.

    A dispersive film (index models, SPEC §12) is written with its indices at
    `wavelength_nm` (default 550 nm; `constant_film`), which the material records in
    ``extras.thinfilm_jax`` (``index_wavelength_nm`` and the models' names): glTF holds one
    constant IOR, so this is an approximation, measured in docs/how-to/gltf.md.

    With ``alpha=`` (the GGX α ∈ [0, 1] of `patch_radiance`/`envmap_radiance`) it also writes
    `roughnessFactor` = √α: glTF's roughness r is perceptual, its GGX α = r² (glTF 2.0
    specification, Appendix B). Without it the field is omitted and glTF's default
    roughness 1 (α = 1) applies. `alpha_from_gltf` reads it back.

    Example:
        >>> film_to_gltf(Film(350.0, 1.33, 1.52), alpha=0.25)["pbrMetallicRoughness"]
        {'metallicFactor': 0.0, 'roughnessFactor': 0.5}
    """
    film, models = constant_film(film, wavelength_nm)
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
    pbr = {"metallicFactor": 0.0}
    if alpha is not None:
        pbr["roughnessFactor"] = math.sqrt(_alpha(alpha))
    material = {"pbrMetallicRoughness": pbr,
                "extensions": {
                    EXTENSION: {"iridescenceFactor": factor, "iridescenceIor": eta2,
                                "iridescenceThicknessMaximum": d},
                    IOR_EXTENSION: {"ior": eta3}}}
    material.update(_extras(models, wavelength_nm))
    return material


def _extras(models: dict, wavelength_nm) -> dict:
    """The material's ``extras`` recording a dispersive film's evaluation wavelength (none
    for a film of numbers)."""
    if not models:
        return {}
    return {"extras": {EXTRAS: {"index_wavelength_nm": float(wavelength_nm),
                                "dispersive_indices": models}}}


def alpha_from_gltf(material) -> float:
    """The GGX α = `roughnessFactor`² of a glTF material (glTF 2.0 specification, Appendix B;
    the factor's default 1 gives α = 1). A roughness that varies over a
    `metallicRoughnessTexture` is a ValueError.

    Example:
        >>> alpha_from_gltf({"pbrMetallicRoughness": {"roughnessFactor": 0.5}})
        0.25
    """
    pbr = _mapping("material.pbrMetallicRoughness",
                   _mapping("material", material).get("pbrMetallicRoughness", {}))
    if "metallicRoughnessTexture" in pbr:
        raise ValueError("roughness varies over metallicRoughnessTexture: no single alpha")
    r = _number("pbrMetallicRoughness.roughnessFactor", pbr.get("roughnessFactor", 1.0),
                0.0, 1.0)
    return r * r


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

