"""Reading the alpha-tested geometry of a glTF 2.0 scene (.gltf or .glb) with pygltflib.

One small API, ``alpha_primitives(path)``: every triangle primitive of the scene's meshes whose
material is alpha-tested (MASK) or blended (BLEND), with its positions, triangle indices, UVs
(KHR_texture_transform applied), cut-off, base colour factor alpha and texture alpha, sampler
filter and wrap modes. Opaque primitives are returned in ``skipped`` with the reason, so nothing
disappears silently. UVs are the stored values: glTF's (0, 0) is the first texel of the first
image row, omaps' convention as well.

A base colour texture that cannot be read (a missing file, an unsupported image) does not stop
the scene: the primitive comes back with ``alpha = None`` and ``problem`` naming the file; the
caller decides the fallback (omaps omm: every micro-triangle unknown).
"""

from __future__ import annotations

import base64
import io
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .texture import AlphaTexture

# glTF sampler enums
WRAP_MODES = {10497: "wrap", 33071: "clamp", 33648: "mirror"}
NEAREST_FILTERS = {9728, 9984, 9986}  # NEAREST, NEAREST_MIPMAP_NEAREST, NEAREST_MIPMAP_LINEAR
DEFAULT_CUTOFF = 0.5

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES, _STRIP, _FAN = 4, 5, 6


@dataclass
class AlphaPrimitive:
    mesh: int
    primitive: int
    name: str
    alpha_mode: str  # MASK or BLEND
    cutoff: float  # alphaCutoff (MASK: opaque iff alpha >= cutoff)
    positions: np.ndarray  # (V, 3) float64, mesh space
    triangles: np.ndarray  # (T, 3) vertex indices
    uvs: np.ndarray  # (V, 2) float64, texture transform applied
    alpha_factor: float  # baseColorFactor's alpha
    alpha: AlphaTexture | None  # base colour texture's alpha (None: no texture, or unreadable)
    texture_name: str | None
    wrap_u: str = "wrap"
    wrap_v: str = "wrap"
    filter: str = "linear"
    problem: str | None = None  # why ``alpha`` is None although a texture is referenced

    @property
    def tris_uv(self) -> np.ndarray:
        return self.uvs[self.triangles]

    @property
    def areas(self) -> np.ndarray:
        """Mesh-space area of each triangle."""
        p = self.positions[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


@dataclass
class Scene:
    path: str
    primitives: list[AlphaPrimitive]
    skipped: list[dict] = field(default_factory=list)  # {mesh, primitive, reason}


def load(path) -> "object":
    """The pygltflib document of a .gltf / .glb file (InputError when it cannot be parsed)."""
    import pygltflib

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            doc = pygltflib.GLTF2().load(path)
    except Exception as exc:  # pygltflib raises many kinds on bad input
        raise InputError(f"cannot read glTF ({type(exc).__name__}: {exc})", path) from None
    if doc is None:
        raise InputError("cannot read glTF", path)
    return doc


class _Reader:
    def __init__(self, doc, path):
        self.doc = doc
        self.path = path
        self.folder = os.path.dirname(os.path.abspath(path))
        self._buffers: dict[int, bytes] = {}

    def _uri_bytes(self, uri: str) -> bytes:
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1])
            except (IndexError, ValueError):
                raise InputError("bad data URI", self.path) from None
        from urllib.parse import unquote

        full = os.path.join(self.folder, unquote(uri))
        try:
            with open(full, "rb") as f:
                return f.read()
        except OSError:
            raise InputError(f"referenced file {uri!r} cannot be read", full) from None

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.doc.buffers[i]
            if b.uri is None:
                data = self.doc.binary_blob()
                if data is None:
                    raise InputError(f"buffer {i} has no URI and the file has no binary chunk", self.path)
            else:
                data = self._uri_bytes(b.uri)
            self._buffers[i] = bytes(data)
        return self._buffers[i]

    def view(self, i: int) -> tuple[bytes, int, int, int | None]:
        bv = self.doc.bufferViews[i]
        return self.buffer(bv.buffer), bv.byteOffset or 0, bv.byteLength, bv.byteStride

    def accessor(self, i: int) -> np.ndarray:
        """Accessor ``i`` as float64 (normalised integers scaled) or int64 (indices), (count, width)."""
        acc = self.doc.accessors[i]
        dt = np.dtype(_COMPONENTS[acc.componentType]).newbyteorder("<")
        width = _WIDTH[acc.type]
        if acc.sparse is not None:
            raise InputError(f"accessor {i} is sparse (not supported)", self.path)
        if acc.bufferView is None:
            out = np.zeros((acc.count, width), dtype=dt)
        else:
            data, off, length, stride = self.view(acc.bufferView)
            off += acc.byteOffset or 0
            item = dt.itemsize * width
            stride = stride or item
            need = off + stride * (acc.count - 1) + item if acc.count else off
            if need > len(data):
                raise InputError(f"accessor {i} reads past the end of its buffer", self.path)
            raw = np.frombuffer(data, dtype=np.uint8, count=max(need - off, 0), offset=off)
            if stride == item:
                out = raw.view(dt).reshape(acc.count, width)
            else:
                rows = np.lib.stride_tricks.as_strided(raw, (acc.count, item), (stride, 1))
                out = np.ascontiguousarray(rows).view(dt).reshape(acc.count, width)
        if dt.kind == "f":
            return out.astype(np.float64)
        if acc.normalized:
            info = np.iinfo(dt)
            return np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out.astype(np.int64)

    def image_alpha(self, image_index: int) -> tuple[AlphaTexture, str]:
        """Alpha of an image (all 255 when it has no alpha channel) and its name."""
        from PIL import Image, UnidentifiedImageError

        img = self.doc.images[image_index]
        if img.uri is not None and not img.uri.startswith("data:"):
            name = img.uri
        else:
            name = img.name or f"image {image_index}"
        if img.bufferView is not None:
            data, off, length, _ = self.view(img.bufferView)
            raw = data[off:off + length]
        elif img.uri is not None:
            raw = self._uri_bytes(img.uri)
        else:
            raise InputError(f"image {image_index} has neither a URI nor a buffer view", self.path)
        try:
            with Image.open(io.BytesIO(raw)) as im:
                im.load()
                if im.mode in ("P", "PA", "RGBa", "La", "1"):
                    im = im.convert("RGBA")
                bands = im.getbands()
                if "A" in bands:
                    a = np.asarray(im.getchannel("A"))
                else:  # glTF: no alpha channel means alpha 1
                    a = np.full((im.height, im.width), 255, dtype=np.uint8)
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as exc:
            raise InputError(f"cannot decode image {name!r} ({exc})", self.path) from None
        return AlphaTexture(name, np.ascontiguousarray(a), 255), name


