"""What the any-hit filter reads: the table of addresses (one per scheme) and the query context.

Everything a filter needs lives in numpy arrays; the filter gets their addresses through an int64
table (``T_*`` words) that the query context points to (``C_*`` words after Embree's part).
docs/FORMAT.md "Scenes" describes the data; this module is its layout.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .embree import CONTEXT_BYTES

__all__ = ["TraceTables", "base_tables", "scheme_tables"]

# ---- the table of addresses a filter reads (int64 words) -------------------------------------
T_PROTO_OF_INST, T_ALPHA_BASE, T_TRI_MAT, T_TRI_UV, T_TRI_CORNER, T_TRI_VALPHA = 0, 1, 2, 3, 4, 5
T_MAT_TEX_START, T_MAT_W, T_MAT_H, T_MAT_WRAP_U, T_MAT_WRAP_V, T_MAT_FILTER, T_MAT_THR, T_MAT_INCL = 6, 7, 8, 9, 10, 11, 12, 13
T_TEX = 14
T_MAP_ROW, T_MAP_DATA, T_MAP_ROW_BYTES, T_MAP_PARAM = 15, 16, 17, 18
T_MAP_LEVEL, T_MAP_OFFSET = 19, 20  # stored micromaps (scheme omm): per row its level (int32) and byte offset (int64)
T_MAP_FORMAT = 21  # a budget's maps: per row its codec's format code (int32, 0 no map); offsets in T_MAP_OFFSET
T_COUNT = 22  # view weights: candidate hits per alpha triangle (int64), counted by lookups.counting_state
T_MAP_CODEC = 23  # square maps of one codec: its format code (``Codec.code``; lookups.pair_map_state)
# ``trace --memory``: every lookup of the primary pass recorded per pixel (``filter.make_recording_filter``):
# per pixel its first slot (int64, pixels + 1) and lookups so far (int64); per slot the triangle (int64),
# barycentrics (float64, 2 each) and the state read (uint8)
T_REC_START, T_REC_COUNT, T_REC_TRI, T_REC_BARY, T_REC_STATE = 24, 25, 26, 27, 28
TABLE_WORDS = 29

# ---- a query context: Embree's part, then ours (int64 words) -----------------------------------
C0 = CONTEXT_BYTES // 8
C_TABLE, C_MODE, C_CAND, C_TESTS, C_CALLS = C0, C0 + 1, C0 + 2, C0 + 3, C0 + 4
C_SET_KEYS, C_SET_STAMPS, C_STAMP, C_SET_FULL = C0 + 5, C0 + 6, C0 + 7, C0 + 8
C_REC_N, C_REC_TRI, C_REC_BARY, C_REC_CAP = C0 + 9, C0 + 10, C0 + 11, C0 + 12
CONTEXT_WORDS = C0 + 16
SET_SIZE = 1024  # distinct candidates per ray we can tell apart (power of two)
REC_CAP = 512  # C candidates a deferred shadow ray can record
MODE_NORMAL, MODE_RECORD = 0, 1


@dataclass
class TraceTables:
    """Everything a filter reads, with the int64 table of addresses (one per scheme)."""

    arrays: dict = field(default_factory=dict)
    table: np.ndarray = None

    @property
    def address(self) -> int:
        return int(self.table.ctypes.data)


def base_tables(tests: dict, n_materials: int, at, proto_of_instance) -> dict:
    """Arrays shared by every scheme: the alpha triangles and, per material, its alpha test
    (``tests``: material -> ``AlphaTest``; the texture values as uint16, which holds 8- and 16-bit
    values exactly)."""
    tex_parts, rows = [], []
    pos = 0
    seen: dict[int, tuple] = {}
    filt = np.zeros(n_materials, np.int64)
    wu = np.zeros(n_materials, np.int64)
    wv = np.zeros(n_materials, np.int64)
    thr = np.full(n_materials, np.inf)
    incl = np.ones(n_materials, np.int64)
    for mi in range(n_materials):
        test = tests.get(mi)
        if test is None:
            rows.append((0, 1, 1))
            continue
        key = id(test.value)
        if key not in seen:
            v = np.asarray(test.value)
            if v.dtype.kind not in "ui" or (v.size and v.max() > 65535):
                raise ValueError("the tracer's textures hold integers 0..65535")
            seen[key] = (pos, v.shape[1], v.shape[0])
            tex_parts.append(v.ravel().astype(np.uint16))
            pos += v.size
        rows.append(seen[key])
        filt[mi], wu[mi], wv[mi] = test.codes()
        thr[mi] = test.threshold
        incl[mi] = 1 if test.inclusive else 0
    if not tex_parts:
        tex_parts = [np.zeros(1, np.uint16)]
    st = np.array(rows, dtype=np.int64).reshape(-1, 3)
    return {
        T_PROTO_OF_INST: np.ascontiguousarray(proto_of_instance, dtype=np.int32),
        T_ALPHA_BASE: np.ascontiguousarray(at.base, dtype=np.int64),
        T_TRI_MAT: np.ascontiguousarray(at.material, dtype=np.int32),
        T_TRI_UV: np.ascontiguousarray(at.uv, dtype=np.float64),
        T_TRI_CORNER: np.ascontiguousarray(at.corners, dtype=np.int8),
        T_TRI_VALPHA: np.ascontiguousarray(at.vertex_alpha, dtype=np.float64),
        T_MAT_TEX_START: np.ascontiguousarray(st[:, 0]),
        T_MAT_W: np.ascontiguousarray(st[:, 1]),
        T_MAT_H: np.ascontiguousarray(st[:, 2]),
        T_MAT_WRAP_U: wu,
        T_MAT_WRAP_V: wv,
        T_MAT_FILTER: filt,
        T_MAT_THR: thr,
        T_MAT_INCL: incl,
        T_TEX: np.concatenate(tex_parts),
    }


def scheme_tables(base: dict, sm) -> TraceTables:
    arrays = dict(base)
    arrays[T_MAP_ROW] = np.ascontiguousarray(sm.rows, dtype=np.int32)
    arrays[T_MAP_DATA] = np.ascontiguousarray(sm.data, dtype=np.uint8)
    arrays.update(sm.extra)  # words a scheme sets itself (stored micromaps' levels, a file's corner codes)
    table = np.zeros(TABLE_WORDS, np.int64)
    for k, a in arrays.items():
        table[k] = a.ctypes.data
    table[T_MAP_ROW_BYTES] = sm.row_bytes
    table[T_MAP_PARAM] = sm.param
    if sm.codec is not None:
        table[T_MAP_CODEC] = sm.codec.code  # its format code (codecs.registry)
    return TraceTables(arrays, table)


@dataclass
class SchemeMaps:
    """One scheme's maps as the tracer reads them: alpha triangle t uses row ``rows[t]`` of
    ``data`` (``row_bytes`` each). kind: "none" (no maps), "micromap" (raw 2-bit micromap per
    triangle, param L), "square" (a pair's stored square map through ``codec``, param N), "mixed"
    (a budget: per row a format code and byte offset, ``trace.budget``), "succinct" (per row the
    byte offset of a succinct micromap, param L) or "csm" (one merged DAG, a root per triangle,
    param L); for the last two ``row_bytes`` is the data's length (``trace.maps.hierarchical_maps``)."""

    name: str
    kind: str
    param: int
    rows: np.ndarray  # int32 (T,)
    data: np.ndarray  # uint8 (R * row_bytes,)
    row_bytes: int
    map_bytes: int  # storage of every prototype pair's (or triangle's) map, as a BLAS holds them
    distinct_maps: int
    known_fraction: float  # mean over pairs (triangles for micromaps) of the fraction of known regions
    codec: object = None
    scheme: object = None
    extra: dict = field(default_factory=dict)  # table word -> array the scheme sets itself (trace.tables)
    info: dict = field(default_factory=dict)  # what the scheme reports besides (a budget's choices)
