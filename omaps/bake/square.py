"""The pair-square baker: an N x N map over the square of a pair of triangles.

One baker serves every square map: eval's ``sqN`` (the corpus pair, whose corner UVs are the
square's corners), the tracer's square and codec maps (a mesh's pairs with their real UVs) and
``omaps omm --from`` (square maps expanded into micromaps).

A pair is given by its corner UVs (P, 6, 2): the UVs at A's corners (0,0), (1,0), (1,1), then at
B's (0,0), (1,1), (0,1) (``omaps.pair``). Cell (i, j) covers s in [i/N, (i+1)/N], t in
[j/N, (j+1)/N]; its part in A (t <= s) and its part in B (t >= s) are mapped to texture space by
each triangle's own affine UV map (``pair.square_uv``), grown by ``grow`` texels, and the
cell's flag is the OR of the footprint flags either part overlaps (``raster.rows_flag``; in
an exact bilinear grid, the part's own state in each mixed cell).
A lone triangle (``has_b`` False) leaves the cells wholly in B at flag 0: cells no hit reaches,
stored as C (a "don't care" encoders never need to keep).

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.bake.square import bake_pair_squares
    >>> from omaps.pair import PAIR_CORNER_UV
    >>> from omaps.texture import load_alpha
    >>> grid = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8))).grid()
    >>> bake_pair_squares(grid, PAIR_CORNER_UV, np.array([True]), 2)[0].tolist()
    [[0, 1], [0, 1]]
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike

from .. import raster, states
from ..bilinear import POLY_MAX, point_flag
from ..errors import InputError
from ..pair import square_uv
from ..sampling import FootprintGrid
from ..flag_table import MARGIN, box_flag, flag_table
from ..parallel import fetch_add
from ..checks import typed

__all__ = ["bake_pair_squares", "bake_pair_flags", "or_downsample", "flags_to_states", "MAX_SQUARE",
           "check_square_size"]

MAX_SQUARE = 128


@typed
def check_square_size(n: object, param: str = "n") -> int:
    """A square map size: a power of two from 1 to MAX_SQUARE (an ``InputError`` naming ``param``)."""
    from ..checks import integer

    v = integer(n, param)
    if v < 1 or v > MAX_SQUARE or (v & (v - 1)):
        raise InputError(f"{param} must be a square map size, a power of two from 1 to {MAX_SQUARE}, got {v}",
                         param=param)
    return v


@njit(cache=True)
def _clip(poly, k, a, b, c, out):
    """Convex polygon poly[:k] clipped to a*x + b*y + c >= 0, written to ``out``; returns the
    vertex count."""
    m = 0
    for i in range(k):
        j = (i + 1) % k
        x0 = poly[i, 0]
        y0 = poly[i, 1]
        x1 = poly[j, 0]
        y1 = poly[j, 1]
        d0 = a * x0 + b * y0 + c
        d1 = a * x1 + b * y1 + c
        if d0 >= 0:
            out[m, 0] = x0
            out[m, 1] = y0
            m += 1
        if (d0 >= 0) != (d1 >= 0):
            f = d0 / (d0 - d1)
            out[m, 0] = x0 + f * (x1 - x0)
            out[m, 1] = y0 + f * (y1 - y0)
            m += 1
    return m


@njit(cache=True)
def _area2(poly, k):
    a = 0.0
    for i in range(k):
        j = (i + 1) % k
        a += poly[i, 0] * poly[j, 1] - poly[j, 0] * poly[i, 1]
    return a


@njit(cache=True, inline="always")
def _texel_point(uv, b, tri, s, t, w, h, off):
    """Texel coordinates (plus the grid offset) of square point (s, t) through triangle ``tri``'s
    affine UV map (its corners' UVs at ``uv[b:b + 3]``)."""
    u, v = square_uv(uv, b, tri, s, t)
    return u * w + off, v * h + off


@njit(cache=True, _nrt=False)
def _cell_flag(sat, grid, off, w, h, uv, tri, n, i, j, grow, rect, poly, pts, buf_a, buf_b):
    """Flag of triangle ``tri``'s part of cell (i, j) (0 when the part has no area)."""
    s0 = i / n
    s1 = (i + 1) / n
    t0 = j / n
    t1 = (j + 1) / n
    rect[0, 0] = s0
    rect[0, 1] = t0
    rect[1, 0] = s1
    rect[1, 1] = t0
    rect[2, 0] = s1
    rect[2, 1] = t1
    rect[3, 0] = s0
    rect[3, 1] = t1
    if tri == 0:
        k = _clip(rect, 4, 1.0, -1.0, 0.0, poly)  # s - t >= 0
    else:
        k = _clip(rect, 4, -1.0, 1.0, 0.0, poly)  # t - s >= 0
    if k < 3 or abs(_area2(poly, k)) <= 0.0:
        return 0
    for v in range(k):
        pts[v, 0], pts[v, 1] = _texel_point(uv, 3 * tri, tri, poly[v, 0], poly[v, 1], w, h, off)
    return raster.polygon_flags_table(sat, grid, pts, k, grow, np.int64(-1), buf_a, buf_b)


MIN_TREE_AREA = 1e-3  # texel area below which an ungrown triangle is baked cell by cell
STACK = 64  # blocks pending: 3 more per level down (7 levels at most), plus the root


@njit(cache=True, _nrt=False)
def _pair_flags(sat, grid, off, w, h, uv, has_b, n, grow, out, rect, poly, pts, gp, vf, buf_a, buf_b, st_i, st_j,
                st_n):
    """Flags (n, n) of one pair's square map ORed into ``out`` (zeros on entry).

    Each triangle's part is walked as a quadtree of cell blocks: when the box around a block's
    image in texture space (``flag_table.box_flag``) holds only T, only O, or only unmixed C
    cells, every cell of the block in that triangle reads exactly that flag, as ``_cell_flag``
    would find it cell by cell (each part has area, so it reads at least one cell of the box);
    otherwise the block splits. A 2 x 2 block rasterises its four cells in place: their nine
    corners (and, grown over an exact grid, the corners' own flags) are computed once; each cell
    reads its box first, then a cell off the diagonal is rasterised as its whole square (what
    ``_clip`` would return) and a diagonal one by ``_cell_flag``.

    Scratch from the caller: ``rect`` (4, 2), ``poly``, ``pts`` (8, 2), ``buf_*`` (POLY_MAX, 2),
    the block stack ``st_*`` (STACK,). It allocates nothing and runs without numba's reference
    counting (``_nrt=False``), as the leaf kernels below it."""
    flags, mixed, values, bounds, px, py = grid
    points_first = grow > 0.0 and mixed.shape[0] > 0  # as ``raster.polygon_flags_table`` reads them
    no_points = np.int64(-1)
    for tri in range(2):
        if tri == 1 and not has_b:
            break
        b = 3 * tri
        ax, ay = _texel_point(uv, b, tri, 0.0, 0.0, w, h, off)
        bx, by = _texel_point(uv, b, tri, 1.0, 1.0, w, h, off)
        cx, cy = _texel_point(uv, b, tri, 1.0 - tri, float(tri), w, h, off)
        area = 0.5 * abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
        tree = grow > 0.0 or area >= MIN_TREE_AREA  # ungrown, every cell's part then has area
        scale = 1.0
        scale = max(scale, max(abs(ax), abs(ay)))
        scale = max(scale, max(abs(bx), abs(by)))
        scale = max(scale, max(abs(cx), abs(cy)))
        margin = MARGIN * scale + grow
        st_i[0] = 0
        st_j[0] = 0
        st_n[0] = n
        top = 1
        while top > 0:
            top -= 1
            i0 = st_i[top]
            j0 = st_j[top]
            m = st_n[top]
            # the block's cells in this triangle: i >= j for A, i <= j for B
            if (tri == 0 and i0 + m - 1 < j0) or (tri == 1 and i0 > j0 + m - 1):
                continue
            if m == 1:
                out[j0, i0] |= _cell_flag(sat, grid, off, w, h, uv, tri, n, i0, j0, grow, rect, poly, pts, buf_a,
                                          buf_b)
                continue
            f = 0
            if tree:
                xmin = np.inf
                xmax = -np.inf
                ymin = np.inf
                ymax = -np.inf
                for corner in range(4):
                    s = (i0 + (corner & 1) * m) / n
                    t = (j0 + (corner >> 1) * m) / n
                    x, y = _texel_point(uv, b, tri, s, t, w, h, off)
                    xmin = min(xmin, x)
                    xmax = max(xmax, x)
                    ymin = min(ymin, y)
                    ymax = max(ymax, y)
                f, _, _ = box_flag(sat, xmin, xmax, ymin, ymax, margin, py, px)
            if f:
                for j in range(j0, j0 + m):
                    for i in range(i0, i0 + m):
                        if (tri == 0 and i >= j) or (tri == 1 and i <= j):
                            out[j, i] |= f
                continue
            half = m // 2
            if half == 1:  # the children are cells: rasterise the four here, sharing their corners
                for c in range(9):
                    gp[c, 0], gp[c, 1] = _texel_point(uv, b, tri, (i0 + c % 3) / n, (j0 + c // 3) / n, w, h, off)
                    if points_first:  # the corners' own flags, read once for the cells sharing them
                        vf[c] = point_flag(flags, mixed, values, bounds, px, py, gp[c, 0], gp[c, 1], grow)
                for c in range(4):
                    i = i0 + (c & 1)
                    j = j0 + (c >> 1)
                    if (tri == 0 and i < j) or (tri == 1 and i > j):
                        continue
                    g = (c >> 1) * 3 + (c & 1)
                    if tree:  # the cell's box first, as a block's (the part has area: it reads a cell of it)
                        f, _, _ = box_flag(sat, min(min(gp[g, 0], gp[g + 1, 0]), min(gp[g + 3, 0], gp[g + 4, 0])),
                                           max(max(gp[g, 0], gp[g + 1, 0]), max(gp[g + 3, 0], gp[g + 4, 0])),
                                           min(min(gp[g, 1], gp[g + 1, 1]), min(gp[g + 3, 1], gp[g + 4, 1])),
                                           max(max(gp[g, 1], gp[g + 1, 1]), max(gp[g + 3, 1], gp[g + 4, 1])),
                                           margin, py, px)
                        if f:
                            out[j, i] |= f
                            continue
                    if i == j:  # on the diagonal: the cell's part is clipped (``_cell_flag``)
                        out[j, i] |= _cell_flag(sat, grid, off, w, h, uv, tri, n, i, j, grow, rect, poly, pts, buf_a,
                                                buf_b)
                        continue
                    # off the diagonal the part is the whole cell, the polygon ``_clip`` returns:
                    # corners (s0, t0), (s1, t0), (s1, t1), (s0, t1)
                    pts[0, 0], pts[0, 1] = gp[g, 0], gp[g, 1]
                    pts[1, 0], pts[1, 1] = gp[g + 1, 0], gp[g + 1, 1]
                    pts[2, 0], pts[2, 1] = gp[g + 4, 0], gp[g + 4, 1]
                    pts[3, 0], pts[3, 1] = gp[g + 3, 0], gp[g + 3, 1]
                    points = no_points
                    if points_first:
                        points = vf[g] | vf[g + 1] | vf[g + 3] | vf[g + 4]
                        if points == 3:
                            out[j, i] |= 3
                            continue
                    # (k typed, not a literal: a literal 4 made numba compile a second copy of the
                    # rasteriser, 15 s of the first command's compile, for no faster bake)
                    out[j, i] |= raster.polygon_flags_table(sat, grid, pts, np.int64(4), grow, points, buf_a, buf_b)
                continue
            for c in range(3, -1, -1):
                st_i[top] = i0 + (c & 1) * half
                st_j[top] = j0 + (c >> 1) * half
                st_n[top] = half
                top += 1


CHUNK = 16  # pairs per parallel work item (one set of scratch arrays each)


@njit(cache=True, parallel=True)
def _bake_pairs(sat, grid, off, w, h, uv, has_b, n, grow, out, n_workers):
    n_chunks = (uv.shape[0] + CHUNK - 1) // CHUNK
    next_chunk = np.zeros(1, np.int64)
    for worker in prange(n_workers):  # each thread takes the next chunk as it frees up (``omaps.parallel``)
        rect = np.empty((4, 2))
        poly = np.empty((8, 2))
        pts = np.empty((8, 2))
        gp = np.empty((9, 2))
        vf = np.empty(9, np.int64)
        buf_a = np.empty((POLY_MAX, 2))
        buf_b = np.empty((POLY_MAX, 2))
        st_i = np.empty(STACK, np.int64)
        st_j = np.empty(STACK, np.int64)
        st_n = np.empty(STACK, np.int64)
        while True:
            c = fetch_add(next_chunk, 1)
            if c >= n_chunks:
                break
            for p in range(c * CHUNK, min((c + 1) * CHUNK, uv.shape[0])):
                _pair_flags(sat, grid, off, w, h, uv[p], has_b[p], n, grow, out[p], rect, poly, pts, gp, vf, buf_a,
                            buf_b, st_i, st_j, st_n)


@typed
def bake_pair_flags(grid: FootprintGrid, corner_uv: ArrayLike, has_b: ArrayLike, n: int,
                    grow: float = 0.0) -> np.ndarray:
    """Footprint flags (P, n, n) uint8 of the pairs' square maps (0: a cell no hit reaches).
    ``grid`` may be an ``AlphaTest`` (its ``grid()``); an argument of the wrong type or shape
    raises an ``InputTypeError`` / ``InputError`` naming it."""
    from .. import checks

    from ..alpha_test import as_grid

    grid = as_grid(grid)
    n = check_square_size(n)
    grow = checks.number(grow, "grow", 0)
    uv = checks.array(corner_uv, "corner_uv", kinds="iuf", dtype=np.float64)
    if uv.size % 12 or (uv.ndim == 3 and uv.shape[1:] != (6, 2)):
        raise InputError(f"corner_uv must have shape (P, 6, 2), got {uv.shape}", param="corner_uv")
    uv = np.ascontiguousarray(uv).reshape(-1, 6, 2)
    hb_in = checks.array(has_b, "has_b", kinds="biu")
    if hb_in.ndim > 1 or (hb_in.ndim == 1 and len(hb_in) != len(uv)):
        raise InputError(f"has_b must be one bool or one per pair ({len(uv)}), got shape {hb_in.shape}",
                         param="has_b")
    hb = np.array(np.broadcast_to(hb_in.astype(np.bool_), (len(uv),)))  # writable: one specialisation
    if not np.isfinite(uv).all():
        raise InputError("pair corner UVs must be finite")
    out = np.zeros((len(uv), n, n), np.uint8)
    if len(uv):
        _bake_pairs(flag_table(grid), grid.kernel_args(), float(grid.offset), float(grid.width),
                    float(grid.height), uv, hb, n, float(grow), out, numba.get_num_threads())
    return out


@typed
def bake_pair_squares(grid: FootprintGrid, corner_uv: ArrayLike, has_b: ArrayLike, n: int,
                      grow: float = 0.0) -> np.ndarray:
    """States (P, n, n) of the pairs' N x N square maps, ``map[j, i]`` (0 T, 1 O, 2 C).

    Parameters: ``corner_uv`` (P, 6, 2) as in the module docstring; ``has_b`` (P,) bool;
    ``grow`` the region growth in texels (``bake.micromap.GROW_TEXEL`` for real geometry)."""
    return flags_to_states(bake_pair_flags(grid, corner_uv, has_b, n, grow))


def or_downsample(flags: np.ndarray, factor: int) -> np.ndarray:
    """Flags (P, n/factor, n/factor) of square maps from flags (P, n, n) uint8: a coarse cell
    reads what its fine cells read (exact: a coarse cell's parts are the union of its fine cells'
    parts). ``factor`` divides n."""
    from .. import checks

    f = checks.array(flags, "flags", ndim=3, kinds="u")
    if f.shape[1] != f.shape[2]:
        raise InputError(f"flags must have shape (P, n, n), got {f.shape}", param="flags")
    factor = checks.integer(factor, "factor", 1, max(1, f.shape[1]))
    if f.shape[1] % factor:
        raise InputError(f"factor must divide the map size {f.shape[1]}, got {factor}", param="factor")
    return _or_downsample(np.ascontiguousarray(f, dtype=np.uint8), factor)


@njit(cache=True)
def _or_downsample(flags, factor):
    p, n, _ = flags.shape
    m = n // factor
    out = np.zeros((p, m, m), np.uint8)
    for q in range(p):
        for j in range(n):
            for i in range(n):
                out[q, j // factor, i // factor] |= flags[q, j, i]
    return out


def flags_to_states(flags: np.ndarray) -> np.ndarray:
    """Flag 0 (a cell no hit can reach) becomes C."""
    return states.FLAG_TO_STATE[flags]
