"""Opacity micromaps stored in a glTF file: the draft extension ``EXT_mesh_opacity_micromap``
(KhronosGroup/glTF pull request 2623) and omaps' own ``OMAPS_pair_opacity_maps`` (the deck's
compressed square maps per pair) and ``OMAPS_merged_micromaps`` (every triangle's micromap in one
merged DAG of identical subtrees, ``codecs.csm``). docs/FORMAT.md "Opacity micromaps in glTF"
states every field.

Reading (``read_extensions``) runs inside the one scene reader (``scene.gltf``: it passes its
checked accessor and bufferView readers), so the tracer and ``omaps omm --verify`` see exactly
what the file stores; every rule of the extension is checked there and a broken one is an
InputError naming the file. Writing (``write_gltf``) works on the file's JSON and binary chunk
(``scene.container``, the one reader and writer of the glTF container, under the same URI policy
as the scene reader) directly (no glTF library round trip), so every mesh, material, image,
node, animation, camera and unknown extension or extra of the input is kept as it was, its
buffers and images made part of the output (``container.self_contained``: in a .glb's binary
chunk, or copied beside a .gltf): the new data is appended as buffer views (and accessors for the
per-primitive indices), the data of micromaps it replaces dropped. The OMM format's
facts (record layout, level limit, sizes, record checks) are ``omm_format``'s.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..omm_format import MAX_LEVEL, PAIR_RECORD, TRIANGLE_RECORD, record_problem
from .container import AssetPolicy, drop_unnamed, read_container, self_contained, write_glb, write_json

__all__ = ["EXT_OMM", "EXT_PAIRS", "EXT_MERGED", "MicromapArray", "PrimitiveMicromap", "PairMaps", "PrimitivePairs",
           "MergedMicromaps", "StoredMicromaps", "read_extensions", "write_gltf", "index_component_type",
           "encode_indices"]

EXT_OMM = "EXT_mesh_opacity_micromap"
EXT_PAIRS = "OMAPS_pair_opacity_maps"
EXT_MERGED = "OMAPS_merged_micromaps"
_EXTS = (EXT_OMM, EXT_PAIRS, EXT_MERGED)
RECORD = TRIANGLE_RECORD  # VkMicromapTriangleKHR (omm_format's)
_UNSIGNED = {5121: 8, 5123: 16, 5125: 32}
_SIGNED = {5122: 16, 5124: 32}


@dataclass
class MicromapArray:
    """One element of the root ``micromaps``: packed states, records, usage histogram."""

    data: np.ndarray  # uint8
    triangles: np.ndarray  # RECORD (M,)
    usage: list  # [(count, level, format)] as stored
    extras: dict = field(default_factory=dict)


@dataclass
class PrimitiveMicromap:
    micromap: int
    values: np.ndarray  # int64 (T,) signed lookup values (specials -1..-4), base triangle not added
    base: int = 0

    @property
    def records(self) -> np.ndarray:
        """Per triangle its record index, or the special index (-1..-4)."""
        return np.where(self.values >= 0, self.values + self.base, self.values)


@dataclass
class PairMaps:
    """One element of ``OMAPS_pair_opacity_maps.maps``: a codec's blocks."""

    codec: str
    block_bytes: int
    map_size: int
    blocks: bytes
    extras: dict = field(default_factory=dict)


@dataclass
class PrimitivePairs:
    maps: int
    records: np.ndarray  # PAIR_RECORD (T,)


@dataclass
class MergedMicromaps:
    """``OMAPS_merged_micromaps``: level-``level`` micromaps in one merged DAG (``codecs.csm``'s
    blob, checked), ``micromaps`` roots; a primitive's triangle t is micromap first + t."""

    level: int
    micromaps: int
    dag: bytes
    extras: dict = field(default_factory=dict)


@dataclass
class StoredMicromaps:
    micromaps: list  # MicromapArray
    primitives: dict  # (glTF mesh, primitive) -> PrimitiveMicromap
    pair_maps: list  # PairMaps
    pair_primitives: dict  # (glTF mesh, primitive) -> PrimitivePairs
    merged: MergedMicromaps | None = None
    merged_primitives: dict = field(default_factory=dict)  # (glTF mesh, primitive) -> its first micromap


