"""The glTF container and the files it names: the one place omaps opens a glTF asset.

Reading (``read_container``) gives the JSON document and the GLB binary chunk; every external
resource of the document (buffers, images) is then found and read through the returned
``Container`` under one policy (``AssetPolicy``), for the scene reader (``scene.gltf``) and the
writer of baked scenes (``scene.micromaps``) alike. Writing (``write_glb``, ``write_json``) packs
a document back into a file; ``self_contained`` first makes the document name nothing outside
the output (the one rule of every glTF file omaps writes; docs/guide/io.md "glTF outputs"; and
``drop_unnamed`` removes the data of micromaps the writer replaces). The rule:

* a **.glb** output holds every buffer and image in its binary chunk: the buffers one after the
  other (each at a multiple of 8 bytes, their buffer views re-based), image files and data URIs
  as buffer views with a ``mimeType``; no buffer or image keeps a ``uri``; a buffer without data
  (``EXT_meshopt_compression``'s fallback placeholder: no URI, not the binary chunk) stays one,
  after buffer 0, and the compressed ranges that extension names are re-based too;
* a **.gltf** output keeps data URIs and buffer views as they are; every file it names (buffers,
  images) is copied, byte for byte, into the folder ``OUT_files`` beside it (names made safe and
  unique, a file named twice copied once) and named by ``OUT_files/NAME``; that folder is
  replaced whole on a later write, only when it is empty or holds ``omaps-files.json`` (omaps
  wrote it);
* an image omaps cannot read (missing, unreadable, a URI omaps never fetches) is left out: the
  images after it move up one, the textures that used it keep their place but name no image,
  and a warning names it (reading treats such an image as absent: the maps of a material using
  it are unknown, its texel white); a buffer omaps cannot read is an error, as on reading.

The policy, for assets that may come from strangers (docs/guide/untrusted.md states the same):

* a URI is a ``data:`` URI (base64) or a relative path, percent-decoded and resolved against the
  asset's folder; its real path (symbolic links followed) must lie under the **root**: the
  asset's own folder unless ``root`` names another (``--root DIR``); ``allow_outside``
  (``--allow-outside``) turns that check off for an asset the user trusts;
* an absolute path (``/x``) or a local ``file:`` URI is a path like any other: read only under the
  root (or with ``allow_outside``);
* a Windows path (``C:\\x``, ``C:/x``, ``\\\\server``), a URI with back-slashes and every other scheme
  (``http:``, ``https:``, ...) are never read: omaps never fetches a URI. A buffer so named is an
  error; an image so named is an error too, unless ``allow_outside`` is given: then it is a
  warning and the image counts as missing;
* sizes: the asset file, a buffer's declared ``byteLength``, an image file and a data URI's
  decoded bytes may each be at most ``max_bytes`` (``DEFAULT_MAX_BYTES``, 2 GiB; the keyword, or
  the environment variable ``OMAPS_MAX_ASSET_BYTES``), checked before anything is read or
  allocated; a buffer's ``byteLength`` larger than its file is refused before the file is read.

Every refusal is an ``InputError`` naming the asset file, the URI, where it resolves and the
parameter that would allow it (``root``, ``allow_outside``; the command line names its options).
"""

from __future__ import annotations

import base64
import binascii
import bisect
import json
import mimetypes
import os
import re
import shutil
import stat
import struct
from dataclasses import dataclass, field
from urllib.parse import quote, unquote

from ..errors import InputError

__all__ = ["DEFAULT_MAX_BYTES", "MAX_BYTES_ENV", "AssetPolicy", "Container", "Location", "read_container",
           "max_asset_bytes", "write_glb", "write_json", "SelfContained", "self_contained", "files_folder",
           "FILES_MANIFEST", "SUPPORTED_EXTENSIONS", "drop_unnamed"]

