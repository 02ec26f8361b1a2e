"""From three states to two: what a C region becomes when it must be O or T.

Used by the OMM formats (4-state output picks unknown-opaque or unknown-transparent, the state a
ray flagged "force 2-state" sees; 2-state output resolves C outright) and by the tracer's 2-state
mode. The rule, per C region with opaque fraction f (``omaps.coverage``):

* ``opaque`` / ``transparent``: always that way;
* ``nearest``: the majority, O iff f > 1/2;
* ``hashed``: O iff f > h, h a threshold in (0, 1) hashed from the region's centroid in texture
  space (as hashed alpha testing does per pixel), so on average a fraction f of such regions turn
  opaque: coverage is kept in expectation instead of rounded. The threshold depends only on the
  texture-space position, so identical UV triangles still get identical micromaps.

Example::

    >>> import numpy as np
    >>> from omaps.promotion import resolve_regions
    >>> resolve_regions(np.array([0, 1, 2, 2]), np.array([0, 1, 0.7, 0.2]), np.zeros((4, 2)), "nearest").tolist()
    [0, 1, 1, 0]
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .errors import InputError

__all__ = ["PROMOTIONS", "promotion_code", "hashed_threshold", "promotion_cut", "hits_needed", "resolve_regions",
           "NEAREST", "OPAQUE", "TRANSPARENT", "HASHED"]

from .names import PROMOTIONS  # noqa: E402 (numba-free, for the command line)
HASH_CELLS_PER_TEXEL = 64  # the hashed threshold is constant over 1/64-texel squares
NEAREST, OPAQUE, TRANSPARENT, HASHED = (PROMOTIONS.index(n) for n in ("nearest", "opaque", "transparent", "hashed"))


def promotion_code(name: str) -> int:
    try:
        return PROMOTIONS.index(name)
    except ValueError:
        raise InputError(f"unknown promotion {name!r} (choose from {', '.join(PROMOTIONS)})") from None


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
def promotion_cut(mode, threshold):
    """The rule: a C region becomes O when its opaque fraction (in [0, 1]) exceeds this cut.

    ``mode`` indexes PROMOTIONS: -1 under ``opaque`` (every fraction exceeds it), 1 under
    ``transparent`` (none does), 1/2 under ``nearest``, ``threshold`` (the region's
    ``hashed_threshold``) under ``hashed``. ``promotion_cut.py_func`` takes an array of
    thresholds too."""
    if mode == OPAQUE:
        return -1.0
    if mode == TRANSPARENT:
        return 1.0
    if mode == NEAREST:
        return 0.5
    return threshold


@njit(cache=True, inline="always")
def hits_needed(mode, threshold, n):
    """``promotion_cut`` as a count: the fewest of ``n`` sample points (a power of two) that must
    pass the alpha test for the region to become O, floor(cut * n) + 1 -- exact, hits / n and
    cut * n being exact. At most 0 under ``opaque``, n + 1 under ``transparent``."""
    return int(math.floor(promotion_cut(mode, threshold) * n)) + 1


@njit(cache=True)
def _thresholds(centroids, seed):
    out = np.empty(len(centroids))
    for i in range(len(centroids)):
        out[i] = hashed_threshold(centroids[i, 0], centroids[i, 1], seed)
    return out


def resolve_regions(states3, fractions, centroids_texel, promotion: str = "hashed", seed: int = 0) -> np.ndarray:
    """2-state (0 T, 1 O) of any regions -- micro-triangles, the cells of a square map -- from
    their T/O/C states, opaque fractions and texel-space centroids."""
    s = np.asarray(states3, dtype=np.uint8)
    f = np.asarray(fractions, dtype=np.float64)
    mode = promotion_code(promotion)
    threshold = 0.0
    if mode == HASHED:
        c = np.ascontiguousarray(np.asarray(centroids_texel, dtype=np.float64).reshape(-1, 2))
        threshold = _thresholds(c, int(seed)).reshape(s.shape)
    opaque = f > promotion_cut.py_func(mode, threshold)
    return np.where(s == 2, opaque, s).astype(np.uint8)
