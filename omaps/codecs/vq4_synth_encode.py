"""VQ4-synth encoder: quadrant transforms by coordinate descent, slots by a greedy over explicit
and derived candidates.

Work happens on *patterns* (``vec4``: known-T and known-O masks of a 4x4 vector) in each
quadrant's stored space. Every non-uniform vector is an *item* (distinct patterns, counted). A
slot *covers* an item when it is equal to it or C in every element, and then keeps its known
cells; each vector takes the covering slot that keeps most, so the encoder can only ever turn a
state into C.

Candidates: explicit -- every item and the conservative merge of every pair of items, projected
onto the general kind (``vec4.project``); derived -- the 15 other variants (8 symmetries, T/O
swap) of each explicit slot already chosen. The greedy takes, slot by slot, the candidate with
the largest gain in known cells (explicit ones while fewer than ``MAX_EXPLICIT`` are chosen),
and ends with a uniform C slot when some item is still uncovered. Efforts: ``fast`` keeps the
identity transforms; ``medium`` tries the 8 transforms of quadrants 1..3 in turn (one pass of
coordinate descent, 25 codebook searches); ``thorough`` runs passes until none improves.

``greedy_codebook`` (the explicit part alone) is shared with ``wavelet3``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .options import EFFORTS, check_maps, check_options
from .vec4 import FULL, GENERAL, entry_code, popcount16, project, transform_mask, untransform_mask
from .vq4_block import SIZE
from .vq4_synth_block import MAX_EXPLICIT, N_SLOTS, NO_SOURCE, VQ4SynthBlock

__all__ = ["encode", "encode_many", "greedy_codebook"]

ENCODERS = ("best",)


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
def _keeps(ct, co, it, io):
    """Known cells a vector (ct, co) keeps of an item it covers; -1 if it does not cover it."""
    if (ct & ~it) != 0 or (co & ~io) != 0:
        return -1
    return popcount16(ct | co)


@njit(cache=True)
def _explicit_pool(it, io):
    """Distinct general-kind projections of every item and of the merge of every pair."""
    n = it.shape[0]
    keys = np.empty(n + n * (n - 1) // 2, dtype=np.int64)
    nk = 0
    for a in range(n):
        for c in range(a, n):
            kt, ko = project(GENERAL, it[a] & it[c], io[a] & io[c])
            if (kt | ko) != 0:
                keys[nk] = (kt << 16) | ko
                nk += 1
    u = np.unique(keys[:nk])
    return u >> 16, u & FULL


@njit(cache=True)
def _gain(ct, co, it, io, w, cur):
    g = 0
    for i in range(it.shape[0]):
        r = _keeps(ct, co, it[i], io[i])
        if r > cur[i]:
            g += w[i] * (r - max(cur[i], 0))
    return g


@njit(cache=True)
def _take(ct, co, it, io, cur):
    for i in range(it.shape[0]):
        r = _keeps(ct, co, it[i], io[i])
        if r > cur[i]:
            cur[i] = r


@njit(cache=True)
def greedy_codebook(it, io, w, n_max):
    """Up to ``n_max`` general-kind patterns chosen greedily by gain in known cells kept (the
    order is the greedy's, so any prefix is the greedy codebook of that size)."""
    pt, po = _explicit_pool(it, io)
    cur = np.full(it.shape[0], -1, dtype=np.int64)
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
        _take(pt[bj], po[bj], it, io, cur)
        n += 1
    return ct[:n], co[:n]


@njit(cache=True, inline="always")
def _variant(kt, ko, op):
    """Derived variant op = u | swap << 3 of a stored pattern."""
    vt, vo = transform_mask(kt, op & 7), transform_mask(ko, op & 7)
    return (vo, vt) if op >> 3 else (vt, vo)


@njit(cache=True)
def _slots(it, io, w):
    """Greedy slots: (kind (N_SLOTS,) 0 explicit / 1 derived / 2 uniform C / -1 unused, ct, co,
    source pick, op, value kept)."""
    pt, po = _explicit_pool(it, io)
    cur = np.full(it.shape[0], -1, dtype=np.int64)
    kind = np.full(N_SLOTS, -1, dtype=np.int64)
    st = np.zeros(N_SLOTS, dtype=np.int64)
    so = np.zeros(N_SLOTS, dtype=np.int64)
    src = np.zeros(N_SLOTS, dtype=np.int64)
    ops = np.zeros(N_SLOTS, dtype=np.int64)
    n_exp = 0
    n = 0
    while n < N_SLOTS:
        best, bj, bsrc, bop = 0, -1, -1, 0
        if n_exp < MAX_EXPLICIT:
            for j in range(pt.shape[0]):
                g = _gain(pt[j], po[j], it, io, w, cur)
                if g > best:
                    best, bj = g, j
        for s in range(n):
            if kind[s] != 0:
                continue
            for op in range(1, 16):
                vt, vo = _variant(st[s], so[s], op)
                g = _gain(vt, vo, it, io, w, cur)
                if g > best:
                    best, bj, bsrc, bop = g, -1, s, op
        if best == 0:
            break
        if bsrc < 0:
            kind[n], st[n], so[n] = 0, pt[bj], po[bj]
            n_exp += 1
        else:
            kind[n], src[n], ops[n] = 1, bsrc, bop
            st[n], so[n] = _variant(st[bsrc], so[bsrc], bop)
        _take(st[n], so[n], it, io, cur)
        n += 1
    uncovered = False
    for i in range(it.shape[0]):
        if cur[i] < 0:
            uncovered = True
    if uncovered:
        if n == N_SLOTS:  # the last pick gives way to uniform C (no later pick depends on it)
            n -= 1
            if kind[n] == 0:
                n_exp -= 1
        kind[n], st[n], so[n] = 2, 0, 0
        n += 1
    # value kept with the final slots
    total = 0
    for i in range(it.shape[0]):
        b = 0
        for s in range(n):
            r = _keeps(st[s], so[s], it[i], io[i])
            if r > b:
                b = r
        total += w[i] * b
    return kind, st, so, src, ops, total


@njit(cache=True)
def _stored(dt, do, tr):
    """Stored patterns of the 64 vectors under quadrant transforms ``tr``."""
    pt = np.empty(64, dtype=np.int64)
    po = np.empty(64, dtype=np.int64)
    for v in range(64):
        q = 2 * ((v >> 3) >> 2) + ((v & 7) >> 2)
        pt[v] = untransform_mask(dt[v], tr[q])
        po[v] = untransform_mask(do[v], tr[q])
    return pt, po


@njit(cache=True)
def _value(dt, do, tr):
    pt, po = _stored(dt, do, tr)
    it, io, w = distinct_items(pt, po)
    return _slots(it, io, w)[5]


@njit(cache=True)
def _search(dt, do, passes):
    tr = np.zeros(4, dtype=np.int64)
    best = _value(dt, do, tr)
    for _ in range(passes):
        improved = False
        for q in range(1, 4):
            keep = tr[q]
            for t in range(8):
                if t == keep:
                    continue
                tr[q] = t
                val = _value(dt, do, tr)
                if val > best:
                    best, keep, improved = val, t, True
            tr[q] = keep
        if not improved:
            break
    return tr


@njit(cache=True)
def encode_arrays(m, passes):
    """One 32x32 map -> (indices (64,), k, explicit codes (k,), derived (14 - k, 3), transforms (4,))."""
    dt, do = vector_masks(m, 8, 0, 0)
    tr = _search(dt, do, passes)
    pt, po = _stored(dt, do, tr)
    it, io, w = distinct_items(pt, po)
    kind, st, so, src, ops, _ = _slots(it, io, w)
    # slot order: explicit first (in pick order), then derived and C
    order = np.empty(N_SLOTS, dtype=np.int64)
    where = np.full(N_SLOTS, -1, dtype=np.int64)
    k = 0
    for s in range(N_SLOTS):
        if kind[s] == 0:
            order[k], where[s] = s, k
            k += 1
    j = k
    for s in range(N_SLOTS):
        if kind[s] != 0:
            order[j], where[s] = s, j
            j += 1
    explicit = np.zeros(k, dtype=np.int64)
    derived = np.zeros((N_SLOTS - k, 3), dtype=np.int64)
    for p in range(N_SLOTS):
        s = order[p]
        if p < k:
            explicit[p] = entry_code(GENERAL, st[s], so[s])
        elif kind[s] == 1:
            derived[p - k, 0], derived[p - k, 1], derived[p - k, 2] = where[src[s]], ops[s] & 7, ops[s] >> 3
        else:  # uniform C, or unused
            derived[p - k, 0] = NO_SOURCE
    idx = np.zeros(64, dtype=np.int64)
    for v in range(64):
        if dt[v] == FULL:
            idx[v] = 0
        elif do[v] == FULL:
            idx[v] = 1
        else:
            b, bs = -1, -1
            for p in range(N_SLOTS):
                s = order[p]
                if kind[s] < 0:
                    continue
                r = _keeps(st[s], so[s], pt[v], po[v])
                if r > b:
                    b, bs = r, p
            idx[v] = 2 + bs
    return idx, k, explicit, derived, tr


def _passes(effort: str) -> int:
    return {"fast": 0, "medium": 1, "thorough": 8}[effort]


def encode(map32, encoder: str = "best", effort: str = "medium") -> VQ4SynthBlock:
    """One 32x32 map -> its symbolic block (conservative: only O->C or T->C)."""
    return encode_many(np.asarray(map32)[None], encoder, effort)[0]


def encode_many(maps32, encoder: str = "best", effort: str = "medium") -> list[VQ4SynthBlock]:
    """Maps (P, 32, 32) -> symbolic blocks."""
    if encoder not in ENCODERS:
        raise ValueError(f"unknown vq4-synth encoder {encoder!r} (choose from {', '.join(ENCODERS)})")
    check_options("vq4-synth", "best", effort)
    m = check_maps(maps32, SIZE, "vq4-synth").reshape(-1, SIZE, SIZE)
    out = []
    for one in m:
        idx, k, ex, der, tr = encode_arrays(one, _passes(effort))
        out.append(VQ4SynthBlock(idx, k, ex, der, tr))
    return out


assert set(EFFORTS) == {"fast", "medium", "thorough"}