DEFAULT_MAX_BYTES = 2 << 30  # 2 GiB: any one asset file, buffer, image file or data URI
MAX_BYTES_ENV = "OMAPS_MAX_ASSET_BYTES"
MESHOPT = "EXT_meshopt_compression"  # bufferViews whose bytes are compressed in another buffer's range
DRACO = "KHR_draco_mesh_compression"  # a primitive's Draco data: a bufferView
INSTANCING = "EXT_mesh_gpu_instancing"  # a node's mesh drawn at many transforms: accessors
# the extensions the scene reader knows (``scene.gltf``): those whose data it reads, or that cannot change
# geometry, texture coordinates or alpha; none names an accessor or a buffer view but where ``drop_unnamed``
# looks
SUPPORTED_EXTENSIONS = frozenset({
    "KHR_texture_transform", "KHR_mesh_quantization", "EXT_texture_webp", "KHR_materials_emissive_strength",
    "KHR_materials_ior", "KHR_materials_specular", "KHR_materials_sheen", "KHR_materials_clearcoat",
    "KHR_materials_transmission", "KHR_materials_volume", "KHR_materials_iridescence", "KHR_materials_anisotropy",
    "KHR_materials_dispersion", "KHR_materials_unlit", "KHR_materials_variants", "KHR_materials_pbrSpecularGlossiness",
    "KHR_lights_punctual", "KHR_xmp_json_ld", "KHR_animation_pointer",
    "EXT_mesh_opacity_micromap", "OMAPS_pair_opacity_maps", "OMAPS_merged_micromaps",  # read by scene.micromaps
    "EXT_mesh_gpu_instancing",  # its nodes' instances (``GltfReader.gpu_instances``)
    "MSFT_texture_dds",  # a texture's DDS image (``_source_of``)
    "KHR_draco_mesh_compression",  # a primitive's Draco data (``GltfReader.draco``)
    "EXT_meshopt_compression",  # a bufferView's compressed bytes (``GltfReader.view_bytes``)
})
GLB_MAGIC, JSON_CHUNK, BIN_CHUNK = 0x46546C67, 0x4E4F534A, 0x004E4942
URI_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]*):")
_DRIVE = re.compile(r"^[A-Za-z]:([\\/]|$)")


def max_asset_bytes(value=None) -> int:
    """The size cap: ``value`` when given, else the environment variable ``OMAPS_MAX_ASSET_BYTES``,
    else ``DEFAULT_MAX_BYTES``. An ``InputError`` unless it is a positive integer."""
    where = "max_bytes"
    if value is None:
        value = os.environ.get(MAX_BYTES_ENV)
        where = MAX_BYTES_ENV
        if value is None or value == "":
            return DEFAULT_MAX_BYTES
    try:
        n = int(value)
    except (TypeError, ValueError):
        n = 0
    if isinstance(value, bool) or n < 1 or (isinstance(value, float) and value != n):
        raise InputError(f"{where} is {value!r}, not a positive number of bytes")
    return n


@dataclass(frozen=True)
class AssetPolicy:
    """Where a glTF asset's URIs may lead (the module docstring states the rules).

    Parameters
    ----------
    root : str or path, optional
        The folder every file the asset names must lie under (symbolic links followed); default:
        the asset's own folder.
    allow_outside : bool
        Read files anywhere (the root check off). Scheme URIs are still never fetched.
    max_bytes : int, optional
        The size cap (``max_asset_bytes``).
    """

    root: str | None = None
    allow_outside: bool = False
    max_bytes: int | None = None

    @classmethod
    def of(cls, root=None, allow_outside=False, max_bytes=None) -> "AssetPolicy":
        """The policy of the library's keywords, checked: ``root`` an existing folder."""
        if root is not None:
            root = os.fspath(root)
            if not os.path.isdir(root):
                raise InputError("the root folder (--root) does not exist or is not a folder", root)
        return cls(root, bool(allow_outside), max_asset_bytes(max_bytes))


@dataclass(frozen=True)
class Location:
    """Where a URI leads: ``kind`` "data", "file" (``path``: the real path, allowed) or "unread"
    (a scheme or Windows path, allowed to go unread: ``problem`` says why)."""

    kind: str
    path: str | None = None
    problem: str | None = None


def inside_root(path: str, root: str) -> bool:
    """``path`` is ``root`` or lies under it (both real, absolute paths)."""
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)


