"""VQ4 encoders: the deck's top-down partitioning (``paper``) and our search (``best``).

Both work on *patterns* (``vec4``: known-T and known-O masks of a 4x4 vector) in each quadrant's
stored space: a displayed vector D of a quadrant with transform t is stored as t^-1(D). Uniform
T, O and C vectors take the implicit indices 0, 1, 2. Every other vector takes the codebook entry
that keeps most of its known cells among those that *cover* it (equal or C in every element), or
uniform C; so no encoder can change a state other than to C.

``paper`` splits the set of distinct vectors top-down, as median cut does for colours: it
repeatedly splits one set in two (by the state of one element, the split that keeps most known
cells) until there are as many sets as entries, represents each set by its conservative merge,
and gives the sets to the entry kinds by dynamic programming. Transforms by coordinate descent.

``best`` builds the codebook from a candidate pool -- each distinct vector and the conservative
merge of each pair, projected onto every entry kind -- greedily by marginal gain (known cells
kept), then swaps single entries while that keeps more cells. A candidate keeps the same cells of
every vector it covers, so the pool is a list of 64-bit item masks and the gains are popcounts;
the greedy is lazy (gains only fall: a candidate is re-scored only when its bucket is the top).
Transforms:
  fast      quadrant by quadrant, the transform that best aligns its vectors with those placed;
  medium    every combination ranked by cheap coverage scores of the vectors' general-kind
            projections (tabled per relative transform, ``_rank_transforms``), the best 5 scored
            by the codebook search over the pair merges that keep at least half of a vector;
  thorough  every combination scored by a greedy over the vectors alone, the best 16 by the full
            codebook search, then coordinate descent with it; the final codebook also tries
            merges of the vectors each entry serves.
On the shared corpus the codebook is close to optimal for its transforms (simulated annealing
over vector groupings found 0.7 % more of the lost cells); the transforms matter more.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic

from .. import states
from .options import ENCODERS, EFFORTS, check_maps, check_options  # noqa: F401 (re-exported)
from .vec4 import FULL, FWD4, GENERAL, INV4, entry_code, popcount16, project, transform_mask, untransform_mask
from .vq4_block import ENTRY_KIND, N_ENTRIES, SIZE, X64_BYTES, X64_SIZE, VQ4Block, pack_many

N_KINDS = 4
TOP_K = 16
PRUNED = 4  # added to a codebook level: fewer pair merges (see ``_candidates``)
RANK_PRE = 8  # combinations the cheaper ranking score passes to the greedy one
CAPACITY = np.bincount(ENTRY_KIND, minlength=N_KINDS).astype(np.int64)  # entries per kind: 3, 1, 1, 8
# transform search per effort (see ``_search``):
# (start 0 identity / 1 aligned / 3 ranked / 4 ranked cheaply, coordinate-descent level (start 4:
# the level scoring the best few), passes (start 4: how many), final level)
SEARCH = np.array([[1, 0, 0, 2], [4, PRUNED + 2, 5, PRUNED + 2], [3, 2, 1, 3]], dtype=np.int64)
KIND_FIRST = np.array([int(np.flatnonzero(ENTRY_KIND == k)[0]) for k in range(N_KINDS)], dtype=np.int64)
# RELATIVE[tb, ta]: the transform r with r(x) = tb(ta^-1(x)), so that a pattern stored under ta
# and shown under tb is the displayed pattern moved by r
RELATIVE = np.array([[next(r for r in range(8) if np.array_equal(FWD4[r], FWD4[tb][INV4[ta]])) for ta in range(8)]
                     for tb in range(8)], dtype=np.int64)


@intrinsic
def popcount64(typingctx, x):
    """Set bits of an integer (one instruction)."""
    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])
    return x(x), codegen


@njit(cache=True)
def displayed_masks(m):
    """(64,) known-T and known-O masks of the displayed 4x4 vectors of a 32x32 map."""
    dt = np.zeros(64, dtype=np.int64)
    do = np.zeros(64, dtype=np.int64)
    for v in range(64):
        vy, vx = v >> 3, v & 7
        for e in range(16):
            s = m[4 * vy + (e >> 2), 4 * vx + (e & 3)]
            if s == 0:
                dt[v] |= 1 << e
            elif s == 1:
                do[v] |= 1 << e
    return dt, do


@njit(cache=True, inline="always")
def _quadrant(v):
    return 2 * ((v >> 3) >> 2) + ((v & 7) >> 2)


@njit(cache=True, inline="always")
def _uniform(kt, ko):
    return kt == FULL or ko == FULL or (kt | ko) == 0


@njit(cache=True)
def _items(dt, do, tr):
    """Distinct non-uniform stored patterns under transforms ``tr`` and their counts."""
    it = np.zeros(64, dtype=np.int64)
    io = np.zeros(64, dtype=np.int64)
    w = np.zeros(64, dtype=np.int64)
    n = 0
    for v in range(64):
        if _uniform(dt[v], do[v]):
            continue
        t = tr[_quadrant(v)]
        st = untransform_mask(dt[v], t)
        so = untransform_mask(do[v], t)
        k = 0
        while k < n and (it[k] != st or io[k] != so):
            k += 1
        if k == n:
            it[n], io[n] = st, so
            n += 1
        w[k] += 1
    return it[:n], io[:n], w[:n]


@njit(cache=True)
def _lossless_value(it, io, w):
    total = 0
    for i in range(it.shape[0]):
        total += w[i] * popcount16(it[i] | io[i])
    return total


@njit(cache=True, inline="always")
def _retained(ct, co, it, io):
    """Known cells an entry keeps of a vector it covers, 0 if it does not cover it."""
    if (ct & ~it) != 0 or (co & ~io) != 0:
        return 0
    return popcount16(ct | co)


# ---------------------------------------------------------------------------------------------
# candidate pool and its gain matrix

@njit(cache=True)
def _candidates(it, io, pairs):
    """Unique (kind, pattern) candidates: every item and (``pairs`` 1) the conservative merge of
    every pair of items (``pairs`` 2: of the pairs whose merge keeps at least half the known
    cells of the first), projected onto every kind; sorted by kind, so that ties prefer the more
    constrained kinds."""
    n = it.shape[0]
    nb = n + (n * (n - 1) // 2 if pairs > 0 else 0)
    bt = np.empty(nb, dtype=np.int64)
    bo = np.empty(nb, dtype=np.int64)
    bt[:n] = it
    bo[:n] = io
    nb = n
    if pairs > 0:
        for a in range(n):
            half = popcount16(it[a] | io[a]) if pairs == 2 else 1
            for c in range(a + 1, n):
                mt, mo = it[a] & it[c], io[a] & io[c]
                if 2 * popcount16(mt | mo) >= half:
                    bt[nb], bo[nb] = mt, mo
                    nb += 1
    return _pool(bt[:nb], bo[:nb], n)


@njit(cache=True)
def _pool(bt, bo, n_first):
    """Unique projections of base patterns onto every kind, as (kinds, T masks, O masks, whether
    a projection of one of the first ``n_first`` bases)."""
    keys = np.empty(bt.shape[0] * N_KINDS, dtype=np.int64)
    nk = 0
    nk_first = 0
    for b in range(bt.shape[0]):
        for kind in range(N_KINDS):
            kt, ko = project(kind, bt[b], bo[b])
            if (kt | ko) != 0:
                keys[nk] = (kind << 32) | (kt << 16) | ko
                nk += 1
        if b + 1 == n_first:
            nk_first = nk
    u, first = _unique_by_kind(keys[:nk], nk_first)
    return u >> 32, (u >> 16) & FULL, u & FULL, first


# Pools are deduplicated with a small hash table: numba's sort made np.unique the slowest step.

@njit(cache=True)
def _new_table(n):
    size = 16
    while size < 2 * n:
        size <<= 1
    return np.full(size, -1, dtype=np.int64)


@njit(cache=True, inline="always")
def _slot(table, keys, key):
    """Slot of ``key`` in an open-addressing table of positions into ``keys`` (free: -1)."""
    mask = table.shape[0] - 1
    h = ((key * 0x9E3779B1) ^ (key >> 17)) & mask
    while table[h] >= 0 and keys[table[h]] != key:
        h = (h + 1) & mask
    return h


@njit(cache=True)
def _unique_by_kind(keys, n_first):
    """Distinct keys (kind << 32 | T << 16 | O), grouped by kind in increasing order, and whether
    each is among the first ``n_first`` keys."""
    table = _new_table(keys.shape[0])
    uniq = np.empty_like(keys)
    early = np.empty(keys.shape[0], dtype=np.bool_)
    m = 0
    count = np.zeros(N_KINDS + 1, dtype=np.int64)
    for j in range(keys.shape[0]):
        key = keys[j]
        h = _slot(table, uniq, key)
        if table[h] < 0:
            table[h] = m
            uniq[m] = key
            early[m] = j < n_first
            m += 1
            count[(key >> 32) + 1] += 1
    for k in range(N_KINDS):
        count[k + 1] += count[k]
    out = np.empty(m, dtype=np.int64)
    first = np.zeros(m, dtype=np.bool_)
    for i in range(m):
        k = uniq[i] >> 32
        out[count[k]] = uniq[i]
        first[count[k]] = early[i]
        count[k] += 1
    return out, first


@njit(cache=True)
def _positions(pool_keys, queries):
    """Index in ``pool_keys`` of each query key (all present)."""
    table = _new_table(pool_keys.shape[0])
    for i in range(pool_keys.shape[0]):
        table[_slot(table, pool_keys, pool_keys[i])] = i
    out = np.empty(queries.shape[0], dtype=np.int64)
    for j in range(queries.shape[0]):
        out[j] = table[_slot(table, pool_keys, queries[j])]
    return out


@njit(cache=True)
def _covers(ct, co, it, io):
    """Bit i of cov[c] set when candidate c covers item i (at most 64 items), and the known cells
    pc[c] that c keeps of every item it covers: the gain of c on item i is pc[c] or 0."""
    n = it.shape[0]
    nit = ~it & FULL
    nio = ~io & FULL
    cov = np.zeros(ct.shape[0], dtype=np.int64)
    pc = np.empty(ct.shape[0], dtype=np.int64)
    for c in range(ct.shape[0]):
        a, b = ct[c], co[c]
        m = 0
        for i in range(n):
            m |= np.int64(((a & nit[i]) | (b & nio[i])) == 0) << i
        cov[c] = m
        pc[c] = popcount16(a | b)
    return cov, pc


@njit(cache=True)
def _marginal(cov, pc, c, cur, w):
    """Cells candidate c adds to the items' current best counts ``cur``."""
    s = 0
    p = pc[c]
    m = cov[c]
    while m != 0:
        i = trailing_zeros(m)
        m &= m - 1
        d = p - cur[i]
        if d > 0:
            s += d * w[i]
    return s


