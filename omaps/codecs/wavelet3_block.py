"""wavelet3: a 64x64 map in one 512-bit block as a three-level hierarchy -- physical layout,
symbolic block, decoder and random-access lookup.

A Haar-like decomposition on the three-state lattice: a parent is T or O when all its cells are,
C when it keeps nothing worth its bits, and R (*refine*) otherwise; only R nodes carry detail.

    level 1  8x8 cells of 8x8 map cells: 2 bits each (0 T, 1 O, 2 C, 3 R)
    level 2  each R cell of level 1: its 2x2 children of 4x4 map cells, 2 bits each (T, O, C, R)
    level 3  each R child of level 2: a 4-bit index into a per-block codebook of E 4x4 vectors
             (``vec4`` general entries, 20 bits); an index >= E is uniform C

Physical block (64 bytes, bits numbered as in ``bits.py``)::

    bits   0..127  level 1: cell c = 8*cy + cx at bit 2c
    bits 128..131  E, the number of codebook entries (0..15)
    bits 132..     level 2: the r-th R cell of level 1 (raster order) at 132 + 8r, child
                   k = 2*ky + kx at bit 2k of it
    then           level 3: from 132 + 8*m1 (m1 = R cells in level 1), the j-th R child (in the
                   order of level 2) at 4 bits each
    end            codebook: entry i at bit 512 - 20(i + 1)

Every field must end at or before the codebook (bit 512 - 20E); a node whose field does not is
uniform C. So every 512-bit pattern is a valid block, and a lookup reads at most the two level
fields, a rank over them, one index and one entry element.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import states
from .bits import as_block, get_bits, put_bits
from .vec4 import CFLAG_BIT, GENERAL, PALETTE_BIT, entry_pattern, pattern_states

__all__ = ["Wavelet3Block", "decode", "lookup", "lookup_at", "BLOCK_BYTES", "SIZE", "MAX_ENTRIES", "R"]

BLOCK_BYTES = 64
SIZE = 64
BLOCK_BITS = 8 * BLOCK_BYTES
R = 3  # the refine code of levels 1 and 2
E_POS, E_BITS = 128, 4
L2_POS = 132
L2_BITS, L3_BITS, ENTRY_BITS = 8, 4, 20
MAX_ENTRIES = 15

_CF = CFLAG_BIT[GENERAL].copy()
_PAL = PALETTE_BIT[GENERAL].copy()
# number of 2-bit fields equal to R in a byte
_R_IN_BYTE = np.array([sum(((b >> (2 * i)) & 3) == R for i in range(4)) for b in range(256)], dtype=np.int64)


@njit(cache=True, inline="always")
def _count_r(blk, pos, n):
    """Number of R codes among the n 2-bit fields from bit ``pos`` (pos even)."""
    c = 0
    while n >= 4:
        c += _R_IN_BYTE[get_bits(blk, pos, 8)]
        pos += 8
        n -= 4
    if n > 0:
        c += _R_IN_BYTE[get_bits(blk, pos, 2 * n)]  # the missing high fields read as 0 (not R)
    return c


@njit(cache=True)
def lookup_at(data, base, x, y):
    """State of cell (x, y), 0..63, of the block at byte ``base`` of ``data``."""
    blk = data[base:base + BLOCK_BYTES]
    c = ((y >> 3) << 3) | (x >> 3)
    s = get_bits(blk, 2 * c, 2)
    if s != R:
        return s
    n_e = get_bits(blk, E_POS, E_BITS)
    limit = BLOCK_BITS - ENTRY_BITS * n_e
    r = _count_r(blk, 0, c)
    p2 = L2_POS + L2_BITS * r
    if p2 + L2_BITS > limit:
        return states.C
    k = (((y >> 2) & 1) << 1) | ((x >> 2) & 1)
    s = get_bits(blk, p2 + 2 * k, 2)
    if s != R:
        return s
    m1 = _count_r(blk, 0, 64)
    j = _count_r(blk, L2_POS, 4 * r + k)
    p3 = L2_POS + L2_BITS * m1 + L3_BITS * j
    if p3 + L3_BITS > limit:
        return states.C
    i = get_bits(blk, p3, L3_BITS)
    if i >= n_e:
        return states.C
    pos = BLOCK_BITS - ENTRY_BITS * (i + 1)
    e = ((y & 3) << 2) | (x & 3)
    if get_bits(blk, pos + _CF[e], 1):
        return states.C
    return get_bits(blk, pos + _PAL[e], 1)


@njit(cache=True)
def lookup(block, x, y):
    """``lookup_at`` of a single 64-byte block, x and y in 0..63."""
    return lookup_at(block, 0, x, y)


@dataclass
class Wavelet3Block:
    """Symbolic block: ``level1`` (64,) codes 0..3; ``level2`` (m1, 4) child codes of the R cells
    of level 1 in raster order; ``level3`` (m2,) codebook indices of the R children of level 2 in
    order; ``entries`` (E,) general entry codes. ``pack`` requires that everything fits."""

    level1: np.ndarray
    level2: np.ndarray
    level3: np.ndarray
    entries: np.ndarray

    def __post_init__(self):
        self.level1 = np.asarray(self.level1, dtype=np.uint8).reshape(64)
        self.level2 = np.asarray(self.level2, dtype=np.uint8).reshape(-1, 4)
        self.level3 = np.asarray(self.level3, dtype=np.uint8).reshape(-1)
        self.entries = np.asarray(self.entries, dtype=np.int64).reshape(-1)
        if len(self.level2) != int((self.level1 == R).sum()) or len(self.level3) != int((self.level2 == R).sum()):
            raise ValueError("one level-2 row per R cell of level 1, one level-3 index per R child")
        if self.level1.max() > 3 or self.level2.max(initial=0) > 3 or self.level3.max(initial=0) > 15 \
                or len(self.entries) > MAX_ENTRIES or np.any(self.entries < 0) \
                or np.any(self.entries >= 1 << ENTRY_BITS):
            raise ValueError("field out of range")
        if self.bits > BLOCK_BITS:
            raise ValueError(f"the fields need {self.bits} bits, more than {BLOCK_BITS}")

    @property
    def bits(self) -> int:
        return L2_POS + L2_BITS * len(self.level2) + L3_BITS * len(self.level3) + ENTRY_BITS * len(self.entries)

    def pack(self) -> bytes:
        b = np.zeros(BLOCK_BYTES, dtype=np.uint8)
        for c in range(64):
            put_bits(b, 2 * c, 2, int(self.level1[c]))
        put_bits(b, E_POS, E_BITS, len(self.entries))
        for r, row in enumerate(self.level2):
            put_bits(b, L2_POS + L2_BITS * r, L2_BITS, int(sum(int(v) << (2 * k) for k, v in enumerate(row))))
        p3 = L2_POS + L2_BITS * len(self.level2)
        for j, i in enumerate(self.level3):
            put_bits(b, p3 + L3_BITS * j, L3_BITS, int(i))
        for i, e in enumerate(self.entries):
            put_bits(b, BLOCK_BITS - ENTRY_BITS * (i + 1), ENTRY_BITS, int(e))
        return b.tobytes()

    @classmethod
    def unpack(cls, data) -> "Wavelet3Block":
        """The fields of a block whose fields all fit (as ``pack`` writes); ValueError otherwise
        (such a block still decodes: ``decode``)."""
        b = as_block(data, BLOCK_BYTES, "a wavelet3 block")
        l1 = np.array([get_bits(b, 2 * c, 2) for c in range(64)])
        n_e = int(get_bits(b, E_POS, E_BITS))
        m1 = int((l1 == R).sum())
        l2 = np.array([[get_bits(b, L2_POS + L2_BITS * r + 2 * k, 2) for k in range(4)] for r in range(m1)],
                      dtype=np.int64).reshape(-1, 4)
        p3 = L2_POS + L2_BITS * m1
        m2 = int((l2 == R).sum())
        if p3 + L3_BITS * m2 + ENTRY_BITS * n_e > BLOCK_BITS:
            raise ValueError("the fields of this block do not all fit (it decodes with C in their place)")
        l3 = np.array([get_bits(b, p3 + L3_BITS * j, L3_BITS) for j in range(m2)], dtype=np.int64)
        ent = np.array([get_bits(b, BLOCK_BITS - ENTRY_BITS * (i + 1), ENTRY_BITS) for i in range(n_e)], dtype=np.int64)
        return cls(l1, l2, l3, ent)


def decode(data) -> np.ndarray:
    """Any 64 bytes to their 64x64 map (``map[y, x]``), level by level."""
    b = as_block(data, BLOCK_BYTES, "a wavelet3 block")
    n_e = int(get_bits(b, E_POS, E_BITS))
    limit = BLOCK_BITS - ENTRY_BITS * n_e
    vec = [pattern_states(*entry_pattern(GENERAL, get_bits(b, BLOCK_BITS - ENTRY_BITS * (i + 1), ENTRY_BITS)))
           for i in range(n_e)]
    l1 = [int(get_bits(b, 2 * c, 2)) for c in range(64)]
    m1 = l1.count(R)
    out = np.empty((SIZE, SIZE), dtype=np.uint8)
    r = j = 0
    p3 = L2_POS + L2_BITS * m1
    for c in range(64):
        y0, x0 = 8 * (c >> 3), 8 * (c & 7)
        if l1[c] != R:
            out[y0:y0 + 8, x0:x0 + 8] = l1[c]
            continue
        p2 = L2_POS + L2_BITS * r
        r += 1
        if p2 + L2_BITS > limit:
            out[y0:y0 + 8, x0:x0 + 8] = states.C
            continue
        for k in range(4):
            y1, x1 = y0 + 4 * (k >> 1), x0 + 4 * (k & 1)
            s = int(get_bits(b, p2 + 2 * k, 2))
            if s != R:
                out[y1:y1 + 4, x1:x1 + 4] = s
                continue
            p = p3 + L3_BITS * j
            j += 1
            i = int(get_bits(b, p, L3_BITS)) if p + L3_BITS <= limit else MAX_ENTRIES
            out[y1:y1 + 4, x1:x1 + 4] = vec[i] if i < n_e else states.C
    return out
