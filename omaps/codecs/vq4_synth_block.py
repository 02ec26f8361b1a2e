"""VQ4-synth: a 32x32 map in one 512-bit block whose codebook *synthesises* vectors from the
stored ones -- physical layout, symbolic block, decoder and random-access lookup.

The deck's VQ4 spends index values 0..2 on implicit uniform T, O and C and 13 on stored entries
(247 bits). Uniform C is rare at 32x32 (it is mostly the encoder's fallback), and a leaf's edges
appear in every orientation inside one quadrant, which one transform per quadrant cannot align.
VQ4-synth keeps VQ4's indices and quadrant transforms but gives index values 2..15 to 14
*slots*: the first ``k`` are explicit 20-bit general entries (``vec4`` kind 3), the others are
8-bit *derived* slots that show an explicit entry under any of the 8 symmetries, optionally with
T and O swapped (16 variants of each stored vector for 8 bits). Uniform C is a derived slot like
any other (one whose source is not an explicit entry), so it costs a slot only when a map needs
it.

Physical block (64 bytes, bits numbered as in ``bits.py``)::

    bits   0..255  index of vector v = 8*vy + vx, 4 bits each, at bit 4v (as VQ4):
                   0 uniform T, 1 uniform O, i >= 2: slot i - 2
    bits 256..259  k, the number of explicit slots
    bits 260..502  the 14 slots: slot s < k explicit (20 bits at 260 + 20s), slot s >= k derived
                   (8 bits at 260 + 20k + 8(s - k)): bits 0..3 source a, bits 4..6 transform u,
                   bit 7 swap T and O
    bits 503..511  transforms of quadrants 1, 2, 3 (3 bits each, as VQ4)

A slot's vector: explicit -- its general entry; derived -- u(entry a), T and O swapped if the bit
is set, where a must be an explicit slot (a < k); a slot whose field would run past bit 503, or a
derived slot whose source is not an explicit slot that fits, is uniform C. So every 512-bit
pattern is a valid block (k <= 10 fits all 14 slots; the encoder keeps to that). A vector shows
its slot's vector through its quadrant's transform, as in VQ4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import states
from .bits import as_block, get_bits, put_bits
from .vec4 import CFLAG_BIT, FWD4, GENERAL, INV4, PALETTE_BIT, entry_pattern, pattern_states, transform_mask
from .vq4_block import SIZE, TRANSFORM_BITS, TRANSFORM_POS

__all__ = ["VQ4SynthBlock", "decode", "lookup", "lookup_at", "slot_pattern", "BLOCK_BYTES", "SIZE", "N_SLOTS",
           "MAX_EXPLICIT"]

BLOCK_BYTES = 64
INDEX_BITS = 4
K_POS, K_BITS = 256, 4
SLOT_POS = 260
EXPLICIT_BITS, DERIVED_BITS = 20, 8
N_SLOTS = 14
AREA_END = TRANSFORM_POS  # 503
MAX_EXPLICIT = (AREA_END - SLOT_POS - DERIVED_BITS * N_SLOTS) // (EXPLICIT_BITS - DERIVED_BITS)  # 10
NO_SOURCE = 15  # a derived slot with this source is uniform C whatever k is
assert SLOT_POS + EXPLICIT_BITS * MAX_EXPLICIT + DERIVED_BITS * (N_SLOTS - MAX_EXPLICIT) <= AREA_END

_CF = CFLAG_BIT[GENERAL].copy()
_PAL = PALETTE_BIT[GENERAL].copy()


@njit(cache=True, inline="always")
def _slot_field(k, s):
    """(position, explicit) of slot s when k slots are explicit; position -1 if it does not fit."""
    if s < k:
        pos = SLOT_POS + EXPLICIT_BITS * s
        return (pos if pos + EXPLICIT_BITS <= AREA_END else -1), True
    pos = SLOT_POS + EXPLICIT_BITS * k + DERIVED_BITS * (s - k)
    return (pos if pos + DERIVED_BITS <= AREA_END else -1), False


@njit(cache=True)
def slot_pattern(block, s):
    """(kt, ko) known-T / known-O masks of slot s's stored vector (before the quadrant transform)."""
    k = get_bits(block, K_POS, K_BITS)
    pos, explicit = _slot_field(k, s)
    if pos < 0:
        return 0, 0
    if explicit:
        return entry_pattern(GENERAL, get_bits(block, pos, EXPLICIT_BITS))
    d = get_bits(block, pos, DERIVED_BITS)
    a, u, swap = d & 15, (d >> 4) & 7, d >> 7
    apos, aexp = _slot_field(k, a)
    if not aexp or apos < 0:
        return 0, 0
    kt, ko = entry_pattern(GENERAL, get_bits(block, apos, EXPLICIT_BITS))
    kt, ko = transform_mask(kt, u), transform_mask(ko, u)
    return (ko, kt) if swap else (kt, ko)


