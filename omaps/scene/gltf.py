"""Reading glTF 2.0 (.gltf / .glb) into the scene model: the only module that imports pygltflib.

One reader, one policy per case, for ``omaps trace``, ``omaps omm`` and all later work
(docs/FORMAT.md "Reading glTF" states the same):

* a file that is not glTF, an accessor, buffer view or index out of range, a node cycle: an
  ``InputError`` naming the file (exit 2);
* ``extensionsRequired`` naming an extension omaps cannot honour (Draco or meshopt compression,
  KTX2 textures, GPU instancing, ...): an ``InputError`` naming the extension;
* a buffer file that is missing: an ``InputError`` naming it (the geometry is not there to trace
  or bake); buffers nobody reads are never opened;
* an image that is missing or cannot be decoded: a ``SceneWarning`` naming it; a material using it
  is still alpha-tested, but every region of its maps is C (unknown: the any-hit shader decides),
  and the tracer's shader sees a white texel (alpha 1). A missing image no material uses as its
  base colour is named once too;
* an image with no alpha channel used by an alpha-tested material: a warning (alpha is 1);
* sparse accessors, normalized and quantized (KHR_mesh_quantization) attributes, strides,
  triangle strips and fans, ``KHR_texture_transform`` (and its ``texCoord``), ``EXT_texture_webp``
  are read; points and lines are left out and listed in ``Scene.skipped``;
* ``COLOR_0`` alpha multiplies the base colour alpha (glTF's rule): where it is not 1 everywhere,
  the primitive's triangles are *unknown* (all C) and the tracer's shader multiplies by it;
* texture coordinates that are NaN or infinite: a warning naming mesh, primitive and count;
  those triangles are unknown and get vertices of their own at UV (0, 0) (the shader reads that
  one point; their neighbours keep their coordinates); missing although the material samples a
  texture: the same warning, the primitive's triangles unknown at UV (0, 0);
* cameras are read (``Scene.cameras``: perspective ``yfov`` and the world transform of the first
  node of the default scene placing each) and checked only when one is used;
* a warning is given once per problem (a missing file named by several images or materials once).
"""

from __future__ import annotations

import base64
import io
import os
import warnings
from urllib.parse import unquote

import numpy as np

from ..errors import InputError
from .model import ALPHA_MODES, Material, Mesh, Primitive, Scene, SceneCamera, SceneWarning, Texture

__all__ = ["load_scene", "SUPPORTED_EXTENSIONS", "node_matrix", "texture_transform_matrix"]

# extensions whose data we read, or that cannot change geometry, texture coordinates or alpha
SUPPORTED_EXTENSIONS = frozenset({
    "KHR_texture_transform", "KHR_mesh_quantization", "EXT_texture_webp", "KHR_materials_emissive_strength",
    "KHR_materials_ior", "KHR_materials_specular", "KHR_materials_sheen", "KHR_materials_clearcoat",
    "KHR_materials_transmission", "KHR_materials_volume", "KHR_materials_iridescence", "KHR_materials_anisotropy",
    "KHR_materials_dispersion", "KHR_materials_unlit", "KHR_materials_variants", "KHR_materials_pbrSpecularGlossiness",
    "KHR_lights_punctual", "KHR_xmp_json_ld", "KHR_animation_pointer",
})
_GL_NEAREST = (9728, 9984, 9986)  # magFilter NEAREST, or min NEAREST_MIPMAP_*
_WRAP = {33071: "clamp", 33648: "mirror", 10497: "wrap"}
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_TRIANGLES, _STRIP, _FAN = 4, 5, 6