@njit(cache=True)
def _weight_planes(w):
    """Bit planes of the item weights: plane b holds the items whose weight has bit b, so that
    the weight of an item set x is the sum of popcount(x & plane b) << b."""
    top = 0
    for i in range(w.shape[0]):
        top = max(top, w[i])
    n_planes = 1
    while top >> n_planes:
        n_planes += 1
    planes = np.zeros(n_planes, dtype=np.int64)
    for i in range(w.shape[0]):
        for b in range(planes.shape[0]):
            if (w[i] >> b) & 1:
                planes[b] |= np.int64(1) << i
    return planes


@njit(cache=True)
def _weight(x, planes):
    s = 0
    for b in range(planes.shape[0]):
        s += popcount64(x & planes[b]) << b
    return s


@njit(cache=True)
def _greedy(cov, pc, ck, w, cands):
    """Slots filled one at a time by the candidate (of ``cands``, increasing) of largest marginal
    gain whose kind has room, the first on a tie. chosen[s] is the candidate in entry s (-1
    empty). Lazily: marginal gains only fall as entries are chosen, so each candidate waits in
    the bucket of its last known gain and is re-scored only when that bucket is the highest."""
    nc = cands.shape[0]
    planes = _weight_planes(w)
    cur = np.zeros(w.shape[0], dtype=np.int64)
    hi = 16 * w.sum()
    head = np.full(hi + 1, -1, dtype=np.int64)  # bucket lists by gain
    nxt = np.empty(nc, dtype=np.int64)
    stamp = np.full(nc, -1, dtype=np.int64)  # the step at which the gain was last computed
    fresh = np.empty(nc, dtype=np.int64)
    for j in range(nc):
        v = pc[cands[j]] * _weight(cov[cands[j]], planes)
        if v > 0:
            nxt[j] = head[v]
            head[v] = j
    used = np.zeros(N_KINDS, dtype=np.int64)
    chosen = np.full(N_ENTRIES, -1, dtype=np.int64)
    step = 0
    while step < N_ENTRIES:
        while hi > 0 and head[hi] < 0:
            hi -= 1
        if hi == 0:
            break
        j = head[hi]
        head[hi] = -1
        nf = 0
        pick = nc
        while j >= 0:  # re-score the bucket: those still at hi are the best
            nj = nxt[j]
            c = cands[j]
            if used[ck[c]] < CAPACITY[ck[c]]:
                v = hi
                if stamp[j] != step:
                    v = _marginal(cov, pc, c, cur, w)
                    stamp[j] = step
                if v == hi:
                    fresh[nf] = j
                    nf += 1
                    pick = min(pick, j)
                elif v > 0:
                    nxt[j] = head[v]
                    head[v] = j
            j = nj
        for f in range(nf):
            if fresh[f] != pick:
                nxt[fresh[f]] = head[hi]
                head[hi] = fresh[f]
        if nf == 0:
            continue
        p = cands[pick]
        k = ck[p]
        chosen[KIND_FIRST[k] + used[k]] = p
        used[k] += 1
        m = cov[p]
        while m != 0:
            i = trailing_zeros(m)
            m &= m - 1
            cur[i] = max(cur[i], pc[p])
        step += 1
    return chosen