# ---- reading (inside scene.gltf's reader) ------------------------------------------------------
def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def read_extensions(r) -> StoredMicromaps | None:
    """The extensions of the document the scene reader ``r`` holds (``r.g``: the document,
    ``r.view_bytes``, ``r.accessor``, ``r.path``); None when the file has none of them."""
    g = r.g
    root = g.extensions if isinstance(g.extensions, dict) else {}
    has_prim = any(isinstance(getattr(p, "extensions", None), dict) and any(e in p.extensions for e in _EXTS)
                   for m in (g.meshes or []) for p in (getattr(m, "primitives", None) or []))
    if not any(e in root for e in _EXTS) and not has_prim:
        return None
    path = r.path

    def bad(msg):
        raise InputError(f"{EXT_OMM}: {msg}", path)

    arrays = []
    ext = root.get(EXT_OMM, {"micromaps": []})
    if not isinstance(ext, dict) or not isinstance(ext.get("micromaps"), list):
        bad("the root extension needs a micromaps array")
    for i, mm in enumerate(ext["micromaps"]):
        arrays.append(_read_array(r, i, mm, bad))
    pair_maps = []
    pext = root.get(EXT_PAIRS, {"maps": []})
    if not isinstance(pext, dict) or not isinstance(pext.get("maps"), list):
        raise InputError(f"{EXT_PAIRS}: the root extension needs a maps array", path)
    for i, pm in enumerate(pext["maps"]):
        pair_maps.append(_read_pair_maps(r, i, pm))
    merged = _read_merged(r, root[EXT_MERGED]) if EXT_MERGED in root else None
    prims, pair_prims, merged_prims = {}, {}, {}
    for mi, m in enumerate(g.meshes or []):
        for pi, p in enumerate(getattr(m, "primitives", None) or []):
            exts = p.extensions if isinstance(getattr(p, "extensions", None), dict) else {}
            if EXT_OMM in exts:
                prims[(mi, pi)] = _read_primitive(r, mi, pi, p, exts[EXT_OMM], arrays, bad)
            if EXT_PAIRS in exts:
                pair_prims[(mi, pi)] = _read_pair_primitive(r, mi, pi, p, exts[EXT_PAIRS], pair_maps)
            if EXT_MERGED in exts:
                merged_prims[(mi, pi)] = _read_merged_primitive(r, mi, pi, p, exts[EXT_MERGED], merged)
    return StoredMicromaps(arrays, prims, pair_maps, pair_prims, merged, merged_prims)


def _read_array(r, i, mm, bad) -> MicromapArray:
    what = f"micromaps[{i}]"
    if not isinstance(mm, dict):
        bad(f"{what} is not an object")
    for key in ("data", "triangles"):
        if not _is_int(mm.get(key)):
            bad(f"{what}.{key} is {mm.get(key)!r}, not a bufferView index")
    lists = []
    for key in ("usageCounts", "usageLevels", "usageFormats"):
        v = mm.get(key)
        if not isinstance(v, list) or not v or not all(_is_int(x) for x in v):
            bad(f"{what}.{key} is {v!r}, not a non-empty array of integers")
        lists.append(v)
    counts, levels, formats = lists
    if not len(counts) == len(levels) == len(formats):
        bad(f"{what}: usageCounts, usageLevels and usageFormats differ in length")
    if any(c < 1 for c in counts) or any(not 0 <= lv <= MAX_LEVEL for lv in levels) or any(f not in (1, 2) for f in formats):
        bad(f"{what}: a usage entry is out of range (counts >= 1, levels 0..{MAX_LEVEL}, formats 1 or 2)")
    data, _ = r.view_bytes(mm["data"])
    raw, stride = r.view_bytes(mm["triangles"])
    if stride is not None and (stride < 8 or stride % 4):
        bad(f"{what}: the triangles bufferView has byteStride {stride} (at least 8, a multiple of 4)")
    stride = stride or 8
    n = (len(raw) - 8) // stride + 1 if len(raw) >= 8 else 0
    if stride == 8 and len(raw) % 8:
        bad(f"{what}: the triangles bufferView holds {len(raw)} bytes, not whole 8-byte records")
    buf = np.frombuffer(raw, np.uint8)
    rows = np.lib.stride_tricks.as_strided(buf, shape=(n, 8), strides=(stride, 1)) if n else np.zeros((0, 8), np.uint8)
    tris = np.ascontiguousarray(rows).view(RECORD).ravel().copy()
    problem = record_problem(tris, len(data), disjoint=True)
    if problem:
        bad(f"{what}: {problem}")
    want: dict = {}
    for lv, f in zip(tris["level"].tolist(), tris["format"].tolist()):
        want[(lv, f)] = want.get((lv, f), 0) + 1
    got: dict = {}
    for c, lv, f in zip(counts, levels, formats):
        got[(lv, f)] = got.get((lv, f), 0) + c
    if got != want:
        bad(f"{what}: the usage counts {sorted(got.items())} are not the records' {sorted(want.items())}")
    extras = mm.get("extras") if isinstance(mm.get("extras"), dict) else {}
    return MicromapArray(np.frombuffer(data, np.uint8).copy(), tris, list(zip(counts, levels, formats)), extras)