def load_scene(path) -> Scene:
    """Load a .gltf or .glb file into the scene model (``omaps.scene.model``).

    Parameters: ``path`` of the file. Returns a ``Scene``. Raises ``InputError`` naming the file
    for the cases the module docstring lists; recoverable problems are ``SceneWarning``s (also
    kept in ``Scene.warnings``).

    Example::

        >>> from omaps.scene import load_scene                       # doctest: +SKIP
        >>> scene = load_scene("palm.glb")                            # doctest: +SKIP
        >>> scene.counts()["alpha_triangles"]                         # doctest: +SKIP
        3840
    """
    import pygltflib

    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    if os.path.isdir(path):
        raise InputError("is a folder, not a glTF file", path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            doc = pygltflib.GLTF2().load(path)
    except Exception as exc:  # pygltflib raises assorted types on bad JSON / GLB headers
        raise InputError(f"cannot read glTF ({type(exc).__name__}: {exc})", path) from None
    if doc is None:
        raise InputError("cannot read glTF", path)
    try:
        return _Reader(doc, path).scene()
    except InputError:
        raise
    except (IndexError, TypeError, KeyError, ValueError, AttributeError) as exc:  # references out of range
        raise InputError(f"malformed glTF ({type(exc).__name__}: {exc})", path) from None


class _Reader:
    def __init__(self, doc, path: str):
        self.g = doc
        self.path = path
        self.folder = os.path.dirname(os.path.abspath(path))
        self.warnings: list[str] = []
        self._buffers: dict[int, bytes] = {}

    def warn(self, message: str) -> None:
        if message in self.warnings:  # one warning per problem, however many images or materials share it
            return
        self.warnings.append(message)
        warnings.warn(f"{self.path}: {message}", SceneWarning, stacklevel=2)

    # -- raw data ---------------------------------------------------------------------------
    def _uri_bytes(self, uri: str) -> bytes | None:
        """Bytes of a data URI or a file beside the scene; None when the file is missing."""
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1])
            except (IndexError, ValueError):
                raise InputError("bad data URI", self.path) from None
        full = os.path.join(self.folder, unquote(uri))
        try:
            with open(full, "rb") as f:
                return f.read()
        except OSError:
            return None

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.g.buffers[i]
            if b.uri is None:
                data = self.g.binary_blob()
                if data is None:
                    raise InputError(f"buffer {i} has no URI and the file has no binary chunk", self.path)
            else:
                data = self._uri_bytes(b.uri)
                if data is None:
                    raise InputError(f"buffer {i}: file {b.uri!r} is missing or unreadable", self.path)
            if b.byteLength is not None and len(data) < b.byteLength:
                raise InputError(f"buffer {i} holds {len(data)} bytes, byteLength says {b.byteLength}", self.path)
            self._buffers[i] = bytes(data)
        return self._buffers[i]

    def view_bytes(self, vi: int) -> tuple[bytes, int | None]:
        v = self.g.bufferViews[vi]
        data = self.buffer(v.buffer)
        off = v.byteOffset or 0
        if off + v.byteLength > len(data):
            raise InputError(f"bufferView {vi} runs past the end of buffer {v.buffer}", self.path)
        return data[off:off + v.byteLength], v.byteStride

    def accessor(self, ai: int) -> np.ndarray:
        """Accessor ``ai`` as an array (count, components): floats as float64, normalised
        integers scaled to [0, 1] or [-1, 1], other integers as int64."""
        if not isinstance(ai, int) or not 0 <= ai < len(self.g.accessors or []):
            raise InputError(f"accessor {ai} does not exist", self.path)
        a = self.g.accessors[ai]
        if a.componentType not in _DTYPES or a.type not in _COMPONENTS:
            raise InputError(f"accessor {ai}: unsupported type {a.type}/{a.componentType}", self.path)
        dt = np.dtype(_DTYPES[a.componentType]).newbyteorder("<")
        ncomp = _COMPONENTS[a.type]
        count = int(a.count or 0)
        if a.bufferView is None:
            out = np.zeros((count, ncomp), dtype=dt)
        else:
            raw, stride = self.view_bytes(a.bufferView)
            start = a.byteOffset or 0
            elem = dt.itemsize * ncomp
            stride = stride or elem
            need = start + stride * (count - 1) + elem if count else 0
            if need > len(raw):
                raise InputError(f"accessor {ai} runs past the end of its bufferView", self.path)
            if count == 0:
                out = np.zeros((0, ncomp), dtype=dt)
            else:
                buf = np.frombuffer(raw, dtype=np.uint8)
                rows = np.lib.stride_tricks.as_strided(buf[start:], shape=(count, elem), strides=(stride, 1))
                out = np.ascontiguousarray(rows).view(dt).reshape(count, ncomp)
        if a.sparse is not None:
            out = out.copy()
            s = a.sparse
            idx = self._sparse_part(s.indices.bufferView, s.indices.byteOffset, s.count, 1,
                                    np.dtype(_DTYPES[s.indices.componentType]))
            val = self._sparse_part(s.values.bufferView, s.values.byteOffset, s.count, ncomp, dt)
            idx = idx.ravel().astype(np.int64)
            if idx.size and (idx.min() < 0 or idx.max() >= count):
                raise InputError(f"accessor {ai}: sparse index out of range", self.path)
            out[idx] = val
        if dt.kind == "f":
            return out.astype(np.float64)
        if a.normalized:
            return np.maximum(out.astype(np.float64) / np.iinfo(dt).max, -1.0)
        return out.astype(np.int64)

    def _sparse_part(self, view, offset, count, ncomp, dt):
        raw, _ = self.view_bytes(view)
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
            data = self._uri_bytes(im.uri)
        else:
            data = None
        if data is None:
            problem = f"image file {label!r} is missing"
        else:
            try:
                with Image.open(io.BytesIO(data)) as pil:
                    pil.load()
                    return _texture(label, pil)
            except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as exc:
                problem = f"image {label!r} cannot be decoded ({exc})"
        return Texture(label, None, 255, None, problem)

    def materials(self) -> tuple[list[Material], list[Texture], list[np.ndarray]]:
        """Materials, the textures they use, and per material its 2x3 UV transform."""
        textures: list[Texture] = []
        by_image: dict[int, int] = {}
        mats, transforms = [], []
        for mi, m in enumerate(self.g.materials or []):
            pbr = m.pbrMetallicRoughness
            factor = tuple(float(x) for x in (pbr.baseColorFactor if pbr and pbr.baseColorFactor else [1, 1, 1, 1]))
            mode = (m.alphaMode or "OPAQUE").upper()
            if mode not in ALPHA_MODES:
                raise InputError(f"material {mi} ({m.name}): unknown alphaMode {m.alphaMode!r}", self.path)
            cutoff = 0.5 if m.alphaCutoff is None else float(m.alphaCutoff)
            tex_index, filt, wu, wv, coord, xf = -1, "linear", "wrap", "wrap", 0, np.eye(2, 3)
            info = pbr.baseColorTexture if pbr else None
            name = m.name or f"material {mi}"
            if info is not None and info.index is not None:
                if not 0 <= info.index < len(self.g.textures or []):
                    raise InputError(f"material {mi} ({name}): texture {info.index} does not exist", self.path)
                t = self.g.textures[info.index]
                source = t.source
                if source is None:
                    source = ((t.extensions or {}).get("EXT_texture_webp") or {}).get("source")
                if source is None:
                    key = ("none", info.index)
                    if key not in by_image:
                        by_image[key] = len(textures)
                        problem = f"texture {info.index} has no image omaps can decode (KTX2 / basisu?)"
                        textures.append(Texture(f"texture {info.index}", None, 255, None, problem))
                        self.warn(f"{problem}: the maps of {name} are unknown")
                    tex_index = by_image[key]
                else:
                    if source not in by_image:
                        by_image[source] = len(textures)
                        tex = self.image(source)
                        textures.append(tex)
                        if tex.problem is not None:
                            self.warn(f"{tex.problem}: the maps of materials using it are unknown (all C) and "
                                      "the tracer's shader sees alpha 1")
                    tex_index = by_image[source]
                    tex = textures[tex_index]
                    if tex.problem is None and not tex.has_alpha and mode != "OPAQUE":
                        self.warn(f"material {mi} ({name}) is {mode} but its base colour image {tex.name!r} has "
                                  "no alpha channel: alpha is 1 everywhere")
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
            mats.append(Material(mi, name, mode, cutoff, factor, tex_index, filt, wu, wv, int(coord),
                                 bool(m.doubleSided)))
            transforms.append(xf)
        return mats, textures, transforms

    def check_unused_images(self, used: set) -> None:
        """Name referenced image files that are missing but not a base colour (normal maps and the
        like), once each, so no missing file goes unmentioned (a file that is also a base colour
        was named as one)."""
        images = self.g.images or []
        used_uris = {images[ii].uri for ii in used if isinstance(ii, int) and 0 <= ii < len(images)}
        for ii, im in enumerate(images):
            if ii in used or not im.uri or im.uri.startswith("data:") or im.uri in used_uris:
                continue
            if not os.path.isfile(os.path.join(self.folder, unquote(im.uri))):
                self.warn(f"image file {im.uri!r} is missing (not a base colour texture, so not needed)")

    # -- geometry ---------------------------------------------------------------------------
    def mesh(self, mi: int, mats: list[Material], transforms, default_material: int, skipped: list) -> Mesh:
        m = self.g.meshes[mi]
        name = m.name or f"mesh {mi}"
        prims = []
        for pi, p in enumerate(m.primitives):
            where = {"mesh": mi, "primitive": pi, "name": name}
            label = f"mesh {mi} ({name}) primitive {pi}"
            mode = _TRIANGLES if p.mode is None else p.mode
            if mode not in (_TRIANGLES, _STRIP, _FAN):
                skipped.append({**where, "reason": f"primitive mode {mode} (points or lines) has no triangles"})
                continue
            if p.attributes.POSITION is None:
                skipped.append({**where, "reason": "no POSITION attribute"})
                continue
            material = default_material if p.material is None else p.material
            if not 0 <= material < len(mats):
                raise InputError(f"{label}: material {material} does not exist", self.path)
            mat = mats[material]
            positions = self.accessor(p.attributes.POSITION)[:, :3]
            n = len(positions)
            idx = np.arange(n, dtype=np.int64) if p.indices is None else self.accessor(p.indices).ravel()
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise InputError(f"{label}: vertex index out of range", self.path)
            tris = _triangles(idx, mode)
            unknown = np.zeros(len(tris), bool)
            own = None  # triangles given vertices of their own, all at UV (0, 0)
            uv_acc = getattr(p.attributes, f"TEXCOORD_{mat.texcoord}", None)
            if uv_acc is None:
                uvs = np.zeros((n, 2))
                if mat.texture >= 0 and mat.alpha_mode != "OPAQUE":
                    self.warn(f"{label}: its material's base colour texture reads TEXCOORD_{mat.texcoord}, which "
                              f"the primitive lacks: its {len(tris)} triangles are unknown")
                    unknown[:] = True
            else:
                uvs = self.accessor(uv_acc)[:, :2]
                uvs = uvs @ transforms[material][:, :2].T + transforms[material][:, 2]
                bad_v = ~np.isfinite(uvs).all(axis=1)
                if bad_v.any():
                    bad_t = bad_v[tris].any(axis=1)
                    uvs = np.where(bad_v[:, None], 0.0, uvs)
                    unknown |= bad_t
                    own = bad_t
                    if mat.alpha_mode != "OPAQUE":
                        self.warn(f"{label}: {int(bad_t.sum())} triangles have NaN or infinite texture "
                                  "coordinates: they are unknown (all C), read as UV (0, 0) at every vertex")
            vertex_alpha = None
            colour = getattr(p.attributes, "COLOR_0", None)
            if colour is not None:
                col = self.accessor(colour)
                if col.shape[1] == 4 and not np.all(col[:, 3] == 1.0):
                    vertex_alpha = np.clip(np.nan_to_num(col[:, 3], nan=0.0), 0.0, 1.0)
                    if mat.alpha_mode != "OPAQUE":
                        unknown[:] = True
                        self.warn(f"{label}: COLOR_0 alpha is not 1 everywhere: its {len(tris)} triangles are "
                                  "unknown and the tracer's shader multiplies by it")
            if own is not None:
                positions, uvs, tris, vertex_alpha = _own_vertices(positions, uvs, tris, vertex_alpha, own)
            prims.append(Primitive(mi, pi, positions, uvs, tris, material, vertex_alpha, unknown))
        return Mesh(mi, name, prims)

    def node_instances(self) -> list[tuple[int, np.ndarray]]:
        g = self.g
        nodes = g.nodes or []
        if g.scenes:
            si = g.scene or 0
            if not 0 <= si < len(g.scenes):
                raise InputError(f"default scene {si} does not exist", self.path)
            roots = g.scenes[si].nodes or []
        elif nodes:
            roots = sorted(set(range(len(nodes))) - {c for n in nodes for c in (n.children or [])})
        else:  # meshes without nodes: each once, untransformed
            return [(mi, np.eye(4)) for mi in range(len(g.meshes or []))]
        out = []
        cams = self._camera_nodes = {}
        stack = [(r, np.eye(4), ()) for r in reversed(roots)]
        while stack:
            ni, parent, path = stack.pop()
            if not isinstance(ni, int) or not 0 <= ni < len(nodes):
                raise InputError(f"node {ni} does not exist", self.path)
            if ni in path:
                raise InputError("node hierarchy has a cycle", self.path)
            n = nodes[ni]
            world = parent @ node_matrix(n)
            if n.mesh is not None:
                if not 0 <= n.mesh < len(g.meshes or []):
                    raise InputError(f"node {ni}: mesh {n.mesh} does not exist", self.path)
                out.append((n.mesh, world))
            if n.camera is not None:
                if not isinstance(n.camera, int) or not 0 <= n.camera < len(g.cameras or []):
                    raise InputError(f"node {ni}: camera {n.camera} does not exist", self.path)
                cams.setdefault(n.camera, (ni, world))
            for c in reversed(n.children or []):
                stack.append((c, world, path + (ni,)))
        return out

    def scene(self) -> Scene:
        g = self.g
        required = sorted(set(g.extensionsRequired or []) - SUPPORTED_EXTENSIONS)
        if required:
            raise InputError(f"requires the glTF extension{'s' if len(required) > 1 else ''} "
                             f"{', '.join(required)}, which omaps cannot read", self.path)
        mats, textures, transforms = self.materials()
        self.check_unused_images({src for m in g.materials or [] for src in [_base_image(g, m)] if src is not None})
        default_material = len(mats)
        mats.append(Material(default_material, "default", "OPAQUE", 0.5, (1, 1, 1, 1), -1, "linear", "wrap", "wrap",
                             0, False))
        transforms.append(np.eye(2, 3))
        self._camera_nodes: dict = {}
        inst = self.node_instances()
        cameras = [self.camera(ci) for ci in range(len(g.cameras or []))]
        used = list(dict.fromkeys(mi for mi, _ in inst))
        remap = {mi: k for k, mi in enumerate(used)}
        skipped: list[dict] = []
        meshes = [self.mesh(mi, mats, transforms, default_material, skipped) for mi in used]
        inst = [(remap[mi], m) for mi, m in inst]
        return Scene(self.path, meshes, inst, mats, textures, self.warnings, skipped, cameras)

    def camera(self, ci: int) -> SceneCamera:
        """Camera ``ci`` placed by its first node in the default scene (glTF: it looks down the
        node's -Z with +Y up). Problems are recorded, not raised: a camera is only read when asked
        for (``omaps trace --camera gltf:N``)."""
        c = self.g.cameras[ci]
        kind = str(getattr(c, "type", None) or "perspective")
        name = getattr(c, "name", None) or f"camera {ci}"
        persp = getattr(c, "perspective", None)
        yfov = getattr(persp, "yfov", None) if persp is not None else None
        aspect = getattr(persp, "aspectRatio", None) if persp is not None else None
        yfov = float(yfov) if isinstance(yfov, (int, float)) else None
        aspect = float(aspect) if isinstance(aspect, (int, float)) else None
        node, world = self._camera_nodes.get(ci, (None, None))
        problem = None
        eye = forward = up = None
        if kind != "perspective":
            problem = f"camera {ci} ({name}) is {kind}; omaps trace renders perspective views only"
        elif yfov is None or not 0 < yfov < np.pi:
            problem = f"camera {ci} ({name}) has no valid perspective yfov (got {yfov})"
        if world is None:
            problem = problem or f"camera {ci} ({name}) is not placed by any node of the default scene"
        else:
            eye = world[:3, 3].copy()
            f = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
            u = world[:3, :3] @ np.array([0.0, 1.0, 0.0])
            fn = float(np.linalg.norm(f))
            if np.all(np.isfinite(world)) and fn > 0:
                forward = f / fn
                u = u - (u @ forward) * forward
                un = float(np.linalg.norm(u))
                up = u / un if un > 0 else None
            if forward is None or up is None or not np.all(np.isfinite(eye)):
                problem = problem or f"camera {ci} ({name}): node {node}'s transform is degenerate"
        return SceneCamera(ci, name, kind, yfov, aspect, node, eye, forward, up, problem)