class Container:
    """A glTF asset's JSON document (``doc``), GLB binary chunk (``bin``, None for .gltf or a GLB
    without one) and the policy its URIs are resolved under (``locate``, ``read``)."""

    def __init__(self, path: str, doc: dict, bin_chunk: bytes | None, policy: AssetPolicy):
        self.path = path
        self.doc = doc
        self.bin = bin_chunk
        self.policy = policy
        self.max_bytes = max_asset_bytes(policy.max_bytes)
        self.folder = os.path.dirname(os.path.abspath(path))
        given = policy.root is not None
        self.root = os.path.realpath(policy.root if given else self.folder)
        self._root_label = "the {root} folder" if given else "the asset's folder"

    # -- where a URI leads ------------------------------------------------------------------
    def _refuse(self, what, uri, problem, params=()):
        """An ``InputError``; ``problem`` names the parameters ``params`` as ``{root}``,
        ``{allow_outside}`` (the command line names its options there)."""
        raise InputError(f"{what}: URI {_show(uri)} {problem}", self.path, param=tuple(params) or None)

    def _never_read(self, what, uri, problem, unread_ok):
        if unread_ok and self.policy.allow_outside:
            return Location("unread", problem=f"{what}: URI {_show(uri)} {problem}")
        tail = " ({allow_outside}: go on without it)" if unread_ok else ""
        self._refuse(what, uri, problem + tail, ("allow_outside",) if unread_ok else ())

    def locate(self, uri: str, what: str, unread_ok: bool = False) -> Location:
        """Where ``uri`` (of ``what``: "buffer 0", "image 2") leads under the policy; an
        ``InputError`` when it is refused. ``unread_ok``: a URI omaps never reads (a scheme, a
        Windows path) is allowed to go unread with ``allow_outside`` (an image: then missing)."""
        if uri.startswith("data:"):
            return Location("data")
        scheme = URI_SCHEME.match(uri)
        local = None
        if _DRIVE.match(uri) or uri.startswith(("\\\\", "//")):
            return self._never_read(what, uri, "is a Windows or network path, not a relative path: omaps reads "
                                    "only relative paths (with '/') and data: URIs", unread_ok)
        if scheme:
            name = scheme.group(1).lower()
            rest = uri[len(name) + 1:]
            if name == "file" and (not rest.startswith("//") or rest[2:].startswith(("/", "localhost/"))):
                local = unquote(rest[2:] if rest.startswith("//") else rest)  # file:///x, file://localhost/x
                local = local[len("localhost"):] if local.startswith("localhost/") else local
            else:
                article = "an" if name[0] in "aehiou" else "a"
                return self._never_read(what, uri, f"is {article} {name}: URI; omaps never fetches URIs (no network "
                                        "access): put the file beside the asset and name it by a relative path",
                                        unread_ok)
        if "\\" in uri or (local or unquote(uri)).find("\\") >= 0:
            return self._never_read(what, uri, "has back-slashes: glTF URIs separate folders with '/'", unread_ok)
        decoded = local if local is not None else unquote(uri)
        if "\0" in decoded:
            self._refuse(what, uri, "holds a NUL character: not a file name")
        full = os.path.join(self.folder, decoded)
        real = os.path.realpath(full)
        if self.policy.allow_outside or inside_root(real, self.root):
            return Location("file", real)
        kind = ("is a file: URI" if local is not None else "is an absolute path" if os.path.isabs(decoded)
                else "leads")
        self._refuse(what, uri, f"{kind} to {real}, outside {self.root} ({self._root_label}): omaps reads only "
                                "files under it ({root}: a folder holding both; {allow_outside}: if you trust "
                                "this asset)", ("root", "allow_outside"))

    # -- reading ----------------------------------------------------------------------------
    def buffer_data(self, i: int, uri: str | None, length: int):
        """The bytes of buffer ``i`` (at least ``length``: its byteLength): the binary chunk when
        ``uri`` is None (buffer 0 only: another is a placeholder without data), else the file or data URI it names; an ``InputError`` naming the asset
        when there is none, it is missing or unreadable, or it is shorter than ``length``."""
        if uri is None:
            data = self.bin
            if data is None:
                raise InputError(f"buffer {i} has no URI and the file has no binary chunk", self.path)
            if i != 0:
                raise InputError(f"buffer {i} has no URI, and only buffer 0 may hold a .glb's binary chunk (a "
                                 f"buffer without data is a placeholder, read only through {MESHOPT})", self.path)
        else:
            data = self.read(uri, f"buffer {i}", None if uri.startswith("data:") else length)
            if data is None:
                raise InputError(f"buffer {i}: file {_show(uri)} is missing or unreadable", self.path)
        if len(data) < length:
            raise InputError(f"buffer {i} holds {len(data)} bytes, byteLength says {length}", self.path)
        return data

    def check_data_size(self, uri: str, what: str) -> None:
        """An ``InputError`` when a data URI would decode to more bytes than the cap."""
        size = len(uri) // 4 * 3
        if size > self.max_bytes:
            raise InputError(f"{what}: its data URI holds about {size} bytes, over the size cap of "
                             f"{self.max_bytes} ({MAX_BYTES_ENV})", self.path)

    def data_uri(self, uri: str, what: str) -> bytes:
        """The bytes of a base64 ``data:`` URI, its decoded size checked against the cap first."""
        self.check_data_size(uri, what)
        head, comma, payload = uri.partition(",")
        if not comma or not head.endswith(";base64"):
            raise InputError(f"data URI {uri[:40]!r}... is not base64 data", self.path)
        try:
            return base64.b64decode(payload)
        except (ValueError, binascii.Error) as exc:
            raise InputError(f"bad base64 in a data URI ({exc})", self.path) from None

    def read(self, uri: str, what: str, length: int | None = None, unread_ok: bool = False):
        """The bytes ``uri`` names (``locate``): a data URI's, or the file's (``length``: its
        first ``length`` bytes, a buffer's byteLength, refused when the file is shorter). Returns
        None when the file is missing or unreadable, a ``Location`` of kind "unread" for a URI
        allowed to go unread; an ``InputError`` for a refused URI or a size over the cap."""
        if length is not None and length > self.max_bytes:
            raise InputError(f"{what}: byteLength {length} is over the size cap of {self.max_bytes} bytes "
                             f"({MAX_BYTES_ENV})", self.path)
        loc = self.locate(uri, what, unread_ok)
        if loc.kind == "data":
            return self.data_uri(uri, what)
        if loc.kind == "unread":
            return loc
        try:
            st = os.stat(loc.path)
            if not stat.S_ISREG(st.st_mode):
                return None  # a folder, a device, a pipe: never opened
            if st.st_size > self.max_bytes and length is None:
                raise InputError(f"{what}: file {_show(uri)} holds {st.st_size} bytes, over the size cap of "
                                 f"{self.max_bytes} ({MAX_BYTES_ENV})", self.path)
            if length is not None and st.st_size < length:
                raise InputError(f"{what}: file {_show(uri)} holds {st.st_size} bytes, byteLength says {length}",
                                 self.path)
            with open(loc.path, "rb") as f:
                return f.read(st.st_size if length is None else length)
        except InputError:
            raise
        except (OSError, ValueError):  # gone meanwhile, unreadable
            return None


