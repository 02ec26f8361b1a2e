"""The exact state of a region's part of a mixed bilinear cell, from the alpha's extremes there.

Under bilinear filtering a hit in footprint cell (r, c) (``omaps.sampling``) reads
``f(x, y) = a00 + x (a01 - a00) + y (a10 - a00) + x y (a00 - a01 - a10 + a11)`` at local
coordinates (x, y) in [0, 1]², the cell's four taps a.. (the texels of rows r-1, r and columns
c-1, c, addressed). A region is O there iff the minimum of f over its part of the cell passes the
alpha test, T iff the maximum fails it. f has no extremum inside a convex polygon (its only
critical point is a saddle), so over the region clipped to the cell its extremes lie at the
clipped polygon's vertices or inside an edge, where f is a quadratic of the edge parameter.

A cell is only evaluated here when its taps disagree (``FootprintGrid.mixed``); elsewhere the OR
of the tap flags is already exact. Real geometry (the tracer's maps, OMMs) is baked with a
growth ``grow`` > 0 (``bake.micromap.GROW_TEXEL``), and two allowances then keep the answer
conservative for the shader:

* growth: the grown region is bounded by clipping the *ungrown* region to the cell grown by
  ``grow`` and widening the extremes by ``grow`` times f's slope bound there;
* rounding: the extremes are widened by 1e-12 of the largest tap (the shader's float64
  evaluation, ``sampling.sample_texture``) and by the slope times 1e-14 texel (the clipping's
  arithmetic), so a region whose extreme is within that of the cut-off stays C.

With no growth (the corpus pair's exact regions, which no ray reads) the extremes are compared
as computed: for dyadic regions and integer alphas the arithmetic is exact, so a tie -- the
alpha equal to the cut-off, e.g. on the edge between texels 0 and 255 at cut-off 127.5 --
follows the rule's own > or >=.

Example: a cell whose alpha rises from 0 on the left to 255 on the right, cut-off 127.5, is O on
its right half and C across the middle::

    >>> import numpy as np
    >>> from omaps.bilinear import POLY_MAX, cell_flag
    >>> values = np.array([[0.0, 255.0]]); bounds = np.array([127.5, 0, 127.5, 1])
    >>> right = np.array([[1.6, 0.0], [2.0, 0.0], [2.0, 1.0], [1.6, 1.0]])  # in cell (0, 1)
    >>> a, b = np.empty((POLY_MAX, 2)), np.empty((POLY_MAX, 2))
    >>> int(cell_flag(values, bounds, 0, 0, 0, 1, right, 4, 1, 0, 0.0, a, b))  # FLAG_O
    2
    >>> int(cell_flag(values, bounds, 0, 0, 0, 1, right - [0.3, 0.0], 4, 1, 0, 0.0, a, b))  # FLAG_C
    3
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .alpha_test import below, passes
from .sampling import cell_index

__all__ = ["cell_flag", "point_flag", "cell_taps", "region_extremes", "POLY_MAX"]

POLY_MAX = 24  # vertices of a region clipped to a cell: at most the region's (<= 8) + 4
# The kernels the bakers call per region (``region_extremes``, ``cell_flag``, ``point_flag``)
# run without numba's reference counting (``_nrt=False``): they allocate nothing, and the atomic
# counts of their array arguments took about a tenth of the OMM bake.


@njit(cache=True, inline="always")
def extent(poly, k, axis):
    """(min, max) of coordinate ``axis`` over polygon ``poly[:k]``."""
    lo = poly[0, axis]
    hi = poly[0, axis]
    for i in range(1, k):
        lo = min(lo, poly[i, axis])
        hi = max(hi, poly[i, axis])
    return lo, hi


@njit(cache=True, inline="always")
def _tap_pair(i, n, period):
    """The two taps (i - 1, i) of stored cell index i on an axis of n texels: periodic (the
    taps of cell 0 wrap to period - 1) or clamped into [0, n)."""
    if period:
        return (i - 1 if i > 0 else period - 1), i
    return max(i - 1, 0), min(i, n - 1)


@njit(cache=True, inline="always")
def cell_taps(values, period_x, period_y, row, col):
    """The taps (a00, a01, a10, a11) of stored cell (row, col): rows row-1, row and columns
    col-1, col of ``values`` (extended like the flags), periodic or clamped."""
    h, w = values.shape
    ya, yb = _tap_pair(row, h, period_y)
    xa, xb = _tap_pair(col, w, period_x)
    ya, yb, xa, xb = np.uint64(ya), np.uint64(yb), np.uint64(xa), np.uint64(xb)  # >= 0: no negative-index checks
    return values[ya, xa], values[ya, xb], values[yb, xa], values[yb, xb]


@njit(cache=True, inline="always")
def _coefficients(a00, a01, a10, a11):
    """(b, c, d) of the cell's bilinear f = a00 + b x + c y + d x y: the shader's blend
    (``sampling.blend``) in the form whose extremes over a polygon are found from its edges."""
    return a01 - a00, a10 - a00, a00 - a01 - a10 + a11


@njit(cache=True, inline="always")
def _at(a00, b, c, d, x, y):
    """The cell's bilinear f = a00 + b x + c y + d x y at local (x, y)."""
    return a00 + b * x + c * y + d * x * y


