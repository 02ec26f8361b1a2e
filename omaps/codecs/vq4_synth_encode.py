"""VQ4-synth encoder: VQ4's block (``vq4_encode``, any encoder and effort), then the best
synthesised two-value vector for index 2.

Trials: VQ4's block of the map, and (``medium``: 6, ``thorough``: 12, ``fast``: none) VQ4's
blocks of the map with one of its two-value vectors hidden (its copies turned uniform T, so VQ4
spends no entry on it and X can take it), the vectors with most known cells first. Each trial
gets the synthesis below; the block that keeps most cells wins, VQ4's own on a tie, so VQ4-synth
never keeps less than VQ4 with the same encoder and effort.

Index 2 stops being uniform C when it shows X, so X must cover every vector VQ4 left at uniform C
(X is at most the conservative merge of them). Candidates: the two-value projection
(``vec4.project``) of that merge with each mixed vector and with each pair of mixed vectors; the
one that adds most known cells wins, and every vector that X keeps more of than its VQ4 entry
moves to index 2. No gain: the block stays a VQ4 block (general entries ascending). X needs the
general and the two-value codes distinct (their order carries it): a duplicate entry serves no
vector that its twin cannot, so its vectors move to the twin and it gets an unused code.

Only O->C or T->C: every vector shows an entry or X that covers it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import vq4_encode
from ..states import C as C_STATE, T as T_STATE
from .options import ENCODERS, check_maps  # noqa: F401 (ENCODERS re-exported for the registry)
from .vec4 import FULL, TWO_VALUE, entry_code, entry_pattern, popcount16, project, untransform_mask
from .vec4_search import keeps, vector_masks
from .vq4_block import ENTRY_KIND, N_ENTRIES, SIZE, VQ4Block
from .vq4_synth_block import GENERAL_SLOTS, NO_EXTRA, TWO_VALUE_SLOTS, VQ4SynthBlock

__all__ = ["encode", "encode_many", "synthesise", "ENCODERS"]


@njit(cache=True)
def _distinct(idx, ent, slots):
    """Give duplicate codes among ``slots`` unused codes, moving their vectors to the twin."""
    for a in range(slots.shape[0]):
        for b in range(a):
            if ent[slots[a]] == ent[slots[b]]:
                for v in range(64):
                    if idx[v] == slots[a] + 3:
                        idx[v] = slots[b] + 3
                code = 0
                while True:
                    used = False
                    for c in range(slots.shape[0]):
                        if ent[slots[c]] == code:
                            used = True
                    if not used:
                        break
                    code += 1
                ent[slots[a]] = code
                break


@njit(cache=True)
def _best_x(pt, po, mixed, cur):
    """The two-value vector X that adds most cells over ``cur`` (cells each vector keeps now; 0 at
    uniform C, which X must then cover): the two-value projection of a vector's or a pair's merge
    with the merge of the vectors at C. Returns (gain, xt, xo)."""
    mt, mo = FULL, FULL
    for v in range(64):
        if mixed[v] and cur[v] == 0:
            mt &= pt[v]
            mo &= po[v]
    best, bt, bo = 0, 0, 0
    for a in range(64):
        if not mixed[a]:
            continue
        for b in range(a, 64):
            if not mixed[b]:
                continue
            xt, xo = project(TWO_VALUE, pt[a] & pt[b] & mt, po[a] & po[b] & mo)
            g = 0
            for v in range(64):
                if mixed[v]:
                    g += max(keeps(xt, xo, pt[v], po[v]) - cur[v], 0)
            if g > best:
                best, bt, bo = g, xt, xo
    return best, bt, bo


@njit(cache=True)
def synthesise(m, indices, entries, tr):
    """A 32x32 map and its VQ4 block -> (indices, entries, extra code or NO_EXTRA): X where it
    keeps more than VQ4's entries and uniform C, the block unchanged otherwise."""
    dt, do = vector_masks(m, 8, 0, 0)
    idx = indices.copy()
    ent = entries.copy()
    _distinct(idx, ent, GENERAL_SLOTS)
    _distinct(idx, ent, TWO_VALUE_SLOTS)
    pt = np.zeros(64, dtype=np.int64)
    po = np.zeros(64, dtype=np.int64)
    mixed = np.zeros(64, dtype=np.bool_)
    cur = np.zeros(64, dtype=np.int64)  # cells each mixed vector keeps now
    et = np.zeros(N_ENTRIES, dtype=np.int64)
    eo = np.zeros(N_ENTRIES, dtype=np.int64)
    for j in range(N_ENTRIES):
        et[j], eo[j] = entry_pattern(ENTRY_KIND[j], ent[j])
    for v in range(64):  # every vector again: a trial's block hid some of them as uniform T
        if dt[v] == FULL or do[v] == FULL:
            idx[v] = 0 if dt[v] == FULL else 1
            continue
        q = 2 * ((v >> 3) >> 2) + ((v & 7) >> 2)
        pt[v], po[v] = untransform_mask(dt[v], tr[q]), untransform_mask(do[v], tr[q])
        mixed[v] = True
        idx[v] = 2
        for j in range(N_ENTRIES):
            r = keeps(et[j], eo[j], pt[v], po[v])
            if r > cur[v]:
                cur[v], idx[v] = r, 3 + j
    gain, xt, xo = _best_x(pt, po, mixed, cur)
    if gain == 0:
        return idx, ent, NO_EXTRA
    for v in range(64):
        if mixed[v] and (idx[v] == 2 or keeps(xt, xo, pt[v], po[v]) > cur[v]):
            idx[v] = 2
    return idx, ent, entry_code(TWO_VALUE, xt, xo)