def _triangles(mode: int, idx: np.ndarray) -> np.ndarray:
    if mode == _TRIANGLES:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    n = len(idx) - 2
    if n <= 0:
        return np.zeros((0, 3), dtype=np.int64)
    k = np.arange(n)
    if mode == _STRIP:  # alternate winding so every triangle keeps the strip's orientation
        even = k % 2 == 0
        a = np.where(even, idx[k], idx[k + 1])
        b = np.where(even, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], axis=1)
    return np.stack([np.full(n, idx[0]), idx[k + 1], idx[k + 2]], axis=1)


def _texture_transform(uv: np.ndarray, ext: dict) -> np.ndarray:
    """KHR_texture_transform: uv' = T * R * S * uv (offset, rotation in radians, scale)."""
    ox, oy = ext.get("offset", [0.0, 0.0])
    r = float(ext.get("rotation", 0.0))
    sx, sy = ext.get("scale", [1.0, 1.0])
    c, s = math.cos(r), math.sin(r)
    u = c * sx * uv[:, 0] + s * sy * uv[:, 1] + ox
    v = -s * sx * uv[:, 0] + c * sy * uv[:, 1] + oy
    return np.stack([u, v], axis=1)


def _scene_meshes(doc) -> list[int]:
    """Meshes reachable from the default scene (all meshes when there is no scene), in order."""
    if not doc.scenes:
        return list(range(len(doc.meshes or [])))
    scene = doc.scenes[doc.scene or 0]
    seen, order, stack = set(), [], list(reversed(scene.nodes or []))
    visited = set()
    while stack:
        n = stack.pop()
        if n in visited:
            continue
        visited.add(n)
        node = doc.nodes[n]
        if node.mesh is not None and node.mesh not in seen:
            seen.add(node.mesh)
            order.append(node.mesh)
        stack.extend(reversed(node.children or []))
    return order