def _show(uri: str) -> str:
    return repr(uri if len(uri) <= 200 else uri[:200] + "...")


def read_container(path, policy: AssetPolicy | None = None) -> Container:
    """Read a .gltf (JSON) or .glb (binary container) file: an ``InputError`` naming it when it is
    over the size cap, not glTF JSON, or a GLB whose header or chunks are broken."""
    path = os.fspath(path)
    policy = policy or AssetPolicy()
    cap = max_asset_bytes(policy.max_bytes)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size > cap:
                raise InputError(f"the file holds {size} bytes, over the size cap of {cap} ({MAX_BYTES_ENV})", path)
            raw = f.read()
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    bin_chunk = None
    try:
        if path.lower().endswith(".glb"):
            js, bin_chunk = _glb_chunks(raw, path)
        else:
            js = raw
        doc = json.loads(js.decode("utf-8"))
    except InputError:  # the GLB's own checks name the problem
        raise
    except UnicodeDecodeError as exc:
        raise InputError(f"cannot read glTF: its JSON is not UTF-8 ({exc.reason} at byte {exc.start})", path) from None
    except ValueError as exc:  # json.JSONDecodeError
        raise InputError(f"cannot read glTF: not JSON ({exc})", path) from None
    except RecursionError:
        raise InputError("cannot read glTF: its JSON nests too deeply", path) from None
    if not isinstance(doc, dict):
        raise InputError(f"cannot read glTF (its JSON is {type(doc).__name__}, not an object)", path)
    return Container(path, doc, bin_chunk, policy)


def _glb_chunks(raw: bytes, path: str) -> tuple[bytes, bytes | None]:
    """The JSON chunk and the BIN chunk (or None) of a GLB file; unknown chunks are skipped."""
    if len(raw) < 20 or raw[:4] != b"glTF":
        raise InputError("not a GLB file (no 'glTF' header)", path)
    _, version, length = struct.unpack_from("<III", raw, 0)
    if version != 2:
        raise InputError(f"GLB version {version}; omaps reads version 2", path)
    if length > len(raw):
        raise InputError(f"the GLB header says {length} bytes, the file holds {len(raw)}", path)
    pos, js, bin_chunk = 12, None, None
    while pos + 8 <= length:
        clen, ctype = struct.unpack_from("<II", raw, pos)
        if pos + 8 + clen > length:
            raise InputError(f"GLB chunk at byte {pos} ({clen} bytes) runs past the end ({length} bytes)", path)
        body = raw[pos + 8:pos + 8 + clen]
        if js is None:
            if ctype != JSON_CHUNK:
                raise InputError("the first GLB chunk is not JSON", path)
            js = body
        elif ctype == BIN_CHUNK and bin_chunk is None:
            bin_chunk = bytes(body)
        pos += 8 + clen
    if js is None:
        raise InputError("the GLB file has no JSON chunk", path)
    return js, bin_chunk