@njit(cache=True)
def _value_without(cov, pc, chosen, skip, w, cur):
    """Fills ``cur`` with each item's best retained count over the chosen entries but ``skip``."""
    cur[:] = 0
    for s in range(N_ENTRIES):
        c = chosen[s]
        if s != skip and c >= 0:
            p = pc[c]
            m = cov[c]
            while m != 0:
                i = trailing_zeros(m)
                m &= m - 1
                cur[i] = max(cur[i], p)
    total = 0
    for i in range(cur.shape[0]):
        total += cur[i] * w[i]
    return total


@njit(cache=True)
def _swap(cov, pc, ck, w, chosen, target, max_passes):
    """Replace one entry at a time by the candidate of its kind that keeps most cells."""
    n = w.shape[0]
    cur = np.zeros(n, dtype=np.int64)
    below = np.zeros(17, dtype=np.int64)  # below[p]: the items whose count is under p
    planes = _weight_planes(w)
    first = np.zeros(N_KINDS + 1, dtype=np.int64)  # candidates are sorted by kind
    for c in range(ck.shape[0]):
        first[ck[c] + 1] += 1
    for k in range(N_KINDS):
        first[k + 1] += first[k]
    value = _value_without(cov, pc, chosen, -1, w, cur)
    for _ in range(max_passes):
        improved = False
        for s in range(N_ENTRIES):
            if value == target:
                return value
            base = _value_without(cov, pc, chosen, s, w, cur)
            below[:] = 0
            for i in range(n):
                for p in range(cur[i] + 1, 17):
                    below[p] |= np.int64(1) << i
            best, bc = value - base, chosen[s]
            for c in range(first[ENTRY_KIND[s]], first[ENTRY_KIND[s] + 1]):
                x = cov[c] & below[pc[c]]
                if x != 0 and pc[c] * _weight(x, planes) > best:  # a bound first
                    m = _marginal(cov, pc, c, cur, w)
                    if m > best:
                        best, bc = m, c
            if bc != chosen[s]:
                chosen[s] = bc
                value = base + best
                improved = True
        if not improved:
            break
    return value