def _triangle_count(r, p) -> int | None:
    """The primitive's triangle count as the glTF spec defines it for TRIANGLES mode."""
    attrs = getattr(p, "attributes", None)
    acc = p.indices if p.indices is not None else getattr(attrs, "POSITION", None)
    if not _is_int(acc) or not 0 <= acc < len(r.g.accessors or []):
        return None
    count = getattr(r.g.accessors[acc], "count", None)
    return count // 3 if _is_int(count) else None


def _read_primitive(r, mi, pi, p, e, arrays, bad) -> PrimitiveMicromap:
    what = f"mesh {mi} primitive {pi}"
    if not isinstance(e, dict):
        bad(f"{what}: the extension is not an object")
    if p.mode not in (None, 4):
        bad(f"{what} has mode {p.mode}; micromaps need TRIANGLES (4)")
    m = e.get("micromap")
    if not _is_int(m) or not 0 <= m < len(arrays):
        bad(f"{what}: micromap {m!r} does not exist ({len(arrays)} defined)")
    base = e.get("micromapBaseTriangle", 0)
    if not _is_int(base) or base < 0:
        bad(f"{what}: micromapBaseTriangle is {base!r}, not a non-negative integer")
    n = _triangle_count(r, p)
    if n is None:
        bad(f"{what}: no triangle count (indices or POSITION accessor)")
    ai = e.get("micromapIndices")
    if ai is None:
        values = np.arange(n, dtype=np.int64)
    else:
        if not _is_int(ai) or not 0 <= ai < len(r.g.accessors or []):
            bad(f"{what}: micromapIndices accessor {ai!r} does not exist")
        a = r.g.accessors[ai]
        ct = a.componentType
        if ct not in _UNSIGNED and ct not in _SIGNED or a.normalized:
            bad(f"{what}: micromapIndices accessor {ai} has componentType {ct!r} "
                "(5121, 5123, 5125, 5122 or 5124, not normalized)")
        if a.count != n:
            bad(f"{what}: micromapIndices accessor {ai} has {a.count} elements, the primitive {n} triangles")
        values = r.accessor(ai, ("SCALAR",)).ravel().astype(np.int64)
        if ct in _UNSIGNED:
            top = 1 << _UNSIGNED[ct]
            values = np.where(values >= top - 4, values - top, values)  # two's-complement specials
        elif np.any(values < -4):
            bad(f"{what}: micromapIndices accessor {ai} holds {int(values.min())} (specials are -1..-4)")
    out = PrimitiveMicromap(int(m), values, int(base))
    rec = out.records
    n_rec = len(arrays[m].triangles)
    big = np.flatnonzero(rec >= n_rec)
    if len(big):
        bad(f"{what}: triangle {big[0]} references micromap triangle {rec[big[0]]} ({n_rec} records)")
    return out


def _read_pair_maps(r, i, pm) -> PairMaps:
    from ..codecs import get_codec

    what = f"{EXT_PAIRS}: maps[{i}]"
    if not isinstance(pm, dict):
        raise InputError(f"{what} is not an object", r.path)
    try:
        codec = get_codec(pm.get("codec")) if isinstance(pm.get("codec"), str) else None
    except InputError:
        codec = None
    if codec is None:
        raise InputError(f"{what}.codec is {pm.get('codec')!r}, not a codec", r.path)
    if pm.get("blockBytes") != codec.block_bytes or pm.get("mapSize") != codec.map_size:
        raise InputError(f"{what}: blockBytes / mapSize are {pm.get('blockBytes')!r} / {pm.get('mapSize')!r}, "
                         f"a {codec.name} block has {codec.block_bytes} / {codec.map_size}", r.path)
    if not _is_int(pm.get("blocks")):
        raise InputError(f"{what}.blocks is {pm.get('blocks')!r}, not a bufferView index", r.path)
    raw, stride = r.view_bytes(pm["blocks"])
    if stride is not None or len(raw) % codec.block_bytes:
        raise InputError(f"{what}: the blocks bufferView holds {len(raw)} bytes, not whole "
                         f"{codec.block_bytes}-byte blocks (tightly packed)", r.path)
    extras = pm.get("extras") if isinstance(pm.get("extras"), dict) else {}
    return PairMaps(codec.name, codec.block_bytes, codec.map_size, bytes(raw), extras)


