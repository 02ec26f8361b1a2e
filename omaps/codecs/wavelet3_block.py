"""wavelet3: a 64x64 map in one 512-bit block as a three-level hierarchy -- physical layout,
symbolic block, decoder and random-access lookup.

A Haar-like decomposition on the three-state lattice: a node is T or O when all its cells are,
C when it keeps nothing worth its bits, and R (*refine*) otherwise; only R nodes carry detail.
An R block of level 1 refines either at 64x64 (its four 4x4-cell children, then the mixed
children through the codebook) or, when that costs more than it keeps, at 32x32 in one step
(one codebook vector whose elements are 2x2 cells):

    level 1  8x8 blocks of 8x8 map cells: 2 bits each (0 T, 1 O, 2 C, 3 R)
    mode     one bit per R block: 0 refine at 64x64, 1 at 32x32
    level 2  mode 0: the block's 2x2 children of 4x4 cells, 2 bits each (T, O, C, R);
             mode 1: a codebook index, the vector's element (ex, ey) covering the block's
             cells 2ex..2ex+1, 2ey..2ey+1
    level 3  each R child: a codebook index, element (ex, ey) one cell
    codebook E 4x4 vectors (``vec4`` general entries, 20 bits), shared by both uses; an index
             is w = bit_length(E) bits (0 for E = 0, 4 for E = 8..15); an index >= E is uniform C

Physical block (64 bytes, bits numbered as in ``bits.py``)::

    bits   0..127  level 1: block c = 8*cy + cx at bit 2c
    bits 128..131  E, the number of codebook entries (0..15)
    bits 132..140  transforms of the 32x32 quadrants 1, 2, 3 (3 bits each, as VQ4's): an entry
                   shown in quadrant q is t_q(entry), quadrant 0 untransformed
    bits 141..     mode bits: the r-th R block of level 1 (raster order) at 141 + r
    F = 141 + m1   (m1 R blocks) level-2 children fields of the mode-0 blocks, 8 bits each: the
                   z-th at F + 8z, child k = 2*ky + kx at bit 2k of it
    F + 8*Z        (Z mode-0 blocks) level-2 indices of the mode-1 blocks, w bits each
    then           level 3: the j-th R child (in the order of the children fields), w bits each
    end            codebook: entry i at bit 512 - 20(i + 1)

Every field must end at or before the codebook (bit 512 - 20E); a node whose field does not is
uniform C. So every 512-bit pattern is a valid block, and a lookup reads the level-1 code, one
mode bit, ranks over the codes before it, at most two fields and one entry element.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import states
from .bits import as_block, get_bits, put_bits
from .vec4 import CFLAG_BIT, FWD4, GENERAL, INV4, PALETTE_BIT, entry_pattern, pattern_states

__all__ = ["Wavelet3Block", "decode", "lookup", "lookup_at", "BLOCK_BYTES", "SIZE", "MAX_ENTRIES", "R"]

BLOCK_BYTES = 64
SIZE = 64
BLOCK_BITS = 8 * BLOCK_BYTES
R = 3  # the refine code of levels 1 and 2
E_POS, E_BITS = 128, 4
T_POS, T_BITS = 132, 3  # transforms of the 32x32 quadrants 1, 2, 3
MODE_POS = 141
CHILD_BITS, ENTRY_BITS = 8, 20
MAX_ENTRIES = 15

_CF = CFLAG_BIT[GENERAL].copy()
_PAL = PALETTE_BIT[GENERAL].copy()
# number of 2-bit fields equal to R in a byte
_R_IN_BYTE = np.array([sum(((b >> (2 * i)) & 3) == R for i in range(4)) for b in range(256)], dtype=np.int64)
_ONES_IN_BYTE = np.array([bin(b).count("1") for b in range(256)], dtype=np.int64)


@njit(cache=True, inline="always")
def _count_r(blk, pos, n):
    """Number of R codes among the n 2-bit fields from bit ``pos``."""
    c = 0
    while n >= 4:
        c += _R_IN_BYTE[get_bits(blk, pos, 8)]
        pos += 8
        n -= 4
    if n > 0:
        c += _R_IN_BYTE[get_bits(blk, pos, 2 * n)]  # the missing high fields read as 0 (not R)
    return c


@njit(cache=True, inline="always")
def _count_ones(blk, pos, n):
    """Number of set bits among the n bits from bit ``pos``."""
    c = 0
    while n >= 8:
        c += _ONES_IN_BYTE[get_bits(blk, pos, 8)]
        pos += 8
        n -= 8
    if n > 0:
        c += _ONES_IN_BYTE[get_bits(blk, pos, n)]
    return c


@njit(cache=True, inline="always")
def index_bits(n_e):
    """Width of a codebook index with E entries: just enough for 0..E (E itself reads as C)."""
    w = 0
    while (1 << w) <= n_e:
        w += 1
    return w


@njit(cache=True, inline="always")
def _element(blk, i, n_e, e, x, y):
    """State of shown element e of codebook index i (uniform C for i >= E) at cell (x, y): the
    entry's stored element under the inverse of the cell's quadrant transform."""
    if i >= n_e:
        return states.C
    q = ((y >> 5) << 1) | (x >> 5)
    if q != 0:
        e = INV4[get_bits(blk, T_POS + T_BITS * (q - 1), T_BITS), e]
    pos = BLOCK_BITS - ENTRY_BITS * (i + 1)
    if get_bits(blk, pos + _CF[e], 1):
        return states.C
    return get_bits(blk, pos + _PAL[e], 1)


@njit(cache=True)
def lookup_at(data, base, x, y):
    """State of cell (x, y), 0..63, of the block at byte ``base`` of ``data``."""
    blk = data[base:base + BLOCK_BYTES]
    c = ((y >> 3) << 3) | (x >> 3)
    s = get_bits(blk, 2 * c, 2)
    if s != R:
        return s
    n_e = get_bits(blk, E_POS, E_BITS)
    w = index_bits(n_e)
    limit = BLOCK_BITS - ENTRY_BITS * n_e
    r = _count_r(blk, 0, c)
    m1 = _count_r(blk, 0, 64)
    if MODE_POS + r + 1 > limit:
        return states.C
    ones = _count_ones(blk, MODE_POS, r)  # mode-1 blocks before this one
    n_ones = _count_ones(blk, MODE_POS, min(m1, limit - MODE_POS))  # mode bits past the limit read as 0
    z_all = m1 - n_ones
    f0 = MODE_POS + m1
    if get_bits(blk, MODE_POS + r, 1):  # 32x32: one index, elements of 2x2 cells
        p = f0 + CHILD_BITS * z_all + w * ones
        if p + w > limit:
            return states.C
        return _element(blk, get_bits(blk, p, w), n_e, (((y & 7) >> 1) << 2) | ((x & 7) >> 1), x, y)
    z = r - ones
    p2 = f0 + CHILD_BITS * z
    if p2 + CHILD_BITS > limit:
        return states.C
    k = (((y >> 2) & 1) << 1) | ((x >> 2) & 1)
    s = get_bits(blk, p2 + 2 * k, 2)
    if s != R:
        return s
    j = _count_r(blk, f0, 4 * z + k)
    p3 = f0 + CHILD_BITS * z_all + w * n_ones + w * j
    if p3 + w > limit:
        return states.C
    return _element(blk, get_bits(blk, p3, w), n_e, ((y & 3) << 2) | (x & 3), x, y)


@njit(cache=True)
def lookup(block, x, y):
    """``lookup_at`` of a single 64-byte block, x and y in 0..63."""
    return lookup_at(block, 0, x, y)


@dataclass
class Wavelet3Block:
    """Symbolic block: ``level1`` (64,) codes 0..3; ``mode`` (m1,) 0/1 per R block of level 1 in
    raster order; ``children`` (Z, 4) child codes of the mode-0 blocks in order; ``coarse`` (m1 - Z,)
    codebook indices of the mode-1 blocks in order; ``fine`` (m2,) codebook indices of the R
    children in order; ``entries`` (E,) general entry codes; ``transforms`` (4,) of the 32x32
    quadrants, transforms[0] = 0 (or 3 values, quadrants 1..3). ``pack`` requires that
    everything fits."""

    level1: np.ndarray
    mode: np.ndarray
    children: np.ndarray
    coarse: np.ndarray
    fine: np.ndarray
    entries: np.ndarray
    transforms: np.ndarray = None

    def __post_init__(self):
        t = np.zeros(4, np.uint8) if self.transforms is None else np.asarray(self.transforms, np.uint8).reshape(-1)
        self.transforms = np.concatenate([[0], t]).astype(np.uint8) if t.size == 3 else t
        if self.transforms.shape != (4,) or self.transforms[0] != 0 or self.transforms.max() > 7:
            raise ValueError("transforms: 3 values (quadrants 1..3) or 4 with the first 0, each 0..7")
        self.level1 = np.asarray(self.level1, dtype=np.uint8).reshape(64)
        self.mode = np.asarray(self.mode, dtype=np.uint8).reshape(-1)
        self.children = np.asarray(self.children, dtype=np.uint8).reshape(-1, 4)
        self.coarse = np.asarray(self.coarse, dtype=np.uint8).reshape(-1)
        self.fine = np.asarray(self.fine, dtype=np.uint8).reshape(-1)
        self.entries = np.asarray(self.entries, dtype=np.int64).reshape(-1)
        m1, z = int((self.level1 == R).sum()), int((self.mode == 0).sum())
        if len(self.mode) != m1 or len(self.children) != z or len(self.coarse) != m1 - z \
                or len(self.fine) != int((self.children == R).sum()):
            raise ValueError("a mode per R block; children rows for mode 0, an index for mode 1; an index per R child")
        if self.level1.max() > 3 or self.mode.max(initial=0) > 1 or self.children.max(initial=0) > 3 \
                or self.coarse.max(initial=0) > 15 or self.fine.max(initial=0) > 15 \
                or len(self.entries) > MAX_ENTRIES or np.any(self.entries < 0) \
                or np.any(self.entries >= 1 << ENTRY_BITS):
            raise ValueError("field out of range")
        if self.bits > BLOCK_BITS:
            raise ValueError(f"the fields need {self.bits} bits, more than {BLOCK_BITS}")

    @property
    def bits(self) -> int:
        w = len(self.entries).bit_length()
        return (MODE_POS + len(self.mode) + CHILD_BITS * len(self.children) + w * len(self.coarse)
                + w * len(self.fine) + ENTRY_BITS * len(self.entries))

    def pack(self) -> bytes:
        b = np.zeros(BLOCK_BYTES, dtype=np.uint8)
        for c in range(64):
            put_bits(b, 2 * c, 2, int(self.level1[c]))
        put_bits(b, E_POS, E_BITS, len(self.entries))
        for q in range(1, 4):
            put_bits(b, T_POS + T_BITS * (q - 1), T_BITS, int(self.transforms[q]))
        pos = MODE_POS
        for v in self.mode:
            put_bits(b, pos, 1, int(v))
            pos += 1
        for row in self.children:
            put_bits(b, pos, CHILD_BITS, int(sum(int(v) << (2 * k) for k, v in enumerate(row))))
            pos += CHILD_BITS
        w = len(self.entries).bit_length()
        for i in list(self.coarse) + list(self.fine):
            if w:
                put_bits(b, pos, w, int(i))
            pos += w
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
        if MODE_POS + m1 > BLOCK_BITS - ENTRY_BITS * n_e:
            raise ValueError("the fields of this block do not all fit (it decodes with C in their place)")
        mode = np.array([get_bits(b, MODE_POS + r, 1) for r in range(m1)], dtype=np.int64)
        z = int((mode == 0).sum())
        pos = MODE_POS + m1
        ch = np.array([[get_bits(b, pos + CHILD_BITS * i + 2 * k, 2) for k in range(4)] for i in range(z)],
                      dtype=np.int64).reshape(-1, 4)
        pos += CHILD_BITS * z
        n_idx = (m1 - z) + int((ch == R).sum())
        w = n_e.bit_length()
        if pos + w * n_idx + ENTRY_BITS * n_e > BLOCK_BITS:
            raise ValueError("the fields of this block do not all fit (it decodes with C in their place)")
        idx = [get_bits(b, pos + w * i, w) if w else 0 for i in range(n_idx)]
        ent = np.array([get_bits(b, BLOCK_BITS - ENTRY_BITS * (i + 1), ENTRY_BITS) for i in range(n_e)], dtype=np.int64)
        tr = [get_bits(b, T_POS + T_BITS * (q - 1), T_BITS) for q in range(1, 4)]
        return cls(l1, mode, ch, np.array(idx[:m1 - z], dtype=np.int64), np.array(idx[m1 - z:], dtype=np.int64), ent,
                   np.array(tr))


def decode(data) -> np.ndarray:
    """Any 64 bytes to their 64x64 map (``map[y, x]``), level by level."""
    b = as_block(data, BLOCK_BYTES, "a wavelet3 block")
    n_e = int(get_bits(b, E_POS, E_BITS))
    w = n_e.bit_length()
    limit = BLOCK_BITS - ENTRY_BITS * n_e
    vec = [pattern_states(*entry_pattern(GENERAL, get_bits(b, BLOCK_BITS - ENTRY_BITS * (i + 1), ENTRY_BITS)))
           for i in range(n_e)]

    tr = [0] + [int(get_bits(b, T_POS + T_BITS * (q - 1), T_BITS)) for q in range(1, 4)]

    def vector(pos, c):  # shown 4x4 states of the index at ``pos`` in block c; C if it does not fit or is >= E
        i = int(get_bits(b, pos, w)) if w and pos + w <= limit else MAX_ENTRIES
        if i >= n_e:
            return np.full((4, 4), states.C, np.uint8)
        shown = np.empty(16, np.uint8)
        shown[FWD4[tr[2 * ((c >> 3) >> 2) + ((c & 7) >> 2)]]] = vec[i].reshape(16)
        return shown.reshape(4, 4)

    l1 = [int(get_bits(b, 2 * c, 2)) for c in range(64)]
    m1 = l1.count(R)
    mode = [int(get_bits(b, MODE_POS + r, 1)) if MODE_POS + r < limit else 0 for r in range(m1)]
    z_all = mode.count(0)
    f0 = MODE_POS + m1
    p_coarse = f0 + CHILD_BITS * z_all
    p_fine = p_coarse + w * (m1 - z_all)
    out = np.empty((SIZE, SIZE), dtype=np.uint8)
    r = z = j = 0
    for c in range(64):
        y0, x0 = 8 * (c >> 3), 8 * (c & 7)
        if l1[c] != R:
            out[y0:y0 + 8, x0:x0 + 8] = l1[c]
            continue
        if MODE_POS + r + 1 > limit:
            out[y0:y0 + 8, x0:x0 + 8] = states.C
        elif mode[r]:
            out[y0:y0 + 8, x0:x0 + 8] = np.kron(vector(p_coarse + w * (r - z), c), np.ones((2, 2), np.uint8))
        else:
            p2 = f0 + CHILD_BITS * z
            z += 1
            for k in range(4):
                y1, x1 = y0 + 4 * (k >> 1), x0 + 4 * (k & 1)
                s = int(get_bits(b, p2 + 2 * k, 2)) if p2 + CHILD_BITS <= limit else states.C
                if s == R:
                    out[y1:y1 + 4, x1:x1 + 4] = vector(p_fine + w * j, c)
                    j += 1
                else:
                    out[y1:y1 + 4, x1:x1 + 4] = s
        r += 1
    return out
