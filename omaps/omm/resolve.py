"""From three states to the OMM formats: what a C micro-triangle becomes.

4-state output keeps C as "unknown" (the any-hit shader runs) and only chooses which unknown:
unknown-opaque or unknown-transparent, the state a ray flagged "force 2-state" sees. 2-state
output has no unknown: C becomes O or T outright (no longer conservative). The choice is
``omaps.promotion``'s rule on the micro-triangle's opaque fraction (``omaps.coverage``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .. import omm_format
from ..alpha_test import AlphaTest
from ..birdcurve import vertex_table
from ..coverage import TAPS, micro_corners_of, micro_hits_with, sample_levels, sample_points, texel_triangles
from ..parallel import fetch_add, item_size
from ..promotion import HASHED, hashed_threshold, hits_needed, promotion_code

__all__ = ["resolve", "resolve_counted"]


@njit(cache=True, inline="always")
def _count_known(states3, base, end, out, copy):
    """(T, O) micro-triangles of ``states3[base:end]``, copied into ``out`` when ``copy``: with no
    branch in the loop and unsigned indices (numba then drops its negative-index check, and the
    compiler vectorises the loop, taking the test of ``copy`` out of it). Most micro-triangles
    are known, most triangles hold no C one: this pass is the resolve of most triangles, so it
    runs in the triangles' loop itself (a call for every triangle, which passes each array as
    nine words, made the whole resolve of the oak case about a sixth slower)."""
    n_t = n_o = 0
    for i in range(np.uint64(base), np.uint64(end)):
        s = states3[i]
        if copy:
            out[i] = s
        n_t += s == 0
        n_o += s == 1
    return n_t, n_o


@njit(cache=True, _nrt=False)
def _resolve_c(states3, base, end, level, two_state, mode, seed, value, thr, inclusive, filt, mu, mv, tris, t,
               samples, sample_k, out, counts, taps, table):
    """The C micro-triangles of triangle ``t`` (``states3[base:end]``) into ``out``, and how many
    became OMM state 0, 1, 2, 3 into ``counts[t, 3:]`` (no reference counting: it allocates
    nothing). ``table``: ``birdcurve.vertex_table()``."""
    n_s = 1 << (2 * sample_k)
    first = np.uint64(base)
    last = np.uint64(end)
    r0 = r1 = r2 = r3 = 0
    need0 = hits_needed(mode, 0.0, n_s)
    for i in range(first, last):
        if states3[i] < 2:
            continue
        need = need0
        if 0 < need <= n_s:  # the opaque fraction decides: O iff at least ``need`` sample points pass
            q = micro_corners_of(tris, t, np.int64(i - first), level, table)
            if mode == HASHED:  # the cut is the threshold hashed from the centroid
                need = hits_needed(mode, hashed_threshold((q[0] + q[2] + q[4]) / 3.0,
                                                          (q[1] + q[3] + q[5]) / 3.0, seed), n_s)
            opaque = micro_hits_with(value, thr, inclusive, filt, mu, mv, q, samples, sample_k, need,
                                     taps) >= need
        else:  # opaque or transparent whatever the fraction
            opaque = need <= 0
        if two_state:
            o = 1 if opaque else 0
        else:
            o = 3 if opaque else 2
        out[i] = o
        if o == 0:
            r0 += 1
        elif o == 1:
            r1 += 1
        elif o == 2:
            r2 += 1
        else:
            r3 += 1
    counts[t, 3] = r0
    counts[t, 4] = r1
    counts[t, 5] = r2
    counts[t, 6] = r3


CHUNK = 16  # triangles per work item (triangles differ a lot in cost: items are taken as threads free up)


@njit(cache=True, parallel=True)
def _resolve(states3, starts, levels, two_state, mode, seed, value, thr, inclusive, filt, mu, mv, tris,
             samples, sample_k, out, copy, counts, table, n_workers):
    n = tris.shape[0]
    per = item_size(n, n_workers, CHUNK)  # (a level-10 chunk is a few triangles: one or two an item)
    n_chunks = (n + per - 1) // per
    next_chunk = np.zeros(1, dtype=np.int64)
    for worker in prange(n_workers):  # each thread takes the next chunk as it frees up (``omaps.parallel``)
        taps = np.empty((TAPS, TAPS))
        while True:
            c = fetch_add(next_chunk, 1)
            if c >= n_chunks:
                break
            for t in range(c * per, min((c + 1) * per, n)):
                base, end = starts[t], starts[t + 1]
                n_t, n_o = _count_known(states3, base, end, out, copy)
                counts[t, 0] = n_t
                counts[t, 1] = n_o
                n_c = (end - base) - n_t - n_o
                counts[t, 2] = n_c
                if n_c > 0:
                    _resolve_c(states3, base, end, levels[t], two_state, mode, seed, value, thr, inclusive, filt, mu,
                               mv, tris, t, samples, sample_k[t], out, counts, taps, table)
                else:
                    counts[t, 3] = counts[t, 4] = counts[t, 5] = counts[t, 6] = 0


def resolve_counted(states3: np.ndarray, starts: np.ndarray, levels, test: AlphaTest, tris_uv, fmt: int,
                    promotion: str = "nearest", seed: int = 0, out: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``resolve``, and per triangle (T, 7) int64 counts: its T, O and C micro-triangles
    (``states3``), then how many C ones became OMM state 0, 1, 2, 3. ``out``: where the OMM
    states go (default: a new array); ``states3`` itself resolves in place, when the caller no
    longer needs the T/O/C states (the pipeline: a pass over the states and their copy saved)."""
    mode = promotion_code(promotion)
    tris = texel_triangles(test, tris_uv)
    lv = np.array(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)  # writable: one specialisation
    copy = out is not states3
    if out is None:
        out = np.empty_like(states3)
    elif out.shape != states3.shape or out.dtype != states3.dtype:
        raise ValueError(f"out must be {states3.dtype} of shape {states3.shape}, got {out.dtype} {out.shape}")
    counts = np.empty((len(tris), 7), dtype=np.int64)
    filt, mu, mv = test.codes()
    _resolve(states3, np.asarray(starts, dtype=np.int64), lv, fmt == omm_format.FORMAT_2_STATE, mode, int(seed),
             test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, sample_points(),
             sample_levels(tris, lv), out, copy, counts, vertex_table(), numba.get_num_threads())
    return out, counts


def resolve(states3: np.ndarray, starts: np.ndarray, levels, test: AlphaTest, tris_uv, fmt: int,
            promotion: str = "nearest", seed: int = 0) -> np.ndarray:
    """OMM states (flat, like ``states3``) of baked T/O/C states: 0/1 in 2-state, 0..3 in 4-state."""
    return resolve_counted(states3, starts, levels, test, tris_uv, fmt, promotion, seed)[0]