def _read_pair_primitive(r, mi, pi, p, e, pair_maps) -> PrimitivePairs:
    what = f"{EXT_PAIRS}: mesh {mi} primitive {pi}"
    if not isinstance(e, dict) or not _is_int(e.get("maps")) or not 0 <= e["maps"] < len(pair_maps):
        raise InputError(f"{what}: maps {e.get('maps') if isinstance(e, dict) else e!r} does not exist", r.path)
    if not _is_int(e.get("pairs")):
        raise InputError(f"{what}: pairs is not a bufferView index", r.path)
    raw, stride = r.view_bytes(e["pairs"])
    n = _triangle_count(r, p)
    if stride is not None or len(raw) != 8 * (n or 0):
        raise InputError(f"{what}: the pairs bufferView holds {len(raw)} bytes, not 8 per triangle ({n})", r.path)
    rec = np.frombuffer(raw, PAIR_RECORD).copy()
    pm = pair_maps[e["maps"]]
    n_blocks = len(pm.blocks) // pm.block_bytes
    if np.any(rec["pair"] < 0) or np.any(rec["pair"] >= n_blocks) or np.any(rec["corners"] > 3):
        raise InputError(f"{what}: a pair index or corner code is out of range ({n_blocks} blocks)", r.path)
    return PrimitivePairs(int(e["maps"]), rec)


def _read_merged(r, e) -> MergedMicromaps:
    """The root ``OMAPS_merged_micromaps``: its level, micromap count and DAG, the blob checked
    (``codecs.csm.check``: every reference in range, every descent ending within the level)."""
    from ..codecs import csm_check

    if not isinstance(e, dict):
        raise InputError(f"{EXT_MERGED}: the root extension is not an object", r.path)
    level, n = e.get("level"), e.get("micromaps")
    if not _is_int(level) or not 0 <= level <= MAX_LEVEL:
        raise InputError(f"{EXT_MERGED}: level is {level!r}, not a level 0..{MAX_LEVEL}", r.path)
    if not _is_int(n) or n < 0:
        raise InputError(f"{EXT_MERGED}: micromaps is {n!r}, not a count", r.path)
    if not _is_int(e.get("dag")):
        raise InputError(f"{EXT_MERGED}: dag is {e.get('dag')!r}, not a bufferView index", r.path)
    raw, stride = r.view_bytes(e["dag"])
    if stride is not None:
        raise InputError(f"{EXT_MERGED}: the dag bufferView has a byteStride", r.path)
    try:
        csm_check(np.frombuffer(bytes(raw), np.uint8), int(level), int(n))
    except InputError as exc:
        raise InputError(f"{EXT_MERGED}: the dag: {exc.problem}", r.path) from None
    extras = e.get("extras") if isinstance(e.get("extras"), dict) else {}
    return MergedMicromaps(int(level), int(n), bytes(raw), extras)


def _read_merged_primitive(r, mi, pi, p, e, merged) -> int:
    what = f"{EXT_MERGED}: mesh {mi} primitive {pi}"
    if merged is None:
        raise InputError(f"{what}: the file has no root {EXT_MERGED}", r.path)
    first = e.get("first") if isinstance(e, dict) else None
    n = _triangle_count(r, p) or 0
    if not _is_int(first) or first < 0 or first + n > merged.micromaps:
        raise InputError(f"{what}: first is {first!r}: its {n} triangles are not among the {merged.micromaps} "
                         "merged micromaps", r.path)
    return int(first)


# ---- writing -------------------------------------------------------------------------------
def index_component_type(n_records: int) -> int:
    """The smallest unsigned component type whose two's-complement specials (-1..-4, the top four
    values) cannot collide with a record index below ``n_records``."""
    for ct, bits in _UNSIGNED.items():
        if n_records <= (1 << bits) - 4:
            return ct
    raise InputError(f"{n_records} micromaps do not fit an UNSIGNED_INT index")


