"""Which footprint cells a convex region touches, and the OR of their flags.

A cell counts when its interior and the region's interior overlap (positive area). Rows are
scanned as bands [r, r+1]; within a band the region's x-extent comes from its edges clipped to
the band, and the cells are the unit intervals overlapping that open extent. The arithmetic is
exact for the dyadic coordinates of square cells and micro-triangles (edge/band intersections
whose true value is representable are computed exactly), so maps match an exact reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import states
from .bilinear import POLY_MAX, box_flag_in_cell, cell_flag, extent, point_flag
from .flag_table import box_counts, flag_table, unmixed_flag
from .sampling import cell_index


DIRECT_SPAN = 4  # a row span of at most this many cells is read cell by cell, not counted from the table


@njit(cache=True, inline="always")
def edge_extent(ax, ay, bx, by, y0, y1, xmin, xmax):
    """(xmin, xmax) widened by the x-extent of edge (a, b) within the row band [y0, y1]; exact
    where the true intersection is representable (the band limits hit exactly at vertices)."""
    if ay == by:
        if y0 <= ay <= y1:
            xmin = min(xmin, min(ax, bx))
            xmax = max(xmax, max(ax, bx))
        return xmin, xmax
    if ay > by:
        ax, ay, bx, by = bx, by, ax, ay
    lo = max(ay, y0)
    hi = min(by, y1)
    if lo > hi:
        return xmin, xmax
    xl = ax if lo == ay else ax + ((lo - ay) * (bx - ax)) / (by - ay)
    xh = bx if hi == by else ax + ((hi - ay) * (bx - ax)) / (by - ay)
    return min(xmin, min(xl, xh)), max(xmax, max(xl, xh))


@njit(cache=True, inline="always")
def row_span(poly, k, r, grow, ymin, ymax):
    """Cell columns [c0, c1) that convex polygon ``poly[:k]`` (y-range [ymin, ymax]), grown by
    ``grow``, overlaps in the row band [r, r+1]; (0, 0) when none."""
    y0 = max(float(r) - grow, ymin)
    y1 = min(float(r + 1) + grow, ymax)
    if y1 < y0 or (y1 == y0 and grow == 0.0):
        return 0, 0
    xmin = np.inf
    xmax = -np.inf
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        xmin, xmax = edge_extent(poly[i, 0], poly[i, 1], poly[j, 0], poly[j, 1], y0, y1, xmin, xmax)
    xmin -= grow
    xmax += grow
    if not xmax > xmin:
        return 0, 0
    return int(math.floor(xmin)), int(math.ceil(xmax))


@njit(cache=True, _nrt=False)
def _vertex_flags(grid, poly, k, grow):
    flags, mixed, values, bounds, period_x, period_y = grid
    acc = 0
    for i in range(k):
        acc |= point_flag(flags, mixed, values, bounds, period_x, period_y, poly[i, 0], poly[i, 1], grow)
    return acc


@njit(cache=True, _nrt=False)
def polygon_flags_table(sat, grid, poly, k, grow, points, buf_a, buf_b):
    """OR of the flags of every cell overlapped by convex polygon ``poly[:k]`` given in cell
    coordinates (texel coordinates plus the grid offset), grown by ``grow``; 0 when the polygon
    has no area. ``rows_flag`` (the one rasteriser) as a kernel of its own: the square baker's
    per-cell call. It allocates nothing and runs without numba's reference counting
    (``_nrt=False``), whose atomic counts of the array arguments cost about a tenth of a bake."""
    return rows_flag(sat, grid, poly, k, grow, points, buf_a, buf_b)


@njit(cache=True, inline="always")
def rows_flag(sat, grid, poly, k, grow, points, buf_a, buf_b):
    """OR of the flags of every cell overlapped by convex polygon ``poly[:k]`` (cell coordinates:
    texel coordinates plus the grid offset); 0 when the polygon has no area. Every baker's
    regions are rasterised here.

    Per row band, the polygon's x-extent (``row_span``) gives a span of cells: a short one (at
    most DIRECT_SPAN cells, a micro-triangle's) is read cell by cell, a longer one counted in O(1)
    from the summed-area table ``sat`` (``flag_table.flag_table``) and walked only where it holds
    mixed bilinear cells; each mixed cell's part is decided by ``bilinear.cell_flag``. ``grid``:
    ``FootprintGrid.kernel_args()``; ``points``: the OR of the vertices' own flags
    (``bilinear.point_flag``) when the caller has them (vertices shared with neighbouring
    regions), else -1 (read here when needed); ``buf_*`` (POLY_MAX, 2) scratch.

    Grown on an exact bilinear grid, a region whose vertices agree (all T or all O) is first
    tried from its bounding box (``_box_proof``): most regions beside the cut-off are known from
    the box's cells alone, without their row spans.

    ``grow`` > 0: the polygon grown by a square of half-side ``grow`` (its Minkowski sum), which
    has area even when the polygon has none: per band, the polygon's x-extent over the band
    widened by ``grow`` above and below, then widened by ``grow`` left and right."""
    flags, mixed, values, bounds, period_x, period_y = grid
    ymin, ymax = extent(poly, k, 1)
    r0 = int(math.floor(ymin - grow))  # the row bands it overlaps, grown
    r1 = int(math.ceil(ymax + grow))
    acc = 0
    points_done = False
    has_mixed = mixed.shape[0] > 0
    if grow > 0.0 and has_mixed:
        # grown, every vertex's cell is in a row span below, so its flag is part of the OR: read
        # first (cheap), a region across the cut-off is C before any row is counted. (Ungrown, a
        # vertex on a row's lower edge lies outside the spans: then only after a mixed span.)
        points_done = True
        acc = points if points >= 0 else _vertex_flags(grid, poly, k, grow)
        if acc == 3:
            return 3
        if _box_proof(grid, poly, k, grow, acc, ymin, ymax, r0, r1):
            return acc
    hc, wc = flags.shape
    for r in range(r0, r1):
        c0, c1 = row_span(poly, k, r, grow, ymin, ymax)
        if c1 <= c0:
            continue
        row = cell_index(r, hc, period_y)
        if c1 - c0 <= DIRECT_SPAN:  # a few cells: read them, cheaper than the table's twelve counts
            urow = np.uint64(row)  # stored indices are >= 0: the reads skip numba's negative-index checks
            for c in range(c0, c1):
                col = cell_index(c, wc, period_x)
                ucol = np.uint64(col)
                if has_mixed and mixed[urow, ucol]:  # decided on its own, after the vertices' own flags
                    if not points_done:
                        points_done = True
                        acc |= points if points >= 0 else _vertex_flags(grid, poly, k, grow)
                        if acc == 3:
                            return 3
                    acc |= cell_flag(values, bounds, period_x, period_y, row, col, poly, k, c, r, grow, buf_a, buf_b)
                else:
                    acc |= flags[urow, ucol]
                if acc == 3:
                    return 3
            continue
        nt, no, nm, n = box_counts(sat, r, r + 1, c0, c1, period_y, period_x)
        acc |= unmixed_flag(nt, no, nm)
        if nm > 0 and acc != 3:  # the mixed cells, each decided on its own
            if not points_done:  # the vertices' own flags first
                points_done = True
                acc |= points if points >= 0 else _vertex_flags(grid, poly, k, grow)
                if acc == 3:
                    return 3
            acc |= _mixed_cells_flag(grid, poly, k, grow, r, row, c0, c1, buf_a, buf_b)
        if acc == 3:
            return 3
    return acc


BOX_PROOF_CELLS = 16  # a region's bounding box of at most this many cells is tried first


@njit(cache=True, inline="always")
def _box_proof(grid, poly, k, grow, keep, ymin, ymax, r0, r1):
    """True when the region's grown bounding box (at most BOX_PROOF_CELLS cells) is known to
    be ``keep`` (1 T or 2 O) in every cell: an unmixed cell by its flag, a mixed one by the
    box's part of it (``bilinear.box_flag_in_cell``). The region's cells are among the box's,
    and its part of each within the box's, so the region is then ``keep`` too (with its
    vertices' own flags ``keep``): most regions whose vertices agree are proven so without
    their row spans. (ymin, ymax): the region's y-range, rows [r0, r1) its grown rows."""
    flags, mixed, values, bounds, period_x, period_y = grid
    xmin, xmax = extent(poly, k, 0)
    c0 = int(math.floor(xmin - grow))
    c1 = int(math.ceil(xmax + grow))
    if (r1 - r0) * (c1 - c0) > BOX_PROOF_CELLS:
        return False
    hc, wc = flags.shape
    for r in range(r0, r1):
        row = cell_index(r, hc, period_y)
        urow = np.uint64(row)  # stored indices are >= 0: the reads skip numba's negative-index checks
        for c in range(c0, c1):
            col = cell_index(c, wc, period_x)
            ucol = np.uint64(col)
            if mixed[urow, ucol]:
                if box_flag_in_cell(values, bounds, period_x, period_y, row, col, xmin - c, xmax - c, ymin - r,
                                    ymax - r, grow) != keep:
                    return False
            elif flags[urow, ucol] != keep:
                return False
    return True