def _texture(label: str, pil) -> Texture:
    if pil.mode in ("P", "PA", "RGBa", "La", "1"):
        pil = pil.convert("RGBA")
    bands = pil.getbands()
    if pil.mode in ("I;16", "I;16B", "I;16L", "I"):
        alpha = np.clip(np.asarray(pil, dtype=np.int64), 0, 65535).astype(np.uint16)  # a 16-bit mask
        grey = (alpha >> 8).astype(np.uint8)
        return Texture(label, np.ascontiguousarray(alpha), 65535, np.repeat(grey[..., None], 3, axis=2), None, True)
    rgba = np.asarray(pil.convert("RGBA"), dtype=np.uint8)
    has_alpha = "A" in bands
    return Texture(label, np.ascontiguousarray(rgba[..., 3]), 255, np.ascontiguousarray(rgba[..., :3]), None, has_alpha)


def _base_image(g, m):
    pbr = m.pbrMetallicRoughness
    info = pbr.baseColorTexture if pbr else None
    if info is None or info.index is None or not 0 <= info.index < len(g.textures or []):
        return None
    t = g.textures[info.index]
    return t.source if t.source is not None else ((t.extensions or {}).get("EXT_texture_webp") or {}).get("source")


def _triangles(idx: np.ndarray, mode: int) -> np.ndarray:
    if mode == _TRIANGLES:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if len(idx) < 3:
        return np.zeros((0, 3), np.int64)
    k = np.arange(len(idx) - 2)
    if mode == _STRIP:  # odd triangles swap their first two vertices to keep the winding
        a = np.where(k % 2 == 0, idx[k], idx[k + 1])
        b = np.where(k % 2 == 0, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], axis=1)
    return np.stack([np.full(len(k), idx[0]), idx[k + 1], idx[k + 2]], axis=1)  # fan


def _own_vertices(positions, uvs, tris, vertex_alpha, sel):
    """Triangles ``sel`` get three new vertices each (same positions and vertex alpha) at UV
    (0, 0): a triangle with NaN texture coordinates reads one defined point of the texture, and
    its neighbours keep theirs. Pairing welds by position, so the pairs are unchanged."""
    k = np.flatnonzero(sel)
    old = tris[k].ravel()
    tris = tris.copy()
    tris[k] = len(positions) + np.arange(3 * len(k)).reshape(-1, 3)
    positions = np.concatenate([positions, positions[old]])
    uvs = np.concatenate([uvs, np.zeros((len(old), 2))])
    if vertex_alpha is not None:
        vertex_alpha = np.concatenate([vertex_alpha, vertex_alpha[old]])
    return positions, uvs, tris, vertex_alpha


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
