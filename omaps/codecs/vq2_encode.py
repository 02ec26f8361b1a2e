"""VQ2 encoders: the deck's naive compressor (``paper``) and our search (``best``).

Both start by making every 2x2 vector encodable (a vector with O and T together loses its
minority state to C, keeping O on a tie) and never change a state other than to C: a vector is
stored either exactly, or through a codebook entry that *covers* it (equal or C in every
element), or as uniform C. Encoders work in each quadrant's canonical space: a displayed vector
D of a quadrant with transform t is stored as an entry covering t^-1(D).

``best`` first fills the codebook greedily by marginal gain (known cells kept) over all 11 slots
with every quadrant untransformed, and stops there when that is lossless. Otherwise it searches
the *global* entries, which are what couples the quadrants: once the 3 globals are fixed, each
quadrant's transform and 2 local entries are chosen on their own. The globals are picked one at a
time (a lazy greedy: a candidate's gain from the previous pick bounds its next one), each scored
by every quadrant taking its best transform and 2 greedy locals; the first pick is scored in
displayed space (a quadrant with transform t and global g is the untransformed quadrant with
t(g)). ``medium`` (default) runs this search; ``fast`` caps the candidates scored per pick;
``thorough`` starts from ``medium``'s block, runs the greedy over every transform combination
that gives distinct canonical vectors (``medium`` before issue 14, ``EXHAUSTIVE``) and then swaps
codebook entries while that keeps more cells. Every effort keeps the best block it has seen and stops once one is lossless.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .options import ENCODERS, EFFORTS, check_maps, check_options  # noqa: F401 (re-exported)
from .vec2 import INVERSE_T, KNOWN, RETAINED, TRANS_CODE
from .vq2_block import N_ENTRIES, N_GLOBAL, N_LOCAL, SIZE, VQ2Block, pack_many, quadrant_of_vector

__all__ = ["encode", "encode_many", "encode_blocks", "encode_arrays", "encode_many_arrays", "vector_codes", "EXHAUSTIVE",
           "ENCODERS", "EFFORTS"]

CAP_FAST, CAP_MEDIUM = 3, 99  # candidates scored per pick of a global entry after the first
EXHAUSTIVE = 3  # effort number of the issue-14 baseline (``medium`` before): the greedy codebook
# for every distinct transform combination; encode_many_arrays(maps, 1, EXHAUSTIVE)

# non-uniform codes: C mask 1..14 with either palette
CANDIDATES = np.array([(m << 1) | p for m in range(1, 15) for p in (0, 1)], dtype=np.int64)


@njit(cache=True)
def vector_codes(m):
    """(64,) displayed codes of a 16x16 map, made encodable; uniform C -> 30."""
    codes = np.empty(64, dtype=np.int64)
    for vy in range(8):
        for vx in range(8):
            nt = 0
            no = 0
            for e in range(4):
                s = m[2 * vy + (e >> 1), 2 * vx + (e & 1)]
                nt += s == 0
                no += s == 1
            drop = 3  # no state dropped
            if nt > 0 and no > 0:  # both O and T: turn the minority to C (keep O on a tie)
                drop = 1 if nt > no else 0
                no = 0 if drop == 1 else no
            mask = 0
            for e in range(4):
                s = m[2 * vy + (e >> 1), 2 * vx + (e & 1)]
                if s == 2 or s == drop:
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
    """COVERERS[d, :N_COVERERS[d]]: the non-uniform codes that cover code d (keep some of it),
    most cells kept first (a search stops at the first that keeps no more than it has);
    COVER_KEEPS[d, j]: the cells COVERERS[d, j] keeps of d."""
    cov = np.full((32, 16), -1, dtype=np.int64)
    keeps = np.zeros((32, 16), dtype=np.int64)
    n = np.zeros(32, dtype=np.int64)
    for d in range(32):
        for c in sorted(CANDIDATES, key=lambda c: (-RETAINED[d, c], c)):
            if RETAINED[d, c] > 0:
                cov[d, n[d]] = c
                keeps[d, n[d]] = RETAINED[d, c]
                n[d] += 1
    return cov, keeps, n


COVERERS, COVER_KEEPS, N_COVERERS = _coverers()


def _orbits():
    """ORBITS[o, :]: the non-uniform codes one transform takes into each other (-1 padded)."""
    out, seen = [], set()
    for c in CANDIDATES:
        if c not in seen:
            o = sorted(set(int(x) for x in TRANS_CODE[:, c]))
            seen.update(o)
            out.append(o + [-1] * (8 - len(o)))
    return np.array(out, dtype=np.int64)


ORBITS = _orbits()


@njit(cache=True)
def _greedy(cc, item_cnt, n_item):
    """Fill the slots one at a time with the (entry, slot) of largest marginal gain."""
    gl = np.zeros(3, dtype=np.int64)
    lo = np.zeros((4, 2), dtype=np.int64)
    nlo = np.zeros(4, dtype=np.int64)
    ngl = 0
    cur = np.zeros((4, 16), dtype=np.int64)
    gain = np.zeros((4, 32), dtype=np.int64)  # marginal gain of each code in each quadrant
    missing = 0  # known cells not kept yet
    for q in range(4):
        for k in range(n_item[q]):
            missing += KNOWN[cc[q, k]] * item_cnt[q, k]
    for _ in range(N_ENTRIES):
        if missing == 0:
            break
        gain[:] = 0
        for q in range(4):
            for k in range(n_item[q]):
                d = cc[q, k]
                for j in range(N_COVERERS[d]):
                    r = COVER_KEEPS[d, j] - cur[q, k]
                    if r <= 0:
                        break
                    gain[q, COVERERS[d, j]] += r * item_cnt[q, k]
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
        missing -= best_gain
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
    without stored vectors keeps only the identity; symmetric content needs fewer), in
    increasing order, and each one's canonical item codes: ``cc[q, j, k]`` is item k of
    quadrant q under transform ``opts[q, j]``."""
    opts = np.zeros((4, 8), dtype=np.int64)
    n_opts = np.ones(4, dtype=np.int64)
    cc = np.zeros((4, 8, 16), dtype=np.int64)
    count = np.zeros((8, 32), dtype=np.int64)  # count[j, code]: the kept transform j's counts
    sets = np.zeros(8, dtype=np.int64)  # bit mask of the codes each kept transform gives
    for k in range(n_item[0]):
        cc[0, 0, k] = item_code[0, k]
    for q in range(1, 4):
        n = n_item[q]
        for k in range(n):
            cc[q, 0, k] = item_code[q, k]
        if n == 0:
            continue
        n_opts[q] = 0
        for t in range(8):
            j = n_opts[q]
            ti = INVERSE_T[t]
            mask = 0
            for k in range(n):
                c = TRANS_CODE[ti, item_code[q, k]]
                cc[q, j, k] = c
                mask |= 1 << c
            new = True
            for i in range(j):  # the same codes (a transform keeps items distinct) and counts
                if sets[i] == mask:
                    same = True
                    for k in range(n):
                        if count[i, cc[q, j, k]] != item_cnt[q, k]:
                            same = False
                            break
                    if same:
                        new = False
                        break
            if new:
                opts[q, j] = t
                sets[j] = mask
                for k in range(n):
                    count[j, cc[q, j, k]] = item_cnt[q, k]
                n_opts[q] += 1
        for i in range(n_opts[q]):  # clear the counts for the next quadrant
            for k in range(n):
                count[i, cc[q, i, k]] = 0
    return opts, n_opts, cc