def encode_indices(index: np.ndarray, ct: int) -> bytes:
    """Signed lookup values (specials -1..-4) as the unsigned type's two's-complement patterns."""
    dt = {5121: "<u1", 5123: "<u2", 5125: "<u4"}[ct]
    return (np.asarray(index, np.int64) & ((1 << _UNSIGNED[ct]) - 1)).astype(dt).tobytes()


class _Appender:
    """New buffer views (8-byte aligned) in one new or extended buffer."""

    def __init__(self, base: int = 0):
        self.base = base
        self.blob = bytearray()
        self.views: list[dict] = []

    def add(self, raw: bytes) -> int:
        self.blob += b"\0" * ((-(self.base + len(self.blob))) % 8)
        self.views.append({"byteOffset": self.base + len(self.blob), "byteLength": len(raw)})
        self.blob += raw
        return len(self.views) - 1


def _named_by_extensions(doc: dict) -> tuple[set, set]:
    """The accessors and buffer views the micromaps of ``_EXTS`` in ``doc`` name."""

    def obj(holder, key) -> dict:
        v = holder.get(key) if isinstance(holder, dict) else None
        return v if isinstance(v, dict) else {}

    root = obj(doc, "extensions")
    omm, pairs, merged = (obj(root, e) for e in _EXTS)
    views = {item.get(k) for item in omm.get("micromaps") or [] if isinstance(item, dict) for k in ("data", "triangles")}
    views |= {item.get("blocks") for item in pairs.get("maps") or [] if isinstance(item, dict)}
    views.add(merged.get("dag"))
    accessors = set()
    for m in doc.get("meshes") or []:
        for p in (m.get("primitives") if isinstance(m, dict) else None) or []:
            ext = obj(p, "extensions")
            accessors.add(obj(ext, EXT_OMM).get("micromapIndices"))
            views.add(obj(ext, EXT_PAIRS).get("pairs"))
    return accessors, views


