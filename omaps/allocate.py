"""The allocation of a byte budget: which option each item takes, so that the value (expected
any-hit calls saved) is largest for the bytes spent.

Each item (a pair of triangles, or a triangle) has a few options, each a (bytes, value) point:
no map (0 bytes, 0), a raw square, a codec block, a micromap level... ``value`` is the expected
alpha tests the option saves (the item's weight -- expected candidate hits -- times its known
fraction). Options off the upper convex hull of an item's points are never worth taking: a
mix of its neighbours gives more per byte. Along the hull the marginal value per byte falls, so
the allocation takes hull steps of all items in order of falling value per byte, skipping a step
that no longer fits (and every later step of that item), until the budget is spent. Steps are
taken whole, so the bytes chosen never exceed the budget.

Example::

    >>> import numpy as np
    >>> from omaps.allocate import allocate
    >>> nbytes = np.array([[0, 32, 64], [0, 32, 64]])
    >>> value = np.array([[0.0, 5.0, 6.0], [0.0, 1.0, 4.0]])
    >>> allocate(nbytes, value, 96).tolist()  # item 0 takes 32 bytes (5 per 32), item 1 its 64
    [1, 2]
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .errors import InputError

__all__ = ["allocate", "allocate_arrays", "upper_hull"]


@njit(cache=True)
def upper_hull(nbytes, value):
    """Indices of the options of one item on the upper convex hull of (bytes, value), by
    increasing bytes and strictly increasing value, starting at the cheapest option."""
    order = np.argsort(nbytes, kind="mergesort")
    hull = np.empty(len(order), dtype=np.int64)
    m = 0
    for i in order:
        if m > 0 and nbytes[i] == nbytes[hull[m - 1]]:
            if value[i] <= value[hull[m - 1]]:
                continue
            m -= 1  # same bytes, more value: replaces it
        if m > 0 and value[i] <= value[hull[m - 1]]:
            continue  # more bytes for no more value
        while m >= 2:
            a = hull[m - 2]
            b = hull[m - 1]
            # b lies on or below the segment a -> i: drop it
            if (value[b] - value[a]) * (nbytes[i] - nbytes[a]) <= (value[i] - value[a]) * (nbytes[b] - nbytes[a]):
                m -= 1
            else:
                break
        hull[m] = i
        m += 1
    return hull[:m]


@njit(cache=True)
def _steps(nbytes, value):
    """All hull steps: (item, from option, to option, extra bytes, value per byte)."""
    n_items, n_opt = nbytes.shape
    item = np.empty(n_items * n_opt, np.int64)
    src = np.empty(n_items * n_opt, np.int64)
    dst = np.empty(n_items * n_opt, np.int64)
    cost = np.empty(n_items * n_opt, np.int64)
    gain = np.empty(n_items * n_opt, np.float64)
    start = np.empty(n_items, np.int64)
    k = 0
    for p in range(n_items):
        h = upper_hull(nbytes[p], value[p])
        start[p] = h[0]
        for j in range(1, len(h)):
            item[k] = p
            src[k] = h[j - 1]
            dst[k] = h[j]
            cost[k] = nbytes[p, h[j]] - nbytes[p, h[j - 1]]
            gain[k] = (value[p, h[j]] - value[p, h[j - 1]]) / cost[k]
            k += 1
    return item[:k], src[:k], dst[:k], cost[:k], gain[:k], start


@njit(cache=True)
def _take(item, src, dst, cost, order, start, budget, spent):
    choice = start.copy()
    for s in order:
        p = item[s]
        if choice[p] != src[s]:
            continue  # an earlier step of this item was skipped
        if spent + cost[s] <= budget:
            choice[p] = dst[s]
            spent += cost[s]
    return choice, spent


@njit(cache=True)
def allocate_arrays(nbytes, value, budget):
    """``allocate`` on arrays it has checked (int64 and float64, at least one item), for kernels
    that allocate many times: (choice, bytes of the cheapest options); the choice is empty when
    those exceed ``budget``."""
    item, src, dst, cost, gain, start = _steps(nbytes, value)
    base = 0
    for p in range(start.shape[0]):
        base += nbytes[p, start[p]]
    if base > budget:
        return np.zeros(0, np.int64), base
    # falling value per byte, ties by item: the steps come item by item and the sort is stable
    order = np.argsort(-gain, kind="mergesort")
    choice, _ = _take(item, src, dst, cost, order, start, budget, base)
    return choice, base


def allocate(nbytes, value, budget: int) -> np.ndarray:
    """Per item, the index of the option to take (items (P,) by options (K,) arrays of bytes, int,
    and value, float) so that the total bytes stay within ``budget`` and the total value is the
    greedy hull optimum. Each item starts at its cheapest option; those must fit the budget."""
    b = np.ascontiguousarray(nbytes, dtype=np.int64)
    v = np.ascontiguousarray(value, dtype=np.float64)
    if b.ndim != 2 or b.shape != v.shape or b.shape[1] == 0:
        raise ValueError(f"bytes and values must be (items, options) arrays of one shape, got {b.shape}, {v.shape}")
    if not np.isfinite(v).all() or (b < 0).any():
        raise ValueError("option values must be finite and bytes non-negative")
    if len(b) == 0:
        return np.zeros(0, np.int64)
    choice, base = allocate_arrays(b, v, int(budget))
    if base > budget:
        raise InputError(f"the budget of {budget} bytes is below the {base} bytes the cheapest options need")
    return choice