@njit(cache=True)
def _search_exhaustive(item_code, item_cnt, n_item, target, gl, ngl, lo, nlo, best_tr, best_val):
    """The greedy codebook for every distinct transform combination, from a starting block."""
    tr = np.zeros(4, dtype=np.int64)
    opts, n_opts, _ = _distinct_transforms(item_code, item_cnt, n_item)
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
    return best_val, gl, ngl, lo, nlo


@njit(cache=True)
def _fill_locals(cc, row, w, n, cur, gain, lo):
    """Two local entries chosen greedily for the n items ``cc[row, :n]`` (counts ``w``) on top of
    ``cur`` (known cells each keeps so far; updated) -> (value, entries put in ``lo``). ``gain``
    (32,) is zero on entry and on return."""
    nl = 0
    for _ in range(N_LOCAL):
        some = False
        for k in range(n):
            d = cc[row, k]
            ck = cur[k]
            for j in range(N_COVERERS[d]):
                r = COVER_KEEPS[d, j] - ck
                if r <= 0:
                    break
                gain[COVERERS[d, j]] += r * w[k]
                some = True
        if not some:
            break
        best_g = 0
        best_c = -1
        for k in range(n):  # the largest gain (the first found on a tie); clears gain
            d = cc[row, k]
            for j in range(N_COVERERS[d]):
                if COVER_KEEPS[d, j] <= cur[k]:
                    break
                c = COVERERS[d, j]
                if gain[c] > best_g:
                    best_g = gain[c]
                    best_c = c
                gain[c] = 0
        lo[nl] = best_c
        nl += 1
        for k in range(n):
            cur[k] = max(cur[k], RETAINED[cc[row, k], best_c])
    v = 0
    for k in range(n):
        v += cur[k] * w[k]
    return v, nl


