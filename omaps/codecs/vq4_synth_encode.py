"""VQ4-synth encoder: VQ4's block (``vq4_encode``, any encoder and effort), then the best
synthesised two-value vector for index 2.

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
from .options import ENCODERS, check_maps  # noqa: F401 (ENCODERS re-exported for the registry)
from .vec4 import FULL, TWO_VALUE, entry_code, entry_pattern, project, untransform_mask
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
def synthesise(m, indices, entries, tr):
    """A 32x32 map and its VQ4 block -> (indices, entries, extra code or NO_EXTRA)."""
    dt, do = vector_masks(m, 8, 0, 0)
    idx = indices.copy()
    ent = entries.copy()
    _distinct(idx, ent, GENERAL_SLOTS)
    _distinct(idx, ent, TWO_VALUE_SLOTS)
    pt = np.zeros(64, dtype=np.int64)
    po = np.zeros(64, dtype=np.int64)
    cur = np.full(64, -1, dtype=np.int64)  # cells kept now; -1 for uniform T / O vectors
    mt, mo = FULL, FULL  # merge of the vectors at uniform C
    for v in range(64):
        if dt[v] == FULL or do[v] == FULL:
            continue
        q = 2 * ((v >> 3) >> 2) + ((v & 7) >> 2)
        pt[v], po[v] = untransform_mask(dt[v], tr[q]), untransform_mask(do[v], tr[q])
        if idx[v] == 2:
            cur[v] = 0
            mt &= pt[v]
            mo &= po[v]
        else:
            j = idx[v] - 3
            et, eo = entry_pattern(ENTRY_KIND[j], ent[j])
            cur[v] = keeps(et, eo, pt[v], po[v])
    best, bt, bo = 0, 0, 0
    for a in range(64):
        if cur[a] < 0:
            continue
        for b in range(a, 64):
            if cur[b] < 0:
                continue
            xt, xo = project(TWO_VALUE, pt[a] & pt[b] & mt, po[a] & po[b] & mo)
            g = 0
            for v in range(64):
                if cur[v] >= 0:
                    r = keeps(xt, xo, pt[v], po[v])
                    if r > cur[v]:
                        g += r - cur[v]
            if g > best:
                best, bt, bo = g, xt, xo
    if best == 0:
        return idx, ent, NO_EXTRA
    for v in range(64):
        if cur[v] >= 0 and keeps(bt, bo, pt[v], po[v]) > cur[v]:
            idx[v] = 2
    return idx, ent, entry_code(TWO_VALUE, bt, bo)


def encode(map32, encoder: str = "best", effort: str = "medium") -> VQ4SynthBlock:
    """One 32x32 map -> its symbolic block (conservative: only O->C or T->C)."""
    return encode_many(np.asarray(map32)[None], encoder, effort)[0]


def encode_many(maps32, encoder: str = "best", effort: str = "medium") -> list[VQ4SynthBlock]:
    """Maps (P, 32, 32) -> symbolic blocks: VQ4's ``encoder`` / ``effort``, then the synthesis."""
    m = check_maps(maps32, SIZE, "VQ4-synth").reshape(-1, SIZE, SIZE)
    out = []
    for one, b in zip(m, vq4_encode.encode_many(m, encoder, effort)):
        tr = b.transforms.astype(np.int64)
        idx, ent, extra = synthesise(one, b.indices.astype(np.int64), b.entries.astype(np.int64), tr)
        out.append(VQ4SynthBlock(VQ4Block(idx, ent, tr), int(extra)))
    return out


assert N_ENTRIES == 13
