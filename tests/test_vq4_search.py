"""VQ4 encoder search pieces against brute force: the relative-transform table, the bit count,
the lazy codebook greedy against the plain greedy it must equal, and the transform ranking on
maps whose quadrants are transformed copies of one another."""

import numpy as np
from hypothesis import given, settings
from numba import njit
from hypothesis import strategies as st

from omaps import states
from omaps.codecs import vec4, vq4_encode as ve

T, O, C = states.T, states.O, states.C


@given(st.integers(0, 0xFFFF), st.integers(0, 7), st.integers(0, 7))
def test_relative_transform(m, ta, tb):
    """A pattern stored under ta and shown under tb is the displayed pattern moved by RELATIVE."""
    assert vec4.transform_mask(vec4.untransform_mask(m, ta), tb) == vec4.transform_mask(m, int(ve.RELATIVE[tb, ta]))


@njit
def _popcount(x):
    return ve.popcount64(x)


@given(st.integers(-(1 << 63), (1 << 63) - 1))
def test_popcount64(x):
    assert _popcount(np.int64(x)) == bin(x & ((1 << 64) - 1)).count("1")


def plain_greedy(cov, pc, ck, w, cands):
    """The greedy as specified: each step the candidate of largest marginal gain whose kind has
    room, the first on a tie; no laziness."""
    cur = np.zeros(len(w), np.int64)
    used = np.zeros(ve.N_KINDS, np.int64)
    chosen = np.full(ve.N_ENTRIES, -1, np.int64)
    for _ in range(ve.N_ENTRIES):
        best, pick = 0, -1
        for c in cands:
            if used[ck[c]] >= ve.CAPACITY[ck[c]]:
                continue
            gain = sum(int(w[i]) * max(int(pc[c]) - int(cur[i]), 0) for i in range(len(w)) if cov[c] >> i & 1)
            if gain > best:
                best, pick = gain, c
        if pick < 0:
            break
        chosen[ve.KIND_FIRST[ck[pick]] + used[ck[pick]]] = pick
        used[ck[pick]] += 1
        for i in range(len(w)):
            if cov[pick] >> i & 1:
                cur[i] = max(cur[i], pc[pick])
    return chosen


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_lazy_greedy_equals_plain_greedy(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 65))
    nc = int(rng.integers(1, 80))
    w = rng.integers(1, 5, n).astype(np.int64)
    bits = rng.random((nc, n)) < rng.uniform(0.02, 0.5)
    cov = np.array([sum(1 << i for i in np.flatnonzero(b)) for b in bits], dtype=np.uint64).view(np.int64)
    pc = rng.integers(1, 6, nc).astype(np.int64)  # few values: many ties
    ck = np.sort(rng.integers(0, ve.N_KINDS, nc)).astype(np.int64)
    cands = np.flatnonzero(rng.random(nc) < 0.8).astype(np.int64)
    np.testing.assert_array_equal(ve._greedy(cov, pc, ck, w, cands), plain_greedy(cov, pc, ck, w, cands))


def _asymmetric_vectors(rng, k):
    out = []
    while len(out) < k:
        g = np.where(rng.random((4, 4)) < 0.3, C,
                     np.kron(rng.integers(0, 2, (2, 2)), np.ones((2, 2), int))).astype(np.uint8)
        shown = [vec4.transform_mask(int(sum(1 << e for e in range(16) if g.flat[e] == T)), t) for t in range(8)]
        if len(set(shown)) == 8 and len(np.unique(g)) == 3:
            out.append(g)
    return out


def _shown(g, t):
    """The 4x4 vector g (stored) as transform t shows it."""
    e = np.arange(16)
    out = np.empty(16, np.uint8)
    out[vec4.FWD4[t, e]] = g.flat[e]
    return out.reshape(4, 4)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_ranking_finds_transformed_copies(seed):
    """Each quadrant shows the same 8 general vectors (no symmetries), quadrant q under a random
    transform t_q: lossless only with transforms that undo them, which medium must find (fast,
    starting from one guess, need not)."""
    rng = np.random.default_rng(seed)
    vecs = _asymmetric_vectors(rng, 8)
    tr = [0] + [int(t) for t in rng.integers(0, 8, 3)]
    m = np.full((32, 32), T, np.uint8)
    for q in range(4):
        oy, ox = 16 * (q >> 1), 16 * (q & 1)
        for i, slot in enumerate(rng.permutation(16)[:8]):
            vy, vx = divmod(int(slot), 4)
            m[oy + 4 * vy:oy + 4 * vy + 4, ox + 4 * vx:ox + 4 * vx + 4] = _shown(vecs[i], tr[q])
    blk = ve.encode(m, "best", "medium")
    np.testing.assert_array_equal(blk.decode(), m)
    # the vectors have no symmetry, so lossless means the copies' own transforms (medium scores
    # only the few best-ranked combinations: the ranking put them among those)
    assert [int(t) for t in blk.transforms] == tr


def test_deterministic(rng):
    m = rng.integers(0, 3, (32, 32)).astype(np.uint8)
    a, b = ve.encode(m), ve.encode(m.copy())
    assert a.pack() == b.pack()
