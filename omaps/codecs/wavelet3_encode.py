"""wavelet3 encoder: the lossless tree, a greedy shared codebook, then a bit allocation over the
R blocks' options.

1. Level 1: an 8x8-cell block is T or O when all its cells are, C when none is known, else R;
   level 2 likewise for the 4x4-cell children of each R block. An R block's 32x32 vector has an
   element per 2x2 cells: T or O when all four are, else C.
2. Codebook (``vec4_search.greedy_codebook``, general entries chosen greedily by known cells kept):
   its items are the R children's patterns (a known element is one cell) and the R blocks' 32x32
   vectors (four cells). A node takes the entry that covers it and keeps most. Any prefix of the
   greedy order is the greedy codebook of that size, so every size E = 0..15 is tried.
3. Each R block has options (bits, cells kept): C (0, 0); at 32x32 (1 + w, its vector's cells);
   at 64x64 (1 + 8 + w n, its T/O children's cells and its n best R children's). ``allocate.allocate``
   picks one per block within 512 - 132 - 20E bits (hull steps in falling cells per bit); the best
   E wins, then the codebook is chosen again with the items weighted by the options taken, twice.

4. Transforms (one per 32x32 quadrant, quadrant 0 untransformed; nodes work in their quadrant's
   stored space): identity and ``aligned_transforms``, the better one; then ``PASSES[effort]``
   passes of coordinate descent, each quadrant trying its other 7 transforms with steps 1-3.

Only O->C or T->C changes are ever made: a node is cut to C, or shows a covering entry.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import states
from ..allocate import allocate_arrays
from .options import check_maps, check_options
from .symmetry import position_tables
from .vec4 import FULL, GENERAL, entry_code, untransform_mask
from .vec4_search import greedy_codebook, keeps, vector_masks
from .wavelet3_block import (BLOCK_BITS, CHILD_BITS, ENTRY_BITS, MAX_ENTRIES, MODE_POS, R, SIZE, Wavelet3Block,
                             index_bits)

__all__ = ["encode", "encode_many"]

ENCODERS = ("best",)
_FWD32 = position_tables(32)[0]


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
def _coarse(ct, co):
    """The 32x32 vector of a block from its four children's masks: element (ex, ey) known only
    when its 2x2 cells all are, and agree."""
    vt = 0
    vo = 0
    for e in range(16):
        ex, ey = e & 3, e >> 2
        k = 2 * (ey >> 1) + (ex >> 1)
        m = 0
        for dy in range(2):
            for dx in range(2):
                m |= 1 << (4 * (2 * (ey & 1) + dy) + 2 * (ex & 1) + dx)
        if (ct[k] & m) == m:
            vt |= 1 << e
        elif (co[k] & m) == m:
            vo |= 1 << e
    return vt, vo


@njit(cache=True)
def _coarse_all(l1, ct, co):
    vt = np.zeros(64, dtype=np.int64)
    vo = np.zeros(64, dtype=np.int64)
    for c in range(64):
        if l1[c] == R:
            vt[c], vo[c] = _coarse(ct[c], co[c])
    return vt, vo


@njit(cache=True)
def _items(l1, l2, ct, co, vt, vo, use_coarse, use_fine):
    """Codebook items: R children (weight 1 per copy) and R blocks' 32x32 vectors (weight 4),
    each only where the mask allows."""
    pt = np.empty(320, dtype=np.int64)
    po = np.empty(320, dtype=np.int64)
    w = np.empty(320, dtype=np.int64)
    n = 0
    for c in range(64):
        if l1[c] != R:
            continue
        if use_coarse[c] and (vt[c] | vo[c]) != 0:
            pt[n], po[n], w[n] = vt[c], vo[c], 4
            n += 1
        for k in range(4):
            if l2[c, k] == R and use_fine[c, k]:
                pt[n], po[n], w[n] = ct[c, k], co[c, k], 1
                n += 1
    # merge equal patterns, adding weights
    it = np.empty(n, dtype=np.int64)
    io = np.empty(n, dtype=np.int64)
    iw = np.zeros(n, dtype=np.int64)
    m = 0
    for a in range(n):
        j = 0
        while j < m and not (it[j] == pt[a] and io[j] == po[a]):
            j += 1
        if j == m:
            it[m], io[m] = pt[a], po[a]
            m += 1
        iw[j] += w[a]
    return it[:m], io[:m], iw[:m]


@njit(cache=True)
def _to_stored(l1, ct, co, vt, vo, tr):
    """Every R block's masks in its quadrant's stored space (the inverse of its transform)."""
    for c in range(64):
        if l1[c] != R:
            continue
        t = tr[2 * ((c >> 3) >> 2) + ((c & 7) >> 2)]
        vt[c], vo[c] = untransform_mask(vt[c], t), untransform_mask(vo[c], t)
        for k in range(4):
            ct[c, k], co[c, k] = untransform_mask(ct[c, k], t), untransform_mask(co[c, k], t)


def aligned_transforms(m) -> np.ndarray:
    """Per 32x32 quadrant q = 1..3 the symmetry that best maps quadrant 0's known cells onto it
    (the most equal known cells; identity on a tie), transforms[0] = 0."""
    quads = m.reshape(2, 32, 2, 32).transpose(0, 2, 1, 3).reshape(4, -1)
    tr = np.zeros(4, dtype=np.int64)
    for q in range(1, 4):
        scores = []
        for t in range(8):
            shown = np.empty(1024, np.uint8)
            shown[_FWD32[t]] = quads[0]
            scores.append(int(((shown == quads[q]) & (shown != states.C)).sum()))
        tr[q] = int(np.argmax(scores))
    return tr


PASSES = {"fast": 0, "medium": 1, "thorough": 3}  # coordinate-descent passes over the transforms


def _encode_one(m, passes: int) -> Wavelet3Block:
    """The better of identity transforms and ``aligned_transforms``, then ``passes`` passes of
    coordinate descent: each quadrant 1..3 in turn tries its 7 other transforms. It stops as soon
    as every known cell is kept (no transform can do better: most real maps are that simple)."""
    known = int((m != states.C).sum())
    tr = np.zeros(4, np.int64)
    best, found = _search(m, tr)
    if best < known:
        aligned = aligned_transforms(m)
        if aligned.any():
            t2, f2 = _search(m, aligned)
            if t2 > best:
                best, found, tr = t2, f2, aligned
    for _ in range(passes):
        if best >= known:
            break
        improved = False
        for q in range(1, 4):
            for t in range(8):
                if t == tr[q] or best >= known:
                    continue
                trial = tr.copy()
                trial[q] = t
                v, f = _search(m, trial)
                if v > best:
                    best, found, tr, improved = v, f, trial, True
        if not improved:
            break
    return _block(found, tr)


@njit(cache=True)
def _best_prefix(l1, l2, ct, co, vt, vo, et, eo, rb, fixed):
    """Of the codebook's prefixes (sizes 0 .. len(et)), the one whose bit allocation keeps most
    cells (the smallest on a tie): (cells kept, size, choice per R block, and at that size each
    R block's coarse entry (64,), its children's entries (64, 4) and its children by falling
    value (64, 4)). A node takes the covering entry that keeps most (the first on a tie; 15 when
    none keeps anything). Each size adds one entry, so a node's best entry is updated, not
    searched again. Per R block the options are (bits, cells kept): C (0, 0), 32x32 (1 + w,
    its vector's cells), 64x64 with its n = 0..4 best R children (1 + 8 + w n, its T/O
    children's cells and those n's), w the index bits of the size."""
    nr = rb.shape[0]
    bits = np.zeros((nr, 7), dtype=np.int64)
    val = np.zeros((nr, 7), dtype=np.float64)
    cv = np.zeros(nr, dtype=np.int64)
    kv = np.zeros((nr, 4), dtype=np.int64)
    base = np.zeros(nr, dtype=np.int64)
    cidx = np.full(64, MAX_ENTRIES, dtype=np.int64)
    kidx = np.full((64, 4), MAX_ENTRIES, dtype=np.int64)
    korder = np.zeros((64, 4), dtype=np.int64)
    for r in range(nr):
        for k in range(4):
            if l2[rb[r], k] != R and l2[rb[r], k] != states.C:
                base[r] += 16
    best = -1.0
    best_n = 0
    best_choice = np.zeros(nr, dtype=np.int64)
    best_c, best_k, best_o = cidx.copy(), kidx.copy(), korder.copy()
    for n_e in range(et.shape[0] + 1):
        if n_e > 0:
            e = n_e - 1
            for r in range(nr):
                c = rb[r]
                v = keeps(et[e], eo[e], vt[c], vo[c])
                if v > cv[r]:
                    cv[r], cidx[c] = v, e
                for k in range(4):
                    if l2[c, k] == R:
                        v = keeps(et[e], eo[e], ct[c, k], co[c, k])
                        if v > kv[r, k]:
                            kv[r, k], kidx[c, k] = v, e
        w = index_bits(n_e)
        for r in range(nr):
            c = rb[r]
            bits[r, 1], val[r, 1] = 1 + w, 4 * cv[r]
            for k in range(4):  # children by falling value, ties by position (a stable sort)
                korder[c, k] = k
            for a in range(1, 4):
                b = a
                while b > 0 and kv[r, korder[c, b]] > kv[r, korder[c, b - 1]]:
                    korder[c, b], korder[c, b - 1] = korder[c, b - 1], korder[c, b]
                    b -= 1
            acc = base[r]
            for n in range(5):
                if n > 0:
                    acc += kv[r, korder[c, n - 1]]
                bits[r, 2 + n] = 1 + CHILD_BITS + w * n
                val[r, 2 + n] = acc
        choice = np.zeros(nr, dtype=np.int64)
        if nr:
            choice, _ = allocate_arrays(bits, val, BLOCK_BITS - MODE_POS - ENTRY_BITS * n_e)
        total = float(fixed)
        for r in range(nr):
            total += val[r, choice[r]]
        if total > best:
            best, best_n, best_choice = total, n_e, choice
            best_c[:], best_k[:], best_o[:] = cidx, kidx, korder
    return best, best_n, best_choice, best_c, best_k, best_o


@njit(cache=True)
def _search(m, tr):
    """One transform set's encoding: (cells kept, and what ``_block`` makes the block of)."""
    l1, l2, ct, co = _tree(m)
    vt, vo = _coarse_all(l1, ct, co)
    _to_stored(l1, ct, co, vt, vo, tr)
    rb = np.flatnonzero(l1 == R)
    fixed = 0
    for c in range(64):
        if l1[c] == states.T or l1[c] == states.O:
            fixed += 64
    use_c = np.ones(64, np.bool_)
    use_f = np.ones((64, 4), np.bool_)
    best = -1.0
    best_et = best_eo = np.zeros(0, np.int64)
    best_choice = np.zeros(rb.shape[0], np.int64)
    best_c = np.zeros(64, np.int64)
    best_k = best_o = np.zeros((64, 4), np.int64)
    for _ in range(3):  # the codebook from every node, then (twice) from the nodes the allocation kept
        it, io, iw = _items(l1, l2, ct, co, vt, vo, use_c, use_f)
        et, eo = greedy_codebook(it, io, iw, MAX_ENTRIES)
        total, n_e, choice, cidx, kidx, korder = _best_prefix(l1, l2, ct, co, vt, vo, et, eo, rb, fixed)
        if total > best:
            best, best_et, best_eo, best_choice = total, et[:n_e].copy(), eo[:n_e].copy(), choice
            best_c, best_k, best_o = cidx, kidx, korder
        use_c[:] = False
        use_f[:] = False
        for r in range(rb.shape[0]):
            c, ch = rb[r], best_choice[r]
            use_c[c] = ch == 1
            for n in range(max(0, ch - 2)):
                use_f[c, best_o[c, n]] = True
    return best, (l1, l2, rb, best_et, best_eo, best_choice, best_c, best_k, best_o)


