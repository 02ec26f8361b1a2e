"""Reading glTF 2.0 (.gltf / .glb) into the scene model: the only module that imports pygltflib.

One reader, one policy per case, for ``omaps trace``, ``omaps omm`` and all later work
(docs/FORMAT.md "Reading glTF" states the same):

* a file not named .gltf or .glb (``files.SCENE_RULE``), a file that is not glTF, an accessor,
  buffer view or index out of range, a node cycle: an ``InputError`` naming the file (exit 2);
* ``extensionsRequired`` naming an extension omaps cannot honour (KTX2 textures,
  ``KHR_meshopt_compression``, ...): an ``InputError`` naming the extension;
* ``EXT_meshopt_compression``: a bufferView's bytes are decoded from the range its extension names
  (``scene.meshopt``: the attribute, triangle and index codecs and the filters of its
  specification), whether the extension is required or only used; its own buffer (a fallback) is
  never read; a stream that does not decode exactly is an ``InputError`` naming the bufferView;
* ``KHR_draco_mesh_compression``: a primitive's attributes and indices are its Draco data's, as
  Google's decoder (DracoPy) gives them (dequantised), its uncompressed accessors ignored but for
  their types; an attribute the extension does not name is read from its accessor;
* ``EXT_mesh_gpu_instancing``: a node's mesh is an instance per element of its ``TRANSLATION``,
  ``ROTATION`` and ``SCALE`` accessors (composed with the node's transform), whether the extension
  is required or only used: every command sees every instance (the mesh baked once);
* every URI (buffers, images) is resolved under one policy (``scene.container``: relative paths
  and data URIs only, under the asset's folder or ``root``, no network, size caps): a URI it
  refuses is an ``InputError`` naming the file, the URI, where it leads and the parameter that would
  allow it, before anything is read;
* a buffer file that is missing: an ``InputError`` naming it (the geometry is not there to trace
  or bake); buffers nobody reads are never opened;
* an image over Pillow's decompression-bomb limit: an ``InputError`` naming it;
* an image that is missing or cannot be decoded: a ``SceneWarning`` naming it; a material using it
  is still alpha-tested, but every region of its maps is C (unknown: the any-hit shader decides),
  and the tracer's shader sees a white texel (alpha 1). A missing image no material uses as its
  base colour is named once too;
* an image with no alpha channel used by an alpha-tested material: a warning (alpha is 1);
* sparse accessors, normalized and quantized (KHR_mesh_quantization) attributes, strides,
  triangle strips and fans, ``KHR_texture_transform`` (and its ``texCoord``), ``EXT_texture_webp``
  and ``MSFT_texture_dds`` (its DDS image preferred to the texture's own source, as a renderer
  that reads the extension samples it; BC1 to BC7 decoded by Pillow) are read; points and lines
  are left out and listed in ``Scene.skipped``;
* ``COLOR_0`` alpha multiplies the base colour alpha (glTF's rule): where it is not 1 everywhere,
  the primitive's triangles are *unknown* (all C) and the tracer's shader multiplies by it;
* texture coordinates that are NaN, infinite or huge (beyond ``MAX_TEXEL_COORDINATE`` texels from
  the origin): a warning naming mesh, primitive and count;
  those triangles are unknown and get vertices of their own at UV (0, 0) (the shader reads that
  one point; their neighbours keep their coordinates); missing although the material samples a
  texture: the same warning, the primitive's triangles unknown at UV (0, 0);
* cameras are read (``Scene.cameras``: perspective ``yfov`` and the world transform of the first
  node of the default scene placing each) and checked only when one is used;
* a warning is given once per problem (a missing file named by several images or materials once).
"""

from __future__ import annotations

import dataclasses
import io
import os
import warnings

import numpy as np

from ..errors import InputError
from .container import (DRACO, INSTANCING, MESHOPT, SUPPORTED_EXTENSIONS, AssetPolicy, Container, Location,
                        read_container)
from .files import check_scene_file
from .model import ALPHA_MODES, Material, Mesh, Primitive, Scene, SceneCamera, SceneWarning, Texture, own_vertices

__all__ = ["load_scene", "SUPPORTED_EXTENSIONS", "node_matrix", "texture_transform_matrix"]

IMAGE_SOURCES = ("MSFT_texture_dds", "EXT_texture_webp")  # texture extensions that name an image (``_source_of``)
_GL_NEAREST = (9728, 9984, 9986)  # magFilter NEAREST, or min NEAREST_MIPMAP_*
_WRAP = {33071: "clamp", 33648: "mirror", 10497: "wrap"}
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_TRIANGLES, _STRIP, _FAN = 4, 5, 6
# the message of the last resort around the reader, for a malformed value no check caught (the
# fuzz tests, tests/test_fuzz.py, fail on it: every problem should be named by a check)
UNCHECKED = "malformed glTF"
MAX_ZERO_ACCESSOR = 1 << 24  # elements of an accessor without a bufferView (zeros, maybe sparse)
# texture coordinates beyond this many texels from the origin (|u| * width or |v| * height) are
# treated like NaN: float64 texel arithmetic there is too coarse for the 2^-20-texel growth the
# maps rely on, and a texel index must stay far inside int64
MAX_TEXEL_COORDINATE = float(1 << 30)