@njit(cache=True)
def _search_globals(item_code, item_cnt, n_item, target, cap):
    """The global entries by a lazy greedy; each quadrant then takes its best transform and two
    greedy locals. ``cap`` bounds the candidates scored per pick after the first.
    Returns (value, transforms, gl, ngl, lo, nlo)."""
    opts, n_opts, cc3 = _distinct_transforms(item_code, item_cnt, n_item)
    cc = cc3.reshape(32, 16)  # row 8q + j: quadrant q's items under transform opts[q, j]
    gain = np.zeros(32, dtype=np.int64)
    cur = np.zeros(16, dtype=np.int64)
    lo2 = np.zeros(N_LOCAL, dtype=np.int64)
    # no globals: a quadrant's value and locals do not depend on its transform
    base = np.zeros(4, dtype=np.int64)
    base_lo = np.zeros((4, N_LOCAL), dtype=np.int64)
    base_nlo = np.zeros(4, dtype=np.int64)
    base_cur = np.zeros((4, 16), dtype=np.int64)
    for q in range(4):
        n = n_item[q]
        cur[:n] = 0
        base[q], base_nlo[q] = _fill_locals(cc, 8 * q, item_cnt[q], n, cur, gain, base_lo[q])
        base_cur[q, :n] = cur[:n]
    value = base.sum()
    # the first pick in displayed space: shown[q, x] = quadrant q (untransformed) with entry x.
    # Quadrants 1..3 take the best transform of a candidate, so only each orbit's best counts.
    shown = np.zeros((4, 32), dtype=np.int64)
    cover = np.zeros((4, 32), dtype=np.int64)  # cells entry x keeps of quadrant q (untransformed)
    full = np.zeros(4, dtype=np.int64)  # every known cell of the quadrant kept
    for q in range(4):
        n = n_item[q]
        w = item_cnt[q]
        for k in range(n):
            full[q] += KNOWN[cc[8 * q, k]] * w[k]
        for o in range(ORBITS.shape[0]):
            top = 0
            for i in range(ORBITS.shape[1]):
                x = ORBITS[o, i]
                if x < 0:
                    break
                lb = base[q]  # x added to the locals already chosen
                ub = base[q]  # x's cells on top of nothing (re-chosen locals can do no better)
                for k in range(n):
                    r = RETAINED[cc[8 * q, k], x]
                    ub += r * w[k]
                    if r > base_cur[q, k]:
                        lb += (r - base_cur[q, k]) * w[k]
                cover[q, x] = ub - base[q]
                if min(ub, full[q]) > (lb if q == 0 else max(lb, top)):
                    for k in range(n):
                        cur[k] = RETAINED[cc[8 * q, k], x]
                    v, _ = _fill_locals(cc, 8 * q, w, n, cur, gain, lo2)
                    lb = max(lb, v)
                shown[q, x] = lb
                top = max(top, lb)
    bound = np.zeros(CANDIDATES.shape[0], dtype=np.int64)  # a candidate's last gain
    for ci in range(CANDIDATES.shape[0]):
        c = CANDIDATES[ci]
        v = shown[0, c]
        for q in range(1, 4):
            b = 0
            for t in range(8):
                b = max(b, shown[q, TRANS_CODE[t, c]])
            v += b
        bound[ci] = v - value
    # per (quadrant, transform) row: cells kept per item by the globals (kept_g) and by the
    # globals and locals (kept), the locals and the value
    kept_g = np.zeros((32, 16), dtype=np.int64)
    kept = np.zeros((32, 16), dtype=np.int64)
    row_lo = np.zeros((32, N_LOCAL), dtype=np.int64)
    row_nlo = np.zeros(32, dtype=np.int64)
    row_val = np.zeros(32, dtype=np.int64)
    for q in range(4):
        for j in range(n_opts[q]):
            r = 8 * q + j
            kept[r, :n_item[q]] = base_cur[q, :n_item[q]]
            for i in range(base_nlo[q]):
                row_lo[r, i] = TRANS_CODE[INVERSE_T[opts[q, j]], base_lo[q, i]]
            row_nlo[r] = base_nlo[q]
            row_val[r] = base[q]
    lbs = np.zeros(32, dtype=np.int64)
    ubs = np.zeros(32, dtype=np.int64)
    q_ub = np.zeros(4, dtype=np.int64)
    q_best = base.copy()  # each quadrant's best row value
    gl = np.zeros(N_GLOBAL, dtype=np.int64)
    ngl = 0
    done = np.zeros(CANDIDATES.shape[0], dtype=np.bool_)
    used = np.zeros(CANDIDATES.shape[0], dtype=np.bool_)
    for step in range(N_GLOBAL):
        if value == target:
            break
        done[:] = used
        best_gain = 0
        best_ci = -1
        scored = 0
        while step == 0 or scored < cap:
            ci = -1  # the unscored candidate of largest bound, if that beats the best so far
            top = best_gain
            for i in range(CANDIDATES.shape[0]):
                if not done[i] and bound[i] > top:
                    top = bound[i]
                    ci = i
            if ci < 0:
                break
            done[ci] = True
            if step > 0:  # score it: each quadrant's best transform with it and 2 locals
                scored += 1
                c = CANDIDATES[ci]
                ub_tot = 0  # first a bound from c's cells alone, per quadrant and transform
                for q in range(4):
                    bu = q_best[q]
                    for j in range(n_opts[q]):
                        bu = max(bu, min(full[q], row_val[8 * q + j] + cover[q, TRANS_CODE[opts[q, j], c]]))
                    ub_tot += bu
                if ub_tot - value <= best_gain:
                    bound[ci] = ub_tot - value
                    continue
                ub_tot = 0
                for q in range(4):
                    n = n_item[q]
                    w = item_cnt[q]
                    bu = q_best[q]
                    for j in range(n_opts[q]):
                        r = 8 * q + j
                        lbs[r] = 0
                        ubs[r] = 0
                        if row_val[r] + cover[q, TRANS_CODE[opts[q, j], c]] <= q_best[q]:
                            continue  # even all of c's cells leave this row behind the best
                        lb = row_val[r]  # c added, locals kept
                        ub = row_val[r]  # c's gain over the globals alone
                        for k in range(n):
                            x = RETAINED[cc[r, k], c]
                            if x > kept[r, k]:
                                lb += (x - kept[r, k]) * w[k]
                            if x > kept_g[r, k]:
                                ub += (x - kept_g[r, k]) * w[k]
                        lbs[r] = lb
                        ubs[r] = min(ub, full[q])
                        bu = max(bu, ubs[r])
                    q_ub[q] = bu
                    ub_tot += bu
                # exact where it may matter, best bound first; stop once c cannot win the pick
                for q in range(4):
                    n = n_item[q]
                    bl = q_best[q]
                    for j in range(n_opts[q]):
                        bl = max(bl, lbs[8 * q + j])
                    while ub_tot - value > best_gain:
                        r = -1
                        top = bl
                        for j in range(n_opts[q]):
                            if ubs[8 * q + j] > top:
                                top = ubs[8 * q + j]
                                r = 8 * q + j
                        if r < 0:
                            break
                        ubs[r] = 0
                        for k in range(n):
                            cur[k] = max(kept_g[r, k], RETAINED[cc[r, k], c])
                        v, _ = _fill_locals(cc, r, item_cnt[q], n, cur, gain, lo2)
                        bl = max(bl, v)
                        ub_tot -= q_ub[q]  # the quadrant's bound: its best so far or a row left
                        q_ub[q] = bl
                        for j in range(n_opts[q]):
                            q_ub[q] = max(q_ub[q], ubs[8 * q + j])
                        ub_tot += q_ub[q]
                bound[ci] = ub_tot - value  # exact unless c lost early (then a bound)
            if bound[ci] > best_gain:
                best_gain = bound[ci]
                best_ci = ci
        if best_ci < 0:
            break
        used[best_ci] = True
        c = CANDIDATES[best_ci]
        gl[ngl] = c
        ngl += 1
        value = 0
        for q in range(4):  # take c into every row: locals kept, or re-chosen where that may win
            n = n_item[q]
            w = item_cnt[q]
            bq = 0
            for j in range(n_opts[q]):
                r = 8 * q + j
                lb = 0
                ub = row_val[r]
                for k in range(n):
                    x = RETAINED[cc[r, k], c]
                    if x > kept_g[r, k]:
                        ub += (x - kept_g[r, k]) * w[k]
                        kept_g[r, k] = x
                    kept[r, k] = max(kept[r, k], x)
                    lb += kept[r, k] * w[k]
                row_val[r] = lb
                ubs[r] = min(ub, full[q])
                bq = max(bq, lb)
            for j in range(n_opts[q]):
                r = 8 * q + j
                if ubs[r] > row_val[r] and (step < N_GLOBAL - 1 or ubs[r] > bq):  # the last pick: only a win counts
                    cur[:n] = kept_g[r, :n]
                    v, nl = _fill_locals(cc, r, w, n, cur, gain, lo2)
                    if v > row_val[r]:
                        row_val[r] = v
                        row_nlo[r] = nl
                        row_lo[r, :] = lo2
                        kept[r, :n] = cur[:n]
                        bq = max(bq, v)
            q_best[q] = bq
            value += bq
    tr = np.zeros(4, dtype=np.int64)
    lo = np.zeros((4, N_LOCAL), dtype=np.int64)
    nlo = np.zeros(4, dtype=np.int64)
    value = 0
    for q in range(4):
        bj = 0
        for j in range(1, n_opts[q]):
            if row_val[8 * q + j] > row_val[8 * q + bj]:
                bj = j
        r = 8 * q + bj
        tr[q] = opts[q, bj]
        lo[q] = row_lo[r]
        nlo[q] = row_nlo[r]
        value += row_val[r]
    return value, tr, gl, ngl, lo, nlo


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
def _prepare(m):
    """A map's displayed codes, per-quadrant items, its known cells (non-uniform vectors), and
    the greedy codebook with every quadrant untransformed (the search's start)."""
    codes = vector_codes(m)
    item_code, item_cnt, n_item = quadrant_items(codes)
    target = 0
    for q in range(4):
        for k in range(n_item[q]):
            target += item_cnt[q, k] * KNOWN[item_code[q, k]]
    return codes, item_code, item_cnt, n_item, target