@njit(cache=True)
def _served_merges(cov, pc, chosen, it, io, w):
    """For each entry, the conservative merge of the items it serves best plus each further item
    it could serve: new base patterns that merge more than two vectors."""
    n = it.shape[0]
    cur = np.zeros(n, dtype=np.int64)
    _value_without(cov, pc, chosen, -1, w, cur)
    out_t = np.empty(N_ENTRIES * (n + 1), dtype=np.int64)
    out_o = np.empty(N_ENTRIES * (n + 1), dtype=np.int64)
    m = 0
    for s in range(N_ENTRIES):
        c = chosen[s]
        if c < 0:
            continue
        mt, mo = FULL, FULL
        cnt = 0
        for i in range(n):
            if (cov[c] >> i) & 1 and pc[c] == cur[i]:
                mt &= it[i]
                mo &= io[i]
                cnt += 1
        if cnt == 0:
            continue
        out_t[m], out_o[m] = mt, mo
        m += 1
        for i in range(n):
            if ((cov[c] >> i) & 1) == 0 or pc[c] < cur[i]:
                out_t[m], out_o[m] = mt & it[i], mo & io[i]
                m += 1
    return out_t[:m], out_o[:m]


@njit(cache=True)
def _extend_pool(ck, ct, co, nt, no):
    """The pool plus the projections of new base patterns, without duplicates."""
    ek, et, eo, _ = _pool(nt, no, 0)
    keys = np.concatenate(((ck << 32) | (ct << 16) | co, (ek << 32) | (et << 16) | eo))
    u, _ = _unique_by_kind(keys, 0)
    return u >> 32, (u >> 16) & FULL, u & FULL


@njit(cache=True)
def _codebook(it, io, w, level, target):
    """Best codebook found for one transform combination: (value, kinds, T masks, O masks) of
    the 13 entries (kind -1: empty). Level 0: greedy over the items alone; 1: over items and
    pair merges; 2: then swaps; 3: then merges of the items each entry serves, and swaps.
    Plus PRUNED: only the pairs that ``_candidates`` keeps with ``pairs`` 2."""
    pruned = level >= PRUNED
    if pruned:
        level -= PRUNED
    ck, ct, co, alone_ok = _candidates(it, io, 0 if level == 0 else (2 if pruned else 1))
    cov, pc = _covers(ct, co, it, io)
    chosen = _greedy(cov, pc, ck, w, np.arange(ck.shape[0]))
    cur = np.zeros(it.shape[0], dtype=np.int64)
    value = _value_without(cov, pc, chosen, -1, w, cur)
    if level >= 1 and value < target:
        # merges can crowd out the scarce general entries: also try the vectors alone
        alone = _greedy(cov, pc, ck, w, np.flatnonzero(alone_ok))
        v = _value_without(cov, pc, alone, -1, w, cur)
        if v > value:
            value, chosen = v, alone
    if level >= 2 and value < target:
        value = _swap(cov, pc, ck, w, chosen, target, 8)
    if level >= 3 and value < target:
        for _ in range(3):
            nt, no = _served_merges(cov, pc, chosen, it, io, w)
            old_keys = (ck << 32) | (ct << 16) | co
            ck, ct, co = _extend_pool(ck, ct, co, nt, no)
            if ck.shape[0] == old_keys.shape[0]:
                break
            # keep the chosen entries: find them in the new pool
            where = _positions((ck << 32) | (ct << 16) | co, old_keys)
            for s in range(N_ENTRIES):
                if chosen[s] >= 0:
                    chosen[s] = where[chosen[s]]
            cov, pc = _covers(ct, co, it, io)
            v = _swap(cov, pc, ck, w, chosen, target, 8)
            if v <= value:
                value = v
                break
            value = v
    kinds = np.full(N_ENTRIES, -1, dtype=np.int64)
    et = np.zeros(N_ENTRIES, dtype=np.int64)
    eo = np.zeros(N_ENTRIES, dtype=np.int64)
    for s in range(N_ENTRIES):
        c = chosen[s]
        if c >= 0:
            kinds[s], et[s], eo[s] = ck[c], ct[c], co[c]
    return value, kinds, et, eo