@njit(cache=True, _nrt=False)
def _mixed_cells_flag(grid, poly, k, grow, r, row, c0, c1, buf_a, buf_b):
    """OR of ``bilinear.cell_flag`` over the mixed cells of columns [c0, c1) of row band r
    (stored row ``row``), stopping at 3: a long span's (rare: a call of its own, which keeps
    this loop out of every rasteriser ``rows_flag`` is inlined into)."""
    flags, mixed, values, bounds, period_x, period_y = grid
    wc = flags.shape[1]
    acc = 0
    for c in range(c0, c1):
        col = cell_index(c, wc, period_x)
        if mixed[row, col]:
            acc |= cell_flag(values, bounds, period_x, period_y, row, col, poly, k, c, r, grow, buf_a, buf_b)
            if acc == 3:
                return 3
    return acc


@njit(cache=True)
def _regions_flags(sat, grid, polys):
    buf_a = np.empty((POLY_MAX, 2))
    buf_b = np.empty((POLY_MAX, 2))
    out = np.empty(polys.shape[0], dtype=np.uint8)
    for i in range(polys.shape[0]):
        out[i] = rows_flag(sat, grid, polys[i], polys.shape[1], 0.0, np.int64(-1), buf_a, buf_b)
    return out


def region_states(grid, polys_texel: np.ndarray) -> np.ndarray:
    """States (T/O/C codes) of convex regions given in *texel* coordinates, shape (R, K, 2), each
    rasterised on its own."""
    polys = np.ascontiguousarray(polys_texel, dtype=np.float64) + grid.offset
    f = _regions_flags(flag_table(grid), grid.kernel_args(), polys)
    if np.any(f == 0):
        bad = int(np.flatnonzero(f == 0)[0])
        raise ValueError(f"region {bad} has no area")
    return states.FLAG_TO_STATE[f]