def load_scene(path, *, root=None, allow_outside: bool = False, max_bytes: int | None = None) -> Scene:
    """Load a .gltf or .glb file into the scene model (``omaps.scene.model``): the glTF reader
    that ``omaps.scene.load_scene`` picks by the file's suffix, with its parameters (``root``,
    ``allow_outside``, ``max_bytes``: the URI policy of ``scene.container``) and its errors (an
    ``InputError`` naming the file, for the cases the module docstring lists; recoverable
    problems are ``SceneWarning``s, also kept in ``Scene.warnings``)."""
    from ..checks import path as checked_path

    path = checked_path(path, "path")
    check_scene_file(path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    if os.path.isdir(path):
        raise InputError("is a folder, not a glTF file", path)
    container = read_container(path, AssetPolicy.of(root, allow_outside, max_bytes))
    doc = _document(container)
    try:
        return _Reader(doc, container).scene()
    except InputError:
        raise
    except (IndexError, TypeError, KeyError, ValueError, AttributeError) as exc:  # a case no check names
        raise InputError(f"{UNCHECKED} ({type(exc).__name__}: {exc})", path) from None


def _document(container: Container):
    """The container's JSON as pygltflib's objects (the checks of ``_Reader`` read them)."""
    import pygltflib

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            doc = pygltflib.GLTF2.from_dict(container.doc, infer_missing=True)
            for mesh in doc.meshes:
                for primitive in mesh.primitives:
                    if primitive.attributes:
                        primitive.attributes = pygltflib.Attributes(**primitive.attributes)
    except Exception as exc:  # pygltflib's decoding raises assorted types on values of the wrong type
        raise InputError(f"cannot read glTF ({type(exc).__name__}: {exc})", container.path) from None
    return doc


class _Reader:
    def __init__(self, doc, container: Container):
        self.g = doc
        self.container = container
        self.path = container.path
        self.warnings: list[str] = []
        self._buffers: dict[int, bytes] = {}
        self._decoded: dict[int, tuple[bytes, int]] = {}  # EXT_meshopt_compression views, decoded once

    def warn(self, message: str) -> None:
        if message in self.warnings:  # one warning per problem, however many images or materials share it
            return
        self.warnings.append(message)
        warnings.warn(f"{self.path}: {message}", SceneWarning, stacklevel=2)

    # -- checked fields: every value the reader uses is checked where it is read --------------
    def _int(self, value, what: str, lo: int = 0, hi: int | None = None) -> int:
        """``value`` as an int in [lo, hi); an InputError saying what is wrong otherwise."""
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise InputError(f"{what} is {value!r}, not an integer", self.path)
        if value < lo or (hi is not None and value >= hi):
            raise InputError(f"{what} is {value}, outside {lo}..{'' if hi is None else hi - 1}", self.path)
        return int(value)

    def _ref(self, value, items, what: str) -> int:
        """A reference (an index into the document's list ``items``) that must exist."""
        n = len(items) if isinstance(items, list) else 0
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < n:
            raise InputError(f"{what} {value!r} does not exist ({n} defined)", self.path)
        if not dataclasses.is_dataclass(items[value]):
            raise InputError(f"{what} {value} is {items[value]!r}, not an object", self.path)
        return int(value)

    def _numbers(self, value, n: int, what: str) -> list[float]:
        """A list of ``n`` finite numbers."""
        if (not isinstance(value, (list, tuple)) or len(value) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and -1e300 < x < 1e300
                           for x in value)):  # finite (no NaN, no infinity, no int too large for a float)
            raise InputError(f"{what} must be {n} finite number{'s' if n > 1 else ''}, got {value!r}", self.path)
        return [float(x) for x in value]

    def _number(self, value, what: str) -> float:
        return self._numbers([value], 1, what)[0]

    def _list(self, value, what: str, objects: bool = False) -> list:
        """An optional JSON array (None: empty); ``objects``: of glTF objects."""
        if value is None:
            return []
        if not isinstance(value, list):
            raise InputError(f"{what} is {value!r}, not an array", self.path)
        if objects:
            for i, item in enumerate(value):
                if not dataclasses.is_dataclass(item):
                    raise InputError(f"{what}[{i}] is {item!r}, not an object", self.path)
        return value

    def _dict(self, value, what: str) -> dict:
        """An optional JSON object (None: empty)."""
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise InputError(f"{what} is {value!r}, not an object", self.path)
        return value

    def _uri(self, value, what: str) -> str | None:
        if value is not None and not isinstance(value, str):
            raise InputError(f"{what}: uri is {value!r}, not a string", self.path)
        return value

    # -- raw data ---------------------------------------------------------------------------
    def check_uris(self) -> None:
        """Every buffer and image URI resolved under the policy before anything is read: a refused
        one is an ``InputError`` even where nothing reads it (a baked copy would still name it)."""
        for key, items in (("buffer", self.g.buffers), ("image", self.g.images)):
            for i, item in enumerate(self._list(items, f"{key}s", True)):
                uri = self._uri(item.uri, f"{key} {i}")
                if uri is not None:
                    self.container.locate(uri, f"{key} {i}", unread_ok=True)

    def buffer(self, i: int) -> bytes:
        i = self._ref(i, self.g.buffers, "buffer")
        if i not in self._buffers:
            b = self.g.buffers[i]
            uri = self._uri(b.uri, f"buffer {i}")
            length = self._int(b.byteLength, f"buffer {i}: byteLength")
            self._buffers[i] = bytes(self.container.buffer_data(i, uri, length))
        return self._buffers[i]

    def view_bytes(self, vi: int) -> tuple[bytes, int | None]:
        """The bytes of bufferView ``vi`` and its byteStride (None: tightly packed); a view with
        ``EXT_meshopt_compression`` decoded from the range its extension names (``scene.meshopt``),
        its own buffer (a fallback) never read."""
        vi = self._ref(vi, self.g.bufferViews, "bufferView")
        if vi in self._decoded:
            return self._decoded[vi]
        v = self.g.bufferViews[vi]
        length = self._int(v.byteLength, f"bufferView {vi}: byteLength")
        stride = None if v.byteStride is None else self._int(v.byteStride, f"bufferView {vi}: byteStride", 1)
        ext = v.extensions.get(MESHOPT) if isinstance(v.extensions, dict) else None
        if ext is not None:
            from . import meshopt

            what = f"bufferView {vi}: {MESHOPT}"
            ext = self._dict(ext, what)
            raw = self._range(ext.get("buffer"), ext.get("byteOffset"), ext.get("byteLength"), what)
            try:
                out, stride = meshopt.decode_view(raw, ext, length, stride)
            except meshopt.MeshoptError as exc:
                raise InputError(f"{what}: {exc}", self.path) from None
            self._decoded[vi] = (out.tobytes(), stride)
            return self._decoded[vi]
        return self._range(v.buffer, v.byteOffset, length, f"bufferView {vi}"), stride

    def _range(self, buffer, offset, length, what: str) -> bytes:
        """``length`` bytes from ``offset`` (None: 0) of buffer ``buffer``, checked."""
        data = self.buffer(self._ref(buffer, self.g.buffers, f"{what}: buffer"))
        off = 0 if offset is None else self._int(offset, f"{what}: byteOffset")
        length = self._int(length, f"{what}: byteLength")
        if off + length > len(data):
            raise InputError(f"{what} (bytes {off}..{off + length}) runs past the end of buffer {buffer} "
                             f"({len(data)} bytes)", self.path)
        return data[off:off + length]

    def accessor(self, ai: int, types=None) -> np.ndarray:
        """Accessor ``ai`` as an array (count, components): floats as float64, normalised
        integers scaled to [0, 1] or [-1, 1], other integers as int64. ``types``: the accessor
        types (``"VEC3"``, ...) the caller accepts. Every offset, length, stride and count is
        checked against its bufferView here, before any byte is read."""
        ai = self._ref(ai, self.g.accessors, "accessor")
        a = self.g.accessors[ai]
        what = f"accessor {ai}"
        if not isinstance(a.componentType, int) or a.componentType not in _DTYPES \
                or not isinstance(a.type, str) or a.type not in _COMPONENTS:
            raise InputError(f"{what}: unsupported type {a.type!r}/{a.componentType!r}", self.path)
        if types is not None and a.type not in types:
            raise InputError(f"{what} is {a.type}, {' or '.join(types)} expected here", self.path)
        dt = np.dtype(_DTYPES[a.componentType]).newbyteorder("<")
        ncomp = _COMPONENTS[a.type]
        count = self._int(a.count, f"{what}: count")
        if a.bufferView is None:
            if count > MAX_ZERO_ACCESSOR:
                raise InputError(f"{what} has no bufferView and {count} elements (at most {MAX_ZERO_ACCESSOR})",
                                 self.path)
            out = np.zeros((count, ncomp), dtype=dt)
        else:
            raw, stride = self.view_bytes(a.bufferView)
            start = 0 if a.byteOffset is None else self._int(a.byteOffset, f"{what}: byteOffset")
            elem = dt.itemsize * ncomp
            stride = stride or elem
            if stride < elem:
                raise InputError(f"{what}: byteStride {stride} is smaller than one element ({elem} bytes)", self.path)
            need = start + stride * (count - 1) + elem if count else 0
            if need > len(raw):
                raise InputError(f"{what} needs {need} bytes, its bufferView {a.bufferView} has {len(raw)}", self.path)
            if count == 0:
                out = np.zeros((0, ncomp), dtype=dt)
            else:
                buf = np.frombuffer(raw, dtype=np.uint8)
                rows = np.lib.stride_tricks.as_strided(buf[start:], shape=(count, elem), strides=(stride, 1))
                out = np.ascontiguousarray(rows).view(dt).reshape(count, ncomp)
        if a.sparse is not None:
            out = out.copy()
            s = a.sparse
            n = self._int(getattr(s, "count", None), f"{what}: sparse count", 0, count + 1)
            ind, val = getattr(s, "indices", None), getattr(s, "values", None)
            if ind is None or val is None:
                raise InputError(f"{what}: sparse needs indices and values", self.path)
            ict = getattr(ind, "componentType", None)
            if ict not in (5121, 5123, 5125) or isinstance(ict, bool):
                raise InputError(f"{what}: sparse indices componentType {ict!r} is not an unsigned integer type",
                                 self.path)
            idx = self._sparse_part(what, "indices", ind, n, 1, np.dtype(_DTYPES[ict]))
            val = self._sparse_part(what, "values", val, n, ncomp, dt)
            idx = idx.ravel().astype(np.int64)
            if idx.size and idx.max() >= count:
                raise InputError(f"{what}: sparse index {int(idx.max())} is out of range ({count} elements)", self.path)
            out[idx] = val
        if dt.kind == "f":
            return out.astype(np.float64)
        if a.normalized:
            return np.maximum(out.astype(np.float64) / np.iinfo(dt).max, -1.0)
        return out.astype(np.int64)

    def _sparse_part(self, what, part, ref, count, ncomp, dt):
        raw, _ = self.view_bytes(getattr(ref, "bufferView", None))
        offset = getattr(ref, "byteOffset", None)
        start = 0 if offset is None else self._int(offset, f"{what}: sparse {part} byteOffset")
        n = count * ncomp * dt.itemsize
        if start + n > len(raw):
            raise InputError(f"{what}: sparse {part} need {start + n} bytes, their bufferView has {len(raw)}",
                             self.path)
        return np.frombuffer(raw[start:start + n], dtype=dt.newbyteorder("<")).reshape(count, ncomp)

    # -- textures and materials -------------------------------------------------------------
    def image(self, ii: int) -> Texture:
        from PIL import Image

        from ..texture import open_image

        im = self.g.images[ii]
        uri = self._uri(im.uri, f"image {ii}")
        label = uri if uri and not uri.startswith("data:") else (im.name if isinstance(im.name, str) and im.name
                                                                 else f"image {ii}")
        data = problem = None
        if im.bufferView is not None:
            data, _ = self.view_bytes(im.bufferView)
        elif uri and uri.startswith("data:"):
            self.container.check_data_size(uri, f"image {ii}")
            try:
                data = self.container.data_uri(uri, f"image {ii}")
            except InputError as exc:  # an image (unlike a buffer) that cannot be read is a warning
                problem = f"image {label!r}: {exc.problem}"
        elif uri:
            data = self.container.read(uri, f"image {ii}", unread_ok=True)  # a refused URI: InputError
            if isinstance(data, Location):  # a URI omaps never reads, let go by allow_outside
                problem, data = f"{data.problem}; it is not read", None
        if data is None:
            problem = problem or f"image file {label!r} is missing"
        else:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error", Image.DecompressionBombWarning)
                    with open_image(io.BytesIO(data), label) as pil:
                        return Texture.from_image(label, pil)
            except InputError as exc:
                if "DecompressionBomb" in exc.problem:  # a service's limit, not a broken file: an error
                    raise InputError(f"image {ii} ({label!r}) is over Pillow's decompression-bomb limit of "
                                     f"{Image.MAX_IMAGE_PIXELS} pixels ({exc.problem}): not decoded",
                                     self.path) from None
                problem = f"image {label!r} cannot be decoded ({exc.problem})"
        return Texture(label, None, 255, None, problem)

    def materials(self) -> tuple[list[Material], list[Texture], list[np.ndarray]]:
        """Materials, the textures they use, and per material its 2x3 UV transform."""
        textures: list[Texture] = []
        by_image: dict[int, int] = {}
        mats, transforms = [], []
        for mi, m in enumerate(self._list(self.g.materials, "materials", True)):
            name = m.name if isinstance(m.name, str) and m.name else f"material {mi}"
            what = f"material {mi} ({name})"
            pbr = m.pbrMetallicRoughness
            factor = (1.0, 1.0, 1.0, 1.0)
            if pbr is not None and pbr.baseColorFactor is not None:
                factor = tuple(self._numbers(pbr.baseColorFactor, 4, f"{what}: baseColorFactor"))
            if m.alphaMode is not None and not isinstance(m.alphaMode, str):
                raise InputError(f"{what}: alphaMode {m.alphaMode!r} is not a string", self.path)
            mode = (m.alphaMode or "OPAQUE").upper()
            if mode not in ALPHA_MODES:
                raise InputError(f"{what}: unknown alphaMode {m.alphaMode!r}", self.path)
            cutoff = 0.5 if m.alphaCutoff is None else self._number(m.alphaCutoff, f"{what}: alphaCutoff")
            if cutoff < 0:
                raise InputError(f"{what}: alphaCutoff {cutoff} is negative", self.path)
            tex_index, filt, wu, wv, coord, xf = -1, "linear", "wrap", "wrap", 0, np.eye(2, 3)
            info = pbr.baseColorTexture if pbr is not None else None
            if info is not None and info.index is not None:
                ti = self._ref(info.index, self.g.textures, f"{what}: texture")
                t = self.g.textures[ti]
                exts = self._dict(t.extensions, f"texture {ti}: extensions")
                for ext in IMAGE_SOURCES:
                    self._dict(exts.get(ext), f"texture {ti}: {ext}")
                source = _source_of(t)
                if source is None:
                    key = ("none", ti)
                    if key not in by_image:
                        by_image[key] = len(textures)
                        problem = f"texture {ti} has no image omaps can decode (KTX2 / basisu?)"
                        textures.append(Texture(f"texture {ti}", None, 255, None, problem))
                        self.warn(f"{problem}: the maps of {name} are unknown")
                    tex_index = by_image[key]
                else:
                    source = self._ref(source, self.g.images, f"texture {ti}: image")
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
                    s = self.g.samplers[self._ref(t.sampler, self.g.samplers, f"texture {ti}: sampler")]
                    filt = "nearest" if s.magFilter in _GL_NEAREST else "linear"
                    wu, wv = (self._wrap(w, f"sampler {t.sampler}: {key}") for key, w in (("wrapS", s.wrapS),
                                                                                         ("wrapT", s.wrapT)))
                coord = 0 if info.texCoord is None else self._int(info.texCoord, f"{what}: texCoord")
                ext = self._dict(info.extensions, f"{what}: baseColorTexture extensions").get("KHR_texture_transform")
                if ext is not None:
                    ext = self._dict(ext, f"{what}: KHR_texture_transform")
                    xf = texture_transform_matrix({
                        "offset": self._numbers(ext.get("offset", [0.0, 0.0]), 2, f"{what}: texture transform offset"),
                        "rotation": self._number(ext.get("rotation", 0.0), f"{what}: texture transform rotation"),
                        "scale": self._numbers(ext.get("scale", [1.0, 1.0]), 2, f"{what}: texture transform scale")})
                    if ext.get("texCoord") is not None:
                        coord = self._int(ext["texCoord"], f"{what}: texture transform texCoord")
            mats.append(Material(mi, name, mode, cutoff, factor, tex_index, filt, wu, wv, coord, bool(m.doubleSided)))
            transforms.append(xf)
        return mats, textures, transforms

    def _wrap(self, code, what: str) -> str:
        if code is None:
            return "wrap"
        if isinstance(code, bool) or not isinstance(code, int) or code not in _WRAP:
            raise InputError(f"{what} is {code!r}, not a glTF wrap mode (33071, 33648, 10497)", self.path)
        return _WRAP[code]

    def check_unused_images(self, used: set) -> None:
        """Name referenced image files that are missing but not a base colour (normal maps and the
        like), once each, so no missing file goes unmentioned (a file that is also a base colour
        was named as one)."""
        images = self._list(self.g.images, "images", True)
        used_uris = {images[ii].uri for ii in used if isinstance(ii, int) and 0 <= ii < len(images)}
        for ii, im in enumerate(images):
            uri = self._uri(im.uri, f"image {ii}")
            if ii in used or not uri or uri.startswith("data:") or uri in used_uris:
                continue
            loc = self.container.locate(uri, f"image {ii}", unread_ok=True)
            if loc.kind == "unread":
                self.warn(f"{loc.problem}; it is not read (not a base colour texture, so not needed)")
            elif not os.path.isfile(loc.path):
                self.warn(f"image file {uri!r} is missing (not a base colour texture, so not needed)")

    # -- geometry ---------------------------------------------------------------------------
    def mesh(self, mi: int, mats: list[Material], transforms, default_material: int, skipped: list) -> Mesh:
        m = self.g.meshes[mi]
        name = m.name if isinstance(m.name, str) and m.name else f"mesh {mi}"
        prims = []
        for pi, p in enumerate(self._list(m.primitives, f"mesh {mi} ({name}): primitives", True)):
            where = {"mesh": mi, "primitive": pi, "name": name}
            label = f"mesh {mi} ({name}) primitive {pi}"
            mode = _TRIANGLES if p.mode is None else self._int(p.mode, f"{label}: mode", 0, 7)
            if mode not in (_TRIANGLES, _STRIP, _FAN):
                skipped.append({**where, "reason": f"primitive mode {mode} (points or lines) has no triangles"})
                continue
            if p.attributes is None or getattr(p.attributes, "POSITION", None) is None:
                skipped.append({**where, "reason": "no POSITION attribute"})
                continue
            material = default_material if p.material is None else self._ref(p.material, self.g.materials,
                                                                            f"{label}: material")
            mat = mats[material]
            draco = self.draco(p, label)
            if draco is not None and mode == _FAN:
                raise InputError(f"{label}: a Draco-compressed primitive must be of triangles or a strip", self.path)
            positions = self._read(draco, "POSITION", p.attributes.POSITION, ("VEC3",), None, label)
            n = len(positions)
            if draco is not None:
                idx, mode = draco[1], _TRIANGLES  # (Draco decodes a triangle list)
            elif p.indices is None:
                idx = np.arange(n, dtype=np.int64)
            else:
                ia = self._ref(p.indices, self.g.accessors, f"{label}: indices accessor")
                if self.g.accessors[ia].componentType not in (5121, 5123, 5125) or self.g.accessors[ia].normalized:
                    raise InputError(f"{label}: indices accessor {ia} is not of an unsigned integer type", self.path)
                idx = self.accessor(ia, ("SCALAR",)).ravel()
            if idx.size and idx.max() >= n:
                raise InputError(f"{label}: vertex index {int(idx.max())} is out of range ({n} vertices)", self.path)
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
                uvs = self._read(draco, f"TEXCOORD_{mat.texcoord}", uv_acc, ("VEC2",), n, label)
                uvs = uvs @ transforms[material][:, :2].T + transforms[material][:, 2]
                tex = self._textures[mat.texture] if mat.texture >= 0 else None
                size = max(tex.alpha.shape) if tex is not None and tex.alpha is not None else 1
                with np.errstate(invalid="ignore"):
                    bad_v = ~(np.abs(uvs) * size <= MAX_TEXEL_COORDINATE).all(axis=1)  # NaN and inf too
                if bad_v.any():
                    bad_t = bad_v[tris].any(axis=1)
                    uvs = np.where(bad_v[:, None], 0.0, uvs)
                    unknown |= bad_t
                    own = bad_t
                    if mat.alpha_mode != "OPAQUE":
                        self.warn(f"{label}: {int(bad_t.sum())} triangles have NaN, infinite or huge (beyond "
                                  "2^30 texels) texture coordinates: they are unknown (all C), read as UV (0, 0) "
                                  "at every vertex")
            vertex_alpha = None
            colour = getattr(p.attributes, "COLOR_0", None)
            if colour is not None:
                col = self._read(draco, "COLOR_0", colour, ("VEC3", "VEC4"), n, label)
                if col.shape[1] == 4 and not np.all(col[:, 3] == 1.0):
                    vertex_alpha = np.clip(np.nan_to_num(col[:, 3], nan=0.0), 0.0, 1.0)
                    if mat.alpha_mode != "OPAQUE":
                        unknown[:] = True
                        self.warn(f"{label}: COLOR_0 alpha is not 1 everywhere: its {len(tris)} triangles are "
                                  "unknown and the tracer's shader multiplies by it")
            if own is not None:
                positions, uvs, tris, vertex_alpha = own_vertices(positions, uvs, tris, vertex_alpha, own)
            prims.append(Primitive(mi, pi, positions, uvs, tris, material, vertex_alpha, unknown))
        return Mesh(mi, name, prims)

    def draco(self, p, label: str):
        """A primitive's ``KHR_draco_mesh_compression`` data decoded (DracoPy, Google's decoder):
        (its attributes by glTF name, as float64 arrays (count, components), its triangle list's
        vertex indices), or None without the extension. Integer attributes are scaled as their
        accessors' ``normalized`` says, as an accessor's would be."""
        ext = (p.extensions or {}).get(DRACO) if isinstance(p.extensions, dict) else None
        if ext is None:
            return None
        import DracoPy

        what = f"{label}: {DRACO}"
        ext = self._dict(ext, what)
        raw, _ = self.view_bytes(self._ref(ext.get("bufferView"), self.g.bufferViews, f"{what}: bufferView"))
        try:
            mesh = DracoPy.decode(bytes(raw))
        except Exception as exc:  # (the decoder's own error types and messages)
            raise InputError(f"{what}: its Draco data cannot be decoded ({type(exc).__name__}: {exc})",
                             self.path) from None
        if not isinstance(mesh, DracoPy.DracoMesh):
            raise InputError(f"{what}: its Draco data is a point cloud, not a mesh", self.path)
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1)
        attrs = {}
        for name, uid in self._dict(ext.get("attributes"), f"{what}: attributes").items():
            uid = self._int(uid, f"{what}: attributes: {name}")
            found = mesh.get_attribute_by_unique_id(uid)
            if found is None:
                raise InputError(f"{what}: attribute {name}'s Draco id {uid} is not in its Draco data", self.path)
            data = np.asarray(found.get("data") if isinstance(found, dict) else None)
            if data.ndim == 0 or data.dtype.kind not in "fiu":
                raise InputError(f"{what}: attribute {name} has no data in its Draco data", self.path)
            data = data.reshape(len(data), -1)
            acc = getattr(p.attributes, name, None) if p.attributes is not None else None
            a = self.g.accessors[self._ref(acc, self.g.accessors, f"{what}: {name}'s accessor")] \
                if acc is not None else None
            if data.dtype.kind in "iu" and a is not None and a.normalized:
                data = np.maximum(data.astype(np.float64) / np.iinfo(data.dtype).max, -1.0)
            attrs[name] = data.astype(np.float64)
        if "POSITION" not in attrs:
            raise InputError(f"{what} names no POSITION attribute", self.path)
        n = len(attrs["POSITION"])
        if faces.size and (faces.min() < 0 or faces.max() >= n):
            raise InputError(f"{what}: a Draco face names vertex {int(faces.max())} of {n}", self.path)
        return attrs, faces

    def _read(self, draco, name: str, ai, types, n, label: str) -> np.ndarray:
        """A vertex attribute: from the primitive's Draco data where it names it, else its
        accessor; ``n``: the count it must have (POSITION's), None for POSITION itself."""
        if draco is not None and name in draco[0]:
            out = draco[0][name]
            if out.shape[1] not in [_COMPONENTS[t] for t in types]:
                raise InputError(f"{label}: {DRACO}: {name} has {out.shape[1]} components, {' or '.join(types)} "
                                 "expected", self.path)
            if n is not None and len(out) != n:
                raise InputError(f"{label}: {DRACO}: {name} has {len(out)} elements, POSITION has {n}", self.path)
            return out
        return self.accessor(ai, types) if n is None else self._attribute(ai, types, n, f"{label}: {name}")

    def _attribute(self, ai, types, n: int, what: str) -> np.ndarray:
        """A vertex attribute: one element per vertex, as POSITION has."""
        out = self.accessor(ai, types)
        if len(out) != n:
            raise InputError(f"{what} (accessor {ai}) has {len(out)} elements, POSITION has {n}", self.path)
        return out

    def node_instances(self) -> list[tuple[int, np.ndarray]]:
        g = self.g
        nodes = self._list(g.nodes, "nodes", True)
        children = {}
        for ni, n in enumerate(nodes):  # glTF node hierarchies are disjoint trees
            for c in self._list(n.children, f"node {ni}: children"):
                c = self._ref(c, nodes, f"node {ni}: child")
                if c in children:
                    raise InputError(f"node {c} has two parents (nodes {children[c]} and {ni}); glTF node "
                                     "hierarchies are trees", self.path)
                children[c] = ni
        if g.scenes:
            scenes = self._list(g.scenes, "scenes", True)
            si = 0 if g.scene is None else self._ref(g.scene, scenes, "default scene")
            roots = [self._ref(r, nodes, f"scene {si}: node")
                     for r in self._list(scenes[si].nodes, f"scene {si}: nodes")]
        elif nodes:
            roots = sorted(set(range(len(nodes))) - set(children))
        else:  # meshes without nodes: each once, untransformed
            return [(mi, np.eye(4)) for mi in range(len(self._list(g.meshes, "meshes")))]
        out = []
        cams = self._camera_nodes = {}
        stack = [(r, np.eye(4), ()) for r in reversed(roots)]
        while stack:
            ni, parent, path = stack.pop()
            if ni in path:
                raise InputError("node hierarchy has a cycle", self.path)
            n = nodes[ni]
            world = parent @ self.node_matrix(ni)
            if n.mesh is not None:
                mi = self._ref(n.mesh, g.meshes, f"node {ni}: mesh")
                many = (n.extensions or {}).get(INSTANCING) if isinstance(n.extensions, dict) else None
                if many is None:
                    out.append((mi, world))
                else:  # the instances' transforms in the node's space, in accessor order (composed as a
                    out += [(mi, world @ m) for m in self.gpu_instances(ni, many)]  # child node's would be)
            if n.camera is not None:
                if not isinstance(n.camera, int) or not 0 <= n.camera < len(g.cameras or []):
                    raise InputError(f"node {ni}: camera {n.camera} does not exist", self.path)
                cams.setdefault(n.camera, (ni, world))
            for c in reversed(n.children or []):
                stack.append((c, world, path + (ni,)))
        return out

    def gpu_instances(self, ni: int, ext) -> np.ndarray:
        """Node ``ni``'s ``EXT_mesh_gpu_instancing`` instances as (n, 4, 4) transforms T * R * S
        in the node's space: ``TRANSLATION`` and ``SCALE`` VEC3 and ``ROTATION`` VEC4 accessors
        (floats, or integers as KHR_mesh_quantization allows: a rotation's normalised), one element
        per instance each, the missing ones the identity's; other (custom) attributes are not read."""
        what = f"node {ni}: {INSTANCING}"
        ext = self._dict(ext, what)
        attrs = self._dict(ext.get("attributes"), f"{what}: attributes")
        got = {}
        for key, kind in (("TRANSLATION", "VEC3"), ("ROTATION", "VEC4"), ("SCALE", "VEC3")):
            if key in attrs:
                ai = self._ref(attrs[key], self.g.accessors, f"{what}: {key}")
                if key == "ROTATION" and self.g.accessors[ai].componentType != 5126 \
                        and not self.g.accessors[ai].normalized:
                    raise InputError(f"{what}: ROTATION (accessor {ai}) must be floats or normalised integers",
                                     self.path)
                v = self.accessor(ai, (kind,)).astype(np.float64)
                if not np.all(np.isfinite(v)):
                    raise InputError(f"{what}: {key} (accessor {ai}) holds a NaN or an infinity", self.path)
                got[key] = v
        if not got:
            raise InputError(f"{what} has no TRANSLATION, ROTATION or SCALE attribute", self.path)
        counts = {k: len(v) for k, v in got.items()}
        if len(set(counts.values())) > 1:
            raise InputError(f"{what}: its attributes' counts differ ({counts})", self.path)
        n = next(iter(counts.values()))
        return trs_matrices(got.get("TRANSLATION", np.zeros((n, 3))),
                            got.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))),
                            got.get("SCALE", np.ones((n, 3))))

    def node_matrix(self, ni: int) -> np.ndarray:
        """Node ``ni``'s local transform (``node_matrix``), its fields checked: finite numbers,
        16 for ``matrix``, 3 for ``translation`` and ``scale``, 4 for ``rotation``."""
        n = self.g.nodes[ni]
        for key, size in (("matrix", 16), ("translation", 3), ("rotation", 4), ("scale", 3)):
            if getattr(n, key) is not None:
                self._numbers(getattr(n, key), size, f"node {ni}: {key}")
        return node_matrix(n)

    def scene(self) -> Scene:
        g = self.g
        names = self._list(g.extensionsRequired, "extensionsRequired")
        if not all(isinstance(e, str) for e in names):
            raise InputError(f"extensionsRequired {names!r} is not a list of extension names", self.path)
        required = sorted(set(names) - SUPPORTED_EXTENSIONS)
        if required:
            raise InputError(f"requires the glTF extension{'s' if len(required) > 1 else ''} "
                             f"{', '.join(required)}, which omaps cannot read", self.path)
        self.check_uris()
        mats, textures, transforms = self.materials()
        self._textures = textures
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
        from .micromaps import read_extensions

        stored = read_extensions(self)  # EXT_mesh_opacity_micromap, OMAPS_pair_opacity_maps: their rules checked
        return Scene(self.path, meshes, inst, mats, textures, self.warnings, skipped, cameras, stored)

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