# One compiled entry per search, each a flat loop (a kernel's cached code holds every kernel it
# calls, so nesting entries would compile the searches again per level): effort fast / medium
# (``_encode_best``), thorough / EXHAUSTIVE (``_encode_exhaustive``), and the deck's encoder.
@njit(cache=True)
def _encode_best(maps, cap):
    n = maps.shape[0]
    idx = np.zeros((n, 64), dtype=np.int64)
    cb = np.zeros((n, N_ENTRIES), dtype=np.int64)
    trs = np.zeros((n, 4), dtype=np.int64)
    for i in range(n):
        codes, item_code, item_cnt, n_item, target = _prepare(maps[i])
        tr = np.zeros(4, dtype=np.int64)
        val, gl, ngl, lo, nlo = _greedy(item_code, item_cnt, n_item)
        if val < target:
            v, t2, g2, n2, l2, m2 = _search_globals(item_code, item_cnt, n_item, target, cap)
            if v > val:
                tr, gl, ngl, lo, nlo = t2, g2, n2, l2, m2
        idx[i], cb[i] = _assemble(codes, tr, gl, ngl, lo, nlo)
        trs[i] = tr
    return idx, cb, trs


@njit(cache=True)
def _encode_exhaustive(maps, start_cb, start_tr, thorough):
    """EXHAUSTIVE from the untransformed greedy block; thorough from the better of that and the
    given start blocks (medium's: its kernel is not linked here, which halves this compile)."""
    n = maps.shape[0]
    idx = np.zeros((n, 64), dtype=np.int64)
    cb = np.zeros((n, N_ENTRIES), dtype=np.int64)
    trs = np.zeros((n, 4), dtype=np.int64)
    for i in range(n):
        codes, item_code, item_cnt, n_item, target = _prepare(maps[i])
        tr = np.zeros(4, dtype=np.int64)
        val, gl, ngl, lo, nlo = _greedy(item_code, item_cnt, n_item)
        if thorough and val < target:
            g2 = start_cb[i, :N_GLOBAL].copy()
            l2 = start_cb[i, N_GLOBAL:].copy().reshape(4, N_LOCAL)
            m2 = np.full(4, N_LOCAL, dtype=np.int64)  # unused entries hold code 0, which keeps nothing
            v = _value(_canonical(item_code, n_item, start_tr[i]), item_cnt, n_item, g2, N_GLOBAL, l2, m2)
            if v > val:
                val, gl, ngl, lo, nlo = v, g2, N_GLOBAL, l2, m2
                tr[:] = start_tr[i]
        if val < target:
            val, gl, ngl, lo, nlo = _search_exhaustive(item_code, item_cnt, n_item, target, gl, ngl, lo, nlo,
                                                       tr, val)
        if thorough and val < target:
            val, gl, ngl, lo, nlo = _refine(_canonical(item_code, n_item, tr), item_cnt, n_item, gl, ngl, lo,
                                            nlo, target, 4)
        idx[i], cb[i] = _assemble(codes, tr, gl, ngl, lo, nlo)
        trs[i] = tr
    return idx, cb, trs


