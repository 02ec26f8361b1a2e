"""glTF 2.0 scenes (.gltf / .glb) for the tracer: prototype meshes, instances, alpha materials.

A glTF mesh becomes one *prototype* (positions, texture coordinates, triangles with a material
each); every node that references it becomes an *instance* (its world transform). Prototypes
are what maps are baked for; instances share them, as a BLAS shared by several TLAS instances.

Materials keep what the alpha test needs: ``alphaMode`` (OPAQUE, MASK with ``alphaCutoff``,
default 0.5; BLEND treated as alpha-tested at a settable cut-off), the base colour factor and
texture, the texture's sampler (filter and wrap per axis) and ``KHR_texture_transform``, which is
applied to the texture coordinates at load time (it is affine, so interpolating transformed
coordinates equals transforming interpolated ones). docs/FORMAT.md "Scenes" has the rules.

A referenced file that is missing is reported by a warning naming it, then: an image is
replaced by one white texel (alpha 1: the material behaves as if it had no texture); a buffer's
primitives are left out (their meshes lose those triangles). Nothing else is dropped silently.
"""

from __future__ import annotations

import base64
import io
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")
DEFAULT_BLEND_CUTOFF = 0.5
_GL_NEAREST = (9728, 9984, 9986)  # magFilter NEAREST, or min NEAREST_MIPMAP_*
_WRAP = {33071: "clamp", 33648: "mirror", 10497: "wrap"}
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}


class SceneWarning(UserWarning):
    """A problem in a scene file that has a documented fallback (e.g. a missing image)."""


@dataclass(frozen=True)
class Material:
    name: str
    alpha_mode: str  # OPAQUE / MASK / BLEND as declared
    cutoff: float  # opaque iff alpha >= cutoff (MASK: alphaCutoff; BLEND: the settable cut-off)
    base_colour: tuple[float, float, float, float]
    texture: int  # index into Scene.textures, -1 for none
    filter: str  # "nearest" | "linear" (the sampler's magFilter; the test samples mip level 0)
    wrap_u: str
    wrap_v: str
    double_sided: bool

    @property
    def alpha_tested(self) -> bool:
        return self.alpha_mode != "OPAQUE"


@dataclass(frozen=True)
class Texture:
    name: str
    rgba: np.ndarray  # uint8 (H, W, 4); row 0 is the first image row (v = 0)

    @property
    def alpha(self) -> np.ndarray:
        return self.rgba[..., 3]


@dataclass
class Mesh:
    """A prototype: triangles of one glTF mesh in its own (object) space."""

    name: str
    positions: np.ndarray  # float32 (V, 3)
    uvs: np.ndarray  # float64 (V, 2), KHR_texture_transform applied per primitive
    triangles: np.ndarray  # int32 (T, 3)
    material: np.ndarray  # int32 (T,), index into Scene.materials


