"""VQ2: a 16x16 map in one 256-bit block -- physical layout, symbolic block, decoders.

The map is an 8x8 grid of 2x2 vectors (vector (vx, vy) holds cells x = 2vx..2vx+1,
y = 2vy..2vy+1 of ``map[y, x]``), in four quadrants of 4x4 vectors: q = 2*(vy >> 2) + (vx >> 2),
0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right.

Physical block (32 bytes, bits numbered as in ``bits.py``):

    bits   0..191  index of vector v = 8*vy + vx, 3 bits each, at bit 3v
    bits 192..246  codebook: 11 entries x 5 bits (``vec2`` codes), entry s at bit 192 + 5s;
                   entries 0..2 global, entries 3 + 2q + k local to quadrant q
    bits 247..255  transforms of quadrants 1, 2, 3 (3 bits each, at 247 + 3(q-1))

Index 0, 1, 2: uniform T, O, C (the state codes themselves); 3, 4, 5: global entries 0..2;
6, 7: the quadrant's local entries. Every 256-bit pattern is a valid block.

Many blocks at once (compiled, no block objects): ``pack_many`` (fields -> bytes),
``unpack_many`` (bytes -> fields) and ``decode_many`` (bytes -> maps). ``VQ2Block`` packs and
unpacks through them.

Example::

    >>> import numpy as np
    >>> idx = np.zeros((1, 64), np.int64); idx[0, 0] = 2  # vector 0 uniform C, the rest T
    >>> data = pack_many(idx, np.zeros((1, 11), np.int64), np.zeros((1, 4), np.int64))
    >>> data.shape, int(data[0, 0]), decode_many(data)[0, :2, :3].tolist()
    ((1, 32), 2, [[2, 2, 0], [2, 2, 0]])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import states
from . import bits
from .bits import as_block, kernel_bytes
from .vec2 import CODE_STATES, FWD2, INV2

BLOCK_BYTES = 32
SIZE = 16
INDEX_BITS, INDEX_POS = 3, 0
CODE_BITS, CODEBOOK_POS = 5, 192
N_GLOBAL, N_LOCAL, N_ENTRIES = 3, 2, 11
TRANSFORM_BITS, TRANSFORM_POS = 3, 247
# the block's fields in ``pack_many``'s order: 64 indices, 11 codebook entries, transforms of quadrants 1..3
FIELD_POS = np.concatenate([INDEX_POS + INDEX_BITS * np.arange(64), CODEBOOK_POS + CODE_BITS * np.arange(N_ENTRIES),
                            TRANSFORM_POS + TRANSFORM_BITS * np.arange(3)]).astype(np.int64)
FIELD_BITS = np.array([INDEX_BITS] * 64 + [CODE_BITS] * N_ENTRIES + [TRANSFORM_BITS] * 3, dtype=np.int64)


@njit(cache=True, inline="always")
def quadrant_of_vector(vx, vy):
    return 2 * (vy >> 2) + (vx >> 2)


@njit(cache=True, inline="always")
def entry_of_index(index, quadrant):
    """Codebook entry an index >= 3 selects in a quadrant."""
    return index - 3 if index < 6 else N_GLOBAL + N_LOCAL * quadrant + (index - 6)


@dataclass
class VQ2Block:
    """Symbolic block: ``indices`` (64,) in 0..7, ``codebook`` (11,) 5-bit codes,
    ``transforms`` (4,) with transforms[0] = 0 (the top-left quadrant is untransformed)."""

    indices: np.ndarray
    codebook: np.ndarray
    transforms: np.ndarray

    def __post_init__(self):
        self.indices = np.asarray(self.indices, dtype=np.uint8).reshape(64)
        self.codebook = np.asarray(self.codebook, dtype=np.uint8).reshape(N_ENTRIES)
        t = np.asarray(self.transforms, dtype=np.uint8).reshape(-1)
        self.transforms = np.concatenate([[0], t]).astype(np.uint8) if t.size == 3 else t
        if self.transforms.shape != (4,) or self.transforms[0] != 0:
            raise ValueError("transforms: 3 values (quadrants 1..3) or 4 with the first 0")
        if self.indices.max() > 7 or self.codebook.max() > 31 or self.transforms.max() > 7:
            raise ValueError("field out of range")

    def pack(self) -> bytes:
        """The physical block (32 bytes)."""
        return pack_many(self.indices[None], self.codebook[None], self.transforms[None])[0].tobytes()

    @classmethod
    def unpack(cls, data) -> "VQ2Block":
        idx, cb, tr = unpack_many(as_block(data, BLOCK_BYTES, "a VQ2 block")[None])
        return cls(idx[0], cb[0], tr[0])

    def decode(self) -> np.ndarray:
        """The 16x16 map (``map[y, x]``)."""
        out = np.empty((SIZE, SIZE), dtype=np.uint8)
        for vy in range(8):
            for vx in range(8):
                q = quadrant_of_vector(vx, vy)
                i = int(self.indices[8 * vy + vx])
                if i < 3:
                    vec = np.full(4, i, dtype=np.uint8)
                else:
                    stored = CODE_STATES[self.codebook[entry_of_index(i, q)]]
                    vec = np.empty(4, dtype=np.uint8)
                    vec[FWD2[self.transforms[q]]] = stored  # shown = t(stored)
                out[2 * vy:2 * vy + 2, 2 * vx:2 * vx + 2] = vec.reshape(2, 2)
        return out


def decode(data) -> np.ndarray:
    """Physical block (32 bytes) to its 16x16 map."""
    return VQ2Block.unpack(data).decode()


def pack_many(indices, codebook, transforms) -> np.ndarray:
    """Symbolic fields of n blocks -> their physical blocks (n, 32) uint8: ``indices`` (n, 64) in
    0..7, ``codebook`` (n, 11) 5-bit codes, ``transforms`` (n, 4) with column 0 all 0, or (n, 3)
    for quadrants 1..3. ValueError for a field out of range."""
    return bits.pack_block_fields(indices, codebook, transforms, FIELD_POS, FIELD_BITS, BLOCK_BYTES)


def unpack_many(blocks):
    """Physical blocks (n, 32) uint8 -> (indices (n, 64), codebook (n, 11), transforms (n, 4)), int64,
    transforms[:, 0] = 0."""
    return bits.unpack_block_fields(blocks, FIELD_POS, FIELD_BITS)


# _CODE_POS[i, q]: bit position of the codebook entry index i selects in quadrant q (i >= 3; rows
# 0..2 point at entry 0 so that the lookup needs no branch)
_CODE_POS = np.array([[CODEBOOK_POS + CODE_BITS * (entry_of_index(i, q) if i >= 3 else 0) for q in range(4)]
                      for i in range(8)], dtype=np.int64)


@njit(cache=True)
def lookup(block, x, y):
    """State of cell (x, y) (column, row) of a physical block, reading only the bits it needs:
    the vector's index, one codebook entry and the quadrant transform. Each field sits in a
    16-bit window of two bytes (the transforms in bytes 30-31). Written without branches on the
    index (a mispredicted branch costs more than the loads it would skip)."""
    p = 3 * (((y >> 1) << 3) | (x >> 1))
    b = p >> 3
    idx = ((np.int64(block[b]) | (np.int64(block[b + 1]) << 8)) >> (p & 7)) & 7
    q = quadrant_of_vector(x >> 1, y >> 1)
    p = _CODE_POS[idx, q]
    b = p >> 3
    code = ((np.int64(block[b]) | (np.int64(block[b + 1]) << 8)) >> (p & 7)) & 31
    tw = np.int64(block[30]) | (np.int64(block[31]) << 8)  # bits 240..255
    t = (tw >> (TRANSFORM_POS - 240 - TRANSFORM_BITS + TRANSFORM_BITS * q)) & 7 & -np.int64(q != 0)
    e = INV2[t, ((y & 1) << 1) | (x & 1)]  # the transform acts on the low coordinate bits
    c = (code >> (1 + e)) & 1
    pal = code & 1
    state = c * states.C + (1 - c) * (states.O * pal + states.T * (1 - pal))
    return idx if idx < 3 else state


@njit(cache=True)
def lookup_batch(blocks, block_ids, xs, ys):
    """``lookup`` for many cells: blocks (B, 32) uint8; block_ids, xs, ys of one length."""
    out = np.empty(xs.shape[0], dtype=np.uint8)
    for i in range(xs.shape[0]):
        out[i] = lookup(blocks[block_ids[i]], xs[i], ys[i])
    return out


@njit(cache=True)
def _decode_many(blocks):
    out = np.empty((blocks.shape[0], SIZE, SIZE), dtype=np.uint8)
    for i in range(blocks.shape[0]):
        for y in range(SIZE):
            for x in range(SIZE):
                out[i, y, x] = lookup(blocks[i], x, y)
    return out


def decode_many(blocks) -> np.ndarray:
    """Physical blocks (n, 32) uint8 -> their 16x16 maps (n, 16, 16): ``lookup`` of every cell,
    compiled (the same maps as ``decode`` of each)."""
    b = kernel_bytes(blocks)
    if b.ndim != 2 or b.shape[1] != BLOCK_BYTES:
        raise ValueError(f"VQ2 blocks must be (n, {BLOCK_BYTES}) bytes, got shape {b.shape}")
    return _decode_many(b)
