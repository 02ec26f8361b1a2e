"""A summed-area table of a footprint grid's flags: the cells of any box, wrapped or clamped as
the sampler addresses them, counted in O(1).

The bakers use it to skip whole regions: when the box around a region (its bounding box, widened
by ``MARGIN``) holds only T cells, only O cells or only C cells with none mixed, every part of
the region has that state, exactly as the cell-by-cell rasteriser would find it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .sampling import FootprintGrid

__all__ = ["flag_table", "box_counts", "box_flag", "unmixed_flag", "MARGIN"]

MARGIN = 1e-9  # relative widening of region boxes; float rounding of the coordinates is ~1e-15


def flag_table(grid: FootprintGrid) -> np.ndarray:
    """Summed-area table (Hc+1, Wc+1, 3) int32 of the T bit (plane 0), the O bit (plane 1) and
    mixed cells (plane 2, ``FootprintGrid.mixed``; none unless the grid is exact): ``sat[y, x, k]``
    counts the cells above row y and left of column x with bit k."""
    return _flag_table(grid.flags, grid.mixed)


@njit(cache=True)
def _flag_table(flags, mixed):
    h, w = flags.shape
    has_mixed = mixed.shape[0] > 0
    sat = np.zeros((h + 1, w + 1, 3), dtype=np.int32)
    for y in range(h):
        rt = 0
        ro = 0
        rm = 0
        for x in range(w):
            f = flags[y, x]
            rt += f & 1
            ro += (f >> 1) & 1
            if has_mixed:
                rm += mixed[y, x]
            sat[y + 1, x + 1, 0] = sat[y, x + 1, 0] + rt
            sat[y + 1, x + 1, 1] = sat[y, x + 1, 1] + ro
            sat[y + 1, x + 1, 2] = sat[y, x + 1, 2] + rm
    return sat


@njit(cache=True, inline="always")
def _axis_ranges(c0, c1, size, period):
    """Unaddressed cell range [c0, c1) as up to two ranges of stored cells [a0, b0), [a1, b1)."""
    if c0 >= 0 and c1 <= size:  # inside the grid every mode reads the cells as they are
        return c0, c1, 0, 0
    if period == 0:  # clamp: the distinct cells the range reads
        lo = min(max(c0, 0), size - 1)
        hi = min(max(c1 - 1, 0), size - 1)
        return lo, hi + 1, 0, 0
    if c1 - c0 >= period:
        return 0, period, 0, 0
    a = c0 % period
    if a < 0:
        a += period
    b = a + (c1 - c0)
    if b <= period:
        return a, b, 0, 0
    return a, period, 0, b - period


@njit(cache=True, inline="always")
def _unsigned(r):
    """Stored ranges (never negative) as unsigned indices: numba then reads the table without its
    check for negative indices (three per read, twelve reads per box)."""
    return np.uint64(r[0]), np.uint64(r[1]), np.uint64(r[2]), np.uint64(r[3])


@njit(cache=True, inline="always")
def _rect(sat, y0, y1, x0, x1, k):
    return sat[y1, x1, k] - sat[y0, x1, k] - sat[y1, x0, k] + sat[y0, x0, k]


@njit(cache=True, inline="always")
def box_counts(sat, r0, r1, c0, c1, period_y, period_x):
    """(cells with the T bit, with the O bit, mixed cells, distinct cells) of the box
    [c0,c1)x[r0,r1)."""
    ya0, yb0, ya1, yb1 = _unsigned(_axis_ranges(r0, r1, sat.shape[0] - 1, period_y))
    xa0, xb0, xa1, xb1 = _unsigned(_axis_ranges(c0, c1, sat.shape[1] - 1, period_x))
    nt = _rect(sat, ya0, yb0, xa0, xb0, 0)
    no = _rect(sat, ya0, yb0, xa0, xb0, 1)
    nm = _rect(sat, ya0, yb0, xa0, xb0, 2)
    if xb1 > xa1:  # the x range wraps around the period
        nt += _rect(sat, ya0, yb0, xa1, xb1, 0)
        no += _rect(sat, ya0, yb0, xa1, xb1, 1)
        nm += _rect(sat, ya0, yb0, xa1, xb1, 2)
    if yb1 > ya1:
        nt += _rect(sat, ya1, yb1, xa0, xb0, 0)
        no += _rect(sat, ya1, yb1, xa0, xb0, 1)
        nm += _rect(sat, ya1, yb1, xa0, xb0, 2)
        if xb1 > xa1:
            nt += _rect(sat, ya1, yb1, xa1, xb1, 0)
            no += _rect(sat, ya1, yb1, xa1, xb1, 1)
            nm += _rect(sat, ya1, yb1, xa1, xb1, 2)
    n = (np.int64(yb0 - ya0) + np.int64(yb1 - ya1)) * (np.int64(xb0 - xa0) + np.int64(xb1 - xa1))
    return nt, no, nm, n


@njit(cache=True, inline="always")
def unmixed_flag(nt, no, nm):
    """The flag bits of a box's cells other than the mixed ones, from ``box_counts`` (a mixed
    cell counts in all three, so a count above ``nm`` is an unmixed cell's)."""
    return (1 if nt > nm else 0) | (2 if no > nm else 0)


@njit(cache=True, inline="always")
def box_flag(sat, xmin, xmax, ymin, ymax, margin, period_y, period_x):
    """The flag every part of a region inside [xmin, xmax] x [ymin, ymax] (widened by ``margin``)
    reads, when the box decides it: 1 (only T cells), 2 (only O cells), 3 (only C cells, none
    mixed), else 0; with the box's mixed and distinct cell counts (nm, nc)."""
    c0 = int(math.floor(xmin - margin))
    c1 = int(math.ceil(xmax + margin))
    r0 = int(math.floor(ymin - margin))
    r1 = int(math.ceil(ymax + margin))
    nt, no, nm, nc = box_counts(sat, r0, r1, c0, c1, period_y, period_x)
    if no == 0:
        return 1, nm, nc
    if nt == 0:
        return 2, nm, nc
    if nt == nc and no == nc and nm == 0:
        return 3, nm, nc
    return 0, nm, nc