@njit(cache=True, inline="always")
def _clip_axis(src, k, dst, axis, bound, keep_above):
    """Polygon src[:k] clipped to coordinate ``axis`` >= bound (``keep_above``) or <= bound."""
    m = 0
    for i in range(k):
        p0 = src[i, axis]
        p1 = src[(i + 1) % k, axis]
        in0 = p0 >= bound if keep_above else p0 <= bound
        in1 = p1 >= bound if keep_above else p1 <= bound
        if in0:
            dst[m, 0] = src[i, 0]
            dst[m, 1] = src[i, 1]
            m += 1
        if in0 != in1:
            j = (i + 1) % k
            f = (bound - p0) / (p1 - p0)
            o = 1 - axis
            dst[m, axis] = bound
            dst[m, o] = src[i, o] + f * (src[j, o] - src[i, o])
            m += 1
    return m


@njit(cache=True, _nrt=False)
def region_extremes(poly, k, ox, oy, lo, hi, a00, a01, a10, a11, buf_a, buf_b):
    """(min, max) of the bilinear f of taps a.. over polygon poly[:k] - (ox, oy) (local
    coordinates) clipped to the box [lo, hi]²; (inf, -inf) when nothing is left. ``buf_*``:
    scratch (POLY_MAX, 2)."""
    xmin = ymin = np.inf
    xmax = ymax = -np.inf
    for i in range(k):
        x = poly[i, 0] - ox
        y = poly[i, 1] - oy
        buf_a[i, 0] = x
        buf_a[i, 1] = y
        xmin = min(xmin, x)
        xmax = max(xmax, x)
        ymin = min(ymin, y)
        ymax = max(ymax, y)
    # clip only against the box sides the polygon crosses (a small region often lies inside)
    cur = buf_a
    other = buf_b
    if xmin < lo:
        k = _clip_axis(cur, k, other, 0, lo, True)
        cur, other = other, cur
    if xmax > hi:
        k = _clip_axis(cur, k, other, 0, hi, False)
        cur, other = other, cur
    if ymin < lo:
        k = _clip_axis(cur, k, other, 1, lo, True)
        cur, other = other, cur
    if ymax > hi:
        k = _clip_axis(cur, k, other, 1, hi, False)
        cur, other = other, cur
    buf_a = cur
    b, c, d = _coefficients(a00, a01, a10, a11)
    mn = np.inf
    mx = -np.inf
    for i in range(k):
        px = buf_a[i, 0]
        py = buf_a[i, 1]
        v = _at(a00, b, c, d, px, py)
        mn = min(mn, v)
        mx = max(mx, v)
        dx = buf_a[(i + 1) % k, 0] - px
        dy = buf_a[(i + 1) % k, 1] - py
        q2 = d * dx * dy  # f along the edge: v + q1 s + q2 s², s in [0, 1]
        if q2 != 0.0:
            q1 = b * dx + c * dy + d * (px * dy + py * dx)
            s = -q1 / (2.0 * q2)
            if 0.0 < s < 1.0:
                v = _at(a00, b, c, d, px + s * dx, py + s * dy)
                mn = min(mn, v)
                mx = max(mx, v)
    return mn, mx


@njit(cache=True, _nrt=False)
def cell_flag(values, bounds, period_x, period_y, row, col, poly, k, c, r, grow, buf_a, buf_b):
    """Flag (1 T, 2 O, 3 C) of convex polygon poly[:k] (grid coordinates), grown by ``grow``,
    within the cell of unaddressed index (r, c), stored at (row, col). ``buf_*``: scratch
    (POLY_MAX, 2). See the module docstring for the allowances. (A call: inlined into the
    rasteriser it saved about a tenth of the bake's instructions but doubled the compile of the
    square baker; the clipped polygon's extremes are ``_clipped_flag``.)"""
    a00, a01, a10, a11 = cell_taps(values, period_x, period_y, row, col)
    # first the region's bounding box within the cell: a box that is known makes the region
    # inside it known (most regions are). (Rounding is monotone: min(p - c) is min(p) - c.)
    x0, x1 = extent(poly, k, 0)
    y0, y1 = extent(poly, k, 1)
    f = _box_flag(x0 - c, x1 - c, y0 - r, y1 - r, a00, a01, a10, a11, bounds, grow)
    if f != 3:
        return f
    return _clipped_flag(bounds, poly, k, c, r, -grow, 1.0 + grow, a00, a01, a10, a11, grow, buf_a, buf_b)