# ---------------------------------------------------------------------------------------------
# the deck's top-down partitioning

@njit(cache=True)
def _set_merge(it, io, member, set_id):
    mt, mo = FULL, FULL
    for i in range(it.shape[0]):
        if member[i] == set_id:
            mt &= it[i]
            mo &= io[i]
    return mt, mo


@njit(cache=True)
def _set_value(it, io, w, member, set_id, kind):
    mt, mo = _set_merge(it, io, member, set_id)
    kt, ko = project(kind, mt, mo)
    total = 0
    for i in range(it.shape[0]):
        if member[i] == set_id:
            total += w[i]
    return total * popcount16(kt | ko)


@njit(cache=True)
def _median_cut(it, io, w):
    """Partition the items into at most 13 sets; returns (value, kinds, T masks, O masks)."""
    n = it.shape[0]
    member = np.zeros(n, dtype=np.int64)
    nsets = 1 if n > 0 else 0
    trial = np.empty(n, dtype=np.int64)
    while nsets < N_ENTRIES:
        best_gain, best_set, best_e, best_s = -1, -1, -1, -1
        for sid in range(nsets):
            size = 0
            for i in range(n):
                if member[i] == sid:
                    size += 1
            if size < 2:
                continue
            before = _set_value(it, io, w, member, sid, 3)
            for e in range(16):
                for st in range(3):
                    cnt = 0
                    for i in range(n):
                        trial[i] = member[i]
                        if member[i] == sid:
                            s_i = 0 if (it[i] >> e) & 1 else (1 if (io[i] >> e) & 1 else 2)
                            if s_i == st:
                                trial[i] = nsets
                                cnt += 1
                    if cnt == 0 or cnt == size:
                        continue
                    gain = _set_value(it, io, w, trial, sid, 3) + _set_value(it, io, w, trial, nsets, 3) - before
                    if gain > best_gain:
                        best_gain, best_set, best_e, best_s = gain, sid, e, st
        if best_set < 0:
            break
        for i in range(n):
            if member[i] == best_set:
                s_i = 0 if (it[i] >> best_e) & 1 else (1 if (io[i] >> best_e) & 1 else 2)
                if s_i == best_s:
                    member[i] = nsets
        nsets += 1
    # give each set a kind: dynamic programming over (sets, entries used per kind)
    n_states = 1
    for k in range(N_KINDS):
        n_states *= CAPACITY[k] + 1
    neg = -(1 << 60)
    dp = np.full((nsets + 1, n_states), neg, dtype=np.int64)
    choice = np.zeros((nsets + 1, n_states), dtype=np.int64)
    dp[0, 0] = 0
    for sid in range(nsets):
        vals = np.empty(N_KINDS, dtype=np.int64)
        for k in range(N_KINDS):
            vals[k] = _set_value(it, io, w, member, sid, k)
        for code in range(n_states):
            if dp[sid, code] == neg:
                continue
            rest, stride = code, 1
            for k in range(N_KINDS):
                used = rest % (CAPACITY[k] + 1)
                rest //= CAPACITY[k] + 1
                if used < CAPACITY[k]:
                    nxt = code + stride
                    v = dp[sid, code] + vals[k]
                    if v > dp[sid + 1, nxt]:
                        dp[sid + 1, nxt] = v
                        choice[sid + 1, nxt] = k
                stride *= CAPACITY[k] + 1
    code = np.argmax(dp[nsets])
    kinds = np.full(N_ENTRIES, -1, dtype=np.int64)
    et = np.zeros(N_ENTRIES, dtype=np.int64)
    eo = np.zeros(N_ENTRIES, dtype=np.int64)
    used = np.zeros(N_KINDS, dtype=np.int64)
    for sid in range(nsets - 1, -1, -1):
        k = choice[sid + 1, code]
        stride = 1
        for j in range(k):
            stride *= CAPACITY[j] + 1
        code -= stride
        s = KIND_FIRST[k] + used[k]
        used[k] += 1
        mt, mo = _set_merge(it, io, member, sid)
        kinds[s] = k
        et[s], eo[s] = project(k, mt, mo)
    return _entries_value(it, io, w, kinds, et, eo), kinds, et, eo