@dataclass
class VQ4SynthBlock:
    """Symbolic block: ``indices`` (64,) in 0..15, ``k`` explicit slots, ``explicit`` (k,) general
    entry codes, ``derived`` (14 - k, 3) rows (source, transform, swap), ``transforms`` (4,) with
    transforms[0] = 0."""

    indices: np.ndarray
    k: int
    explicit: np.ndarray
    derived: np.ndarray
    transforms: np.ndarray

    def __post_init__(self):
        self.indices = np.asarray(self.indices, dtype=np.uint8).reshape(64)
        self.k = int(self.k)
        self.explicit = np.asarray(self.explicit, dtype=np.int64).reshape(-1)
        self.derived = np.asarray(self.derived, dtype=np.int64).reshape(-1, 3)
        t = np.asarray(self.transforms, dtype=np.uint8).reshape(-1)
        self.transforms = np.concatenate([[0], t]).astype(np.uint8) if t.size == 3 else t
        if not 0 <= self.k <= MAX_EXPLICIT or self.explicit.shape != (self.k,) \
                or self.derived.shape != (N_SLOTS - self.k, 3):
            raise ValueError(f"k explicit slots (0..{MAX_EXPLICIT}), k entries and 14 - k derived rows")
        if self.transforms.shape != (4,) or self.transforms[0] != 0:
            raise ValueError("transforms: 3 values (quadrants 1..3) or 4 with the first 0")
        if self.indices.max() > 15 or self.transforms.max() > 7 or np.any(self.explicit < 0) \
                or np.any(self.explicit >= 1 << EXPLICIT_BITS) or np.any(self.derived < 0) \
                or np.any(self.derived[:, 0] > 15) or np.any(self.derived[:, 1] > 7) or np.any(self.derived[:, 2] > 1):
            raise ValueError("field out of range")

    def pack(self) -> bytes:
        b = np.zeros(BLOCK_BYTES, dtype=np.uint8)
        for v in range(64):
            put_bits(b, INDEX_BITS * v, INDEX_BITS, int(self.indices[v]))
        put_bits(b, K_POS, K_BITS, self.k)
        for s in range(self.k):
            put_bits(b, SLOT_POS + EXPLICIT_BITS * s, EXPLICIT_BITS, int(self.explicit[s]))
        for s in range(self.k, N_SLOTS):
            a, u, w = (int(x) for x in self.derived[s - self.k])
            put_bits(b, SLOT_POS + EXPLICIT_BITS * self.k + DERIVED_BITS * (s - self.k), DERIVED_BITS,
                     a | (u << 4) | (w << 7))
        for q in range(1, 4):
            put_bits(b, TRANSFORM_POS + TRANSFORM_BITS * (q - 1), TRANSFORM_BITS, int(self.transforms[q]))
        return b.tobytes()

    @classmethod
    def unpack(cls, data) -> "VQ4SynthBlock":
        """The fields of a block written by ``pack`` (k <= 10); ValueError for a larger k, whose
        block still decodes (``decode``)."""
        b = as_block(data, BLOCK_BYTES, "a VQ4-synth block")
        k = int(get_bits(b, K_POS, K_BITS))
        if k > MAX_EXPLICIT:
            raise ValueError(f"k = {k} explicit slots (a packed block has at most {MAX_EXPLICIT})")
        idx = [get_bits(b, INDEX_BITS * v, INDEX_BITS) for v in range(64)]
        ex = [get_bits(b, SLOT_POS + EXPLICIT_BITS * s, EXPLICIT_BITS) for s in range(k)]
        der = []
        for s in range(k, N_SLOTS):
            d = int(get_bits(b, SLOT_POS + EXPLICIT_BITS * k + DERIVED_BITS * (s - k), DERIVED_BITS))
            der.append((d & 15, (d >> 4) & 7, d >> 7))
        tr = [get_bits(b, TRANSFORM_POS + TRANSFORM_BITS * (q - 1), TRANSFORM_BITS) for q in range(1, 4)]
        return cls(np.array(idx), k, np.array(ex, dtype=np.int64), np.array(der, dtype=np.int64).reshape(-1, 3),
                   np.array(tr))


