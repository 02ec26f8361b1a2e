"""From three states to the OMM formats: what a C micro-triangle becomes.

4-state output keeps C as "unknown" (the any-hit shader runs) and only chooses which unknown:
unknown-opaque or unknown-transparent, the state a ray flagged "force 2-state" sees. 2-state
output has no unknown: C becomes O or T outright (no longer conservative). The choice, per C
micro-triangle with opaque fraction f (alpha_test.micro_fraction):

* ``opaque`` / ``transparent``: always that way;
* ``nearest``: the majority, O iff f > 1/2;
* ``hashed``: O iff f > h, h a threshold in [0, 1) hashed from the micro-triangle's position in
  texture space (as hashed alpha testing does per pixel), so on average a fraction f of such
  regions turn opaque: coverage is kept in expectation instead of rounded. The threshold depends
  only on the texture-space position, so identical UV triangles still get identical micromaps.

``hashed_threshold`` and ``promote`` are numba functions a tracer can call per hit, too.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from . import format as omm_format
from .alpha_test import AlphaTest, micro_fraction, sample_levels, sample_points, texel_triangles

PROMOTIONS = ("nearest", "opaque", "transparent", "hashed")
HASH_CELLS_PER_TEXEL = 64  # the hashed threshold is constant over 1/64-texel squares


@njit(cache=True, inline="always")
def _mix32(x):
    # a 32-bit integer finaliser (two multiply-xorshift rounds)
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x


@njit(cache=True)
def hashed_threshold(x, y, seed):
    """Threshold in (0, 1) for texel-space point (x, y), constant over 1/64-texel squares."""
    qx = int(math.floor(x * HASH_CELLS_PER_TEXEL)) & 0xFFFFFFFF
    qy = int(math.floor(y * HASH_CELLS_PER_TEXEL)) & 0xFFFFFFFF
    h = _mix32(qx ^ _mix32(qy ^ _mix32(seed & 0xFFFFFFFF)))
    return (h + 0.5) / 4294967296.0


@njit(cache=True, inline="always")
def promote(fraction, mode, threshold):
    """True when a C region resolves to opaque under ``mode`` (index into PROMOTIONS)."""
    if mode == 1:
        return True
    if mode == 2:
        return False
    if mode == 0:
        return fraction > 0.5
    return fraction > threshold


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
    mode = PROMOTIONS.index(promotion)
    tris = texel_triangles(test, tris_uv)
    lv = np.ascontiguousarray(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)
    out = np.empty_like(states3)
    filt, mu, mv = test.codes()
    with numba.parallel_chunksize(16):  # triangles differ a lot in cost: hand them out dynamically
        _resolve(states3, np.asarray(starts, dtype=np.int64), lv, fmt == omm_format.FORMAT_2_STATE, mode, int(seed),
                 test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, sample_points(),
                 sample_levels(tris, lv), out)
    return out


@njit(cache=True)
def _thresholds(centroids, seed):
    out = np.empty(len(centroids))
    for i in range(len(centroids)):
        out[i] = hashed_threshold(centroids[i, 0], centroids[i, 1], seed)
    return out


def resolve_regions(states3, fractions, centroids_texel, promotion: str = "hashed", seed: int = 0) -> np.ndarray:
    """2-state (0 T, 1 O) of any regions -- micro-triangles, the cells of a square map -- from
    their T/O/C states, opaque fractions and texel-space centroids: the tracer's 2-state mode."""
    s = np.asarray(states3, dtype=np.uint8)
    f = np.asarray(fractions, dtype=np.float64)
    mode = PROMOTIONS.index(promotion)
    if mode == 1:
        opaque = np.ones(s.shape, dtype=bool)
    elif mode == 2:
        opaque = np.zeros(s.shape, dtype=bool)
    elif mode == 0:
        opaque = f > 0.5
    else:
        c = np.ascontiguousarray(np.asarray(centroids_texel, dtype=np.float64).reshape(-1, 2))
        opaque = f > _thresholds(c, int(seed)).reshape(s.shape)
    return np.where(s == 2, opaque, s).astype(np.uint8)