@njit(cache=True)
def _entries_value(it, io, w, kinds, et, eo):
    total = 0
    for i in range(it.shape[0]):
        best = 0
        for s in range(N_ENTRIES):
            if kinds[s] >= 0:
                best = max(best, _retained(et[s], eo[s], it[i], io[i]))
        total += best * w[i]
    return total


# ---------------------------------------------------------------------------------------------
# transform search and assembly

@njit(cache=True)
def _evaluate(dt, do, tr, encoder, level):
    it, io, w = _items(dt, do, tr)
    target = _lossless_value(it, io, w)
    if encoder == 0:
        value, kinds, et, eo = _median_cut(it, io, w)
    else:
        value, kinds, et, eo = _codebook(it, io, w, level, target)
    return value, target, kinds, et, eo


@njit(cache=True)
def _quadrant_used(dt, do):
    used = np.zeros(4, dtype=np.bool_)
    for v in range(64):
        if not _uniform(dt[v], do[v]):
            used[_quadrant(v)] = True
    return used


@njit(cache=True)
def _aligned_transforms(dt, do):
    """A cheap first guess: quadrant by quadrant, the transform under which the quadrant's
    vectors best match (largest conservative merge) the vectors already placed."""
    tr = np.zeros(4, dtype=np.int64)
    pt = np.zeros(64, dtype=np.int64)
    po = np.zeros(64, dtype=np.int64)
    npl = 0
    for q in range(4):
        best, bt = -1, 0
        for t in range(8 if q > 0 else 1):
            score = 0
            for v in range(64):
                if _quadrant(v) != q or _uniform(dt[v], do[v]):
                    continue
                st = untransform_mask(dt[v], t)
                so = untransform_mask(do[v], t)
                m = 0
                for j in range(npl):
                    m = max(m, popcount16((st & pt[j]) | (so & po[j])))
                score += m
            if score > best:
                best, bt = score, t
        tr[q] = bt
        for v in range(64):
            if _quadrant(v) == q and not _uniform(dt[v], do[v]):
                pt[npl] = untransform_mask(dt[v], bt)
                po[npl] = untransform_mask(do[v], bt)
                npl += 1
    return tr


@njit(cache=True)
def _rank_transforms(dt, do, used, n_pre, n_keep):
    """The ``n_keep`` most promising transform combinations (codes t1 | t2 << 3 | t3 << 6), best
    first, by two cheap scores of the vectors' general-kind projections. A projection commutes
    with the transforms, so whether vector j's projection covers vector k depends only on their
    relative transform: it is tabled once per map. First every combination is scored by a sum
    over the vectors: 64 x the largest projection of another vector that covers it (in cells),
    plus the largest from each quadrant (that tells apart combinations that align quadrants only
    in pairs); the ``n_pre`` best by that are scored by the cells that a greedy 13-entry codebook
    of projections keeps.
    Skipped: a transform other than 0 on a quadrant without mixed vectors, or, with quadrant 0
    empty, on the first quadrant used (turning every quadrant alike changes nothing)."""
    mix = np.empty(64, dtype=np.int64)
    nm = 0
    for v in range(64):
        if not _uniform(dt[v], do[v]):
            mix[nm] = v
            nm += 1
    qof = np.empty(nm, dtype=np.int64)
    gp = np.empty(nm, dtype=np.int64)
    qmask = np.zeros(4, dtype=np.int64)
    cov = np.zeros((nm, 8), dtype=np.int64)  # cov[j, r]: the vectors k that r(projection j) covers
    best_cover = np.zeros((nm, 4, 8), dtype=np.int64)  # largest such projection from quadrant q
    for j in range(nm):
        qof[j] = _quadrant(mix[j])
        qmask[qof[j]] |= np.int64(1) << j
        gt, go = project(GENERAL, dt[mix[j]], do[mix[j]])
        gp[j] = popcount16(gt | go)
        for r in range(8):
            a, b = transform_mask(gt, r), transform_mask(go, r)
            m = 0
            for k in range(nm):
                m |= np.int64(((a & ~dt[mix[k]]) | (b & ~do[mix[k]])) == 0) << k
            cov[j, r] = m
            m &= ~(np.int64(1) << j)
            while m != 0:
                k = trailing_zeros(m)
                m &= m - 1
                best_cover[k, qof[j], r] = max(best_cover[k, qof[j], r], gp[j])
    first = 0
    while first < 3 and not used[first]:
        first += 1
    pre = np.full(512, -1, dtype=np.int64)
    tr = np.zeros(4, dtype=np.int64)
    for code in range(512):
        tr[1], tr[2], tr[3] = code & 7, (code >> 3) & 7, code >> 6
        skip = False
        for q in range(1, 4):
            if tr[q] != 0 and (not used[q] or q == first):
                skip = True
        if skip:
            continue
        total = 0
        for k in range(nm):
            tk = tr[qof[k]]
            b = 0
            for q in range(4):
                x = best_cover[k, q, RELATIVE[tk, tr[q]]]
                b = max(b, x)
                total += x
            total += 64 * b
        pre[code] = total
    order = np.argsort(-512 * pre + np.arange(512))  # ties by code
    n_valid = 0
    while n_valid < 512 and pre[order[n_valid]] >= 0:
        n_valid += 1
    cand = order[:min(n_pre, n_valid)]
    score = np.empty(cand.shape[0], dtype=np.int64)
    cj = np.empty(nm, dtype=np.int64)
    ub = np.empty(nm, dtype=np.int64)
    stamp = np.empty(nm, dtype=np.int64)
    cur = np.empty(nm, dtype=np.int64)
    for ci in range(cand.shape[0]):
        code = cand[ci]
        tr[1], tr[2], tr[3] = code & 7, (code >> 3) & 7, code >> 6
        for j in range(nm):
            ta = tr[qof[j]]
            c = 0
            for q in range(4):
                c |= cov[j, RELATIVE[tr[q], ta]] & qmask[q]
            cj[j] = c
            ub[j] = gp[j] * popcount64(c)
            stamp[j] = -1
            cur[j] = 0
        total = 0
        for s in range(N_ENTRIES):  # lazy greedy: ub holds upper bounds of the marginal gains
            while True:
                best, bj = 0, -1
                for j in range(nm):
                    if ub[j] > best:
                        best, bj = ub[j], j
                if bj < 0 or stamp[bj] == s:
                    break
                g = 0
                m = cj[bj]
                while m != 0:
                    k = trailing_zeros(m)
                    m &= m - 1
                    g += max(gp[bj] - cur[k], 0)
                ub[bj] = g
                stamp[bj] = s
            if bj < 0:
                break
            total += best
            ub[bj] = 0
            m = cj[bj]
            while m != 0:
                k = trailing_zeros(m)
                m &= m - 1
                cur[k] = max(cur[k], gp[bj])
        score[ci] = total
    return cand[np.argsort(-512 * score + np.arange(cand.shape[0]))[:n_keep]]  # ties by the first score


