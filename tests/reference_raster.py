"""The cell-by-cell rasteriser: every cell a convex region overlaps read one at a time, with no
summed-area table, tree walk or shared vertices -- the slow baker the fast ones (``raster.rows_flag``
under both bakers) must equal, flag for flag. It shares the row arithmetic (``raster.row_span``)
and the exact bilinear cell kernels (``bilinear``) with them; ``reference.py`` is the independent
brute force for both."""

import math

import numpy as np
from numba import njit

from omaps.bilinear import POLY_MAX, cell_flag, point_flag
from omaps.raster import row_span
from omaps.sampling import cell_index


@njit(cache=True)
def polygon_flags(flags, mixed, values, bounds, period_x, period_y, poly, grow=0.0):
    """OR of the flags of every cell overlapped by convex polygon ``poly`` (K, 2) given in cell
    coordinates (texel coordinates plus the grid offset). 0 when the polygon has no area.
    The grid's arrays come from ``FootprintGrid.kernel_args``: in an exact bilinear grid a mixed
    cell's flag is the polygon's own part of it (``bilinear.cell_flag``).

    ``grow`` > 0: the polygon grown by a square of half-side ``grow`` (its Minkowski sum), which
    has area even when the polygon has none: per band, the polygon's x-extent over the band
    widened by ``grow`` above and below, then widened by ``grow`` left and right."""
    k = poly.shape[0]
    ymin = poly[0, 1]
    ymax = poly[0, 1]
    for i in range(1, k):
        ymin = min(ymin, poly[i, 1])
        ymax = max(ymax, poly[i, 1])
    hc, wc = flags.shape
    exact = values.shape[0] > 0
    buf_a = np.empty((0, 2))
    buf_b = np.empty((0, 2))
    acc = 0
    for r in range(int(math.floor(ymin - grow)), int(math.ceil(ymax + grow))):
        c0, c1 = row_span(poly, k, r, grow, ymin, ymax)
        if c1 <= c0:
            continue
        row = cell_index(r, hc, period_y)
        for c in range(c0, c1):
            col = cell_index(c, wc, period_x)
            f = flags[row, col]
            if exact and mixed[row, col]:
                if buf_a.shape[0] == 0:  # the first mixed cell: the vertices' own flags first
                    for i in range(k):
                        acc |= point_flag(flags, mixed, values, bounds, period_x, period_y, poly[i, 0], poly[i, 1],
                                          grow)
                    if acc == 3:
                        return acc
                    buf_a = np.empty((POLY_MAX, 2))
                    buf_b = np.empty((POLY_MAX, 2))
                f = cell_flag(values, bounds, period_x, period_y, row, col, poly, k, c, r, grow, buf_a, buf_b)
            acc |= f
            if acc == 3:
                return acc
    return acc