def _base_image(g, m):
    pbr = m.pbrMetallicRoughness
    info = pbr.baseColorTexture if pbr else None
    if info is None or info.index is None or not 0 <= info.index < len(g.textures or []):
        return None
    return _source_of(g.textures[info.index])


def _source_of(t):
    """The image a texture samples (its fields checked by the caller): ``MSFT_texture_dds``'s
    source (what a renderer that reads the extension samples: a DDS image, decoded by Pillow),
    else the texture's own ``source``, else ``EXT_texture_webp``'s."""
    ext = t.extensions if isinstance(t.extensions, dict) else {}
    dds = ext.get("MSFT_texture_dds")
    if isinstance(dds, dict) and dds.get("source") is not None:
        return dds["source"]
    if t.source is not None:
        return t.source
    webp = ext.get("EXT_texture_webp")
    return webp.get("source") if isinstance(webp, dict) else None


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


def node_matrix(n) -> np.ndarray:
    """A node's local 4x4 transform: ``matrix`` (column-major) or T * R * S."""
    if n.matrix is not None:
        return np.array(n.matrix, dtype=np.float64).reshape(4, 4).T
    return trs_matrices(np.array([n.translation if n.translation is not None else (0.0, 0.0, 0.0)], np.float64),
                        np.array([n.rotation if n.rotation is not None else (0.0, 0.0, 0.0, 1.0)], np.float64),
                        np.array([n.scale if n.scale is not None else (1.0, 1.0, 1.0)], np.float64))[0]