def alpha_primitives(path) -> Scene:
    """The alpha-tested (MASK) and blended (BLEND) triangle primitives of a glTF scene."""
    doc = load(path)
    r = _Reader(doc, os.fspath(path))
    prims, skipped = [], []
    images: dict[int, tuple] = {}
    for m in _scene_meshes(doc):
        mesh = doc.meshes[m]
        for p_i, prim in enumerate(mesh.primitives):
            where = {"mesh": m, "primitive": p_i, "name": mesh.name or f"mesh {m}"}
            mat = doc.materials[prim.material] if prim.material is not None else None
            mode = (mat.alphaMode if mat is not None else None) or "OPAQUE"
            if mode == "OPAQUE":
                skipped.append({**where, "reason": "opaque material (no alpha test)"})
                continue
            pmode = _TRIANGLES if prim.mode is None else prim.mode
            if pmode not in (_TRIANGLES, _STRIP, _FAN):
                skipped.append({**where, "reason": f"primitive mode {pmode} is not triangles"})
                continue
            if prim.attributes.POSITION is None:
                skipped.append({**where, "reason": "no POSITION attribute"})
                continue
            pos = r.accessor(prim.attributes.POSITION)
            idx = (r.accessor(prim.indices).ravel() if prim.indices is not None else np.arange(len(pos)))
            tris = _triangles(pmode, idx)
            if len(tris) and (tris.min() < 0 or tris.max() >= len(pos)):
                raise InputError(f"mesh {m} primitive {p_i}: vertex index out of range", path)
            pbr = mat.pbrMetallicRoughness
            factor = float((pbr.baseColorFactor if pbr and pbr.baseColorFactor else [1, 1, 1, 1])[3])
            colour = getattr(prim.attributes, "COLOR_0", None)
            if colour is not None:
                col = r.accessor(colour)
                if col.shape[1] == 4 and not np.all(col[:, 3] == 1.0):
                    skipped.append({**where, "reason": "vertex colour alpha varies (COLOR_0): not supported"})
                    continue
            tex_info = pbr.baseColorTexture if pbr else None
            alpha, tex_name, problem = None, None, None
            wrap_u = wrap_v = "wrap"
            filt = "linear"
            texcoord = 0
            uv_ext = None
            if tex_info is not None:
                texcoord = tex_info.texCoord or 0
                ext = (tex_info.extensions or {}).get("KHR_texture_transform")
                if ext is not None:
                    uv_ext = ext
                    texcoord = ext.get("texCoord", texcoord)
                tex = doc.textures[tex_info.index]
                source = tex.source
                if source is None:
                    source = ((tex.extensions or {}).get("EXT_texture_webp") or {}).get("source")
                if tex.sampler is not None:
                    smp = doc.samplers[tex.sampler]
                    wrap_u = WRAP_MODES.get(smp.wrapS or 10497, "wrap")
                    wrap_v = WRAP_MODES.get(smp.wrapT or 10497, "wrap")
                    filt = "nearest" if smp.magFilter in NEAREST_FILTERS else "linear"
                if source is None:
                    problem = f"texture {tex_info.index} has no image omaps can read"
                else:
                    if source not in images:
                        try:
                            images[source] = r.image_alpha(source) + (None,)
                        except InputError as exc:
                            img = doc.images[source]
                            images[source] = (None, img.uri or img.name or f"image {source}", exc.problem if exc.path == r.path else str(exc))
                    alpha, tex_name, problem = images[source]
            uv_acc = getattr(prim.attributes, f"TEXCOORD_{texcoord}", None)
            if uv_acc is None:
                if tex_info is not None:
                    raise InputError(f"mesh {m} primitive {p_i}: base colour texture uses TEXCOORD_{texcoord}, "
                                     "which the primitive lacks", path)
                uvs = np.zeros((len(pos), 2))
            else:
                uvs = r.accessor(uv_acc)[:, :2]
            if uv_ext is not None:
                uvs = _texture_transform(uvs, uv_ext)
            cutoff = DEFAULT_CUTOFF if mat.alphaCutoff is None else float(mat.alphaCutoff)
            prims.append(AlphaPrimitive(m, p_i, where["name"], mode, cutoff, pos[:, :3], tris, uvs, factor, alpha,
                                        tex_name, wrap_u, wrap_v, filt, problem))
    return Scene(os.fspath(path), prims, skipped)