def write_gltf(src, out_tmp, out_final, micromaps: list[dict], prim_omm: dict, pair_maps: list[dict],
               prim_pairs: dict, warn=None, *, root=None, allow_outside: bool = False,
               max_bytes: int | None = None, merged: dict | None = None, prim_merged: dict | None = None) -> None:
    """Write ``src`` with the extensions to ``out_tmp`` (.glb or .gltf by ``out_final``'s suffix;
    ``out_final`` is where it will be renamed to). Earlier micromaps of these extensions in
    ``src`` are replaced, the accessors, views and bytes they alone named dropped
    (``container.drop_unnamed``). The output is self-contained (``container.self_contained``): a .glb
    holds every buffer and image, a .gltf names only data URIs and its copies in
    ``OUT_files/`` (copied last, beside ``out_final``).

    ``micromaps``: [{data: bytes, triangles: RECORD array, usage: [(count, level, format)], extras}];
    ``prim_omm``: (mesh, primitive) -> (micromap, signed int64 lookup values);
    ``pair_maps``: [{codec, blockBytes, mapSize, blocks: bytes, extras}];
    ``prim_pairs``: (mesh, primitive) -> (maps, PAIR_RECORD array); ``merged``: {level,
    micromaps, dag: bytes, extras} of ``OMAPS_merged_micromaps`` (or None), ``prim_merged``: (mesh,
    primitive) -> its first merged micromap. ``root``, ``allow_outside``,
    ``max_bytes``: the URI policy (``scene.container``) of ``src``, as the scene reader's: every
    file it names is read or copied under it."""
    c = read_container(src, AssetPolicy.of(root, allow_outside, max_bytes))
    doc = c.doc
    glb_out = str(out_final).lower().endswith(".glb")
    packed = self_contained(c, out_final)  # every buffer and image in the output or beside it
    for w in packed.warnings:
        if warn:
            warn(w)
    buffers = doc.setdefault("buffers", [])
    # earlier micromaps of these extensions are replaced: their accessors and views dropped
    old_accessors, old_views = _named_by_extensions(doc)
    root_ext = doc.setdefault("extensions", {})
    for name in _EXTS:
        root_ext.pop(name, None)
    for m in doc.get("meshes") or []:
        for p in (m.get("primitives") or []) if isinstance(m, dict) else []:
            if isinstance(p, dict) and isinstance(p.get("extensions"), dict):
                for name in _EXTS:
                    p["extensions"].pop(name, None)
                if not p["extensions"]:
                    del p["extensions"]
    used = [e for e in doc.get("extensionsUsed") or [] if e not in _EXTS]
    body = drop_unnamed(doc, old_accessors, old_views, packed.body if glb_out else None)
    views = doc.setdefault("bufferViews", [])
    accessors = doc.setdefault("accessors", [])
    if glb_out:  # the new bytes go after the others in the binary chunk (buffer 0, the only one)
        bin_chunk = body
        app = _Appender(len(bin_chunk) + (-len(bin_chunk)) % 8)
        new_buffer = 0
    else:  # a new buffer (a data URI)
        app = _Appender(0)
        new_buffer = len(buffers)
        buffers.append({"byteLength": 0})
    first_view = len(views)
    if micromaps:
        items = []
        for mm in micromaps:
            item = {"data": first_view + app.add(bytes(mm["data"])),
                    "triangles": first_view + app.add(np.asarray(mm["triangles"], RECORD).tobytes()),
                    "usageCounts": [int(c) for c, _, _ in mm["usage"]],
                    "usageLevels": [int(lv) for _, lv, _ in mm["usage"]],
                    "usageFormats": [int(f) for _, _, f in mm["usage"]]}
            if mm.get("extras"):
                item["extras"] = mm["extras"]
            items.append(item)
        root_ext[EXT_OMM] = {"micromaps": items}
        used.append(EXT_OMM)
        n_rec = [len(mm["triangles"]) for mm in micromaps]
        for (mi, pi), (m, values) in sorted(prim_omm.items()):
            prim = doc["meshes"][mi]["primitives"][pi]
            if prim.get("mode", 4) != 4:
                if warn:
                    warn(f"mesh {mi} primitive {pi} is not TRIANGLES (mode {prim.get('mode')}): "
                         f"{EXT_OMM} cannot describe it, its micromaps are not written")
                continue
            ct = index_component_type(n_rec[m])
            view = first_view + app.add(encode_indices(values, ct))
            accessors.append({"bufferView": view, "componentType": ct, "count": int(len(values)), "type": "SCALAR"})
            prim.setdefault("extensions", {})[EXT_OMM] = {"micromap": int(m), "micromapIndices": len(accessors) - 1}
    if pair_maps:
        items = []
        for pm in pair_maps:
            item = {"codec": pm["codec"], "blockBytes": int(pm["blockBytes"]), "mapSize": int(pm["mapSize"]),
                    "blocks": first_view + app.add(bytes(pm["blocks"]))}
            if pm.get("extras"):
                item["extras"] = pm["extras"]
            items.append(item)
        root_ext[EXT_PAIRS] = {"maps": items}
        used.append(EXT_PAIRS)
        for (mi, pi), (k, rec) in sorted(prim_pairs.items()):
            prim = doc["meshes"][mi]["primitives"][pi]
            if prim.get("mode", 4) != 4:
                continue
            view = first_view + app.add(np.asarray(rec, PAIR_RECORD).tobytes())
            prim.setdefault("extensions", {})[EXT_PAIRS] = {"maps": int(k), "pairs": view}
    if merged is not None:
        item = {"level": int(merged["level"]), "micromaps": int(merged["micromaps"]),
                "dag": first_view + app.add(bytes(merged["dag"]))}
        if merged.get("extras"):
            item["extras"] = merged["extras"]
        root_ext[EXT_MERGED] = item
        used.append(EXT_MERGED)
        for (mi, pi), first in sorted((prim_merged or {}).items()):
            prim = doc["meshes"][mi]["primitives"][pi]
            if prim.get("mode", 4) != 4:
                continue
            prim.setdefault("extensions", {})[EXT_MERGED] = {"first": int(first)}
    if not root_ext:
        del doc["extensions"]
    if used:
        doc["extensionsUsed"] = used
    elif "extensionsUsed" in doc:
        del doc["extensionsUsed"]
    for v in app.views:
        views.append({"buffer": new_buffer, **v})
    if not app.views and not glb_out:
        buffers.pop()
    if glb_out:
        body = bytes(bin_chunk) + b"\0" * (app.base - len(bin_chunk)) + bytes(app.blob)
        buffers[0]["byteLength"] = len(body)
        with open(out_tmp, "wb") as f:
            write_glb(f, doc, body)
    else:
        if app.views:
            buffers[new_buffer]["byteLength"] = len(app.blob)
            buffers[new_buffer]["uri"] = ("data:application/octet-stream;base64,"
                                          + base64.b64encode(bytes(app.blob)).decode())
        with open(out_tmp, "w", encoding="utf-8") as f:
            write_json(f, doc)
        packed.write_files(out_final)  # last: the files folder beside it, whole