@njit(cache=True, inline="always")
def _box_flag(x0, x1, y0, y1, a00, a01, a10, a11, bounds, grow):
    """Flag of the box [x0, x1] x [y0, y1] (local coordinates) within the cell grown by ``grow``
    ([-grow, 1 + grow]²), the cell's taps a..: f's extremes over a box are at its corners. 3
    (undecided) when the box misses the cell."""
    x0 = max(x0, -grow)
    y0 = max(y0, -grow)
    x1 = min(x1, 1.0 + grow)
    y1 = min(y1, 1.0 + grow)
    if not (x0 <= x1 and y0 <= y1):
        return 3
    b, cc, d = _coefficients(a00, a01, a10, a11)
    v0 = _at(a00, b, cc, d, x0, y0)
    v1 = _at(a00, b, cc, d, x1, y0)
    v2 = _at(a00, b, cc, d, x0, y1)
    v3 = _at(a00, b, cc, d, x1, y1)
    return _classify(min(min(v0, v1), min(v2, v3)), max(max(v0, v1), max(v2, v3)), a00, a01, a10, a11, bounds, grow)


@njit(cache=True, inline="always")
def box_flag_in_cell(values, bounds, period_x, period_y, row, col, x0, x1, y0, y1, grow):
    """Flag (1 T, 2 O, 3 C or undecided) of the box [x0, x1] x [y0, y1] (local coordinates of
    the mixed cell stored at (row, col)), grown by ``grow``: decided from the box's corners, as
    ``cell_flag`` first decides a region from its bounding box."""
    a00, a01, a10, a11 = cell_taps(values, period_x, period_y, row, col)
    return _box_flag(x0, x1, y0, y1, a00, a01, a10, a11, bounds, grow)


@njit(cache=True, _nrt=False)
def _clipped_flag(bounds, poly, k, c, r, lo, hi, a00, a01, a10, a11, grow, buf_a, buf_b):
    """``cell_flag`` from the extremes over the polygon clipped to the cell [lo, hi]² (local)."""
    mn, mx = region_extremes(poly, k, float(c), float(r), lo, hi, a00, a01, a10, a11, buf_a, buf_b)
    if mn > mx:  # the region misses the cell by rounding: count all of it
        return 3
    return _classify(mn, mx, a00, a01, a10, a11, bounds, grow)


@njit(cache=True, inline="always")
def _classify(mn, mx, a00, a01, a10, a11, bounds, grow):
    """Flag of an alpha range [mn, mx] read in a cell of taps a.., with the allowances."""
    slack = 0.0
    if grow > 0.0:
        sx = max(abs(a01 - a00), abs(a11 - a10))
        sy = max(abs(a10 - a00), abs(a11 - a01))
        amax = max(max(abs(a00), abs(a01)), max(abs(a10), abs(a11)))
        slack = (grow + 1e-14) * (sx + sy) * (1.0 + 2.0 * grow) + 1e-12 * amax
    lo = mn - slack
    hi = mx + slack
    opaque = passes(lo, bounds[0], bounds[1] != 0.0)
    transparent = below(hi, bounds[2], bounds[3] != 0.0)
    if opaque and not transparent:
        return 2
    if transparent and not opaque:
        return 1
    return 3


@njit(cache=True, inline="always")
def point_flag(flags, mixed, values, bounds, period_x, period_y, x, y, grow):
    """Flag of one point (x, y) (grid coordinates) of a region: part of the region's own flag,
    so a region whose points' flags OR to 3 is C without clipping it to any cell (a quick
    answer for regions across the cut-off). A point in a cell whose taps agree has its cell's
    flag (inlined where it is called: that read costs less than a call); in a mixed cell, the
    bilinear alpha there (``_mixed_point_flag``)."""
    c = math.floor(x)
    r = math.floor(y)
    hc, wc = flags.shape
    row = cell_index(r, hc, period_y)
    col = cell_index(c, wc, period_x)
    urow, ucol = np.uint64(row), np.uint64(col)  # >= 0: the reads skip numba's negative-index checks
    if not mixed[urow, ucol]:
        return flags[urow, ucol]
    return _mixed_point_flag(values, bounds, period_x, period_y, row, col, x - c, y - r, grow)


@njit(cache=True, _nrt=False)
def _mixed_point_flag(values, bounds, period_x, period_y, row, col, fx, fy, grow):
    """``point_flag`` at local (fx, fy) of the mixed cell stored at (row, col)."""
    a00, a01, a10, a11 = cell_taps(values, period_x, period_y, row, col)
    b, cc, d = _coefficients(a00, a01, a10, a11)
    v = _at(a00, b, cc, d, fx, fy)
    return _classify(v, v, a00, a01, a10, a11, bounds, grow)
