"""VQ4-synth: VQ4's 512-bit block with a 14th vector synthesised from its codebook's *order* --
physical layout, symbolic block, decoder and random-access lookup.

VQ4 (``vq4_block``) gives index 2 to an implicit uniform C vector, which a map needs only where
no entry covers a vector. Its codebook's order carries no meaning: the 8 general entries can be
arranged in 8! ways and the 3 two-value entries in 3!, about 17.9 bits the format wastes. VQ4-synth
spends them on a synthesised vector X for index 2:

* rho: the Lehmer rank of the 8 general codes (entries 5..12) as stored (the number of later
  codes smaller than each, weighted 7!, 6!, ..., 0!: 0 when ascending), sigma: the same of the
  3 two-value codes (entries 0..2), 0..5.
* If the 8 general codes are pairwise distinct and rho >= 1: x = 6 (rho - 1) + sigma; when
  x < 2^17, index 2 shows the two-value entry of code x (``vec4`` kind 0: palette bit, 16 C
  flags), else uniform C.
* Otherwise (ascending, or two general codes equal) index 2 is uniform C: the block is a plain VQ4
  block and decodes as VQ4 does.

Everything else -- indices, entries, quadrant transforms, bit positions -- is VQ4's, so every VQ4
block written with its general entries ascending is a VQ4-synth block of the same map, and every
512-bit pattern decodes (a total decoder). The encoder starts from VQ4's and adds X when a
two-value vector keeps more cells than uniform C and the entries that served those vectors
(docs/FORMAT.md, "VQ4-synth").
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations
from math import factorial

import numpy as np
from numba import njit

from .. import states
from .bits import as_block, get_bits
from .vec4 import CFLAG_BIT, FWD4, INV4, KIND_BITS, PALETTE_BIT, TWO_VALUE, entry_pattern, pattern_states
from .vq4_block import (BLOCK_BYTES, ENTRY_KIND, ENTRY_POS, N_ENTRIES, SIZE, TRANSFORM_BITS, TRANSFORM_POS, VQ4Block,
                        lookup_at as vq4_lookup_at)

__all__ = ["VQ4SynthBlock", "decode", "lookup", "lookup_at", "synth_code", "lehmer_rank", "arrange",
           "BLOCK_BYTES", "SIZE", "EXTRA_BITS", "NO_EXTRA"]

GENERAL_SLOTS = np.flatnonzero(ENTRY_KIND == 3).astype(np.int64)  # entries 5..12
TWO_VALUE_SLOTS = np.flatnonzero(ENTRY_KIND == TWO_VALUE).astype(np.int64)  # entries 0..2
EXTRA_BITS = int(KIND_BITS[TWO_VALUE])  # 17
NO_EXTRA = -1
_N_G, _N_2 = len(GENERAL_SLOTS), len(TWO_VALUE_SLOTS)
_FACT = np.array([factorial(i) for i in range(_N_G + 1)], dtype=np.int64)
_GPOS = ENTRY_POS[GENERAL_SLOTS].copy()
_TPOS = ENTRY_POS[TWO_VALUE_SLOTS].copy()
_CF2 = CFLAG_BIT[TWO_VALUE].copy()
_PAL2 = PALETTE_BIT[TWO_VALUE].copy()
assert 6 * (_FACT[_N_G] - 1) > 1 << EXTRA_BITS and _FACT[_N_2] == 6


@njit(cache=True)
def lehmer_rank(codes):
    """Lehmer rank of a sequence: sum over i of (later elements smaller than codes[i]) * (n-1-i)!;
    0 when ascending. Ties count as not smaller."""
    n = codes.shape[0]
    r = 0
    for i in range(n):
        c = 0
        for j in range(i + 1, n):
            if codes[j] < codes[i]:
                c += 1
        r += c * _FACT[n - 1 - i]
    return r


@njit(cache=True)
def synth_code(blk):
    """The two-value code index 2 shows in a 64-byte block, or NO_EXTRA (uniform C)."""
    g = np.empty(_N_G, dtype=np.int64)
    for i in range(_N_G):
        g[i] = get_bits(blk, _GPOS[i], 20)
    for i in range(_N_G):
        for j in range(i + 1, _N_G):
            if g[i] == g[j]:
                return NO_EXTRA
    rho = lehmer_rank(g)
    if rho == 0:
        return NO_EXTRA
    t = np.empty(_N_2, dtype=np.int64)
    for i in range(_N_2):
        t[i] = get_bits(blk, _TPOS[i], EXTRA_BITS)
    x = 6 * (rho - 1) + lehmer_rank(t)
    return x if x < (1 << EXTRA_BITS) else NO_EXTRA


def _unrank(sorted_codes, rank: int) -> np.ndarray:
    """The arrangement of distinct ascending codes whose Lehmer rank is ``rank``."""
    pool, out = list(sorted_codes), []
    for i in range(len(pool) - 1, -1, -1):
        d, rank = divmod(rank, factorial(i))
        out.append(pool.pop(d))
    return np.array(out, dtype=np.int64)


def _arrangement(codes: np.ndarray, rank: int) -> np.ndarray | None:
    """Positions into ``codes`` (a permutation) whose codes, in that order, have Lehmer rank
    ``rank`` (ties count as not smaller, as the decoder ranks them); the first such in the order
    of ``itertools.permutations`` of the ascending order, None when no order has that rank (equal
    codes make some ranks unreachable). Distinct codes: the one arrangement of that rank."""
    asc = np.argsort(codes, kind="stable")
    if rank == 0:
        return asc
    if len(set(codes.tolist())) == len(codes):
        target = _unrank(codes[asc], rank)
        return np.array([int(asc[list(codes[asc]).index(c)]) for c in target])
    for p in permutations(asc.tolist()):
        if lehmer_rank(codes[list(p)]) == rank:
            return np.array(p)
    return None


def arrange(block: VQ4Block, extra: int) -> VQ4Block:
    """The same VQ4 block (same map) with its entries reordered to carry ``extra`` (NO_EXTRA: general
    entries ascending). ValueError when ``extra`` needs an order the block's codes do not have:
    distinct general codes, and two-value codes of which some order has rank ``extra % 6`` (any
    order does when they are distinct; a block the decoder read always has one)."""
    ent = block.entries.copy()
    perm = np.arange(N_ENTRIES)  # perm[new position] = old entry
    for slots, rank, what in ((GENERAL_SLOTS, 0 if extra == NO_EXTRA else extra // 6 + 1, "general"),
                              (TWO_VALUE_SLOTS, 0 if extra == NO_EXTRA else extra % 6, "two-value")):
        codes = ent[slots]
        if extra != NO_EXTRA and what == "general" and len(set(codes.tolist())) != len(codes):
            raise ValueError("a synthesised vector needs distinct general codes")
        order = _arrangement(codes, rank)
        if order is None:
            raise ValueError(f"no order of the two-value codes {codes.tolist()} has rank {rank}: "
                             f"they cannot carry synthesised code {extra}")
        perm[slots] = slots[order]
    new_of_old = np.empty(N_ENTRIES, dtype=np.int64)
    new_of_old[perm] = np.arange(N_ENTRIES)
    idx = block.indices.astype(np.int64)
    idx = np.where(idx >= 3, new_of_old[np.maximum(idx - 3, 0)] + 3, idx)
    return VQ4Block(idx, ent[perm], block.transforms.copy())


@dataclass
class VQ4SynthBlock:
    """Symbolic block: a VQ4 block (``vq4``; index 2 means the synthesised vector) and ``extra``,
    the two-value code of that vector (0 .. 2^17 - 1) or NO_EXTRA for uniform C. ``pack``
    arranges the entries (``arrange``); the map does not depend on their order."""

    vq4: VQ4Block
    extra: int = NO_EXTRA

    def __post_init__(self):
        self.extra = int(self.extra)
        if not (self.extra == NO_EXTRA or 0 <= self.extra < 1 << EXTRA_BITS):
            raise ValueError(f"extra: a {EXTRA_BITS}-bit two-value code or NO_EXTRA")

    def pack(self) -> bytes:
        return arrange(self.vq4, self.extra).pack()

    @classmethod
    def unpack(cls, data) -> "VQ4SynthBlock":
        b = as_block(data, BLOCK_BYTES, "a VQ4-synth block")
        return cls(VQ4Block.unpack(b), int(synth_code(b)))

    def decode(self) -> np.ndarray:
        out = self.vq4.decode()
        if self.extra == NO_EXTRA:
            return out
        x = pattern_states(*entry_pattern(TWO_VALUE, self.extra)).reshape(16)
        for v in np.flatnonzero(self.vq4.indices == 2):
            vy, vx = v >> 3, v & 7
            shown = np.empty(16, dtype=np.uint8)
            shown[FWD4[self.vq4.transforms[2 * (vy >> 2) + (vx >> 2)]]] = x
            out[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = shown.reshape(4, 4)
        return out


def decode(data) -> np.ndarray:
    """Any 64 bytes to their 32x32 map (``map[y, x]``)."""
    return VQ4SynthBlock.unpack(data).decode()


@njit(cache=True)
def lookup_at(data, base, x, y):
    """State of cell (x, y) of the block at byte ``base``: VQ4's lookup, except that index 2 reads
    the synthesised vector (ranking the codebook's order: 28 + 3 comparisons, only for index 2)."""
    v = ((y >> 2) << 3) | (x >> 2)
    idx = (np.int64(data[base + (v >> 1)]) >> ((v & 1) << 2)) & 15
    if idx != 2:
        return vq4_lookup_at(data, base, x, y)
    blk = data[base:base + BLOCK_BYTES]
    code = synth_code(blk)
    if code == NO_EXTRA:
        return states.C
    q = ((y >> 4) << 1) | (x >> 4)
    t = 0
    if q != 0:
        t = get_bits(blk, TRANSFORM_POS + TRANSFORM_BITS * (q - 1), TRANSFORM_BITS)
    e = INV4[t, ((y & 3) << 2) | (x & 3)]
    if (code >> _CF2[e]) & 1:
        return states.C
    return (code >> _PAL2[e]) & 1


@njit(cache=True)
def lookup(block, x, y):
    """``lookup_at`` of a single 64-byte block, x and y in 0..31."""
    return lookup_at(block, 0, x, y)
