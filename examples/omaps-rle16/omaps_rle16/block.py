"""rle16: a 16x16 opacity map as runs of states along a serpentine scan, in one 64-byte block.

Scan order: the 256 cells row by row, even rows left to right, odd rows right to left (a
serpentine, so that a region crossing a row's end continues its run); cell (x, y) (column x,
row y of ``map[y, x]``) has scan index ``16 y + x`` on an even row, ``16 y + 15 - x`` on an odd
one.

Physical block (64 bytes = 512 bits; bit k is bit k mod 8 of byte k div 8, a field's least
significant bit first, as every omaps block: ``omaps.codecs.bits``):

    bits   0..7    K: the number of runs (0..50)
    bits   8..507  run r (r = 0..K-1) at bit 8 + 10 r: its state (2 bits: 0 T, 1 O, 2 C),
                   then its length minus one (8 bits: 1..256 cells)
    bits 508..511  unused (0)

The runs cover the scan from index 0 on; the cells after the last run are C. The encoder never
stores a trailing C run (the cells after the runs are C anyway).

Every 64 bytes decode (the decoder is total): K above 50 counts as 50, a state code 3 is C,
cells past 256 are ignored (a run reaching past the end is cut there) and cells no run covers
are C.

Example::

    >>> block = pack([1, 0], [16, 32])     # O for 16 cells (row 0), then T for 32 (rows 1 and 2)
    >>> block[:4].tolist()                 # K = 2; O, 16 - 1; T, 32 - 1
    [2, 61, 240, 1]
    >>> m = decode(block)
    >>> m[0].tolist() == [1] * 16, m[2].tolist() == [0] * 16, int(m[3, 0]), int(lookup(block, 5, 1))
    (True, True, 2, 0)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from omaps.codecs.bits import get_bits

SIZE = 16  # the map is SIZE x SIZE cells
CELLS = SIZE * SIZE
BLOCK_BYTES = 64
COUNT_BITS = 8  # K, at bit 0
STATE_BITS, LENGTH_BITS = 2, 8  # one run: its state, then its length minus one
RUN_BITS = STATE_BITS + LENGTH_BITS
RUNS_POS = COUNT_BITS  # run r at bit RUNS_POS + RUN_BITS * r
MAX_RUNS = (8 * BLOCK_BYTES - RUNS_POS) // RUN_BITS  # 50
C = 2  # the state of cells no run covers, and of a state code 3


@njit(cache=True, inline="always")
def scan_index(x, y):
    """The serpentine scan index of cell (x, y)."""
    return SIZE * y + (x if (y & 1) == 0 else SIZE - 1 - x)


@njit(cache=True, inline="always")
def run_count(block):
    """K, with a value above MAX_RUNS read as MAX_RUNS."""
    return min(np.int64(block[0]), MAX_RUNS)


@njit(cache=True)
def lookup(block, x, y):
    """State of cell (x, y) read from the block alone: walk the runs until the one holding the
    cell's scan index (at most 50 runs, two bit fields each; no allocation)."""
    i = scan_index(x, y)
    end = 0
    for r in range(run_count(block)):
        p = RUNS_POS + RUN_BITS * r
        end += get_bits(block, p + STATE_BITS, LENGTH_BITS) + 1
        if i < end:
            s = get_bits(block, p, STATE_BITS)
            return np.uint8(C if s == 3 else s)
    return np.uint8(C)


@njit(cache=True)
def decode_many(blocks):
    """Blocks (P, 64) uint8 -> their maps (P, 16, 16) uint8 (total: see the module's docstring)."""
    out = np.empty((blocks.shape[0], SIZE, SIZE), np.uint8)
    flat = np.empty(CELLS, np.uint8)
    for b in range(blocks.shape[0]):
        block = blocks[b]
        flat[:] = C
        start = 0
        for r in range(run_count(block)):
            if start >= CELLS:
                break
            p = RUNS_POS + RUN_BITS * r
            s = get_bits(block, p, STATE_BITS)
            end = min(start + get_bits(block, p + STATE_BITS, LENGTH_BITS) + 1, CELLS)
            flat[start:end] = C if s == 3 else s
            start = end
        for y in range(SIZE):
            for x in range(SIZE):
                out[b, y, x] = flat[scan_index(x, y)]
    return out


def decode(data) -> np.ndarray:
    """One block (64 bytes: bytes or a uint8 array) -> its 16x16 map ``map[y, x]``."""
    b = np.frombuffer(bytes(data), np.uint8)
    if b.size != BLOCK_BYTES:
        raise ValueError(f"an rle16 block is {BLOCK_BYTES} bytes, got {b.size}")
    return decode_many(b.copy().reshape(1, BLOCK_BYTES))[0]


def pack(states, lengths) -> np.ndarray:
    """One block's runs -> its 64 bytes (uint8): ``states`` (K,) in 0..2, ``lengths`` (K,) in
    1..256, K <= 50. ValueError for a field out of range."""
    s, n = np.asarray(states, np.int64), np.asarray(lengths, np.int64)
    if s.ndim != 1 or s.shape != n.shape or len(s) > MAX_RUNS or (s < 0).any() or (s > C).any() \
            or (n < 1).any() or (n > CELLS).any():
        raise ValueError(f"rle16 runs: at most {MAX_RUNS} states 0..2 with lengths 1..{CELLS}")
    out = np.zeros((1, BLOCK_BYTES), np.uint8)
    _put_runs(out[0], s, n, len(s))
    return out[0]


@njit(cache=True)
def _put_field(block, pos, n, value):
    for k in range(n):
        if (value >> k) & 1:
            block[(pos + k) >> 3] |= np.uint8(1 << ((pos + k) & 7))


@njit(cache=True)
def _put_runs(block, states, lengths, k):
    """Write K = ``k`` and the first ``k`` runs into a zeroed block."""
    block[0] = k
    for r in range(k):
        p = RUNS_POS + RUN_BITS * r
        _put_field(block, p, STATE_BITS, states[r])
        _put_field(block, p + STATE_BITS, LENGTH_BITS, lengths[r] - 1)