def _block(found, tr) -> Wavelet3Block:
    """The symbolic block of ``_search``'s result."""
    l1, l2, rb, et, eo, choice, cidx, kidx, korder = found
    level1, mode, children, coarse, fine = l1.copy(), [], [], [], []
    for c, ch in zip(rb, choice):
        if ch == 0:
            level1[c] = states.C
        elif ch == 1:
            mode.append(1)
            coarse.append(cidx[c])
        else:
            mode.append(0)
            kept = set(int(k) for k in korder[c, :ch - 2])
            row = [int(v) if v != R or k in kept else states.C for k, v in enumerate(l2[c])]
            children.append(row)
            fine += [kidx[c, k] for k in range(4) if row[k] == R]
    codes = [entry_code(GENERAL, int(t), int(o)) for t, o in zip(et, eo)]
    return Wavelet3Block(level1, mode, np.array(children, np.int64).reshape(-1, 4), coarse, fine, codes, tr)


def encode(map64, encoder: str = "best", effort: str = "medium") -> Wavelet3Block:
    """One 64x64 map -> its symbolic block (conservative: only O->C or T->C); ``effort``: the
    transform search (``PASSES``)."""
    return encode_many(np.asarray(map64)[None], encoder, effort)[0]


def encode_many(maps64, encoder: str = "best", effort: str = "medium") -> list[Wavelet3Block]:
    """Maps (P, 64, 64) -> symbolic blocks."""
    if encoder not in ENCODERS:
        raise ValueError(f"unknown wavelet3 encoder {encoder!r} (choose from {', '.join(ENCODERS)})")
    check_options("wavelet3", "best", effort)
    m = check_maps(maps64, SIZE, "wavelet3").reshape(-1, SIZE, SIZE)
    return [_encode_one(one, PASSES[effort]) for one in m]
