"""glTF 2.0 files of a film (SPEC §10): `write_gltf` writes a UV sphere (`uv_sphere`) with
the film's `KHR_materials_iridescence` material (`gltf.film_to_gltf`) and its thickness
texture as ``.gltf`` + ``.bin`` + PNG or one binary ``.glb`` (glTF 2.0 specification §3.6–3.8
for accessors and buffers, §4.4 for the GLB container); `load_gltf` and `read_gltf` read them
back (external or embedded buffers and images) into the JSON document and the `Film`.
The material's mapping, its defaults and the texture codec are in `gltf`."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..core import _validate as V
from ..core.files import atomic_write, write_json
from ..core.film import Film
from .gltf import (EXTENSION, INDEX_WAVELENGTH_NM, IOR_EXTENSION, _extras, _mapping,
                   constant_film, film_from_gltf, film_to_gltf, read_texture_channel,
                   write_thickness_texture)

__all__ = ["uv_sphere", "write_gltf", "load_gltf", "read_gltf"]


# ------------------------------------------------------------------------------- the asset
#: glTF constants (specification §3.6–3.8): component types, buffer targets, sampler values
_FLOAT, _USHORT, _UINT = 5126, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_LINEAR, _CLAMP_TO_EDGE = 9729, 33071
#: GLB container (specification §4.4): magic "glTF", version 2, chunk types "JSON" and "BIN\0"
_GLB_MAGIC, _GLB_JSON, _GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


def uv_sphere(n_lat: int = 16, n_lon: int = 32):
    """A unit UV sphere: (positions (N, 3), normals (N, 3), texcoords (N, 2), triangles (M, 3)).

    Vertex (i, j) of the (n_lat + 1) × (n_lon + 1) grid (the seam column repeated so that u
    runs 0 → 1) sits at θ = π i / n_lat from +Y, φ = 2π (j / n_lon − ½) from +Z towards +X:
    p = (sin θ sin φ, cos θ, sin θ cos φ), n = p, (u, v) = (j / n_lon, i / n_lat) with glTF's
    texture origin top-left, so a map's first row is the north pole and its centre faces +Z,
    not mirrored (a pole vertex, which serves one triangle, takes u at its middle).
    Triangles wind counter-clockwise seen from outside (glTF's front face); the pole rows keep
    only their non-degenerate triangle (M = 2 n_lon (n_lat − 1)), and the vertices no
    triangle uses (each pole's seam copy) are dropped: N = (n_lat + 1)(n_lon + 1) − 2.

    Example:
        >>> p, n, uv, tri = uv_sphere(4, 8)
        >>> p.shape, tri.shape, float(abs((p * p).sum(-1) - 1).max()) < 1e-15
        ((43, 3), (48, 3), True)
    """
    n_lat, n_lon = V.check_int("n_lat", n_lat, 2), V.check_int("n_lon", n_lon, 3)
    i, j = np.mgrid[0:n_lat + 1, 0:n_lon + 1]
    theta, phi = np.pi * i / n_lat, 2.0 * np.pi * (j / n_lon - 0.5)
    p = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1)
    # a pole vertex serves one triangle (north: columns j, j + 1; south: j − 1, j): u at its
    # middle
    u = j + np.where(i == 0, 0.5, np.where(i == n_lat, -0.5, 0.0))
    uv = np.stack([u / n_lon, i / n_lat], -1)
    k = lambda a, b: a * (n_lon + 1) + b  # noqa: E731 — vertex index of (i, j)
    tris = []
    for a in range(n_lat):
        for b in range(n_lon):
            tl, bl, br, tr = k(a, b), k(a + 1, b), k(a + 1, b + 1), k(a, b + 1)
            if a < n_lat - 1:  # degenerate in the south pole row (bl, br at the pole)
                tris.append((tl, bl, br))
            if a > 0:  # degenerate in the north pole row (tl, tr at the pole)
                tris.append((tl, br, tr))
    tris = np.asarray(tris, np.int64)
    used, tris = np.unique(tris, return_inverse=True)  # drops the two poles' seam copies
    p = p.reshape(-1, 3)[used]
    return p, p.copy(), uv.reshape(-1, 2)[used], tris.reshape(-1, 3)


class _Buffer:
    """The one glTF buffer being assembled: bufferViews appended 4-byte aligned."""

    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def view(self, payload: bytes, target=None) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        if target is not None:
            view["target"] = target
        self.data += payload
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, array, kind: str, target, *, bounds: bool = False) -> int:
        array = np.ascontiguousarray(array)
        ctype = {np.dtype(np.float32): _FLOAT, np.dtype(np.uint16): _USHORT,
                 np.dtype(np.uint32): _UINT}[array.dtype]
        acc = {"bufferView": self.view(array.tobytes(), target), "componentType": ctype,
               "count": int(array.shape[0]), "type": kind}
        if bounds:  # required for POSITION (specification §3.7.2.1); float32 values as written
            acc["min"] = [float(x) for x in array.min(0)]
            acc["max"] = [float(x) for x in array.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _asset(film: Film, factor, alpha, base_color, bits, png_path: Path, glb: bool,
           sphere, wavelength_nm) -> tuple[dict, bytes]:
    """(glTF JSON document, buffer bytes) of the sphere asset (`write_gltf`)."""
    film, models = constant_film(film, wavelength_nm)
    film = V.check_film(film)
    d = np.asarray(film.thickness)
    if d.ndim not in (0, 2) or d.size == 0:
        raise ValueError(f"film.thickness must be one value or a map (H, W), got shape "
                         f"{d.shape}")
    material = film_to_gltf(film._replace(thickness=float(d.max())), factor, alpha=alpha)
    material.update(_extras(models, wavelength_nm))
    colour = np.asarray(base_color, float)
    if colour.shape != (3,) or not np.all((colour >= 0) & (colour <= 1)):
        raise ValueError(f"base_color must be 3 linear values in [0, 1], got {base_color!r}")
    material["pbrMetallicRoughness"]["baseColorFactor"] = [*map(float, colour), 1.0]
    material["name"] = "thinfilm_jax film"
    buf = _Buffer()
    p, n, uv, tri = uv_sphere(*sphere)
    attributes = {
        "POSITION": buf.accessor(p.astype(np.float32), "VEC3", _ARRAY_BUFFER, bounds=True),
        "NORMAL": buf.accessor(n.astype(np.float32), "VEC3", _ARRAY_BUFFER)}
    doc = {"asset": {"version": "2.0", "generator": "thinfilm_jax"},
           "extensionsUsed": [EXTENSION, IOR_EXTENSION], "scene": 0,
           "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "film"}],
           "materials": [material]}
    if d.ndim == 2:
        attributes["TEXCOORD_0"] = buf.accessor(uv.astype(np.float32), "VEC2", _ARRAY_BUFFER)
        lo, hi = write_thickness_texture(png_path, d, bits=bits)
        material["extensions"][EXTENSION].update({
            "iridescenceThicknessMinimum": lo, "iridescenceThicknessMaximum": hi,
            "iridescenceThicknessTexture": {"index": 0}})
        if glb:  # the PNG travels in the BIN chunk
            image = {"bufferView": buf.view(png_path.read_bytes()), "mimeType": "image/png"}
        else:
            image = {"uri": png_path.name}
        doc.update(images=[image], textures=[{"sampler": 0, "source": 0}],
                   samplers=[{"magFilter": _LINEAR, "minFilter": _LINEAR,
                              "wrapS": _CLAMP_TO_EDGE, "wrapT": _CLAMP_TO_EDGE}])
    index_type = np.uint16 if p.shape[0] < 2**16 - 1 else np.uint32
    indices = buf.accessor(tri.reshape(-1).astype(index_type), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    doc["meshes"] = [{"name": "sphere", "primitives": [
        {"attributes": attributes, "indices": indices, "material": 0}]}]
    doc.update(accessors=buf.accessors, bufferViews=buf.views,
               buffers=[{"byteLength": len(buf.data)}])
    return doc, bytes(buf.data)


def _glb(doc: dict, data: bytes) -> bytes:
    """The GLB container (specification §4.4): 12-byte header, the JSON chunk padded with
    spaces and the BIN chunk padded with zeros, each to 4 bytes."""
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    data += b"\0" * (-len(data) % 4)
    chunks = (len(text).to_bytes(4, "little") + _GLB_JSON.to_bytes(4, "little") + text
              + len(data).to_bytes(4, "little") + _GLB_BIN.to_bytes(4, "little") + data)
    return (_GLB_MAGIC.to_bytes(4, "little") + (2).to_bytes(4, "little")
            + (12 + len(chunks)).to_bytes(4, "little") + chunks)


def write_gltf(path, film: Film, factor=1.0, *, alpha=None, base_color=(0.0, 0.0, 0.0),
               bits: int = 8, sphere: tuple[int, int] = (16, 32),
               wavelength_nm=INDEX_WAVELENGTH_NM) -> dict:
    """Write a complete glTF 2.0 asset showing `film` on a unit sphere; returns its document.

    The asset: one UV sphere (`uv_sphere(*sphere)`: POSITION with its min/max, NORMAL, and
    TEXCOORD_0 when there is a texture; indices), one node, one scene (``scene: 0``) and the
    material of `film_to_gltf` (with ``alpha=``, `roughnessFactor` = √α) with
    `baseColorFactor` = (`base_color`, 1): black by default, so that the engine shows the
    film's specular reflection alone — what `patch_radiance` computes; pass (1, 1, 1) for
    glTF's default white diffuse under the film. A thickness map (H, W) (every other field one
    value) becomes the `iridescenceThicknessTexture` (`write_thickness_texture`, its sampler
    linear and clamped) with minimum and maximum covering the map. A dispersive film is
    written with its indices at `wavelength_nm` (default 550 nm), recorded in the material's
    ``extras`` (`film_to_gltf`).

    ``path`` ending in ``.glb``: one binary file (GLB: the JSON chunk and a BIN chunk holding
    the mesh and the PNG). Otherwise JSON ``path`` beside ``<stem>.bin`` (the mesh) and
    ``<stem>_thickness.png``. Each file is written atomically, the document last.
    `read_gltf` reads either back. Checked with the Khronos glTF-Validator: no error, warning
    or unused object (tests/interop/test_gltf_asset.py).
    """
    path = Path(path)
    glb = path.suffix.lower() == ".glb"
    png = path.with_name(f"{path.stem}_thickness.png")
    if glb:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            doc, data = _asset(film, factor, alpha, base_color, bits, Path(tmp) / png.name,
                               True, sphere, wavelength_nm)
        blob = _glb(doc, data)
        atomic_write(path, lambda tmp: Path(tmp).write_bytes(blob))
        return doc
    doc, data = _asset(film, factor, alpha, base_color, bits, png, False, sphere,
                       wavelength_nm)
    doc["buffers"][0]["uri"] = f"{path.stem}.bin"
    atomic_write(path.with_name(f"{path.stem}.bin"), lambda tmp: Path(tmp).write_bytes(data))
    write_json(path, doc)
    return doc


# ------------------------------------------------------------------------------- reading
def _parse_glb(blob: bytes) -> tuple[dict, bytes]:
    """(JSON document, BIN chunk) of a GLB container (specification §4.4)."""
    def u32(at):
        return int.from_bytes(blob[at:at + 4], "little")

    if len(blob) < 20 or u32(0) != _GLB_MAGIC or u32(4) != 2 or u32(8) > len(blob):
        raise ValueError("not a GLB 2.0 container (header)")
    doc, data, at = None, b"", 12
    while at + 8 <= u32(8):
        size, kind = u32(at), u32(at + 4)
        chunk = blob[at + 8:at + 8 + size]
        if kind == _GLB_JSON and doc is None:
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == _GLB_BIN:
            data = chunk
        at += 8 + size
    if doc is None:
        raise ValueError("the GLB container has no JSON chunk")
    return doc, data


def load_gltf(path) -> dict:
    """The JSON document of a `.gltf` file or a `.glb` container (told apart by the magic)."""
    return _load(Path(path))[0]


def _load(path: Path) -> tuple[dict, bytes]:
    blob = path.read_bytes()
    if blob[:4] == b"glTF":
        return _parse_glb(blob)
    return json.loads(blob.decode("utf-8")), b""


def _texture_channel(doc: Mapping, base: Path, data: bytes, info, channel: int) -> np.ndarray:
    """One channel of the image a textureInfo points to: a file uri beside the document, or
    a bufferView of the GLB's BIN chunk."""
    info = _mapping("textureInfo", info)
    try:
        image = doc["images"][doc["textures"][info["index"]]["source"]]
    except (KeyError, IndexError, TypeError) as e:
        raise ValueError(f"texture {info!r} does not resolve to an image: {e!r}") from None
    if "bufferView" in image:
        try:
            view = doc["bufferViews"][image["bufferView"]]
            start = view.get("byteOffset", 0)
            payload = data[start:start + view["byteLength"]]
        except (KeyError, IndexError, TypeError) as e:
            raise ValueError(f"image {image!r} does not resolve to bytes: {e!r}") from None
        if view.get("buffer", 0) != 0 or len(payload) != view["byteLength"]:
            raise ValueError("only images in the GLB's own BIN chunk are read")
        import tempfile

        suffix = {"image/png": ".png", "image/jpeg": ".jpg"}.get(image.get("mimeType"), "")
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / f"texture{suffix}"
            f.write_bytes(payload)
            return read_texture_channel(f, channel)
    uri = image.get("uri")
    if not isinstance(uri, str) or uri.startswith("data:"):
        raise ValueError("only images referenced by a file uri or a GLB bufferView are read "
                         "(no data: URIs)")
    return read_texture_channel(base / uri, channel)


def read_gltf(path, material: int = 0, *, eta_base=None, kappa_base=None):
    """(`Film`, factor) of material `material` of a `.gltf` file or `.glb` container, its
    textures read from their files or the BIN chunk (`film_from_gltf` with the sampled G and
    R channels). The roughness: `alpha_from_gltf(load_gltf(path)["materials"][i])`."""
    path = Path(path)
    doc, data = _load(path)
    try:
        mat = doc["materials"][material]
    except (KeyError, IndexError, TypeError):
        raise ValueError(f"{path} has no material {material!r}") from None
    ext = _mapping(f"extensions.{EXTENSION}", mat.get("extensions", {}).get(EXTENSION))
    g = r = None
    if "iridescenceThicknessTexture" in ext:
        g = _texture_channel(doc, path.parent, data, ext["iridescenceThicknessTexture"], 1)
    if "iridescenceTexture" in ext:
        r = _texture_channel(doc, path.parent, data, ext["iridescenceTexture"], 0)
    return film_from_gltf(mat, eta_base=eta_base, kappa_base=kappa_base, thickness_g=g,
                          factor_r=r)
