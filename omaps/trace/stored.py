"""Maps the traced file stores, as the any-hit filter reads them: scheme ``omm`` (the file's
``EXT_mesh_opacity_micromap`` micromaps), ``file:CODEC`` (its ``OMAPS_pair_opacity_maps``
pair blocks) and ``file:csm`` (its ``OMAPS_merged_micromaps``). Nothing is baked: every alpha triangle the tracer sees is mapped to what the
file stores for its primitive and triangle (``scene.micromaps``, read and checked with the
scene).

``omm``: each micromap record becomes one row of 2-bit T/O/C states at the record's own level
(4-state 0, 1 keep their codes, unknown-transparent and unknown-opaque are C: the any-hit shader
runs; 2-state records hold T and O only), looked up through the bird curve like ``triL``;
special indices are one-state level-0 rows (-1 T, -2 O, -3 and -4 C). A triangle whose
primitive has no micromap is C (alpha-tested). ``file:CODEC``: each triangle reads its pair's
stored block with the codec's random-access lookup and the corner codes the file stores; a
triangle without a stored pair reads an all-C block. ``file:csm``: each triangle descends from
its root in the stored DAG (the primitive's ``first`` + its triangle), as ``csmL`` reads its own;
a triangle whose primitive has none reads an all-C root added to the DAG's roots.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import states
from ..codecs import pack_states, row_bytes, unpack_states
from ..errors import InputError
from .tables import T_MAP_LEVEL, T_MAP_OFFSET, T_TRI_CORNER, SchemeMaps

__all__ = ["stored_maps"]

# 4-state OMM code -> omaps state; 2-state codes 0, 1 read the same
_OMM_TO_STATE = np.array([states.T, states.O, states.C, states.C], np.uint8)
_SPECIAL_STATE = {-1: states.T, -2: states.O, -3: states.C, -4: states.C}


def _primitive_keys(at, scene) -> np.ndarray:
    """(glTF mesh, glTF primitive) of every alpha triangle, as an (T, 2) array."""
    keys = np.zeros((at.count, 2), np.int64)
    for k, mesh in enumerate(scene.meshes):
        a, b = at.base[k], at.base[k + 1]
        prim = at.primitive[a:b]
        keys[a:b, 0] = mesh.index
        keys[a:b, 1] = np.array([p.index for p in mesh.primitives], np.int64)[prim] if b > a else 0
    return keys


def stored_maps(at, scene, scheme) -> SchemeMaps:
    stored = getattr(scene, "micromaps", None)
    path = getattr(scene, "path", None)
    if scheme.representation == "csm":
        if stored is None or stored.merged is None:
            raise InputError(f"holds no OMAPS_merged_micromaps: scheme {scheme.name} has nothing to read", path)
        return _merged_maps(at, scene, stored, scheme)
    if scheme.codec is None:
        if stored is None or not stored.micromaps:
            raise InputError("holds no EXT_mesh_opacity_micromap micromaps: scheme omm has nothing to read", path)
        return _omm_maps(at, scene, stored, scheme)
    if stored is None or not stored.pair_maps:
        raise InputError(f"holds no OMAPS_pair_opacity_maps pair blocks: scheme {scheme.name} has nothing to read",
                         path)
    return _pair_maps(at, scene, stored, scheme)


def _omm_maps(at, scene, stored, scheme) -> SchemeMaps:
    chunks, offsets, levels, known_rows = [], [], [], []
    size = 0

    def add_row(st: np.ndarray, level: int) -> int:
        nonlocal size
        raw = pack_states(st[None, :]).ravel().tobytes()
        chunks.append(raw)
        offsets.append(size)
        levels.append(level)
        known_rows.append(float(np.mean(st != states.C)))
        size += len(raw)
        return len(offsets) - 1

    first_row = []
    for arr in stored.micromaps:
        first_row.append(len(offsets))
        for rec in arr.triangles:
            lv, fmt, off = int(rec["level"]), int(rec["format"]), int(rec["data_offset"])
            n = 4 ** lv
            bits = 1 if fmt == 1 else 2
            packed = arr.data[off:off + row_bytes(n, bits)]
            code = unpack_states(packed[None, :], n, bits).ravel()
            add_row(_OMM_TO_STATE[code], lv)
    special_row = {v: add_row(np.array([s], np.uint8), 0) for v, s in _SPECIAL_STATE.items()}
    none_row = special_row[-3]  # no micromap: C
    rows = np.full(at.count, none_row, np.int32)
    keys = _primitive_keys(at, scene)
    for (mi, pi), pm in stored.primitives.items():
        sel = np.flatnonzero((keys[:, 0] == mi) & (keys[:, 1] == pi))
        if not len(sel):
            continue
        rec = pm.records[at.local[sel]]
        r = np.where(rec >= 0, first_row[pm.micromap] + np.maximum(rec, 0), 0)
        for v, row in special_row.items():
            r[rec == v] = row
        rows[sel] = r
    known = np.array(known_rows)[rows]
    data = np.frombuffer(b"".join(chunks), np.uint8).copy()
    extra = {T_MAP_LEVEL: np.array(levels, np.int32), T_MAP_OFFSET: np.array(offsets, np.int64)}
    map_bytes = sum(len(a.data) + 8 * len(a.triangles) for a in stored.micromaps) + 4 * at.count
    return SchemeMaps(scheme.name, "stored_micromap", 0, rows, data, 1, map_bytes,
                      sum(len(a.triangles) for a in stored.micromaps),
                      float(known.mean()) if len(known) else 0.0, None, scheme, extra)


def _merged_maps(at, scene, stored, scheme) -> SchemeMaps:
    from ..codecs import csm_pack, csm_unpack

    mm = stored.merged
    nodes, roots = csm_unpack(mm.dag, mm.level, mm.micromaps)
    rows = np.full(at.count, len(roots), np.int64)  # no stored micromap: the all-C root added below
    keys = _primitive_keys(at, scene)
    for (mi, pi), first in stored.merged_primitives.items():
        sel = np.flatnonzero((keys[:, 0] == mi) & (keys[:, 1] == pi))
        rows[sel] = first + at.local[sel]
    every = np.append(roots, states.C)
    data = np.frombuffer(csm_pack(nodes, every), np.uint8).copy()
    known = _known_shares(nodes)
    used = every[rows]
    return SchemeMaps(scheme.name, "csm", mm.level, rows.astype(np.int32), data, len(data), len(mm.dag),
                      len(np.unique(used)), float(known[used].mean()) if len(used) else 0.0, None, scheme)


@njit(cache=True)
def _known_shares(nodes):
    """Per reference of a merged DAG the share of its micro-triangles that are T or O: a state's
    1 or 0, a node's the mean of its children's (nodes come children first, the blob's order)."""
    known = np.ones(3 + nodes.shape[0])
    known[states.C] = 0.0
    for i in range(nodes.shape[0]):
        known[3 + i] = 0.25 * (known[nodes[i, 0]] + known[nodes[i, 1]] + known[nodes[i, 2]] + known[nodes[i, 3]])
    return known


def _pair_maps(at, scene, stored, scheme) -> SchemeMaps:
    codec = scheme.codec
    which = [k for k, pm in enumerate(stored.pair_maps) if pm.codec == codec.name]
    if not which:
        raise InputError(f"stores pair blocks of {', '.join(pm.codec for pm in stored.pair_maps)}, "
                         f"not {codec.name}: scheme {scheme.name} has nothing to read", scene.path)
    k = which[0]
    pm = stored.pair_maps[k]
    all_c, _ = codec.encode_many(np.full((1, codec.map_size, codec.map_size), states.C, np.uint8))
    blocks = np.concatenate([np.frombuffer(pm.blocks, np.uint8), all_c.ravel()])
    n_blocks = len(pm.blocks) // pm.block_bytes
    rows = np.full(at.count, n_blocks, np.int32)  # no stored pair: the all-C block
    corners = np.ascontiguousarray(at.corners, dtype=np.int8).copy()
    keys = _primitive_keys(at, scene)
    for (mi, pi), pp in stored.pair_primitives.items():
        if pp.maps != k:
            continue
        sel = np.flatnonzero((keys[:, 0] == mi) & (keys[:, 1] == pi))
        rec = pp.records[at.local[sel]]
        rows[sel] = rec["pair"]
        corners[sel] = rec["corners"].astype(np.int8)
    decoded = codec.decode_many(blocks.reshape(-1, codec.block_bytes))
    known = (decoded != states.C).reshape(len(decoded), -1).mean(axis=1)[rows]
    return SchemeMaps(scheme.name, "square", codec.map_size, rows, blocks, codec.block_bytes, len(pm.blocks),
                      n_blocks, float(known.mean()) if len(known) else 0.0, codec, scheme, {T_TRI_CORNER: corners})