@njit(cache=True)
def _encode_paper(maps):
    n = maps.shape[0]
    idx = np.zeros((n, 64), dtype=np.int64)
    cb = np.zeros((n, N_ENTRIES), dtype=np.int64)
    trs = np.zeros((n, 4), dtype=np.int64)
    for i in range(n):
        codes, item_code, item_cnt, n_item, target = _prepare(maps[i])
        tr, gl, ngl, lo, nlo = _search_paper(item_code, item_cnt, n_item)
        idx[i], cb[i] = _assemble(codes, tr, gl, ngl, lo, nlo)
        trs[i] = tr
    return idx, cb, trs


def encode_many_arrays(maps, encoder: int, effort: int):
    """(n, 16, 16) uint8 maps -> (indices (n, 64), codebooks (n, 11), transforms (n, 4)).
    ``encoder`` 0 paper, 1 best; ``effort`` 0 fast, 1 medium, 2 thorough or ``EXHAUSTIVE``."""
    if encoder == 0:
        return _encode_paper(maps)
    if effort == 2:  # thorough: medium's blocks, then the exhaustive search and swaps from them
        _, cb, tr = _encode_best(maps, CAP_MEDIUM)
        return _encode_exhaustive(maps, cb, tr, True)
    if effort == EXHAUSTIVE:
        n = len(maps)
        return _encode_exhaustive(maps, np.zeros((n, N_ENTRIES), np.int64), np.zeros((n, 4), np.int64), False)
    return _encode_best(maps, CAP_FAST if effort == 0 else CAP_MEDIUM)


