"""rle16's encoder: 16x16 maps -> 64-byte blocks (``block``), conservative.

A map's cells along the serpentine scan (``block.scan_index``) make runs of equal states. When
they are more than a block holds (``block.MAX_RUNS``; a trailing C run is not stored: the cells
after the last run are C), runs are turned into C, greedily, until they fit: each step turns
into C either one known (T or O) run next to a C run or to the end, or two adjacent known runs,
choosing the change that loses the fewest known cells per stored run saved (ties: the fewest
cells, then the earliest). A T or O cell only ever becomes C; C never becomes known and T and O
never swap, so every decoded map is conservative.

Example::

    >>> import numpy as np
    >>> m = np.zeros((1, 16, 16), np.uint8)
    >>> m[0, :, ::2] = 1                             # 8 O columns: 256 runs of one cell
    >>> from omaps_rle16.block import decode_many
    >>> d = decode_many(encode_many(m))[0]
    >>> bool(((d == m[0]) | (d == 2)).all()), int((d != 2).sum()) > 0
    (True, True)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .block import BLOCK_BYTES, C, CELLS, MAX_RUNS, SIZE, _put_runs, scan_index


@njit(cache=True)
def _runs(flat, st, ln):
    """Runs of the scanned cells ``flat`` into ``st``/``ln``; returns their number."""
    k = 0
    for i in range(CELLS):
        if k > 0 and st[k - 1] == flat[i]:
            ln[k - 1] += 1
        else:
            st[k] = flat[i]
            ln[k] = 1
            k += 1
    return k


@njit(cache=True)
def _stored(st, k):
    """Runs a block stores: all but a trailing C run."""
    return k - 1 if k > 0 and st[k - 1] == C else k


@njit(cache=True)
def _best_change(st, ln, k):
    """(first, last) runs to turn into C: the known run or pair of adjacent known runs saving
    the most stored runs per known cell lost."""
    best_i, best_j = -1, -1
    best_cost, best_gain = 1, 0  # compare cost / gain as cost * other_gain
    for i in range(k):
        if st[i] == C:
            continue
        for j in (i, i + 1):
            if j >= k or st[j] == C:
                continue
            left = 1 if i > 0 and st[i - 1] == C else 0
            right = 1 if j + 1 < k and st[j + 1] == C else 0
            # runs i..j become one C run, merged with C neighbours
            gain = (j - i) + left + right
            if j + 1 == k:
                gain += 1  # the C run now ends the scan: it is not stored
            cost = 0
            for r in range(i, j + 1):
                cost += ln[r]
            if gain > 0 and (best_gain == 0 or cost * best_gain < best_cost * gain
                             or (cost * best_gain == best_cost * gain and cost < best_cost)):
                best_i, best_j, best_cost, best_gain = i, j, cost, gain
    return best_i, best_j


@njit(cache=True)
def _merge(st, ln, k, i, j):
    """Turn runs i..j into C and join equal neighbours in place; returns the new count."""
    for r in range(i, j + 1):
        st[r] = C
    w = 0
    for r in range(k):
        if w > 0 and st[w - 1] == st[r]:
            ln[w - 1] += ln[r]
        else:
            st[w] = st[r]
            ln[w] = ln[r]
            w += 1
    return w


@njit(cache=True)
def _encode(maps):
    out = np.zeros((maps.shape[0], BLOCK_BYTES), np.uint8)
    flat = np.empty(CELLS, np.uint8)
    st = np.empty(CELLS, np.int64)
    ln = np.empty(CELLS, np.int64)
    for p in range(maps.shape[0]):
        for y in range(SIZE):
            for x in range(SIZE):
                flat[scan_index(x, y)] = maps[p, y, x]
        k = _runs(flat, st, ln)
        while _stored(st, k) > MAX_RUNS:
            i, j = _best_change(st, ln, k)
            k = _merge(st, ln, k, i, j)
        _put_runs(out[p], st, ln, _stored(st, k))
    return out


def encode_many(maps, encoder=None, effort=None) -> np.ndarray:
    """Maps (P, 16, 16) of states 0..2 -> blocks (P, 64) uint8. rle16 has no encoders or efforts
    to choose (``encoder`` and ``effort`` are None)."""
    m = np.ascontiguousarray(maps, dtype=np.uint8)
    if m.ndim != 3 or m.shape[1:] != (SIZE, SIZE):
        raise ValueError(f"rle16 encodes maps (P, {SIZE}, {SIZE}), got shape {m.shape}")
    return _encode(m)
