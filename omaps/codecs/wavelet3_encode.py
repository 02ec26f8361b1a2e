"""wavelet3 encoder: the lossless three-level tree, a greedy level-3 codebook, then pruning to 512
bits.

1. Level 1: an 8x8-cell block is T or O when all its cells are, C when none is known, else R;
   level 2 likewise for the 4x4-cell children of each R block.
2. The R children's 4x4 patterns are the items of ``vq4_synth_encode.greedy_codebook`` (general
   entries chosen greedily by known cells kept); a child takes the entry that covers it and keeps
   most, and becomes C at level 2 when none covers it. Any prefix of the greedy order is the
   greedy codebook of that size, so every size E = 0..15 is tried.
3. While the fields overflow, the cheapest loss per bit saved goes: an R child (4 bits) or a
   whole R block (8 bits and its children's indices). The best E wins.

Only O->C or T->C changes are ever made: a node is cut to C, or a child shows a covering entry.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import states
from .options import check_maps, check_options
from .vec4 import FULL, GENERAL, entry_code, popcount16
from .vec4_search import distinct_items, greedy_codebook, vector_masks
from .wavelet3_block import BLOCK_BITS, ENTRY_BITS, L2_BITS, L2_POS, L3_BITS, MAX_ENTRIES, R, SIZE, Wavelet3Block

__all__ = ["encode", "encode_many"]

ENCODERS = ("best",)


@njit(cache=True)
def _tree(m):
    """Level-1 codes (64,), level-2 codes (64, 4) (rows of non-R cells unused) and the children's
    patterns (64, 4) known-T / known-O masks."""
    l1 = np.zeros(64, dtype=np.int64)
    l2 = np.zeros((64, 4), dtype=np.int64)
    ct = np.zeros((64, 4), dtype=np.int64)
    co = np.zeros((64, 4), dtype=np.int64)
    for c in range(64):
        cy, cx = c >> 3, c & 7
        dt, do = vector_masks(m, 2, 8 * cy, 8 * cx)
        all_t = all_o = True
        known = False
        for k in range(4):
            ct[c, k], co[c, k] = dt[k], do[k]
            all_t = all_t and dt[k] == FULL
            all_o = all_o and do[k] == FULL
            known = known or (dt[k] | do[k]) != 0
            if dt[k] == FULL:
                l2[c, k] = states.T
            elif do[k] == FULL:
                l2[c, k] = states.O
            elif (dt[k] | do[k]) == 0:
                l2[c, k] = states.C
            else:
                l2[c, k] = R
        l1[c] = states.T if all_t else states.O if all_o else R if known else states.C
    return l1, l2, ct, co


@njit(cache=True)
def _fit(l1, l2, cval, n_e):
    """Prune to the block: (level-1 codes, level-2 codes, kept-child mask, value kept in known
    cells). ``cval[c, k]``: cells an R child keeps with the codebook (0: it becomes C)."""
    l1 = l1.copy()
    l2 = l2.copy()
    keep = np.zeros((64, 4), dtype=np.bool_)
    base = np.zeros(64, dtype=np.int64)
    n_r = 0
    n_kept = 0
    for c in range(64):
        if l1[c] != R:
            continue
        for k in range(4):
            if l2[c, k] == R:
                if cval[c, k] > 0:
                    keep[c, k] = True
                    n_kept += 1
                else:
                    l2[c, k] = states.C
            elif l2[c, k] != states.C:
                base[c] += 16
        if base[c] == 0 and not keep[c].any():
            l1[c] = states.C
        else:
            n_r += 1
    cost = L2_POS + L2_BITS * n_r + L3_BITS * n_kept + ENTRY_BITS * n_e
    while cost > BLOCK_BITS:
        best = 1e18
        bc, bk = -1, -1
        for c in range(64):
            if l1[c] != R:
                continue
            loss = base[c]
            saved = L2_BITS
            for k in range(4):
                if keep[c, k]:
                    loss += cval[c, k]
                    saved += L3_BITS
                    if cval[c, k] / L3_BITS < best:
                        best, bc, bk = cval[c, k] / L3_BITS, c, k
            if loss / saved < best:
                best, bc, bk = loss / saved, c, -1
        if bk >= 0:
            keep[bc, bk] = False
            l2[bc, bk] = states.C
            cost -= L3_BITS
        else:
            for k in range(4):
                if keep[bc, k]:
                    keep[bc, k] = False
                    cost -= L3_BITS
            l1[bc] = states.C
            cost -= L2_BITS
    value = 0
    for c in range(64):
        if l1[c] == states.T or l1[c] == states.O:
            value += 64
        elif l1[c] == R:
            value += base[c]
            for k in range(4):
                if keep[c, k]:
                    value += cval[c, k]
    return l1, l2, keep, value


@njit(cache=True)
def _child_values(l1, l2, ct, co, et, eo, n_e):
    """(cells kept, entry) of every R child with the first n_e codebook entries."""
    cval = np.zeros((64, 4), dtype=np.int64)
    cidx = np.full((64, 4), MAX_ENTRIES, dtype=np.int64)
    for c in range(64):
        if l1[c] != R:
            continue
        for k in range(4):
            if l2[c, k] != R:
                continue
            for i in range(n_e):
                if (et[i] & ~ct[c, k]) == 0 and (eo[i] & ~co[c, k]) == 0:
                    v = popcount16(et[i] | eo[i])
                    if v > cval[c, k]:
                        cval[c, k], cidx[c, k] = v, i
    return cval, cidx


@njit(cache=True)
def encode_arrays(m):
    """One 64x64 map -> (level1 (64,), level2 (m1, 4), level3 (m2,), entry codes (E,))."""
    l1, l2, ct, co = _tree(m)
    n = 0
    pt = np.empty(256, dtype=np.int64)
    po = np.empty(256, dtype=np.int64)
    for c in range(64):
        if l1[c] == R:
            for k in range(4):
                if l2[c, k] == R:
                    pt[n], po[n] = ct[c, k], co[c, k]
                    n += 1
    it, io, w = distinct_items(pt[:n], po[:n])
    et, eo = greedy_codebook(it, io, w, MAX_ENTRIES)
    best_v, best_e = -1, 0
    for n_e in range(et.shape[0] + 1):
        cval, _ = _child_values(l1, l2, ct, co, et, eo, n_e)
        v = _fit(l1, l2, cval, n_e)[3]
        if v > best_v:
            best_v, best_e = v, n_e
    cval, cidx = _child_values(l1, l2, ct, co, et, eo, best_e)
    f1, f2, keep, _ = _fit(l1, l2, cval, best_e)
    m1 = 0
    for c in range(64):
        if f1[c] == R:
            m1 += 1
    level2 = np.zeros((m1, 4), dtype=np.int64)
    level3 = np.zeros(256, dtype=np.int64)
    m2 = 0
    r = 0
    for c in range(64):
        if f1[c] != R:
            continue
        for k in range(4):
            level2[r, k] = f2[c, k]
            if f2[c, k] == R:
                level3[m2] = cidx[c, k]
                m2 += 1
        r += 1
    codes = np.zeros(best_e, dtype=np.int64)
    for i in range(best_e):
        codes[i] = entry_code(GENERAL, et[i], eo[i])
    return f1, level2, level3[:m2], codes


def encode(map64, encoder: str = "best", effort: str = "medium") -> Wavelet3Block:
    """One 64x64 map -> its symbolic block (conservative: only O->C or T->C). The search has no
    effort levels: every effort gives the same block."""
    return encode_many(np.asarray(map64)[None], encoder, effort)[0]


def encode_many(maps64, encoder: str = "best", effort: str = "medium") -> list[Wavelet3Block]:
    """Maps (P, 64, 64) -> symbolic blocks."""
    if encoder not in ENCODERS:
        raise ValueError(f"unknown wavelet3 encoder {encoder!r} (choose from {', '.join(ENCODERS)})")
    check_options("wavelet3", "best", effort)
    m = check_maps(maps64, SIZE, "wavelet3").reshape(-1, SIZE, SIZE)
    return [Wavelet3Block(*encode_arrays(one)) for one in m]