def trs_matrices(t: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(n, 4, 4) transforms T * R * S from translations (n, 3), unit quaternions (n, 4: x, y,
    z, w, as glTF stores them) and scales (n, 3): a node's, or each of a node's GPU instances."""
    x, y, z, w = (r[:, k] for k in range(4))
    m = np.zeros((len(t), 4, 4))
    m[:, 0, 0], m[:, 0, 1], m[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    m[:, 1, 0], m[:, 1, 1], m[:, 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    m[:, 2, 0], m[:, 2, 1], m[:, 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    m[:, :3, :3] *= s[:, None, :]  # R * S: column j scaled by s_j
    m[:, :3, 3] = t
    m[:, 3, 3] = 1.0
    return m


def texture_transform_matrix(ext: dict) -> np.ndarray:
    """KHR_texture_transform as a 2x3 affine matrix: uv' = T(offset) * R(rotation) * S(scale) * uv."""
    ox, oy = ext.get("offset", [0.0, 0.0])
    r = float(ext.get("rotation", 0.0))
    sx, sy = ext.get("scale", [1.0, 1.0])
    c, s = np.cos(r), np.sin(r)
    # the extension's rotation matrix is [[c, s], [-s, c]] (rotates UVs clockwise)
    return np.array([[c * sx, s * sy, ox], [-s * sx, c * sy, oy]], dtype=np.float64)
