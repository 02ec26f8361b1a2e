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

from . import rows as rows_mod
from .birdcurve import MAX_LEVEL  # the APIs' largest subdivision level
from .codecs import pack_states, row_bytes, unpack_states
from .errors import InputError
from .names import OMM_FORMATS

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
MERGED_FILE = "merged_micromaps.bin"  # --from csmL: every triangle's micromap in one merged DAG (codecs.csm's blob)
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


class Packer:
    """The pack stage: collects micromaps, turning uniform ones into special indices and sharing
    duplicates (``rows.RowIndex`` per level and format: hashed, then compared word by word).

    Preconditions of ``add``: rows of OMM states (0..3, above) of one level, every row ``4**level``
    long, 2-state rows holding only 0 and 1. ``record_array`` and ``data`` give the packed buffers
    in the order micromaps were first added. ``omaps omm``'s pack stage, and the tracer's model of
    the memory its micromaps take (``trace --memory``): one statement of the rules.

    Example::

        >>> import numpy as np
        >>> from omaps.omm_format import Packer
        >>> packer = Packer()  # 4-state, special indices, reuse
        >>> packer.add(np.array([[0, 0, 0, 0], [0, 1, 2, 3], [1, 1, 1, 1], [0, 1, 2, 3]], np.uint8), 1).tolist()
        [-1, 0, -2, 0]
        >>> packer.record_array()["data_offset"].tolist(), packer.data().tolist()
        ([0], [228])
    """

    def __init__(self, format_code: int = FORMAT_4_STATE, special: bool = True, dedup: bool = True):
        if format_code not in BITS:
            raise ValueError(f"unknown OMM format code {format_code!r} (1 or 2)")
        self.format_code = int(format_code)
        self.special = bool(special)  # uniform micromaps as special indices
        self.dedup = bool(dedup)  # identical micromaps stored once
        self._data = bytearray()  # the packed micromaps, one after another (grown in place: no copy)
        self.records: list[np.ndarray] = []  # TRIANGLE_RECORD arrays, in order
        self.singles: list[tuple[int, int, int]] = []  # records added one by one, after those
        self.n_records = 0
        # per (level, format): the distinct micromaps stored, and each one's record
        self.stored: dict[tuple[int, int], tuple[rows_mod.RowIndex, np.ndarray]] = {}
        self.needing = 0  # micromaps before reuse of identical ones

    def add(self, omm_states: np.ndarray, level: int, fmt: int | None = None, weights=None) -> np.ndarray:
        """Index buffer entries for micromaps (n, 4**level) of one level (and format: default the
        packer's); ``weights``: how many triangles each row stands for (default one)."""
        fmt = self.format_code if fmt is None else fmt
        idx = np.empty(len(omm_states), dtype=np.int32)
        need = np.ones(len(omm_states), dtype=bool)
        if self.special:
            uniform = uniform_rows(omm_states)
            idx[uniform] = SPECIAL_INDEX[omm_states[uniform, 0]]
            need = ~uniform
        rows = np.flatnonzero(need)
        self.needing += len(rows) if weights is None else int(np.sum(weights[rows]))
        if len(rows) == 0:
            return idx
        packed = pack(omm_states[rows], fmt)
        if not self.dedup:
            for r, row in zip(rows, packed):
                idx[r] = self._new(row.tobytes(), level, fmt)
            return idx
        index, record_of = self.stored.get((level, fmt), (None, np.zeros(0, np.int32)))
        if index is None:
            index = rows_mod.RowIndex(packed.shape[1], external=True)  # it compares with the data itself
        before = index.n
        view = np.frombuffer(self._data, np.uint8)
        ids = index.add(packed, view, self.size)
        del view  # (the data grows below)
        fresh = rows_mod.first_uses(ids, before)  # the first row of each micromap not stored before
        nbytes = packed.shape[1]
        if len(fresh):
            if self.size + len(fresh) * nbytes > 0xFFFFFFFF:
                raise InputError("micromap data exceeds the 4 GiB a 32-bit data offset can address; lower the level")
            rec = np.empty(len(fresh), dtype=TRIANGLE_RECORD)
            rec["data_offset"] = self.size + nbytes * np.arange(len(fresh), dtype=np.int64)
            rec["level"], rec["format"] = level, fmt
            self._flush_singles()  # (they came first)
            self.records.append(rec)
            record_of = np.concatenate([record_of, self.n_records + np.arange(len(fresh), dtype=np.int32)])
            self.n_records += len(fresh)
            self._append(packed[fresh])
        self.stored[(level, fmt)] = (index, record_of)
        idx[rows] = record_of[ids]
        return idx

    def _flush_singles(self) -> None:
        if self.singles:
            self.records.append(np.array(self.singles, dtype=TRIANGLE_RECORD))
            self.singles = []

    def record_array(self) -> np.ndarray:
        """Every record so far, as one TRIANGLE_RECORD array."""
        self._flush_singles()
        if len(self.records) != 1:
            self.records = [np.concatenate(self.records) if self.records else np.zeros(0, TRIANGLE_RECORD)]
        return self.records[0]

    @property
    def size(self) -> int:
        """Bytes of micromap data so far."""
        return len(self._data)

    def data(self) -> np.ndarray:
        """Every micromap's packed states so far, as one uint8 array (record ``data_offset`` into it):
        the packer's own bytes, not a copy (the output's data is held once); micromaps added
        later do not change it."""
        return np.frombuffer(self._data, dtype=np.uint8)

    def _append(self, raw) -> None:
        """Append bytes to the data: in place (a large buffer grows without a copy), unless an
        earlier ``data()`` holds the buffer, which then stays as it is and the data moves on."""
        raw = memoryview(np.ascontiguousarray(raw)).cast("B")
        try:
            self._data += raw
        except BufferError:  # a view from ``data()`` is alive: it keeps the old buffer
            self._data = bytearray(self._data)
            self._data += raw

    def _new(self, raw: bytes, level: int, fmt: int) -> int:
        self.singles.append((self.size, level, fmt))
        self.n_records += 1
        self._append(np.frombuffer(raw, np.uint8))
        if self.size > 0xFFFFFFFF:
            raise InputError("micromap data exceeds the 4 GiB a 32-bit data offset can address; lower the level")
        return self.n_records - 1