TRIALS = {"fast": 0, "medium": 6, "thorough": 12}  # hidden-vector trials per effort


@njit(cache=True)
def two_value_vectors(m, n_max):
    """Displayed masks of the map's mixed vectors that fit the two-value kind exactly, most known
    cells in all their copies first (at most n_max)."""
    dt, do = vector_masks(m, 8, 0, 0)
    kt = np.zeros(64, dtype=np.int64)
    ko = np.zeros(64, dtype=np.int64)
    score = np.zeros(64, dtype=np.int64)
    n = 0
    for v in range(64):
        if dt[v] == FULL or do[v] == FULL or (dt[v] | do[v]) == 0:
            continue
        if project(TWO_VALUE, dt[v], do[v]) != (dt[v], do[v]):
            continue
        j = 0
        while j < n and not (kt[j] == dt[v] and ko[j] == do[v]):
            j += 1
        if j == n:
            kt[n], ko[n] = dt[v], do[v]
            n += 1
        score[j] += popcount16(dt[v] | do[v])
    order = np.argsort(-score[:n], kind="mergesort")[:n_max]
    return kt[order], ko[order]


def _encode_one(m, encoder, effort, base):
    """The best of: synthesis on VQ4's block ``base``, and on VQ4's blocks of the map with each of
    the best few two-value vectors hidden (turned uniform T, so VQ4 spends no entry on it and X can
    take it)."""
    best, best_known = None, -1
    trials = [base] + [vq4_encode.encode(np.where(_mask_of(m, kt, ko), T_STATE, m), encoder, effort)
                       for kt, ko in zip(*two_value_vectors(m, TRIALS[effort]))]
    for b in trials:
        tr = b.transforms.astype(np.int64)
        idx, ent, extra = synthesise(m, b.indices.astype(np.int64), b.entries.astype(np.int64), tr)
        blk = VQ4SynthBlock(VQ4Block(idx, ent, tr), int(extra))
        known = int((blk.decode() != C_STATE).sum())
        if known > best_known:
            best, best_known = blk, known
    return best


def _mask_of(m, kt, ko):
    """Cells of the vectors whose displayed masks are (kt, ko)."""
    dt, do = vector_masks(m, 8, 0, 0)
    hit = ((dt == kt) & (do == ko)).reshape(8, 8)
    return np.kron(hit, np.ones((4, 4), dtype=bool))


def encode(map32, encoder: str = "best", effort: str = "medium") -> VQ4SynthBlock:
    """One 32x32 map -> its symbolic block (conservative: only O->C or T->C)."""
    return encode_many(np.asarray(map32)[None], encoder, effort)[0]


def encode_many(maps32, encoder: str = "best", effort: str = "medium") -> list[VQ4SynthBlock]:
    """Maps (P, 32, 32) -> symbolic blocks: VQ4's ``encoder`` / ``effort``, then the synthesis."""
    m = check_maps(maps32, SIZE, "VQ4-synth").reshape(-1, SIZE, SIZE)
    out = []
    return [_encode_one(one, encoder, effort, b) for one, b in zip(m, vq4_encode.encode_many(m, encoder, effort))]


assert N_ENTRIES == 13
