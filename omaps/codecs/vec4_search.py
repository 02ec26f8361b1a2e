"""Search pieces the 512-bit codecs share over 4x4 *patterns* (``vec4``: known-T and known-O
masks): a map region's vectors, its distinct mixed items, coverage, and a greedy general-kind
codebook. A vector (ct, co) *covers* an item when it is equal to it or C in every element; an
encoder that shows only covering vectors can only turn states into C.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .vec4 import FULL, GENERAL, popcount16, project

__all__ = ["vector_masks", "distinct_items", "keeps", "greedy_codebook"]


@njit(cache=True)
def vector_masks(m, size_vectors, base_y, base_x):
    """Known-T and known-O masks of the size_vectors^2 4x4 vectors of a map region (row-major)."""
    n = size_vectors * size_vectors
    dt = np.zeros(n, dtype=np.int64)
    do = np.zeros(n, dtype=np.int64)
    for v in range(n):
        vy, vx = v // size_vectors, v % size_vectors
        for e in range(16):
            s = m[base_y + 4 * vy + (e >> 2), base_x + 4 * vx + (e & 3)]
            if s == 0:
                dt[v] |= 1 << e
            elif s == 1:
                do[v] |= 1 << e
    return dt, do


@njit(cache=True)
def distinct_items(pt, po):
    """Distinct patterns among (pt, po) that are not uniform T or O, with their counts."""
    n = pt.shape[0]
    it = np.empty(n, dtype=np.int64)
    io = np.empty(n, dtype=np.int64)
    w = np.zeros(n, dtype=np.int64)
    k = 0
    for v in range(n):
        if pt[v] == FULL or po[v] == FULL:
            continue
        j = 0
        while j < k and not (it[j] == pt[v] and io[j] == po[v]):
            j += 1
        if j == k:
            it[k], io[k] = pt[v], po[v]
            k += 1
        w[j] += 1
    return it[:k], io[:k], w[:k]


@njit(cache=True, inline="always")
def keeps(ct, co, it, io):
    """Known cells a vector (ct, co) keeps of an item it covers; -1 if it does not cover it."""
    if (ct & ~it) != 0 or (co & ~io) != 0:
        return -1
    return popcount16(ct | co)


@njit(cache=True)
def _gain(ct, co, it, io, w, cur):
    g = 0
    for i in range(it.shape[0]):
        r = keeps(ct, co, it[i], io[i])
        if r > cur[i]:
            g += w[i] * (r - max(cur[i], 0))
    return g


@njit(cache=True)
def greedy_codebook(it, io, w, n_max):
    """Up to ``n_max`` general-kind patterns chosen greedily by gain in known cells kept, from the
    projections of every item and of the conservative merge of every pair of items. The order is
    the greedy's, so any prefix is the greedy codebook of that size."""
    n_it = it.shape[0]
    keys = np.empty(n_it + n_it * (n_it - 1) // 2, dtype=np.int64)
    nk = 0
    for a in range(n_it):
        for c in range(a, n_it):
            kt, ko = project(GENERAL, it[a] & it[c], io[a] & io[c])
            if (kt | ko) != 0:
                keys[nk] = (kt << 16) | ko
                nk += 1
    u = np.unique(keys[:nk])
    pt, po = u >> 16, u & FULL
    cur = np.full(n_it, -1, dtype=np.int64)
    ct = np.zeros(n_max, dtype=np.int64)
    co = np.zeros(n_max, dtype=np.int64)
    n = 0
    while n < n_max:
        best, bj = 0, -1
        for j in range(pt.shape[0]):
            g = _gain(pt[j], po[j], it, io, w, cur)
            if g > best:
                best, bj = g, j
        if bj < 0:
            break
        ct[n], co[n] = pt[bj], po[bj]
        for i in range(n_it):
            r = keeps(pt[bj], po[bj], it[i], io[i])
            if r > cur[i]:
                cur[i] = r
        n += 1
    return ct[:n], co[:n]