@njit(cache=True)
def _search(dt, do, encoder, start, level, passes, final_level):
    """Transforms and codebook, (transforms, kinds, T masks, O masks). Start from the identity
    (0) or ``_aligned_transforms`` (1), then ``passes`` of coordinate descent over quadrants 1..3
    scored by the codebook at ``level``; or (3) score every combination by the greedy over the
    vectors alone, the TOP_K best at ``level``, then ``passes`` of coordinate descent; or (4)
    score the ``passes`` best by ``_rank_transforms`` at ``level``. The winner is re-encoded at
    ``final_level``. One function, not one per start: numba re-optimises a kernel's whole call
    tree each level up, so a flat search compiles faster."""
    used = _quadrant_used(dt, do)
    tr = np.zeros(4, dtype=np.int64)
    best_tr = np.zeros(4, dtype=np.int64)
    best_v, target = -1, 0
    kinds = np.full(N_ENTRIES, -1, dtype=np.int64)
    et = np.zeros(N_ENTRIES, dtype=np.int64)
    eo = np.zeros(N_ENTRIES, dtype=np.int64)
    score = np.full(512, -1, dtype=np.int64)
    if start >= 3:
        if start == 3:  # every combination scored cheaply, the best few at level
            for code in range(512):
                tr[1], tr[2], tr[3] = code & 7, (code >> 3) & 7, code >> 6
                if (not used[1] and tr[1]) or (not used[2] and tr[2]) or (not used[3] and tr[3]):
                    continue
                score[code] = _evaluate(dt, do, tr, 1, 0)[0]
            order = np.argsort(-score)[:TOP_K]
        else:
            order = _rank_transforms(dt, do, used, RANK_PRE, passes)
            passes = 0
        for code in order:
            if start == 3 and score[code] < 0:
                break
            tr[1], tr[2], tr[3] = code & 7, (code >> 3) & 7, code >> 6
            v, tg, k2, t2, o2 = _evaluate(dt, do, tr, encoder, level)
            if v > best_v:
                best_v, target, kinds, et, eo = v, tg, k2, t2, o2
                best_tr[:] = tr
            if start == 4 and best_v == target:
                break
    else:
        if start == 1:
            best_tr = _aligned_transforms(dt, do)
        for q in range(4):
            if not used[q]:
                best_tr[q] = 0
        best_v, target, kinds, et, eo = _evaluate(dt, do, best_tr, encoder, level)
    for _ in range(passes):  # coordinate descent
        improved = False
        for q in range(1, 4):
            if not used[q]:
                continue
            for t in range(8):
                if t == best_tr[q] or best_v == target:
                    continue
                tr[:] = best_tr
                tr[q] = t
                v, tg, k2, t2, o2 = _evaluate(dt, do, tr, encoder, level)
                if v > best_v:
                    best_v, target, kinds, et, eo = v, tg, k2, t2, o2
                    best_tr[:] = tr
                    improved = True
        if not improved:
            break
    if final_level != level and best_v < target:
        best_v, target, kinds, et, eo = _evaluate(dt, do, best_tr, encoder, final_level)
    return best_tr, kinds, et, eo


