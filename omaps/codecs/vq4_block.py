"""VQ4: a 32x32 map in one 512-bit block (and ``vq4x64``: a 64x64 map in four) -- physical
layout, symbolic block, decoders.

The map is an 8x8 grid of 4x4 vectors (vector (vx, vy) holds cells x = 4vx..4vx+3,
y = 4vy..4vy+3 of ``map[y, x]``), in four quadrants of 4x4 vectors numbered as in VQ2
(q = 2*(vy >> 2) + (vx >> 2)).

Physical block (64 bytes, bits numbered as in ``bits.py``):

    bits   0..255  index of vector v = 8*vy + vx, 4 bits each, at bit 4v
    bits 256..502  codebook: 13 entries (``vec4`` kinds), entry j at ENTRY_POS[j]:
                   j 0..2 two-value (17 bits), 3 vertical and 4 horizontal partition (18 bits),
                   5..12 general (20 bits)
    bits 503..511  transforms of quadrants 1, 2, 3 (3 bits each, at 503 + 3(q-1))

Index 0, 1, 2: uniform T, O, C; index i >= 3: entry i - 3. Every 512-bit pattern is a valid block.
``vq4x64`` stores the 64x64 map's 32x32 quadrants (top-left, top-right, bottom-left,
bottom-right) as four consecutive blocks.

Many blocks at once (compiled, no block objects): ``pack_many`` (fields -> bytes),
``unpack_many`` (bytes -> fields), ``decode_many`` and ``decode_many_x64`` (bytes -> maps).
``VQ4Block`` packs and unpacks through them.

Example::

    >>> import numpy as np
    >>> idx = np.zeros((1, 64), np.int64); idx[0, 1] = 1  # vector 1 uniform O, the rest T
    >>> data = pack_many(idx, np.zeros((1, 13), np.int64), np.zeros((1, 4), np.int64))
    >>> data.shape, int(data[0, 0]), decode_many(data)[0, 0, 2:6].tolist()
    ((1, 64), 16, [0, 0, 1, 1])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import states
from . import bits
from .bits import as_block, kernel_bytes
from .vec4 import CFLAG_BIT, FWD4, INV4, KIND_BITS, PALETTE_BIT, entry_pattern, pattern_states

BLOCK_BYTES = 64
SIZE = 32
INDEX_BITS, INDEX_POS = 4, 0
N_ENTRIES = 13
ENTRY_KIND = np.array([0, 0, 0, 1, 2] + [3] * 8, dtype=np.int64)
ENTRY_POS = 256 + np.concatenate([[0], np.cumsum(KIND_BITS[ENTRY_KIND])[:-1]]).astype(np.int64)
TRANSFORM_BITS, TRANSFORM_POS = 3, 503
assert ENTRY_POS[-1] + KIND_BITS[3] == TRANSFORM_POS and TRANSFORM_POS + 9 == 8 * BLOCK_BYTES

# _BITS[i, t, c]: for index i >= 3 under transform t, the absolute bits of the C flag (low 16) and
# the palette bit (high 16) that cell c = 4*(y & 3) + (x & 3) of the vector reads; rows 0..2 are
# never used but keep the lookup free of branches
_BITS = np.zeros((16, 8, 16), dtype=np.int32)  # int32: 8 KiB, half the cache lines of int64
for _i in range(3, 16):
    _k = ENTRY_KIND[_i - 3]
    _e = INV4  # stored element e = t^-1(c)
    _BITS[_i] = (ENTRY_POS[_i - 3] + CFLAG_BIT[_k][_e]) | ((ENTRY_POS[_i - 3] + PALETTE_BIT[_k][_e]) << 16)

X64_SIZE, X64_BYTES = 64, 4 * BLOCK_BYTES
# the block's fields in ``pack_many``'s order: 64 indices, 13 codebook entries, transforms of quadrants 1..3
FIELD_POS = np.concatenate([INDEX_POS + INDEX_BITS * np.arange(64), ENTRY_POS,
                            TRANSFORM_POS + TRANSFORM_BITS * np.arange(3)]).astype(np.int64)
FIELD_BITS = np.concatenate([[INDEX_BITS] * 64, KIND_BITS[ENTRY_KIND], [TRANSFORM_BITS] * 3]).astype(np.int64)


@dataclass
class VQ4Block:
    """Symbolic block: ``indices`` (64,) in 0..15, ``entries`` (13,) codes of the kinds in
    ENTRY_KIND, ``transforms`` (4,) with transforms[0] = 0."""

    indices: np.ndarray
    entries: np.ndarray
    transforms: np.ndarray

    def __post_init__(self):
        self.indices = np.asarray(self.indices, dtype=np.uint8).reshape(64)
        self.entries = np.asarray(self.entries, dtype=np.int64).reshape(N_ENTRIES)
        t = np.asarray(self.transforms, dtype=np.uint8).reshape(-1)
        self.transforms = np.concatenate([[0], t]).astype(np.uint8) if t.size == 3 else t
        if self.transforms.shape != (4,) or self.transforms[0] != 0:
            raise ValueError("transforms: 3 values (quadrants 1..3) or 4 with the first 0")
        if self.indices.max() > 15 or self.transforms.max() > 7:
            raise ValueError("field out of range")
        if np.any(self.entries < 0) or np.any(self.entries >= (1 << KIND_BITS[ENTRY_KIND])):
            raise ValueError("codebook entry out of range for its kind")

    def pack(self) -> bytes:
        """The physical block (64 bytes)."""
        return pack_many(self.indices[None], self.entries[None], self.transforms[None])[0].tobytes()

    @classmethod
    def unpack(cls, data) -> "VQ4Block":
        idx, ent, tr = unpack_many(as_block(data, BLOCK_BYTES, "a VQ4 block")[None])
        return cls(idx[0], ent[0], tr[0])

    def vector_states(self, index: int) -> np.ndarray:
        """Stored (untransformed) 4x4 states of an index value."""
        if index < 3:
            return np.full((4, 4), index, dtype=np.uint8)
        j = index - 3
        return pattern_states(*entry_pattern(ENTRY_KIND[j], int(self.entries[j])))

    def decode(self) -> np.ndarray:
        """The 32x32 map (``map[y, x]``)."""
        out = np.empty((SIZE, SIZE), dtype=np.uint8)
        for vy in range(8):
            for vx in range(8):
                q = 2 * (vy >> 2) + (vx >> 2)
                stored = self.vector_states(int(self.indices[8 * vy + vx])).reshape(16)
                shown = np.empty(16, dtype=np.uint8)
                shown[FWD4[self.transforms[q]]] = stored  # shown = t(stored)
                out[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = shown.reshape(4, 4)
        return out


def decode(data) -> np.ndarray:
    """Physical block (64 bytes) to its 32x32 map."""
    return VQ4Block.unpack(data).decode()


def pack_many(indices, entries, transforms) -> np.ndarray:
    """Symbolic fields of n blocks -> their physical blocks (n, 64) uint8: ``indices`` (n, 64) in
    0..15, ``entries`` (n, 13) codes of the kinds in ENTRY_KIND, ``transforms`` (n, 4) with column
    0 all 0, or (n, 3) for quadrants 1..3. ValueError for a field out of range."""
    return bits.pack_block_fields(indices, entries, transforms, FIELD_POS, FIELD_BITS, BLOCK_BYTES)


def unpack_many(blocks):
    """Physical blocks (n, 64) uint8 -> (indices (n, 64), entries (n, 13), transforms (n, 4)), int64,
    transforms[:, 0] = 0."""
    return bits.unpack_block_fields(blocks, FIELD_POS, FIELD_BITS)


def decode_x64(data) -> np.ndarray:
    """Four physical blocks (256 bytes) to their 64x64 map."""
    b = as_block(data, X64_BYTES, "a VQ4x64 map (four VQ4 blocks)")
    out = np.empty((X64_SIZE, X64_SIZE), dtype=np.uint8)
    for k in range(4):
        y, x = SIZE * (k >> 1), SIZE * (k & 1)
        out[y:y + SIZE, x:x + SIZE] = decode(b[BLOCK_BYTES * k:BLOCK_BYTES * (k + 1)])
    return out


@njit(cache=True, inline="always")
def _bit(data, base, k):
    return (np.int64(data[base + (k >> 3)]) >> (k & 7)) & 1


@njit(cache=True, inline="always")
def lookup_at(data, base, x, y):
    """State of cell (x, y) of the block at byte ``base`` of ``data``, reading only what it needs:
    the vector's 4-bit index, the quadrant's transform, and for an explicit entry one C flag and
    one palette bit. Written without branches on the index (a mispredicted branch costs more
    than the few loads it would skip), and inlined into its callers (numba does not inline a
    call of another compiled function by itself: as a call, ``lookup_batch_x64`` ran at half
    the rate of ``lookup_batch``)."""
    v = ((y >> 2) << 3) | (x >> 2)
    idx = (np.int64(data[base + (v >> 1)]) >> ((v & 1) << 2)) & 15
    q = ((y >> 4) << 1) | (x >> 4)
    tw = np.int64(data[base + 62]) | (np.int64(data[base + 63]) << 8)  # bits 496..511
    t = (tw >> (TRANSFORM_POS - 496 - TRANSFORM_BITS + TRANSFORM_BITS * q)) & 7 & -np.int64(q != 0)
    p = np.int64(_BITS[idx, t, ((y & 3) << 2) | (x & 3)])
    c = _bit(data, base, p & 0xFFFF)
    pal = _bit(data, base, p >> 16)
    state = c * states.C + (1 - c) * (states.O * pal + states.T * (1 - pal))
    return idx if idx < 3 else state


@njit(cache=True)
def lookup(block, x, y):
    """``lookup_at`` of a single 64-byte block, x and y in 0..31."""
    return lookup_at(block, 0, x, y)


@njit(cache=True, inline="always")
def lookup_x64_at(data, base, x, y):
    """State of cell (x, y), 0..63, of the VQ4x64 map at byte ``base``: its block
    2*(y >> 5) + (x >> 5)."""
    return lookup_at(data, base + BLOCK_BYTES * (((y >> 5) << 1) | (x >> 5)), x & 31, y & 31)


@njit(cache=True)
def lookup_x64(data, x, y):
    """State of cell (x, y), 0..63, of a 256-byte VQ4x64 map."""
    return lookup_x64_at(data, 0, x, y)


@njit(cache=True)
def lookup_batch(blocks, block_ids, xs, ys):
    """``lookup`` for many cells: blocks (B, 64) uint8; block_ids, xs, ys of one length."""
    flat = blocks.reshape(-1)  # a row offset, not a row view per lookup
    out = np.empty(xs.shape[0], dtype=np.uint8)
    for i in range(xs.shape[0]):
        out[i] = lookup_at(flat, BLOCK_BYTES * block_ids[i], xs[i], ys[i])
    return out


@njit(cache=True)
def lookup_batch_x64(maps, map_ids, xs, ys):
    """``lookup_x64`` for many cells: maps (B, 256) uint8."""
    flat = maps.reshape(-1)
    out = np.empty(xs.shape[0], dtype=np.uint8)
    for i in range(xs.shape[0]):
        out[i] = lookup_x64_at(flat, X64_BYTES * map_ids[i], xs[i], ys[i])
    return out


@njit(cache=True)
def _decode_many(data, n, size):
    """Maps (n, size, size) of ``size`` x ``size`` cells each read by ``lookup_at`` (size 32) or
    ``lookup_x64_at`` (size 64) from consecutive rows of flat ``data``."""
    out = np.empty((n, size, size), dtype=np.uint8)
    nbytes = data.shape[0] // max(n, 1)
    for i in range(n):
        for y in range(size):
            for x in range(size):
                if size == SIZE:
                    out[i, y, x] = lookup_at(data, nbytes * i, x, y)
                else:
                    out[i, y, x] = lookup_x64_at(data, nbytes * i, x, y)
    return out


def _rows(blocks, nbytes, name):
    b = kernel_bytes(blocks)
    if b.ndim != 2 or b.shape[1] != nbytes:
        raise ValueError(f"{name} must be (n, {nbytes}) bytes, got shape {b.shape}")
    return b


def decode_many(blocks) -> np.ndarray:
    """Physical blocks (n, 64) uint8 -> their 32x32 maps (n, 32, 32): ``lookup`` of every cell,
    compiled (the same maps as ``decode`` of each)."""
    b = _rows(blocks, BLOCK_BYTES, "VQ4 blocks")
    return _decode_many(b.reshape(-1), len(b), SIZE)


def decode_many_x64(maps) -> np.ndarray:
    """VQ4x64 maps (n, 256) uint8 -> their 64x64 maps (n, 64, 64), as ``decode_x64`` of each."""
    b = _rows(maps, X64_BYTES, "VQ4x64 maps")
    return _decode_many(b.reshape(-1), len(b), X64_SIZE)