def decode(data) -> np.ndarray:
    """Any 64 bytes to their 32x32 map (``map[y, x]``)."""
    b = as_block(data, BLOCK_BYTES, "a VQ4-synth block")
    vec = np.empty((16, 16), dtype=np.uint8)  # stored 4x4 states (flattened) of each index value
    vec[0], vec[1] = states.T, states.O
    for s in range(N_SLOTS):
        vec[2 + s] = pattern_states(*slot_pattern(b, s)).reshape(16)
    tr = [0] + [int(get_bits(b, TRANSFORM_POS + TRANSFORM_BITS * (q - 1), TRANSFORM_BITS)) for q in range(1, 4)]
    out = np.empty((SIZE, SIZE), dtype=np.uint8)
    for v in range(64):
        vy, vx = v >> 3, v & 7
        shown = np.empty(16, dtype=np.uint8)
        shown[FWD4[tr[2 * (vy >> 2) + (vx >> 2)]]] = vec[int(get_bits(b, INDEX_BITS * v, INDEX_BITS))]
        out[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = shown.reshape(4, 4)
    return out


@njit(cache=True)
def lookup_at(data, base, x, y):
    """State of cell (x, y) of the block at byte ``base`` of ``data``: the vector's index, the
    quadrant's transform, and one element of one explicit entry (through a derived slot's
    transform and swap when the slot is derived)."""
    v = ((y >> 2) << 3) | (x >> 2)
    idx = (np.int64(data[base + (v >> 1)]) >> ((v & 1) << 2)) & 15
    if idx < 2:
        return idx
    q = ((y >> 4) << 1) | (x >> 4)
    t = 0
    if q != 0:
        t = get_bits(data[base:base + BLOCK_BYTES], TRANSFORM_POS + TRANSFORM_BITS * (q - 1), TRANSFORM_BITS)
    e = INV4[t, ((y & 3) << 2) | (x & 3)]  # stored element of the slot's vector
    blk = data[base:base + BLOCK_BYTES]
    k = get_bits(blk, K_POS, K_BITS)
    pos, explicit = _slot_field(k, idx - 2)
    if pos < 0:
        return states.C
    swap = 0
    if not explicit:
        d = get_bits(blk, pos, DERIVED_BITS)
        pos, explicit = _slot_field(k, d & 15)
        if not explicit or pos < 0:
            return states.C
        e = INV4[(d >> 4) & 7, e]
        swap = d >> 7
    if get_bits(blk, pos + _CF[e], 1):
        return states.C
    return get_bits(blk, pos + _PAL[e], 1) ^ swap


@njit(cache=True)
def lookup(block, x, y):
    """``lookup_at`` of a single 64-byte block, x and y in 0..31."""
    return lookup_at(block, 0, x, y)
