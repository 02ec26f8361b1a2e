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

from ..alpha_test import AlphaTest
from ..coverage import micro_fraction, sample_levels, sample_points, texel_triangles
from ..promotion import hashed_threshold, promote, promotion_code
from . import format as omm_format

__all__ = ["resolve"]


@njit(cache=True, parallel=True)
def _resolve(states3, starts, levels, two_state, mode, seed, value, thr, inclusive, filt, mu, mv, tris,
             samples, sample_k, out):
    for t in prange(tris.shape[0]):
        base = starts[t]
        for k in range(starts[t + 1] - base):
            s = states3[base + k]
            if s < 2:
                out[base + k] = s
                continue
            if mode == 1 or mode == 2:
                opaque = mode == 1
            else:
                f, cx, cy = micro_fraction(value, thr, inclusive, filt, mu, mv, tris[t], k, levels[t], samples,
                                           sample_k[t])
                opaque = promote(f, mode, hashed_threshold(cx, cy, seed) if mode == 3 else 0.5)
            if two_state:
                out[base + k] = 1 if opaque else 0
            else:
                out[base + k] = 3 if opaque else 2


def resolve(states3: np.ndarray, starts: np.ndarray, levels, test: AlphaTest, tris_uv, fmt: int,
            promotion: str = "nearest", seed: int = 0) -> np.ndarray:
    """OMM states (flat, like ``states3``) of baked T/O/C states: 0/1 in 2-state, 0..3 in 4-state."""
    mode = promotion_code(promotion)
    tris = texel_triangles(test, tris_uv)
    lv = np.ascontiguousarray(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)
    out = np.empty_like(states3)
    filt, mu, mv = test.codes()
    with numba.parallel_chunksize(16):  # triangles differ a lot in cost: hand them out dynamically
        _resolve(states3, np.asarray(starts, dtype=np.int64), lv, fmt == omm_format.FORMAT_2_STATE, mode, int(seed),
                 test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, sample_points(),
                 sample_levels(tris, lv), out)
    return out