def encode_arrays(m, encoder: int, effort: int):
    """One 16x16 map: ``encode_many_arrays`` of it alone."""
    idx, cb, tr = encode_many_arrays(np.ascontiguousarray(m, dtype=np.uint8)[None], encoder, effort)
    return idx[0], cb[0], tr[0]


def encode(map16, encoder: str = "best", effort: str = "medium") -> VQ2Block:
    """Encode a 16x16 map into a symbolic VQ2 block (conservative: only O->C, T->C)."""
    e, f = check_options("VQ2", encoder, effort)
    idx, cb, tr = encode_arrays(check_maps(map16, SIZE, "VQ2"), e, f)
    return VQ2Block(idx, cb, tr)


def encode_blocks(maps16, encoder: str = "best", effort: str = "medium") -> np.ndarray:
    """Encode (n, 16, 16) maps (or one) straight to their physical blocks (n, 32) uint8, packed in
    bulk (no block objects): the bytes ``encode_many``'s blocks pack to."""
    e, f = check_options("VQ2", encoder, effort)
    return pack_many(*encode_many_arrays(check_maps(maps16, SIZE, "VQ2").reshape(-1, SIZE, SIZE), e, f))


def encode_many(maps16, encoder: str = "best", effort: str = "medium") -> list[VQ2Block]:
    """Encode (n, 16, 16) maps (or one) into symbolic VQ2 blocks, as ``encode`` does each."""
    e, f = check_options("VQ2", encoder, effort)
    m = check_maps(maps16, SIZE, "VQ2").reshape(-1, SIZE, SIZE)
    idx, cb, tr = encode_many_arrays(m, e, f)
    return [VQ2Block(idx[i], cb[i], tr[i]) for i in range(len(m))]