@njit(cache=True)
def _assemble(dt, do, tr, kinds, et, eo):
    indices = np.zeros(64, dtype=np.int64)
    for v in range(64):
        if dt[v] == FULL:
            indices[v] = states.T
            continue
        if do[v] == FULL:
            indices[v] = states.O
            continue
        t = tr[_quadrant(v)]
        st = untransform_mask(dt[v], t)
        so = untransform_mask(do[v], t)
        best, idx = 0, states.C
        for s in range(N_ENTRIES):
            if kinds[s] >= 0:
                r = _retained(et[s], eo[s], st, so)
                if r > best:
                    best, idx = r, 3 + s
        indices[v] = idx
    entries = np.zeros(N_ENTRIES, dtype=np.int64)
    for s in range(N_ENTRIES):
        if kinds[s] >= 0:
            entries[s] = entry_code(ENTRY_KIND[s], et[s], eo[s])
    return indices, entries


@njit(cache=True)
def encode_many_arrays(maps, encoder, effort):
    """Numba entry point: 32x32 maps -> (indices, entries, transforms). encoder 0 paper, 1 best."""
    n = maps.shape[0]
    idx = np.zeros((n, 64), dtype=np.int64)
    ent = np.zeros((n, N_ENTRIES), dtype=np.int64)
    tr = np.zeros((n, 4), dtype=np.int64)
    for i in range(n):
        dt, do = displayed_masks(maps[i])
        if encoder == 0:
            tr[i], kinds, et, eo = _search(dt, do, 0, 0, 0, 2, 0)
        else:
            tr[i], kinds, et, eo = _search(dt, do, 1, SEARCH[effort, 0], SEARCH[effort, 1], SEARCH[effort, 2],
                                           SEARCH[effort, 3])
        idx[i], ent[i] = _assemble(dt, do, tr[i], kinds, et, eo)
    return idx, ent, tr


def encode(map32, encoder: str = "best", effort: str = "medium") -> VQ4Block:
    """Encode a 32x32 map into a symbolic VQ4 block (conservative: only O->C, T->C)."""
    e, f = check_options("VQ4", encoder, effort)
    idx, ent, tr = encode_many_arrays(check_maps(map32, SIZE, "VQ4")[None], e, f)
    return VQ4Block(idx[0], ent[0], tr[0])


def encode_blocks(maps32, encoder: str = "best", effort: str = "medium") -> np.ndarray:
    """Encode (n, 32, 32) maps (or one) straight to their physical blocks (n, 64) uint8, packed in
    bulk (no block objects): the bytes ``encode_many``'s blocks pack to."""
    e, f = check_options("VQ4", encoder, effort)
    return pack_many(*encode_many_arrays(check_maps(maps32, SIZE, "VQ4").reshape(-1, SIZE, SIZE), e, f))


def encode_many(maps32, encoder: str = "best", effort: str = "medium") -> list[VQ4Block]:
    e, f = check_options("VQ4", encoder, effort)
    m = check_maps(maps32, SIZE, "VQ4").reshape(-1, SIZE, SIZE)
    idx, ent, tr = encode_many_arrays(m, e, f)
    return [VQ4Block(idx[i], ent[i], tr[i]) for i in range(len(m))]


def split_x64(map64) -> np.ndarray:
    """The four 32x32 quadrants of a 64x64 map, in vq4x64 block order; of (n, 64, 64) maps, their
    4n quadrants, map by map."""
    m = check_maps(map64, 2 * SIZE, "VQ4x64")
    return m.reshape(-1, 2, SIZE, 2, SIZE).transpose(0, 1, 3, 2, 4).reshape(-1, SIZE, SIZE)


def encode_blocks_x64(maps64, encoder: str = "best", effort: str = "medium") -> np.ndarray:
    """(n, 64, 64) maps (or one) -> their VQ4x64 maps (n, 256) uint8, four blocks each, in bulk."""
    return encode_blocks(split_x64(maps64), encoder, effort).reshape(-1, X64_BYTES)


def encode_x64(map64, encoder: str = "best", effort: str = "medium") -> bytes:
    """A 64x64 map as four VQ4 blocks (256 bytes)."""
    m = check_maps(map64, X64_SIZE, "VQ4x64")
    if m.size != X64_SIZE * X64_SIZE:
        raise ValueError(f"encode_x64 encodes one 64x64 map, got shape {m.shape} (encode_blocks_x64 takes many)")
    return encode_blocks_x64(m, encoder, effort)[0].tobytes()