@dataclass
class Scene:
    path: str
    meshes: list[Mesh]
    instances: list[tuple[int, np.ndarray]]  # (mesh index, 4x4 float64 world transform)
    materials: list[Material]
    textures: list[Texture]
    warnings: list[str] = field(default_factory=list)

    def alpha_tested(self) -> np.ndarray:
        """Boolean per material."""
        return np.array([m.alpha_tested for m in self.materials], dtype=bool)

    def bounds(self) -> np.ndarray:
        """World-space box (2, 3) of every instance."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for mi, m in self.instances:
            p = self.meshes[mi].positions
            if len(p) == 0:
                continue
            corners = np.array([[x, y, z, 1.0] for x in (p[:, 0].min(), p[:, 0].max())
                                for y in (p[:, 1].min(), p[:, 1].max()) for z in (p[:, 2].min(), p[:, 2].max())])
            w = corners @ m.T
            lo = np.minimum(lo, w[:, :3].min(axis=0))
            hi = np.maximum(hi, w[:, :3].max(axis=0))
        return np.stack([lo, hi])

    def counts(self) -> dict:
        """Triangle counts over instances (what is traced) and over prototypes (what is baked)."""
        alpha = self.alpha_tested()
        inst = sum(len(self.meshes[mi].triangles) for mi, _ in self.instances)
        inst_alpha = sum(int(alpha[self.meshes[mi].material].sum()) for mi, _ in self.instances)
        used = sorted({mi for mi, _ in self.instances})
        return {"instances": len(self.instances), "prototypes": len(used),
                "triangles": int(inst), "alpha_triangles": int(inst_alpha),
                "prototype_triangles": int(sum(len(self.meshes[i].triangles) for i in used)),
                "prototype_alpha_triangles": int(sum(alpha[self.meshes[i].material].sum() for i in used))}


# --------------------------------------------------------------------------------------------
# loading

def load_scene(path, blend_cutoff: float = DEFAULT_BLEND_CUTOFF) -> Scene:
    """Load a .gltf or .glb file. Bad files raise InputError naming the file; missing referenced
    files give a ``SceneWarning`` and the fallback described in the module docstring."""
    import pygltflib

    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    if os.path.isdir(path):
        raise InputError("is a folder, not a glTF file", path)
    if not (0.0 <= blend_cutoff <= 1.0):
        raise InputError(f"blend cut-off must be in [0, 1], got {blend_cutoff}")
    try:
        gltf = pygltflib.GLTF2().load(path)
    except Exception as exc:  # pygltflib raises assorted types on bad JSON / GLB headers
        raise InputError(f"cannot read glTF ({type(exc).__name__}: {exc})", path) from None
    if gltf is None:
        raise InputError("cannot read glTF", path)
    return _Loader(gltf, path, blend_cutoff).scene()


class _Loader:
    def __init__(self, gltf, path: str, blend_cutoff: float):
        self.g = gltf
        self.path = path
        self.folder = os.path.dirname(os.path.abspath(path))
        self.blend_cutoff = blend_cutoff
        self.warnings: list[str] = []
        self._buffers: dict[int, bytes | None] = {}

    def warn(self, message: str) -> None:
        self.warnings.append(message)
        warnings.warn(f"{self.path}: {message}", SceneWarning, stacklevel=4)

    # -- raw data ---------------------------------------------------------------------------
    def _uri_bytes(self, uri: str, what: str) -> bytes | None:
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1])
            except (IndexError, ValueError):
                raise InputError(f"{what}: bad data URI", self.path) from None
        from urllib.parse import unquote

        full = os.path.join(self.folder, unquote(uri))
        if not os.path.isfile(full):
            return None
        with open(full, "rb") as f:
            return f.read()

    def buffer(self, i: int) -> bytes | None:
        if i not in self._buffers:
            b = self.g.buffers[i]
            if b.uri is None:
                data = self.g.binary_blob()
                if data is None:
                    raise InputError(f"buffer {i} has no URI and the file has no binary chunk", self.path)
            else:
                data = self._uri_bytes(b.uri, f"buffer {i}")
                if data is None:
                    self.warn(f"missing buffer file {b.uri!r}: primitives stored in it are left out")
            self._buffers[i] = data
        return self._buffers[i]

    def view_bytes(self, vi: int) -> tuple[bytes | None, int | None]:
        v = self.g.bufferViews[vi]
        data = self.buffer(v.buffer)
        if data is None:
            return None, None
        off = v.byteOffset or 0
        if off + v.byteLength > len(data):
            raise InputError(f"bufferView {vi} runs past the end of buffer {v.buffer}", self.path)
        return data[off:off + v.byteLength], v.byteStride

    def accessor(self, ai: int) -> np.ndarray | None:
        """Accessor ``ai`` as an array (count, components), normalised integers scaled to [0, 1]
        or [-1, 1]; None when its buffer is missing."""
        try:
            a = self.g.accessors[ai]
        except (IndexError, TypeError):
            raise InputError(f"accessor {ai} does not exist", self.path) from None
        if a.componentType not in _DTYPES or a.type not in _COMPONENTS:
            raise InputError(f"accessor {ai}: unsupported type {a.type}/{a.componentType}", self.path)
        dt = np.dtype(_DTYPES[a.componentType]).newbyteorder("<")
        ncomp = _COMPONENTS[a.type]
        if a.bufferView is None:
            out = np.zeros((a.count, ncomp), dtype=dt)
        else:
            raw, stride = self.view_bytes(a.bufferView)
            if raw is None:
                return None
            start = a.byteOffset or 0
            elem = dt.itemsize * ncomp
            stride = stride or elem
            need = start + stride * (a.count - 1) + elem if a.count else 0
            if need > len(raw):
                raise InputError(f"accessor {ai} runs past the end of its bufferView", self.path)
            buf = np.frombuffer(raw, dtype=np.uint8)
            if a.count == 0:
                out = np.zeros((0, ncomp), dtype=dt)
            else:
                rows = np.lib.stride_tricks.as_strided(buf[start:], shape=(a.count, elem), strides=(stride, 1))
                out = np.ascontiguousarray(rows).view(dt).reshape(a.count, ncomp)
        if a.sparse is not None:
            out = out.copy()
            s = a.sparse
            idx = self._sparse_part(s.indices.bufferView, s.indices.byteOffset, s.count, 1,
                                    np.dtype(_DTYPES[s.indices.componentType]))
            val = self._sparse_part(s.values.bufferView, s.values.byteOffset, s.count, ncomp, dt)
            if idx is None or val is None:
                return None
            out[idx.ravel().astype(np.int64)] = val
        if a.normalized and dt.kind in "iu":
            info = np.iinfo(dt)
            return np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out

    def _sparse_part(self, view, offset, count, ncomp, dt):
        raw, _ = self.view_bytes(view)
        if raw is None:
            return None
        start = offset or 0
        n = count * ncomp * dt.itemsize
        if start + n > len(raw):
            raise InputError("sparse accessor runs past the end of its bufferView", self.path)
        return np.frombuffer(raw[start:start + n], dtype=dt.newbyteorder("<")).reshape(count, ncomp)

    # -- textures and materials -------------------------------------------------------------
    def image(self, ii: int) -> Texture:
        from PIL import Image, UnidentifiedImageError

        im = self.g.images[ii]
        label = im.uri if im.uri and not im.uri.startswith("data:") else (im.name or f"image {ii}")
        if im.bufferView is not None:
            data, _ = self.view_bytes(im.bufferView)
        elif im.uri:
            data = self._uri_bytes(im.uri, f"image {ii}")
        else:
            data = None
        if data is None:
            self.warn(f"missing image file {label!r}: using one white texel (alpha 1) instead")
            return Texture(f"{label} (missing)", np.full((1, 1, 4), 255, dtype=np.uint8))
        try:
            with Image.open(io.BytesIO(data)) as pil:
                pil.load()
                if pil.mode in ("I;16", "I;16B", "I"):  # 16-bit greyscale: keep the top 8 bits
                    arr = (np.asarray(pil, dtype=np.uint32) >> 8).astype(np.uint8)
                    pil = Image.fromarray(arr, "L")
                rgba = np.asarray(pil.convert("RGBA"), dtype=np.uint8)
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as exc:
            raise InputError(f"image {label!r} cannot be decoded ({exc})", self.path) from None
        return Texture(label, np.ascontiguousarray(rgba))

    def materials(self) -> tuple[list[Material], list[Texture], list[tuple[int, np.ndarray]]]:
        """Materials, the textures they use, and per material (texCoord index, 2x3 UV transform)."""
        textures: list[Texture] = []
        by_image: dict[int, int] = {}
        mats, uvinfo = [], []
        for mi, m in enumerate(self.g.materials or []):
            pbr = m.pbrMetallicRoughness
            factor = tuple(float(x) for x in (pbr.baseColorFactor if pbr and pbr.baseColorFactor else [1, 1, 1, 1]))
            mode = (m.alphaMode or "OPAQUE").upper()
            if mode not in ALPHA_MODES:
                raise InputError(f"material {mi} ({m.name}): unknown alphaMode {m.alphaMode!r}", self.path)
            if mode == "MASK":
                cutoff = 0.5 if m.alphaCutoff is None else float(m.alphaCutoff)
            elif mode == "BLEND":
                cutoff = self.blend_cutoff
            else:
                cutoff = 0.0
            tex_index, filt, wu, wv, coord, xf = -1, "linear", "wrap", "wrap", 0, np.eye(2, 3)
            info = pbr.baseColorTexture if pbr else None
            if info is not None and info.index is not None:
                try:
                    t = self.g.textures[info.index]
                except IndexError:
                    raise InputError(f"material {mi} ({m.name}): texture {info.index} does not exist",
                                     self.path) from None
                if t.source is not None:
                    if t.source not in by_image:
                        by_image[t.source] = len(textures)
                        textures.append(self.image(t.source))
                    tex_index = by_image[t.source]
                if t.sampler is not None:
                    s = self.g.samplers[t.sampler]
                    filt = "nearest" if s.magFilter in _GL_NEAREST else "linear"
                    wu = _WRAP.get(s.wrapS or 10497, "wrap")
                    wv = _WRAP.get(s.wrapT or 10497, "wrap")
                coord = info.texCoord or 0
                ext = (info.extensions or {}).get("KHR_texture_transform")
                if ext:
                    xf = texture_transform_matrix(ext)
                    coord = ext.get("texCoord", coord)
            name = m.name or f"material {mi}"
            mats.append(Material(name, mode, cutoff, factor, tex_index, filt, wu, wv, bool(m.doubleSided)))
            uvinfo.append((coord, xf))
        return mats, textures, uvinfo

    # -- geometry ---------------------------------------------------------------------------
    def mesh(self, mi: int, uvinfo, default_material: int) -> Mesh:
        m = self.g.meshes[mi]
        pos, uv, tri, mat = [], [], [], []
        base = 0
        for pi, p in enumerate(m.primitives):
            mode = 4 if p.mode is None else p.mode
            label = f"mesh {mi} ({m.name}) primitive {pi}"
            if mode not in (4, 5, 6):
                self.warn(f"{label}: mode {mode} (points or lines) has no triangles; left out")
                continue
            if p.attributes.POSITION is None:
                raise InputError(f"{label} has no POSITION", self.path)
            material = default_material if p.material is None else p.material
            coord, xf = uvinfo[material] if material < len(uvinfo) else (0, np.eye(2, 3))
            positions = self.accessor(p.attributes.POSITION)
            uv_acc = getattr(p.attributes, f"TEXCOORD_{coord}", None)
            uvs = None if uv_acc is None else self.accessor(uv_acc)
            idx = None if p.indices is None else self.accessor(p.indices)
            if positions is None or (uv_acc is not None and uvs is None) or (p.indices is not None and idx is None):
                continue  # its buffer is missing (warned once in buffer())
            n = len(positions)
            if uvs is None:
                uvs = np.zeros((n, 2))
            idx = np.arange(n, dtype=np.int64) if idx is None else idx.ravel().astype(np.int64)
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise InputError(f"{label}: index out of range", self.path)
            t = _triangles(idx, mode)
            uvs = uvs.astype(np.float64) @ xf[:, :2].T + xf[:, 2]
            pos.append(positions.astype(np.float32))
            uv.append(uvs)
            tri.append(t + base)
            mat.append(np.full(len(t), material, dtype=np.int32))
            base += n
        if not pos:
            return Mesh(m.name or f"mesh {mi}", np.zeros((0, 3), np.float32), np.zeros((0, 2)),
                        np.zeros((0, 3), np.int32), np.zeros(0, np.int32))
        return Mesh(m.name or f"mesh {mi}", np.concatenate(pos), np.concatenate(uv),
                    np.concatenate(tri).astype(np.int32), np.concatenate(mat))

    def instances(self) -> list[tuple[int, np.ndarray]]:
        g = self.g
        roots = (g.scenes[g.scene or 0].nodes if g.scenes else
                 sorted(set(range(len(g.nodes))) - {c for n in g.nodes for c in (n.children or [])}))
        out = []
        stack = [(r, np.eye(4)) for r in reversed(roots or [])]
        seen = 0
        while stack:
            ni, parent = stack.pop()
            seen += 1
            if seen > 10 * len(g.nodes) + 10:
                raise InputError("node hierarchy has a cycle", self.path)
            n = g.nodes[ni]
            world = parent @ node_matrix(n)
            if n.mesh is not None:
                out.append((n.mesh, world))
            for c in reversed(n.children or []):
                stack.append((c, world))
        return out

    def check_unused_images(self, used: set[int]) -> None:
        """Warn about referenced image files that are missing but not needed by the tracer
        (normal maps and the like), so no missing file goes unmentioned."""
        for ii, im in enumerate(self.g.images or []):
            if ii in used or not im.uri or im.uri.startswith("data:"):
                continue
            from urllib.parse import unquote

            if not os.path.isfile(os.path.join(self.folder, unquote(im.uri))):
                self.warn(f"missing image file {im.uri!r}: not a base colour texture, so not needed here")

    def scene(self) -> Scene:
        g = self.g
        mats, textures, uvinfo = self.materials()
        self.check_unused_images({t.source for m in g.materials or [] for t in [_base_texture(g, m)] if t})
        default_material = len(mats)
        mats.append(Material("default", "OPAQUE", 0.0, (1, 1, 1, 1), -1, "linear", "wrap", "wrap", False))
        uvinfo.append((0, np.eye(2, 3)))
        inst = self.instances()
        used = sorted({mi for mi, _ in inst})
        remap = {mi: k for k, mi in enumerate(used)}
        meshes = [self.mesh(mi, uvinfo, default_material) for mi in used]
        inst = [(remap[mi], m) for mi, m in inst if len(meshes[remap[mi]].triangles)]
        if not inst:
            raise InputError("the scene has no triangles", self.path)
        return Scene(self.path, meshes, inst, mats, textures, self.warnings)


def _base_texture(g, m):
    pbr = m.pbrMetallicRoughness
    info = pbr.baseColorTexture if pbr else None
    if info is None or info.index is None or not 0 <= info.index < len(g.textures or []):
        return None
    t = g.textures[info.index]
    return t if t.source is not None else None


def _triangles(idx: np.ndarray, mode: int) -> np.ndarray:
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if len(idx) < 3:
        return np.zeros((0, 3), np.int64)
    k = np.arange(len(idx) - 2)
    if mode == 5:  # strip: odd triangles swap their first two vertices to keep the winding
        a = np.where(k % 2 == 0, idx[k], idx[k + 1])
        b = np.where(k % 2 == 0, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], axis=1)
    return np.stack([np.full(len(k), idx[0]), idx[k + 1], idx[k + 2]], axis=1)  # fan


def node_matrix(n) -> np.ndarray:
    """A node's local 4x4 transform: ``matrix`` (column-major) or T * R * S."""
    if n.matrix is not None:
        return np.array(n.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    if n.scale is not None:
        m = np.diag([*n.scale, 1.0]) @ m
    if n.rotation is not None:
        x, y, z, w = n.rotation
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        rm = np.eye(4)
        rm[:3, :3] = r
        m = rm @ m
    if n.translation is not None:
        t = np.eye(4)
        t[:3, 3] = n.translation
        m = t @ m
    return m


def texture_transform_matrix(ext: dict) -> np.ndarray:
    """KHR_texture_transform as a 2x3 affine matrix: uv' = T(offset) * R(rotation) * S(scale) * uv."""
    ox, oy = ext.get("offset", [0.0, 0.0])
    r = float(ext.get("rotation", 0.0))
    sx, sy = ext.get("scale", [1.0, 1.0])
    c, s = np.cos(r), np.sin(r)
    # the extension's rotation matrix is [[c, s], [-s, c]] (rotates UVs clockwise)
    return np.array([[c * sx, s * sy, ox], [-s * sx, c * sy, oy]], dtype=np.float64)