def write_glb(f, doc: dict, body: bytes) -> None:
    """Write a GLB container to the binary file ``f``: the header, ``doc`` as the JSON chunk
    (compact, padded with spaces) and ``body`` as the BIN chunk (padded with zeros)."""
    body = bytes(body) + b"\0" * ((-len(body)) % 4)
    js = json.dumps(doc, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(body)
    f.write(struct.pack("<III", GLB_MAGIC, 2, total))
    f.write(struct.pack("<II", len(js), JSON_CHUNK) + js)
    f.write(struct.pack("<II", len(body), BIN_CHUNK) + body)


def write_json(f, doc: dict) -> None:
    """Write ``doc`` as .gltf JSON to the text file ``f`` (indented by one, UTF-8 kept)."""
    json.dump(doc, f, indent=1, ensure_ascii=False)
    f.write("\n")


# ---- self-contained outputs ---------------------------------------------------------------------
FILES_SUFFIX = "_files"
FILES_MANIFEST = "omaps-files.json"
ALIGN = 8  # every buffer and image placed in a GLB's binary chunk starts at a multiple of 8 bytes
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_MAGIC = ((b"\x89PNG\r\n\x1a\n", "image/png"), (b"\xff\xd8\xff", "image/jpeg"),
          (b"\xabKTX 20\xbb\r\n\x1a\n", "image/ktx2"), (b"GIF8", "image/gif"), (b"BM", "image/bmp"),
          (b"DDS ", "image/vnd-ms.dds"))


def files_folder(out_path) -> str:
    """The folder a .gltf output's files are copied into: ``OUT_files`` beside ``OUT.gltf``."""
    out = os.path.abspath(os.fspath(out_path))
    return os.path.join(os.path.dirname(out), os.path.splitext(os.path.basename(out))[0] + FILES_SUFFIX)


def _mime(raw: bytes, declared, name: str) -> str:
    """An embedded image's media type: the one the document (or its data URI) declares, else the
    file's signature, else its name's suffix."""
    if isinstance(declared, str) and declared:
        return declared
    for magic, kind in _MAGIC:
        if raw.startswith(magic):
            return kind
    if raw[:4] == b"RIFF" and raw[8:12] == b"WEBP":
        return "image/webp"
    return mimetypes.guess_type(name)[0] or "application/octet-stream"


def _safe_name(decoded: str) -> str:
    """A file name made of letters, digits, '.', '_' and '-', never hidden nor empty."""
    name = _UNSAFE.sub("_", os.path.basename(decoded)).lstrip(".")
    return name or "file"


@dataclass
class SelfContained:
    """What ``self_contained`` made of a document: for a .glb, ``body``, the binary chunk (buffer 0,
    the only buffer); for a .gltf, ``copies`` (name in the files folder -> (source file, its URI
    in the source)) and ``folder`` (where they go); ``warnings`` (the images left out)."""

    body: bytes | None = None
    copies: dict = field(default_factory=dict)
    folder: str | None = None
    warnings: list = field(default_factory=list)

    def write_files(self, out_path) -> None:
        """Copy the files beside the .gltf output ``out_path`` (called when it is written): into
        a temporary folder, renamed over ``folder``; with nothing to copy, an earlier files folder
        omaps wrote there is removed."""
        from .. import atomic

        if not self.copies:
            if self.folder and os.path.isfile(os.path.join(self.folder, FILES_MANIFEST)):
                shutil.rmtree(self.folder, ignore_errors=True)
            return
        tmp = atomic.make_temp_folder(os.path.dirname(self.folder))
        try:
            for name, (src, _) in self.copies.items():
                shutil.copyfile(src, os.path.join(tmp, name))
            manifest = {"gltf": os.path.basename(os.fspath(out_path)),
                        "files": {name: uri for name, (_, uri) in self.copies.items()}}
            with open(os.path.join(tmp, FILES_MANIFEST), "w", encoding="utf-8") as f:
                json.dump(manifest, f, indent=1, ensure_ascii=False)
                f.write("\n")
            atomic.replace_folder(tmp, self.folder)
        except BaseException:
            atomic._remove(tmp)
            raise


def _items(doc: dict, key: str) -> list:
    items = doc.get(key)
    if items is None:
        return []
    if not isinstance(items, list):
        raise InputError(f"{key} is {type(items).__name__}, not an array")
    return items


def self_contained(c: Container, out_path) -> SelfContained:
    """Make ``c.doc`` (changed in place) name nothing outside the output ``out_path`` (.glb or
    .gltf by its suffix), under ``c``'s policy (the module docstring states the rule). Nothing is
    written here: a .gltf's files are copied by ``SelfContained.write_files``. An ``InputError``
    naming the asset for a buffer that is refused, missing or shorter than its byteLength, an
    image URI the policy refuses, or a files folder omaps may not replace."""
    try:
        return _self_contained(c, out_path)
    except InputError as exc:
        if exc.path is None:
            raise InputError(exc.template, c.path, param=exc.param) from None
        raise


def _buffer_bytes(c: Container, i: int, b) -> bytes:
    if not isinstance(b, dict):
        raise InputError(f"buffer {i} is not an object")
    length = b.get("byteLength")
    if isinstance(length, bool) or not isinstance(length, int) or length < 0:
        raise InputError(f"buffer {i}: byteLength is {length!r}, not a number of bytes")
    uri = b.get("uri")
    if uri is not None and not isinstance(uri, str):
        raise InputError(f"buffer {i}: uri is {uri!r}, not a string")
    return bytes(c.buffer_data(i, uri, length)[:length])


def _placeholder(c: Container, i: int, b) -> bool:
    """Whether buffer ``i`` holds no data: no URI, and not the binary chunk (only buffer 0 of a
    .glb may name it), as ``EXT_meshopt_compression``'s fallback buffers are."""
    return isinstance(b, dict) and b.get("uri") is None and (i != 0 or c.bin is None)


def _image_bytes(c: Container, i: int, uri: str):
    """An image's bytes, or (None, why) when omaps cannot read it (left out)."""
    what = f"image {i}"
    if uri.startswith("data:"):
        try:
            return c.data_uri(uri, what), None
        except InputError as exc:
            if "size cap" in exc.problem:
                raise
            return None, f"its data URI cannot be read ({exc.problem})"
    raw = c.read(uri, what, unread_ok=True)
    if isinstance(raw, Location):
        return None, raw.problem.split(": ", 1)[-1]
    if raw is None:
        return None, f"file {_show(uri)} is missing or unreadable"
    return raw, None


def _leave_out_images(doc: dict, gone: dict, out: SelfContained, path: str) -> None:
    """Remove the images ``gone`` (index -> why) from the document: later images move up, every
    texture naming one of them (``source`` or an extension's ``source``) names none."""
    images = doc["images"]
    new = {}
    for i in range(len(images)):
        if i not in gone:
            new[i] = len(new)
    users: dict = {i: [] for i in gone}
    for ti, t in enumerate(_items(doc, "textures")):
        if not isinstance(t, dict):
            continue
        holders = [t]
        if isinstance(t.get("extensions"), dict):  # EXT_texture_webp, KHR_texture_basisu, ...: their source
            holders += [e for e in t["extensions"].values() if isinstance(e, dict)]
        for h in holders:
            s = h.get("source")
            if isinstance(s, int) and not isinstance(s, bool):
                if s in gone:
                    del h["source"]
                    users[s].append(ti)
                elif s in new:
                    h["source"] = new[s]
    for i, why in sorted(gone.items()):
        used = users[i]
        named = (f"; texture{'s' if len(used) > 1 else ''} {', '.join(map(str, used))} now name"
                 f"{'' if len(used) > 1 else 's'} no image" if used else "")
        out.warnings.append(f"{path}: image {i}: {why}: it is left out of the output{named}")
    images[:] = [im for i, im in enumerate(images) if i not in gone]
    if not images:
        del doc["images"]


def _self_contained(c: Container, out_path) -> SelfContained:
    doc = c.doc
    glb = os.fspath(out_path).lower().endswith(".glb")
    buffers, images = _items(doc, "buffers"), _items(doc, "images")
    views = _items(doc, "bufferViews")
    if glb:
        doc["bufferViews"] = views
    out = SelfContained()
    # every image URI checked under the policy first: a refused one is an error, nothing written
    for i, im in enumerate(images):
        if not isinstance(im, dict):
            raise InputError(f"image {i} is not an object")
        uri = im.get("uri")
        if uri is not None and not isinstance(uri, str):
            raise InputError(f"image {i}: uri is {uri!r}, not a string")
    gone: dict = {}
    if glb:
        body = bytearray()
        shift = {}
        placeholders = {}  # buffers without data (EXT_meshopt_compression's fallbacks): kept, after buffer 0
        for i, b in enumerate(buffers):
            if _placeholder(c, i, b):
                placeholders[i] = 1 + len(placeholders)
                continue
            raw = _buffer_bytes(c, i, b)
            body += b"\0" * ((-len(body)) % ALIGN)
            shift[i] = len(body)
            body += raw
        for h in _buffer_holders(views):  # each view's own range, and the compressed range its extension names
            k = h.get("buffer")
            if not _index(k):
                continue
            if k in shift:
                h["buffer"] = 0
                if shift[k] and isinstance(h.get("byteOffset", 0), int):
                    h["byteOffset"] = h.get("byteOffset", 0) + shift[k]
            elif k in placeholders:
                h["buffer"] = placeholders[k]
        for i, im in enumerate(images):
            uri = im.get("uri")
            if uri is None:
                continue  # a buffer view: re-based above
            raw, why = _image_bytes(c, i, uri)
            if raw is None:
                gone[i] = why
                continue
            declared = uri[5:].split(",", 1)[0].split(";")[0] if uri.startswith("data:") else None
            body += b"\0" * ((-len(body)) % ALIGN)
            views.append({"buffer": 0, "byteOffset": len(body), "byteLength": len(raw)})
            body += raw
            im["bufferView"] = len(views) - 1
            im["mimeType"] = _mime(raw, im.get("mimeType") or declared, unquote(uri))
            del im["uri"]
        buffers[:] = [{"byteLength": len(body)}] + [buffers[i] for i in placeholders]
        doc["buffers"] = buffers
        out.body = bytes(body)
    else:
        from .. import atomic

        out.folder = files_folder(out_path)
        rel = os.path.basename(out.folder)
        by_source: dict = {}  # real path -> name

        def copy(uri: str, real: str) -> str:
            if real not in by_source:
                name = _safe_name(unquote(uri))
                stem, ext = os.path.splitext(name)
                k = 1
                while name in out.copies or name == FILES_MANIFEST:
                    k += 1
                    name = f"{stem}-{k}{ext}"
                by_source[real] = name
                out.copies[name] = (real, uri)
            return quote(f"{rel}/{by_source[real]}")

        for i, b in enumerate(buffers):
            uri = b.get("uri") if isinstance(b, dict) else None
            if uri is None or (isinstance(uri, str) and uri.startswith("data:")):
                if isinstance(b, dict) and uri is None and c.bin is not None and i == 0:
                    b["uri"] = "data:application/octet-stream;base64," + base64.b64encode(c.bin).decode()
                continue
            _buffer_bytes(c, i, b)  # refused, missing or short: an error, as on reading
            b["uri"] = copy(uri, c.locate(uri, f"buffer {i}").path)
        for i, im in enumerate(images):
            uri = im.get("uri")
            if uri is None:
                continue
            if uri.startswith("data:"):
                raw, why = _image_bytes(c, i, uri)
                if raw is None:
                    gone[i] = why
                continue
            loc = c.locate(uri, f"image {i}", unread_ok=True)
            if loc.kind == "unread":
                gone[i] = loc.problem.split(": ", 1)[-1]
            elif not os.path.isfile(loc.path) or not os.access(loc.path, os.R_OK):
                gone[i] = f"file {_show(uri)} is missing or unreadable"
            else:
                size = os.path.getsize(loc.path)
                if size > c.max_bytes:
                    raise InputError(f"image {i}: file {_show(uri)} holds {size} bytes, over the size cap of "
                                     f"{c.max_bytes} ({MAX_BYTES_ENV})")
                im["uri"] = copy(uri, loc.path)
        if out.copies:
            atomic.check_folder(out.folder, FILES_MANIFEST, "the files folder of the output",
                                inputs=[c.path] + [src for src, _ in out.copies.values()])
    if gone:
        _leave_out_images(doc, gone, out, c.path)
    return out


# ---- data no longer named -----------------------------------------------------------------------


def _extension_names(node, found: set) -> None:
    """Every extension name ``node`` (a JSON value) uses: ``extensionsUsed`` and the keys of every
    ``extensions`` object, at any depth."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "extensions" and isinstance(v, dict):
                found.update(v)
            elif k == "extensionsUsed" and isinstance(v, list):
                found.update(e for e in v if isinstance(e, str))
            _extension_names(v, found)
    elif isinstance(node, list):
        for v in node:
            _extension_names(v, found)


def _index(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _accessor_holders(doc: dict):
    """(object, key) of every place the core glTF schema and ``EXT_mesh_gpu_instancing`` name an
    accessor: attributes, indices and morph targets of primitives, instance attributes, skins'
    inverse bind matrices, animation samplers' input and output."""
    for m in _items(doc, "meshes"):
        for p in (m.get("primitives") or []) if isinstance(m, dict) else []:
            if not isinstance(p, dict):
                continue
            maps = [p.get("attributes")] + list(p.get("targets") or [])
            for a in maps:
                if isinstance(a, dict):
                    yield from ((a, k) for k in a)
            yield p, "indices"
    for n in _items(doc, "nodes"):
        ext = (n.get("extensions") or {}).get(INSTANCING) if isinstance(n, dict) else None
        if isinstance(ext, dict) and isinstance(ext.get("attributes"), dict):
            yield from ((ext["attributes"], k) for k in ext["attributes"])
    for s in _items(doc, "skins"):
        if isinstance(s, dict):
            yield s, "inverseBindMatrices"
    for a in _items(doc, "animations"):
        for s in (a.get("samplers") or []) if isinstance(a, dict) else []:
            if isinstance(s, dict):
                yield s, "input"
                yield s, "output"


def _view_holders(doc: dict):
    """(object, key) of every place the core schema and ``KHR_draco_mesh_compression`` name a
    buffer view: accessors (and their sparse indices and values), images, Draco primitives."""
    for a in _items(doc, "accessors"):
        if not isinstance(a, dict):
            continue
        yield a, "bufferView"
        sparse = a.get("sparse")
        if isinstance(sparse, dict):
            for part in ("indices", "values"):
                if isinstance(sparse.get(part), dict):
                    yield sparse[part], "bufferView"
    for im in _items(doc, "images"):
        if isinstance(im, dict):
            yield im, "bufferView"
    for m in _items(doc, "meshes"):
        for p in (m.get("primitives") or []) if isinstance(m, dict) else []:
            ext = (p.get("extensions") or {}).get(DRACO) if isinstance(p, dict) else None
            if isinstance(ext, dict):
                yield ext, "bufferView"


def _renumber(holders, gone: set, n: int) -> None:
    """Renumber the indices ``holders`` name after removing the items ``gone`` of ``n``."""
    new, k = {}, 0
    for i in range(n):
        if i not in gone:
            new[i] = k
            k += 1
    for h, key in holders:
        v = h.get(key)
        if _index(v) and v in new:
            h[key] = new[v]


def _buffer_holders(views: list):
    """Every object of ``views`` that names a buffer: a view, and its ``EXT_meshopt_compression``
    (the compressed range)."""
    for v in views:
        if not isinstance(v, dict):
            continue
        ext = (v.get("extensions") or {}).get(MESHOPT) if isinstance(v.get("extensions"), dict) else None
        yield from (h for h in (v, ext) if isinstance(h, dict))


def _ranges(holders, buffer: int) -> list:
    """[start, end) of each of ``holders`` (``_buffer_holders``) in buffer ``buffer``, merged."""
    spans = sorted((h.get("byteOffset", 0), h.get("byteOffset", 0) + h["byteLength"]) for h in holders
                   if h.get("buffer") == buffer and _index(h.get("byteOffset", 0)) and _index(h.get("byteLength")))
    merged: list = []
    for lo, hi in spans:
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return merged


def drop_unnamed(doc: dict, accessors=(), views=(), body: bytes | None = None,
                 known: frozenset = SUPPORTED_EXTENSIONS) -> bytes | None:
    """Remove from ``doc`` the ``accessors`` and buffer ``views`` (indices) that nothing in it
    names any more (the data of micromaps being replaced), renumbering every reference to those
    after them. Returns ``body`` (a .glb's binary chunk, buffer 0) with only the bytes the views
    left cover, when a view was removed (``_compact``: each range at its old offset modulo 16, so
    every alignment holds); for a .gltf (``body`` None) a ``data:`` buffer only removed views named is
    removed. Nothing is removed when ``doc`` uses an extension outside ``known`` (one that may
    name an accessor or a view where this function does not look): ``body`` comes back as it was."""
    found: set = set()
    _extension_names(doc, found)
    if not found <= known:
        return body
    acc = _items(doc, "accessors")
    named = {h.get(k) for h, k in _accessor_holders(doc)}
    gone_acc = {a for a in accessors if _index(a) and 0 <= a < len(acc) and a not in named}
    views_list = _items(doc, "bufferViews")
    candidates = {v for v in views if _index(v)}
    candidates |= {acc[a].get("bufferView") for a in gone_acc if isinstance(acc[a], dict)}
    kept_acc = [a for i, a in enumerate(acc) if i not in gone_acc]
    named_views = {h.get(k) for h, k in _view_holders({**doc, "accessors": kept_acc})}
    gone_views = {v for v in candidates if _index(v) and 0 <= v < len(views_list) and v not in named_views}
    if gone_acc:
        _renumber(list(_accessor_holders(doc)), gone_acc, len(acc))
        acc[:] = kept_acc
        if not acc:
            del doc["accessors"]
    if not gone_views:
        return body
    removed = [v for i, v in enumerate(views_list) if i in gone_views]
    _renumber(list(_view_holders(doc)), gone_views, len(views_list))
    views_list[:] = [v for i, v in enumerate(views_list) if i not in gone_views]
    if not views_list:
        del doc["bufferViews"]
    if body is not None:
        return _compact(views_list, body)
    buffers = _items(doc, "buffers")
    still = {h.get("buffer") for h in _buffer_holders(views_list)}
    gone_buffers = {h.get("buffer") for h in _buffer_holders(removed)}
    gone_buffers = {b for b in gone_buffers if _index(b) and 0 <= b < len(buffers) and b not in still
                    and isinstance(buffers[b], dict) and str(buffers[b].get("uri", "")).startswith("data:")}
    if gone_buffers:
        _renumber([(h, "buffer") for h in _buffer_holders(views_list)], gone_buffers, len(buffers))
        buffers[:] = [b for i, b in enumerate(buffers) if i not in gone_buffers]
    return None


def _compact(views: list, body: bytes) -> bytes:
    """``body`` (buffer 0) holding only the byte ranges ``views`` cover (no glTF object reaches
    a buffer's other bytes), moved down, each range to its old offset modulo 16; ``views``
    re-based."""
    out, shifts = bytearray(), []
    for lo, hi in _ranges(_buffer_holders(views), 0):
        out += b"\0" * ((lo - len(out)) % 16)
        shifts.append((lo, hi, len(out) - lo))
        out += body[lo:hi]
    starts = [lo for lo, _, _ in shifts]
    for h in _buffer_holders(views):
        off = h.get("byteOffset", 0)
        if h.get("buffer") != 0 or not _index(off):
            continue
        k = bisect.bisect_right(starts, off) - 1  # the range that holds it
        if k >= 0 and off < shifts[k][1]:
            h["byteOffset"] = off + shifts[k][2]
    return bytes(out)
