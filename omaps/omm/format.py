"""The standard opacity micromap format (VK_EXT/KHR_opacity_micromap, DXR 1.2): the one place
its facts live. docs/FORMAT.md, section "Standard opacity micromaps (OMM)", states the same.

* States of a micro-triangle: 0 transparent, 1 opaque, 2 unknown-transparent, 3 unknown-opaque.
  omaps' T = 0 and O = 1 keep their codes; C becomes 2 or 3 (the promotion chooses which: the
  state a ray with the "force 2-state" flag sees).
* Formats: 1 = 2-state (1 bit per micro-triangle), 2 = 4-state (2 bits).
* Data: micro-triangle i of a micromap at bit ``bits*(i mod per_byte)`` of byte ``i div per_byte``
  (per_byte = 8 / bits), little-endian; every micromap starts on a byte.
* Triangle records (VkMicromapTriangleEXT): u32 data byte offset, u16 level (at most
  ``MAX_LEVEL``, 12), u16 format (``TRIANGLE_RECORD``; ``record_problem`` checks them).
* omaps' pair records (``PAIR_RECORD``, ``--from SCHEME``): i32 pair, u8 corner code per vertex, pad.
* Special indices (index buffer entries that need no micromap): -1 fully transparent, -2 fully
  opaque, -3 fully unknown-transparent, -4 fully unknown-opaque.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..birdcurve import MAX_LEVEL  # the APIs' largest subdivision level
from ..codecs import pack_states, row_bytes, unpack_states
from ..names import OMM_FORMATS

FORMAT_2_STATE = 1
FORMAT_4_STATE = 2
FORMAT_NAMES = OMM_FORMATS  # {"2state": FORMAT_2_STATE, "4state": FORMAT_4_STATE}
BITS = {FORMAT_2_STATE: 1, FORMAT_4_STATE: 2}

TRANSPARENT = 0
OPAQUE = 1
UNKNOWN_TRANSPARENT = 2
UNKNOWN_OPAQUE = 3

# state -> special index of a micromap whose micro-triangles all have that state
SPECIAL_INDEX = np.array([-1, -2, -3, -4], dtype=np.int32)

TRIANGLE_RECORD = np.dtype([("data_offset", "<u4"), ("level", "<u2"), ("format", "<u2")])
INDEX_DTYPE = np.dtype("<i4")

DATA_FILE = "omm_data.bin"
TRIANGLES_FILE = "omm_triangles.bin"
INDEX_FILE = "omm_index.bin"
USAGE_FILE = "omm_usage.json"
SUMMARY_FILE = "omm.json"
PAIR_BLOCKS_FILE = "pair_blocks.bin"  # --from SCHEME: the stored pair maps the OMMs expand from
PAIRS_FILE = "omm_pairs.bin"  # --from SCHEME: per triangle its pair and the corner codes of its vertices
PAIR_RECORD = np.dtype([("pair", "<i4"), ("corners", "u1", (3,)), ("pad", "u1")])


def micromap_bytes(level: int, fmt: int) -> int:
    """Bytes one micromap of this level and format takes (at least one byte)."""
    return row_bytes(4 ** int(level), BITS[int(fmt)])


def record_problem(triangles: np.ndarray, data_bytes: int, disjoint: bool = False) -> str | None:
    """The first broken triangle record (``TRIANGLE_RECORD``) of a micromap array whose data holds
    ``data_bytes`` bytes, in words ("record 3 has format 7 (1 or 2)"), or None: every format 1 or
    2, every level at most ``MAX_LEVEL``, every micromap's bytes inside the data; ``disjoint``: no
    two micromaps' bytes overlap (the glTF extension's rule; the APIs allow shared data)."""
    tris = np.asarray(triangles)
    bad = np.flatnonzero(~np.isin(tris["format"], list(BITS)))
    if len(bad):
        return f"record {bad[0]} has format {tris['format'][bad[0]]} (1 or 2)"
    bad = np.flatnonzero(tris["level"] > MAX_LEVEL)
    if len(bad):
        return f"record {bad[0]} has subdivision level {tris['level'][bad[0]]} (at most {MAX_LEVEL})"
    sizes = np.array([micromap_bytes(lv, f) for lv, f in zip(tris["level"], tris["format"])], np.int64)
    start = tris["data_offset"].astype(np.int64)
    end = start + sizes
    bad = np.flatnonzero(end > data_bytes)
    if len(bad):
        return f"record {bad[0]} reads bytes up to {end[bad[0]]} of {data_bytes} data bytes"
    if disjoint:
        order = np.argsort(start, kind="stable")
        clash = np.flatnonzero(start[order][1:] < end[order][:-1])
        if len(clash):
            return f"the data regions of records {order[clash[0]]} and {order[clash[0] + 1]} overlap"
    return None


def pack(omm_states: np.ndarray, fmt: int) -> np.ndarray:
    """Pack micromaps of one level, ``omm_states`` (M, 4**L) uint8 in 0..3 (0..1 for 2-state),
    into (M, micromap_bytes) uint8 rows (``codecs.raw``'s layout)."""
    return pack_states(omm_states, BITS[fmt])


def unpack(packed: np.ndarray, level: int, fmt: int) -> np.ndarray:
    """Inverse of ``pack``: (M, bytes) -> (M, 4**level) states."""
    return unpack_states(packed, 4 ** int(level), BITS[fmt])


def usage_histograms(levels: np.ndarray, formats: np.ndarray, index: np.ndarray) -> dict:
    """The usage counts an acceleration-structure build asks for (VkMicromapUsageEXT /
    D3D12 opacity micromap histogram entries): per (level, format), how many micromaps the array
    holds (``micromap_array``) and how many triangles of the geometry reference one
    (``geometry``; special indices reference none)."""
    levels = np.asarray(levels)
    formats = np.asarray(formats)
    index = np.asarray(index)
    used = index[index >= 0]

    def hist(lv, fm):
        out = []
        for (lvl, f), c in sorted(_count_pairs(lv, fm).items()):
            out.append({"count": int(c), "subdivisionLevel": int(lvl), "format": int(f)})
        return out

    return {"micromap_array": hist(levels, formats), "geometry": hist(levels[used], formats[used])}


def _count_pairs(a, b) -> dict:
    a = np.asarray(a, dtype=np.int64).ravel()
    b = np.asarray(b, dtype=np.int64).ravel()
    if len(a) == 0:
        return {}
    if a.min() < 0 or b.min() < 0:  # (not from a valid file: counted the general way)
        keys, counts = np.unique(np.stack([a, b], axis=1), axis=0, return_counts=True)
        return {(int(k[0]), int(k[1])): int(c) for k, c in zip(keys, counts)}
    span = int(b.max()) + 1
    counts = np.bincount(a * span + b)
    return {(int(k // span), int(k % span)): int(counts[k]) for k in np.flatnonzero(counts)}


@njit(cache=True)
def _uniform_rows(rows):
    out = np.empty(rows.shape[0], dtype=np.bool_)
    for i in range(rows.shape[0]):
        s = rows[i, 0]
        d = np.uint8(0)
        for k in range(1, rows.shape[1]):  # no branch: the compiler vectorises the row
            d |= rows[i, k] ^ s
        out[i] = d == 0
    return out


def uniform_rows(omm_states: np.ndarray) -> np.ndarray:
    """Per micromap (M, K), whether all its micro-triangles share one state (a special index)."""
    return _uniform_rows(np.ascontiguousarray(omm_states, dtype=np.uint8))

