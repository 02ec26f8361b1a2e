"""VQ2 encoders: the deck's naive compressor (``paper``) and our search (``best``).

Both start by making every 2x2 vector encodable (a vector with O and T together loses its
minority state to C, keeping O on a tie) and never change a state other than to C: a vector is
stored either exactly, or through a codebook entry that *covers* it (equal or C in every
element), or as uniform C. Encoders work in each quadrant's canonical space: a displayed vector
D of a quadrant with transform t is stored as an entry covering t^-1(D).

``best`` builds the codebook greedily by marginal gain (known cells kept) over all 11 slots --
global or quadrant-local, whichever gains more -- for each transform combination it tries:
``fast`` by coordinate descent from the identity, ``medium`` (default) every combination that
gives distinct canonical vectors, ``thorough`` the same and then swaps codebook entries while
that keeps more cells. It stops as soon as a block is lossless.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .options import ENCODERS, EFFORTS, check_maps, check_options  # noqa: F401 (re-exported)
from .vec2 import INVERSE_T, KNOWN, RETAINED, TRANS_CODE
from .vq2_block import N_ENTRIES, N_GLOBAL, SIZE, VQ2Block, quadrant_of_vector


# non-uniform codes: C mask 1..14 with either palette
CANDIDATES = np.array([(m << 1) | p for m in range(1, 15) for p in (0, 1)], dtype=np.int64)


@njit(cache=True)
def vector_codes(m):
    """(64,) displayed codes of a 16x16 map, made encodable; uniform C -> 30."""
    codes = np.empty(64, dtype=np.int64)
    for vy in range(8):
        for vx in range(8):
            s = np.empty(4, dtype=np.int64)
            nt = 0
            no = 0
            for e in range(4):
                s[e] = m[2 * vy + (e >> 1), 2 * vx + (e & 1)]
                if s[e] == 0:
                    nt += 1
                elif s[e] == 1:
                    no += 1
            if nt > 0 and no > 0:  # both O and T: turn the minority to C (keep O on a tie)
                drop = 1 if nt > no else 0
                for e in range(4):
                    if s[e] == drop:
                        s[e] = 2
                no = 0 if drop == 1 else no
            mask = 0
            for e in range(4):
                if s[e] == 2:
                    mask |= 1 << e
            codes[8 * vy + vx] = 30 if mask == 15 else (mask << 1) | (1 if no > 0 else 0)
    return codes


@njit(cache=True)
def quadrant_items(codes):
    """Distinct non-uniform codes per quadrant with their counts."""
    item_code = np.zeros((4, 16), dtype=np.int64)
    item_cnt = np.zeros((4, 16), dtype=np.int64)
    n_item = np.zeros(4, dtype=np.int64)
    for v in range(64):
        c = codes[v]
        mask = (c >> 1) & 15
        if mask == 0 or mask == 15:
            continue
        q = quadrant_of_vector(v & 7, v >> 3)
        found = False
        for k in range(n_item[q]):
            if item_code[q, k] == c:
                item_cnt[q, k] += 1
                found = True
                break
        if not found:
            item_code[q, n_item[q]] = c
            item_cnt[q, n_item[q]] = 1
            n_item[q] += 1
    return item_code, item_cnt, n_item


@njit(cache=True)
def _canonical(item_code, n_item, tr):
    cc = np.zeros((4, 16), dtype=np.int64)
    for q in range(4):
        ti = INVERSE_T[tr[q]]
        for k in range(n_item[q]):
            cc[q, k] = TRANS_CODE[ti, item_code[q, k]]
    return cc


@njit(cache=True)
def _value(cc, item_cnt, n_item, gl, ngl, lo, nlo):
    """Known cells kept (non-uniform vectors only) when each takes its best accessible entry."""
    total = 0
    for q in range(4):
        for k in range(n_item[q]):
            best = 0
            d = cc[q, k]
            for i in range(ngl):
                best = max(best, RETAINED[d, gl[i]])
            for i in range(nlo[q]):
                best = max(best, RETAINED[d, lo[q, i]])
            total += item_cnt[q, k] * best
    return total


def _coverers():
    """COVERERS[d, :N_COVERERS[d]]: the non-uniform codes that cover code d (keep some of it)."""
    cov = np.full((32, 16), -1, dtype=np.int64)
    n = np.zeros(32, dtype=np.int64)
    for d in range(32):
        for c in CANDIDATES:
            if RETAINED[d, c] > 0:
                cov[d, n[d]] = c
                n[d] += 1
    return cov, n


COVERERS, N_COVERERS = _coverers()


@njit(cache=True)
def _greedy(cc, item_cnt, n_item):
    """Fill the slots one at a time with the (entry, slot) of largest marginal gain."""
    gl = np.zeros(3, dtype=np.int64)
    lo = np.zeros((4, 2), dtype=np.int64)
    nlo = np.zeros(4, dtype=np.int64)
    ngl = 0
    cur = np.zeros((4, 16), dtype=np.int64)
    gain = np.zeros((4, 32), dtype=np.int64)  # marginal gain of each code in each quadrant
    for _ in range(N_ENTRIES):
        gain[:] = 0
        for q in range(4):
            for k in range(n_item[q]):
                d = cc[q, k]
                for j in range(N_COVERERS[d]):
                    c = COVERERS[d, j]
                    r = RETAINED[d, c] - cur[q, k]
                    if r > 0:
                        gain[q, c] += r * item_cnt[q, k]
        best_gain = 0
        best_c = -1
        best_slot = -2
        for ci in range(CANDIDATES.shape[0]):
            c = CANDIDATES[ci]
            tot = 0
            for q in range(4):
                g = gain[q, c]
                tot += g
                if nlo[q] < 2 and g > best_gain:
                    best_gain, best_c, best_slot = g, c, q
            if ngl < 3 and tot > best_gain:  # ties go to a local slot
                best_gain, best_c, best_slot = tot, c, -1
        if best_gain == 0:
            break
        if best_slot == -1:
            gl[ngl] = best_c
            ngl += 1
        else:
            lo[best_slot, nlo[best_slot]] = best_c
            nlo[best_slot] += 1
        for q in range(4):
            if best_slot == -1 or best_slot == q:
                for k in range(n_item[q]):
                    cur[q, k] = max(cur[q, k], RETAINED[cc[q, k], best_c])
    value = 0
    for q in range(4):
        for k in range(n_item[q]):
            value += cur[q, k] * item_cnt[q, k]
    return value, gl, ngl, lo, nlo


@njit(cache=True)
def _refine(cc, item_cnt, n_item, gl, ngl, lo, nlo, target, max_passes):
    """Swap one entry at a time (empty slots count as entries to fill) while it helps."""
    gl = gl.copy()
    lo = lo.copy()
    nlo = nlo.copy()
    value = _value(cc, item_cnt, n_item, gl, ngl, lo, nlo)
    for _ in range(max_passes):
        improved = False
        for slot in range(-1, 4):  # -1: the global entries, q: quadrant q's local entries
            entries = gl if slot == -1 else lo[slot]
            for i in range(entries.shape[0]):
                for ci in range(CANDIDATES.shape[0]):
                    if value == target:
                        return value, gl, ngl, lo, nlo
                    used = ngl if slot == -1 else nlo[slot]
                    if i > used:  # fill slots in order
                        break
                    old = entries[i]
                    entries[i] = CANDIDATES[ci]
                    if slot == -1:
                        ngl = max(used, i + 1)
                    else:
                        nlo[slot] = max(used, i + 1)
                    v = _value(cc, item_cnt, n_item, gl, ngl, lo, nlo)
                    if v > value:
                        value = v
                        improved = True
                    else:
                        entries[i] = old
                        if slot == -1:
                            ngl = used
                        else:
                            nlo[slot] = used
        if not improved:
            break
    return value, gl, ngl, lo, nlo


@njit(cache=True)
def _distinct_transforms(item_code, item_cnt, n_item):
    """Per quadrant, the transforms that give distinct canonical vector sets (a quadrant
    without stored vectors keeps only the identity; symmetric content needs fewer)."""
    opts = np.zeros((4, 8), dtype=np.int64)
    n_opts = np.ones(4, dtype=np.int64)
    hist = np.zeros((8, 32), dtype=np.int64)
    for q in range(1, 4):
        if n_item[q] == 0:
            continue
        n_opts[q] = 0
        for t in range(8):
            hist[t, :] = 0
            ti = INVERSE_T[t]
            for k in range(n_item[q]):
                hist[t, TRANS_CODE[ti, item_code[q, k]]] += item_cnt[q, k]
            new = True
            for j in range(n_opts[q]):
                if np.all(hist[opts[q, j]] == hist[t]):
                    new = False
                    break
            if new:
                opts[q, n_opts[q]] = t
                n_opts[q] += 1
    return opts, n_opts


@njit(cache=True)
def _search_best(item_code, item_cnt, n_item, target, effort):
    tr = np.zeros(4, dtype=np.int64)
    cc = _canonical(item_code, n_item, tr)
    best_val, gl, ngl, lo, nlo = _greedy(cc, item_cnt, n_item)
    best_tr = tr.copy()
    if best_val < target:
        if effort >= 1:  # every distinct transform combination
            opts, n_opts = _distinct_transforms(item_code, item_cnt, n_item)
            for a in range(n_opts[1]):
                for b in range(n_opts[2]):
                    for c in range(n_opts[3]):
                        tr[1], tr[2], tr[3] = opts[1, a], opts[2, b], opts[3, c]
                        if tr[1] == 0 and tr[2] == 0 and tr[3] == 0 or best_val == target:
                            continue
                        cc = _canonical(item_code, n_item, tr)
                        v, g2, n2, l2, m2 = _greedy(cc, item_cnt, n_item)
                        if v > best_val:
                            best_val, gl, ngl, lo, nlo = v, g2, n2, l2, m2
                            best_tr[:] = tr
        else:  # coordinate descent over the three transformed quadrants
            for _ in range(2):
                improved = False
                for q in range(1, 4):
                    for t in range(8):
                        if t == best_tr[q] or best_val == target:
                            continue
                        tr[:] = best_tr
                        tr[q] = t
                        cc = _canonical(item_code, n_item, tr)
                        v, g2, n2, l2, m2 = _greedy(cc, item_cnt, n_item)
                        if v > best_val:
                            best_val, gl, ngl, lo, nlo = v, g2, n2, l2, m2
                            best_tr[:] = tr
                            improved = True
                if not improved:
                    break
    if effort >= 2 and best_val < target:
        cc = _canonical(item_code, n_item, best_tr)
        best_val, gl, ngl, lo, nlo = _refine(cc, item_cnt, n_item, gl, ngl, lo, nlo, target, 4)
    return best_tr, gl, ngl, lo, nlo


@njit(cache=True)
def _naive_fill(cc, item_cnt, n_item):
    """The deck's naive compressor for one transform combination: take vectors with the fewest
    C states first (then the most frequent), into a local slot when only one quadrant uses
    them, else a global slot, else local copies, until the codebook is full."""
    codes = np.zeros(64, dtype=np.int64)
    freq = np.zeros(64, dtype=np.int64)
    qmask = np.zeros(64, dtype=np.int64)
    n = 0
    for q in range(4):
        for k in range(n_item[q]):
            c = cc[q, k]
            j = 0
            while j < n and codes[j] != c:
                j += 1
            if j == n:
                codes[n] = c
                n += 1
            freq[j] += item_cnt[q, k]
            qmask[j] |= 1 << q
    # order: fewest C states, then most frequent, then code
    order = np.arange(n)
    for a in range(n):
        for b in range(a + 1, n):
            ka = (4 - KNOWN[codes[order[a]]], -freq[order[a]], codes[order[a]])
            kb = (4 - KNOWN[codes[order[b]]], -freq[order[b]], codes[order[b]])
            if kb < ka:
                order[a], order[b] = order[b], order[a]
    gl = np.zeros(3, dtype=np.int64)
    lo = np.zeros((4, 2), dtype=np.int64)
    nlo = np.zeros(4, dtype=np.int64)
    ngl = 0
    for oi in range(n):
        if ngl == 3 and nlo.min() == 2:
            break
        j = order[oi]
        c = codes[j]
        in_gl = False
        for i in range(ngl):
            if gl[i] == c:
                in_gl = True
        if in_gl:
            continue
        nq = 0
        only = -1
        for q in range(4):
            if qmask[j] >> q & 1:
                nq += 1
                only = q
        if nq == 1 and nlo[only] < 2:
            lo[only, nlo[only]] = c
            nlo[only] += 1
        elif ngl < 3:
            gl[ngl] = c
            ngl += 1
        else:
            for q in range(4):
                if qmask[j] >> q & 1 and nlo[q] < 2:
                    lo[q, nlo[q]] = c
                    nlo[q] += 1
    return _value(cc, item_cnt, n_item, gl, ngl, lo, nlo), gl, ngl, lo, nlo


@njit(cache=True)
def _search_paper(item_code, item_cnt, n_item):
    tr = np.zeros(4, dtype=np.int64)
    best_tr = tr.copy()
    best_val = -1
    gl = np.zeros(3, dtype=np.int64)
    lo = np.zeros((4, 2), dtype=np.int64)
    nlo = np.zeros(4, dtype=np.int64)
    ngl = 0
    for t in range(512):
        tr[1], tr[2], tr[3] = t & 7, (t >> 3) & 7, t >> 6
        cc = _canonical(item_code, n_item, tr)
        v, g2, n2, l2, m2 = _naive_fill(cc, item_cnt, n_item)
        if v > best_val:
            best_val, gl, ngl, lo, nlo = v, g2, n2, l2, m2
            best_tr[:] = tr
    return best_tr, gl, ngl, lo, nlo


@njit(cache=True)
def _assemble(codes, tr, gl, ngl, lo, nlo):
    indices = np.zeros(64, dtype=np.int64)
    for v in range(64):
        c = codes[v]
        mask = (c >> 1) & 15
        if mask == 0:
            indices[v] = c & 1  # uniform T (0) or O (1)
            continue
        if mask == 15:
            indices[v] = 2
            continue
        q = quadrant_of_vector(v & 7, v >> 3)
        d = TRANS_CODE[INVERSE_T[tr[q]], c]
        best, idx = 0, 2
        for i in range(ngl):
            r = RETAINED[d, gl[i]]
            if r > best:
                best, idx = r, 3 + i
        for i in range(nlo[q]):
            r = RETAINED[d, lo[q, i]]
            if r > best:
                best, idx = r, 6 + i
        indices[v] = idx
    codebook = np.zeros(N_ENTRIES, dtype=np.int64)
    for i in range(ngl):
        codebook[i] = gl[i]
    for q in range(4):
        for i in range(nlo[q]):
            codebook[N_GLOBAL + 2 * q + i] = lo[q, i]
    return indices, codebook


@njit(cache=True)
def encode_arrays(m, encoder, effort):
    """Numba entry point: 16x16 map -> (indices, codebook, transforms). encoder 0 paper, 1 best."""
    codes = vector_codes(m)
    item_code, item_cnt, n_item = quadrant_items(codes)
    target = 0
    for q in range(4):
        for k in range(n_item[q]):
            target += item_cnt[q, k] * KNOWN[item_code[q, k]]
    if encoder == 0:
        tr, gl, ngl, lo, nlo = _search_paper(item_code, item_cnt, n_item)
    else:
        tr, gl, ngl, lo, nlo = _search_best(item_code, item_cnt, n_item, target, effort)
    indices, codebook = _assemble(codes, tr, gl, ngl, lo, nlo)
    return indices, codebook, tr


@njit(cache=True)
def encode_many_arrays(maps, encoder, effort):
    n = maps.shape[0]
    idx = np.zeros((n, 64), dtype=np.int64)
    cb = np.zeros((n, N_ENTRIES), dtype=np.int64)
    tr = np.zeros((n, 4), dtype=np.int64)
    for i in range(n):
        idx[i], cb[i], tr[i] = encode_arrays(maps[i], encoder, effort)
    return idx, cb, tr


def encode(map16, encoder: str = "best", effort: str = "medium") -> VQ2Block:
    """Encode a 16x16 map into a symbolic VQ2 block (conservative: only O->C, T->C)."""
    e, f = check_options("VQ2", encoder, effort)
    idx, cb, tr = encode_arrays(check_maps(map16, SIZE, "VQ2"), e, f)
    return VQ2Block(idx, cb, tr)


def encode_many(maps16, encoder: str = "best", effort: str = "medium") -> list[VQ2Block]:
    e, f = check_options("VQ2", encoder, effort)
    m = check_maps(maps16, SIZE, "VQ2").reshape(-1, SIZE, SIZE)
    idx, cb, tr = encode_many_arrays(m, e, f)
    return [VQ2Block(idx[i], cb[i], tr[i]) for i in range(len(m))]
