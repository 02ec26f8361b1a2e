"""The micromap baker: T/O/C states of every micro-triangle of UV triangles, levels 0..12.

One baker serves every per-triangle map: eval's ``triL`` (the corpus pair's two triangles), the
tracer's ``triL`` and the standard OMMs. A micro-triangle's state is the OR of the footprint
flags of every cell its interior overlaps, as the one rasteriser ``raster.rows_flag`` computes
it, with the optional growth ``grow`` (texels, the Minkowski sum with a square; see
``GROW_TEXEL``). Each triangle is walked down the subdivision tree in the bird-curve order
(``birdcurve.child``), and two facts make it fast without changing a state:

* a summed-area table of the grid's T and O flag bits counts a box of cells in O(1): when the
  box around a node (its bounding box, widened by a margin far above float rounding) is all T,
  all O or all C, every micro-triangle below it has that state, and its index range is filled
  at once (the descendants of node k of level l are k*4^(L-l) ... (k+1)*4^(L-l) - 1);
* a leaf (a micro-triangle under a mixed box) is rasterised by ``raster.rows_flag``: each row's
  cell span is read from the same table in O(1); only a span holding mixed bilinear cells
  (``FootprintGrid.mixed``) is walked cell by cell, each mixed cell decided by
  ``bilinear.cell_flag``; a leaf whose vertices agree is first tried from its bounding box
  (most leaves beside the cut-off are known from the box's few cells).

A box holding a mixed cell is never filled as C from the table: part of it may be known. A small
one (at most NODE_EXACT_CELLS cells) is rasterised like a leaf first; when the node is known, so
is every micro-triangle inside it (a part of a region reads a subset of its values).

The four leaves under a node are baked together: their six vertices, and (grown) the vertices'
own flags (``bilinear.point_flag``, a leaf across the cut-off is C before any row is counted),
are computed once. A vertex's own flag is read once per triangle up to level 6 (a per-thread
table of the triangle's grid points, ``CACHE_N``): nodes and leaves around a vertex share it.
The leaf kernels and ``bilinear``'s cell kernels run without numba's reference counting (they
allocate nothing; the atomic counts of their array arguments took about a tenth of the bake).

Triangles run in parallel, in ``locality_order`` (neighbours in the texture one after another, so
the grid's cells stay in the caches), in chunks each thread takes as it becomes free
(``omaps.parallel``); ``numba.set_num_threads`` picks the thread count.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.bake.micromap import bake_micromaps
    >>> from omaps.texture import load_alpha
    >>> grid = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8))).grid()
    >>> states, starts = bake_micromaps(grid, np.array([[[0, 0], [1, 0], [0, 1]]]), 1)
    >>> states.tolist()
    [0, 0, 1, 0]
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike

from ..bilinear import POLY_MAX, point_flag
from ..birdcurve import CHILD_VERTS, MAX_LEVEL, bary_point, child
from ..errors import InputError
from ..flag_table import MARGIN, box_flag, flag_table
from ..parallel import fetch_add, item_size
from ..raster import rows_flag
from ..sampling import FootprintGrid
from ..checks import typed

__all__ = ["bake_micromaps", "bake_micromap_runs", "bake_micromap_rows", "dynamic_levels", "micro_starts", "check_level",
           "check_uv_triangles", "flag_table", "locality_order", "GROW_TEXEL", "MAX_LEVEL"]

# Growth of every region of real geometry, in texels: a hit's region (from barycentrics) and its
# texel (from interpolated UVs) are two floating-point computations of one point, so a hit on a
# region edge that is also a texel edge could otherwise read a texel the region did not count.
# The corpus pair (exact dyadic regions, no rays) is baked with no growth.
GROW_TEXEL = 2.0 ** -20


@typed
def check_level(level: object, name: str = "level") -> int:
    """A subdivision level of the APIs (0 .. 12); an ``InputError`` naming ``name`` otherwise."""
    from ..checks import integer

    return integer(level, name, 0, MAX_LEVEL)


def check_uv_triangles(tris_uv: object, param: str = "tris_uv") -> np.ndarray:
    """UV triangles as float64 (T, 3, 2); NaN or infinite coordinates are an error."""
    from ..checks import array

    t = array(tris_uv, param, kinds="iuf", dtype=np.float64)
    if t.ndim != 3 or t.shape[1:] != (3, 2):
        raise InputError(f"UV triangles must have shape (T, 3, 2), got {t.shape}", param=param)
    if not np.isfinite(t).all():  # (one reduction; the per-triangle one only to name the first: 30 ms a million)
        finite = np.isfinite(t).all(axis=(1, 2))
        raise InputError(f"UV triangle {int(np.flatnonzero(~finite)[0])} has NaN or infinite coordinates",
                         param=param)
    return t


@njit(cache=True, _nrt=False)
def _leaf_flag(sat, flags, mixed, values, bounds, period_x, period_y, x0, y0, x1, y1, x2, y2, grow, points, tri,
               buf_a, buf_b):
    """OR of the flags of the cells a micro-triangle (grown by ``grow``) overlaps (0: no area):
    ``raster.rows_flag`` on the triangle, written to ``tri`` (3, 2). ``points``: the OR of the
    three vertices' own flags (``bilinear.point_flag``) when the caller has them (a leaf's
    vertices are shared with its siblings), else -1 (read when needed); ``buf_*`` (POLY_MAX, 2)
    scratch. This is the baker's innermost call (millions per bake): it allocates nothing and
    runs without numba's reference counting (``_nrt=False``), whose atomic counts of the array
    arguments took about a tenth of the bake."""
    _set_tri(tri, x0, y0, x1, y1, x2, y2)
    return rows_flag(sat, (flags, mixed, values, bounds, period_x, period_y), tri, 3, grow, points, buf_a, buf_b)


@njit(cache=True, inline="always")
def _set_tri(tri, x0, y0, x1, y1, x2, y2):
    tri[0, 0] = x0
    tri[0, 1] = y0
    tri[1, 0] = x1
    tri[1, 1] = y1
    tri[2, 0] = x2
    tri[2, 1] = y2


@njit(cache=True, inline="always")
def _vertex(tri, i, j, inv_n, w, h, offset):
    """Texel coordinates (plus the grid offset) of barycentric grid point (i, j)/N: the same
    operations, in the same order, as ``bake.square`` maps a pair's points."""
    b1 = i * inv_n
    b2 = j * inv_n
    u = bary_point(b1, b2, tri[0, 0], tri[1, 0], tri[2, 0])
    v = bary_point(b1, b2, tri[0, 1], tri[1, 1], tri[2, 1])
    return u * w + offset, v * h + offset


@njit(cache=True, inline="always")
def _leaf_state(f):
    """A leaf's state from its flag (0, no area: C, counted by the caller)."""
    if f == 0 or f == 3:
        return 2
    return f - 1  # FLAG_T 1 -> T 0, FLAG_O 2 -> O 1


CACHE_N = 64  # triangles of levels up to log2(CACHE_N) keep their vertices' own flags, each read once


@njit(cache=True, inline="always")
def _vertex_flag(flags, mixed, values, bounds, period_x, period_y, x, y, grow, vc_f, vc_s, stamp, n, i, j):
    """``bilinear.point_flag`` of barycentric grid point (i, j)/n at texel point (x, y), read once
    per triangle (``stamp``) when n <= CACHE_N: neighbouring nodes and leaves share their vertices
    (an interior one up to six of them), so most of a triangle's reads are repeats."""
    k = -1
    if n <= CACHE_N:
        k = i * (n + 1) + j
        if vc_s[k] == stamp:
            return vc_f[k]
    return _read_vertex_flag(flags, mixed, values, bounds, period_x, period_y, x, y, grow, vc_f, vc_s, stamp, k)


@njit(cache=True, _nrt=False)
def _read_vertex_flag(flags, mixed, values, bounds, period_x, period_y, x, y, grow, vc_f, vc_s, stamp, k):
    """``_vertex_flag`` not in the cache: read, and kept at ``k`` (-1: not kept)."""
    f = point_flag(flags, mixed, values, bounds, period_x, period_y, x, y, grow)
    if k >= 0:
        vc_s[k] = stamp
        vc_f[k] = f
    return f


NODE_EXACT_CELLS = 16  # a node box this small with mixed cells is rasterised before descending
STACK = 3 * MAX_LEVEL + 4  # nodes pending: 3 more per level down, plus the root


@njit(cache=True, inline="always")
def _run(runs, n_runs, lv, k, state):
    """Append the run (node level, node index, state) when ``runs`` has room; count it always."""
    r = n_runs[0]
    if r < runs.shape[0]:
        runs[r, 0] = lv
        runs[r, 1] = k
        runs[r, 2] = state
    n_runs[0] = r + 1


@njit(cache=True, _nrt=False)
def _bake_one(sat, flags, mixed, values, bounds, period_x, period_y, tri, level, w, h, offset, grow, out, base, st_l,
              st_k, st_v, st_f, vx, vf, vi, vj, vc_f, vc_s, stamp, ptri, buf_a, buf_b, runs, n_runs):
    """States of one triangle's 4**level micro-triangles into ``out[base:]``; returns how many
    micro-triangles had no area (the reference raises on those). With ``n_runs`` of length 1,
    ``out`` is not written: each span of micro-triangles decided at once is appended as a *run*
    instead, ``runs[n_runs[0]] = (node level, node index, state)`` (the node's 4**(level - node
    level) micro-triangles from node index * that), in micro-triangle order, ``n_runs[0]``
    counting every run even past ``runs``' length (a caller sizes ``runs`` from a count). ``st_*``: the node stack
    (level, index, barycentric grid coordinates of p0, p1, p2, and the own flags of p0, p1, p2
    where known, else -1), STACK entries; ``vx`` (6, 2),
    ``vf``, ``vi``, ``vj`` (6,) the vertices of a node's children, their flags and grid
    coordinates; ``vc_f``, ``vc_s`` ((CACHE_N + 1)²,) the vertices' flags read so far, valid
    where ``vc_s`` holds ``stamp`` (unique per triangle); ``ptri`` (3, 2), ``buf_*``
    (POLY_MAX, 2) the leaf's scratch. A node just above the leaves bakes its four children in
    place: their six vertices, and those vertices' own flags, are computed once; a vertex's own
    flag, once read, is handed down the stack to the children that share the vertex."""
    n = 1 << level
    inv_n = 1.0 / n
    scale = 1.0
    for k in range(3):
        scale = max(scale, abs(tri[k, 0] * w) + abs(offset), abs(tri[k, 1] * h) + abs(offset))
    margin = MARGIN * scale + grow
    points_first = grow > 0.0 and mixed.shape[0] > 0  # as ``_leaf_flag`` reads them
    no_points = np.int64(-1)  # typed, not a literal: one compiled ``_leaf_flag`` serves every call
    st_l[0] = 0
    st_k[0] = 0
    st_v[0, 0] = 0
    st_v[0, 1] = 0
    st_v[0, 2] = n
    st_v[0, 3] = 0
    st_v[0, 4] = 0
    st_v[0, 5] = n
    st_f[0, 0] = -1
    st_f[0, 1] = -1
    st_f[0, 2] = -1
    top = 1
    empty = 0
    while top > 0:
        top -= 1
        lv = st_l[top]
        k = st_k[top]
        i0, j0, i1, j1, i2, j2 = st_v[top, 0], st_v[top, 1], st_v[top, 2], st_v[top, 3], st_v[top, 4], st_v[top, 5]
        f0, f1, f2 = st_f[top, 0], st_f[top, 1], st_f[top, 2]
        x0, y0 = _vertex(tri, i0, j0, inv_n, w, h, offset)
        x1, y1 = _vertex(tri, i1, j1, inv_n, w, h, offset)
        x2, y2 = _vertex(tri, i2, j2, inv_n, w, h, offset)
        state = -1
        if lv == level:  # a leaf (level 0 only: deeper ones are baked with their siblings below)
            f = _leaf_flag(sat, flags, mixed, values, bounds, period_x, period_y, x0, y0, x1, y1, x2, y2, grow,
                           no_points, ptri, buf_a, buf_b)
            if f == 0:
                empty += 1
            state = _leaf_state(f)
        else:
            f, nm, nc = box_flag(sat, min(x0, min(x1, x2)), max(x0, max(x1, x2)), min(y0, min(y1, y2)),
                                 max(y0, max(y1, y2)), margin, period_y, period_x)
            if f:
                state = 2 if f == 3 else f - 1  # all T, all O, or every cell C and none mixed
            elif nm > 0 and nc <= NODE_EXACT_CELLS:
                pts = no_points
                if points_first:  # the vertices' own flags (``_leaf_flag`` would read them first)
                    if f0 < 0:
                        f0 = _vertex_flag(flags, mixed, values, bounds, period_x, period_y, x0, y0, grow, vc_f, vc_s,
                                          stamp, n, i0, j0)
                    if f1 < 0:
                        f1 = _vertex_flag(flags, mixed, values, bounds, period_x, period_y, x1, y1, grow, vc_f, vc_s,
                                          stamp, n, i1, j1)
                    if f2 < 0:
                        f2 = _vertex_flag(flags, mixed, values, bounds, period_x, period_y, x2, y2, grow, vc_f, vc_s,
                                          stamp, n, i2, j2)
                    pts = f0 | f1 | f2
                if pts == 3:
                    f = 3
                else:
                    f = _leaf_flag(sat, flags, mixed, values, bounds, period_x, period_y, x0, y0, x1, y1, x2, y2, grow,
                                   pts, ptri, buf_a, buf_b)
                if f == 1 or f == 2:
                    state = f - 1  # known exactly: so is every micro-triangle inside it
        if state >= 0:
            if n_runs.shape[0]:
                _run(runs, n_runs, lv, k, state)
                continue
            # unsigned indices: numba then drops its negative-index check and the compiler
            # vectorises the fill (about 5x faster per byte; most micro-triangles are filled here)
            span = np.uint64(1) << np.uint64(2 * (level - lv))
            first = np.uint64(base + k * (1 << (2 * (level - lv))))
            for i in range(first, first + span):
                out[i] = state
            continue
        m01i, m01j = (i0 + i1) // 2, (j0 + j1) // 2
        m12i, m12j = (i1 + i2) // 2, (j1 + j2) // 2
        m02i, m02j = (i0 + i2) // 2, (j0 + j2) // 2
        if lv + 1 == level:  # the children are leaves: bake the four here, sharing their vertices
            vx[0, 0], vx[0, 1] = x0, y0
            vx[1, 0], vx[1, 1] = x1, y1
            vx[2, 0], vx[2, 1] = x2, y2
            vx[3, 0], vx[3, 1] = _vertex(tri, m01i, m01j, inv_n, w, h, offset)
            vx[4, 0], vx[4, 1] = _vertex(tri, m12i, m12j, inv_n, w, h, offset)
            vx[5, 0], vx[5, 1] = _vertex(tri, m02i, m02j, inv_n, w, h, offset)
            if points_first:
                vf[0], vf[1], vf[2] = f0, f1, f2
                vi[0], vi[1], vi[2], vi[3], vi[4], vi[5] = i0, i1, i2, m01i, m12i, m02i
                vj[0], vj[1], vj[2], vj[3], vj[4], vj[5] = j0, j1, j2, m01j, m12j, m02j
                for v in range(6):
                    if v >= 3 or vf[v] < 0:
                        vf[v] = _vertex_flag(flags, mixed, values, bounds, period_x, period_y, vx[v, 0], vx[v, 1], grow,
                                             vc_f, vc_s, stamp, n, vi[v], vj[v])
            for c in range(4):
                a, b, d = CHILD_VERTS[c]
                pts = no_points
                if points_first:
                    pts = vf[a] | vf[b] | vf[d]
                # (a leaf's own box is not read first: its rows, one or two, cost the same)
                if pts == 3:
                    f = 3
                else:
                    f = _leaf_flag(sat, flags, mixed, values, bounds, period_x, period_y, vx[a, 0], vx[a, 1],
                                   vx[b, 0], vx[b, 1], vx[d, 0], vx[d, 1], grow, pts, ptri, buf_a, buf_b)
                if f == 0:
                    empty += 1
                if n_runs.shape[0]:
                    _run(runs, n_runs, level, 4 * k + c, _leaf_state(f))
                else:
                    out[base + 4 * k + c] = _leaf_state(f)
            continue
        # children in reverse so child 0 is handled first
        for c in range(3, -1, -1):
            st_l[top] = lv + 1
            st_k[top] = 4 * k + c
            (st_v[top, 0], st_v[top, 1]), (st_v[top, 2], st_v[top, 3]), (st_v[top, 4], st_v[top, 5]) = child(
                c, (i0, j0), (i1, j1), (i2, j2), (m01i, m01j), (m12i, m12j), (m02i, m02j))
            st_f[top, 0], st_f[top, 1], st_f[top, 2] = child(c, f0, f1, f2, no_points, no_points, no_points)
            top += 1
    return empty


CHUNK = 64  # triangles per parallel work item at most (one node stack each; ``parallel.item_size``)
TILE = 16  # texels per side of the tiles of ``locality_order``
MAX_TILES = 1024  # tiles per axis at most (larger textures: larger tiles)


@njit(cache=True, inline="always")
def _spread_bits(v):
    """The bits of v (< 2**16) spread to the even bit positions (a Morton code's half)."""
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    return (v | (v << 1)) & 0x55555555


@njit(cache=True, inline="always")
def _tile(c, n):
    """Tile index in [0, n) of coordinate c (in tiles; any finite value, wrapped)."""
    q = math.floor(c)
    q -= math.floor(q / n) * n
    return min(max(int(q), 0), n - 1)


@njit(cache=True)
def _locality_order(tris, sx, sy, n_tiles):
    n = tris.shape[0]
    keys = np.empty(n, dtype=np.int64)
    for t in range(n):
        cx = (tris[t, 0, 0] + tris[t, 1, 0] + tris[t, 2, 0]) * sx
        cy = (tris[t, 0, 1] + tris[t, 1, 1] + tris[t, 2, 1]) * sy
        keys[t] = _spread_bits(_tile(cx, n_tiles)) | (_spread_bits(_tile(cy, n_tiles)) << 1)
    first = np.zeros(n_tiles * n_tiles + 1, dtype=np.int64)  # a counting sort: stable, O(n)
    for t in range(n):
        first[keys[t] + 1] += 1
    for k in range(n_tiles * n_tiles):
        first[k + 1] += first[k]
    order = np.empty(n, dtype=np.int64)
    for t in range(n):
        order[first[keys[t]]] = t
        first[keys[t]] += 1
    return order


def locality_order(tris_uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """An order of UV triangles (T, 3, 2) in which the bakers visit them: by the tile of about
    TILE x TILE texels holding each one's centroid, the tiles along a Morton curve (input order
    within a tile). Triangles near one another read the same cells of the grid, its table and
    the texture, which then stay in the processor's caches (a random order over a large texture
    misses them at almost every triangle). Every triangle is baked on its own, so the states do
    not depend on the order. ``omaps omm``'s plan stage puts a geometry's triangles in this order
    before any stage runs, so that the bake, the resolve and the pack also write and read their
    arrays in order; here, on such input, it changes nothing."""
    n_tiles = 1
    while n_tiles < MAX_TILES and n_tiles * TILE < max(width, height):
        n_tiles *= 2
    tile = max(width, height) / n_tiles  # texels per tile side
    t = np.ascontiguousarray(tris_uv, dtype=np.float64).reshape(-1, 3, 2)
    return _locality_order(t, width / (3.0 * tile), height / (3.0 * tile), n_tiles)


@njit(cache=True, parallel=True)
def _bake_all(sat, grid, tris, order, levels, starts, w, h, offset, grow, out, n_workers, runs, run_starts, counts):
    """Bake every triangle: its states into ``out[starts[t]:]`` (``counts`` empty); or, with
    ``counts`` (T,), its runs (``_bake_one``), each worker appending to its own part of
    ``runs`` (part w: rows w * C to (w + 1) * C, C = len(runs) // n_workers): triangle t's at
    ``runs[run_starts[t]:run_starts[t] + counts[t]]``, or ``counts[t]`` = -(its number of runs)
    when they did not fit in what was left of its worker's part (nothing kept: bake it again)."""
    flags, mixed, values, bounds, period_x, period_y = grid
    empty = np.zeros(tris.shape[0], dtype=np.int64)
    per = item_size(tris.shape[0], n_workers, CHUNK)  # a few triangles at a fine level: items of one or two
    n_chunks = (tris.shape[0] + per - 1) // per
    next_chunk = np.zeros(1, dtype=np.int64)
    for worker in prange(n_workers):  # each thread takes the next chunk as it frees up (``omaps.parallel``)
        st_l = np.empty(STACK, dtype=np.int64)
        st_k = np.empty(STACK, dtype=np.int64)
        st_v = np.empty((STACK, 6), dtype=np.int64)
        st_f = np.empty((STACK, 3), dtype=np.int64)
        vx = np.empty((6, 2))
        vf = np.empty(6, dtype=np.int64)
        vi = np.empty(6, dtype=np.int64)
        vj = np.empty(6, dtype=np.int64)
        vc_f = np.empty((CACHE_N + 1) ** 2, dtype=np.int64)  # the vertices' flags, valid where vc_s is the stamp
        vc_s = np.full((CACHE_N + 1) ** 2, -1, dtype=np.int64)
        tri = np.empty((3, 2))
        ptri = np.empty((3, 2))
        buf_a = np.empty((POLY_MAX, 2))
        buf_b = np.empty((POLY_MAX, 2))
        n_run = np.zeros(1 if counts.shape[0] else 0, dtype=np.int64)
        part = runs.shape[0] // n_workers
        used = worker * part  # the next free row of this worker's part
        end = used + part
        while True:
            c = fetch_add(next_chunk, 1)
            if c >= n_chunks:
                break
            for i in range(c * per, min((c + 1) * per, tris.shape[0])):
                t = order[i]
                for v in range(3):
                    tri[v, 0] = tris[t, v, 0]
                    tri[v, 1] = tris[t, v, 1]
                if n_run.shape[0]:
                    n_run[0] = 0
                empty[t] = _bake_one(sat, flags, mixed, values, bounds, period_x, period_y, tri, levels[t], w, h,
                                     offset, grow, out, starts[t], st_l, st_k, st_v, st_f, vx, vf, vi, vj, vc_f, vc_s, i,
                                     ptri, buf_a, buf_b, runs[used:end], n_run)
                if n_run.shape[0]:
                    if n_run[0] <= end - used:
                        run_starts[t] = used
                        counts[t] = n_run[0]
                        used += n_run[0]
                    else:
                        counts[t] = -n_run[0]
    return empty


def micro_starts(levels: ArrayLike) -> np.ndarray:
    """Start of each triangle's micro-triangles in a flat array, plus the total at the end
    (``levels``: one level 0..12 per triangle)."""
    from ..checks import array

    lv = array(levels, "levels", ndim=(0, 1), kinds="iu", dtype=np.int64).reshape(-1)
    if lv.size and (lv.min() < 0 or lv.max() > MAX_LEVEL):
        raise InputError(f"levels must be integers from 0 to {MAX_LEVEL}", param="levels")
    sizes = np.left_shift(np.int64(1), 2 * lv)
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def bake_micromaps(grid: FootprintGrid, tris_uv: ArrayLike, levels: int | ArrayLike, grow: float = 0.0,
                   sat: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Micromaps of UV triangles (T, 3, 2), triangle t at ``levels[t]`` (or one level for all).

    Parameters: ``grid`` the footprint grid (``AlphaTest.grid()``); ``grow`` the region growth in
    texels (``GROW_TEXEL`` for real geometry, 0 for the exact corpus pair); ``sat`` is
    ``flag_table(grid)`` when the caller bakes the same grid repeatedly.

    Returns (states, starts): states uint8 (0 T, 1 O, 2 C), triangle t's micro-triangles in
    bird-curve order at ``states[starts[t]:starts[t+1]]``. With no growth, a micro-triangle of
    no area is an error (it reads nothing); with growth it reads the texels it touches.
    ``grid`` may be an ``AlphaTest`` (its ``grid()``). A wrong argument raises an
    ``InputTypeError`` / ``InputError`` naming it."""
    from .. import checks

    grid, t, grow = _checked(grid, tris_uv, grow)
    lv_in = checks.array(levels, "levels", ndim=(0, 1), kinds="iu")
    if lv_in.ndim == 1 and len(lv_in) != len(t):
        raise InputError(f"levels must be one level or one per triangle ({len(t)}), got {len(lv_in)}",
                         param="levels")
    lv = np.broadcast_to(lv_in, (len(t),))
    for x in np.unique(lv):
        check_level(x, "levels")
    lv = np.array(lv, dtype=np.int64)  # writable (a broadcast view is not): one compiled specialisation
    starts = micro_starts(lv)
    out = np.empty(int(starts[-1]), dtype=np.uint8)
    if len(t):
        sat = flag_table(grid) if sat is None else sat
        empty = _bake_all(sat, grid.kernel_args(), t, locality_order(t, grid.width, grid.height), lv, starts,
                          float(grid.width), float(grid.height), float(grid.offset), float(grow), out,
                          numba.get_num_threads(), _NO_RUNS, _NO_STARTS, _NO_STARTS)
        _check_area(empty, np.arange(len(t)))
    return out, starts


def _checked(grid, tris_uv, grow):
    """The arguments every bake checks: (footprint grid, UV triangles (T, 3, 2) contiguous, growth)."""
    from .. import checks
    from ..alpha_test import as_grid

    grid = as_grid(grid)
    grow = checks.number(grow, "grow", 0)
    return grid, np.ascontiguousarray(check_uv_triangles(tris_uv)), grow


def _check_area(empty, index):
    """An ``InputError`` naming the first triangle (``index`` of it) with micro-triangles of no area."""
    if empty.any():
        raise InputError(f"UV triangle {int(index[np.flatnonzero(empty)[0]])} has micro-triangles with no area")


_NO_RUNS = np.empty((0, 3), dtype=np.int32)
_NO_STARTS = np.empty(0, dtype=np.int64)


def bake_micromap_runs(grid: FootprintGrid, tris_uv: ArrayLike, level: int, grow: float = 0.0,
                       sat: np.ndarray | None = None, capacity: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``bake_micromaps`` at one level as *runs*, without the 4**level states of each triangle:
    the spans of micro-triangles the baker decides at once (a node whose box is uniform, or
    known exactly, and each leaf below a mixed node), so the work and the output follow the
    mixed nodes, not 4**level. The same states, bit for bit: expanding the runs gives
    ``bake_micromaps``'.

    Returns (runs, starts): runs int32 (R, 3), triangle t's at ``runs[starts[t]:starts[t+1]]``,
    each (node level l, node index k, state): micro-triangles k * 4**(level - l) to
    (k + 1) * 4**(level - l) - 1 have that state; in micro-triangle order, tiling the triangle.
    ``capacity``: the runs expected in all (default: 64 per triangle); the threads write into
    parts of a buffer that large, and a triangle whose runs did not fit is baked again in a
    larger one. Call it on chunks of triangles to bound the memory. Parameters and errors as
    ``bake_micromaps``.

    Example::

        >>> import numpy as np
        >>> from omaps.alpha_test import StateRule
        >>> from omaps.texture import load_alpha
        >>> grid = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8))).grid()
        >>> runs, starts = bake_micromap_runs(grid, np.array([[[0, 0], [1, 0], [0, 1]]]), 1)
        >>> runs.tolist(), starts.tolist()           # the states 0, 0, 1, 0 of bake_micromaps
        ([[1, 0, 0], [1, 1, 0], [1, 2, 1], [1, 3, 0]], [0, 4])
    """
    grid, t, grow = _checked(grid, tris_uv, grow)
    level = check_level(level)
    n = len(t)
    counts = np.zeros(n, dtype=np.int64)
    if not n:
        return _NO_RUNS.copy(), np.zeros(1, dtype=np.int64)
    sat = flag_table(grid) if sat is None else sat
    workers = numba.get_num_threads()
    size = max(workers * 64, int(capacity) if capacity else 64 * n)
    pieces: list = [None] * n
    todo = np.arange(n)
    while len(todo):
        sub = np.ascontiguousarray(t[todo])
        buf = np.empty((size, 3), dtype=np.int32)
        at = np.zeros(len(todo), dtype=np.int64)
        got = np.zeros(len(todo), dtype=np.int64)
        empty = _bake_all(sat, grid.kernel_args(), sub, locality_order(sub, grid.width, grid.height),
                          np.full(len(todo), level, dtype=np.int64), _NO_STARTS, float(grid.width), float(grid.height),
                          float(grid.offset), float(grow), np.empty(0, np.uint8), workers, buf, at, got)
        _check_area(empty, todo)
        fit = got >= 0
        for j in np.flatnonzero(fit):
            pieces[todo[j]] = buf[at[j]:at[j] + got[j]]
        counts[todo[fit]] = got[fit]
        if not fit.all():  # again, in parts large enough for the largest that did not fit
            size = max(2 * size, workers * int(-got[~fit].min()) * 2)
        todo = todo[~fit]
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.concatenate(pieces), starts


def bake_micromap_rows(grid: FootprintGrid, tris_uv: ArrayLike, level: int, grow: float = 0.0) -> np.ndarray:
    """``bake_micromaps`` at one level: states (T, 4**level)."""
    level = check_level(level)
    s, _ = bake_micromaps(grid, tris_uv, level, grow)
    return s.reshape(-1, 4 ** level)


@njit(cache=True)
def _texel_areas(t, width, height, out):
    for i in range(t.shape[0]):
        x0, x1, x2 = t[i, 0, 0] * width, t[i, 1, 0] * width, t[i, 2, 0] * width
        y0, y1, y2 = t[i, 0, 1] * height, t[i, 1, 1] * height, t[i, 2, 1] * height
        out[i] = 0.5 * abs((x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0))


def texel_areas(tris_uv, width: int, height: int) -> np.ndarray:
    """Area in texels of each UV triangle (T, 3, 2) on a width x height texture (one pass: numpy's
    operations one at a time took 80 ms for a million triangles)."""
    t = np.ascontiguousarray(tris_uv, dtype=np.float64).reshape(-1, 3, 2)  # (one compiled layout)
    out = np.empty(len(t))
    _texel_areas(t, float(width), float(height), out)
    return out


@typed
def dynamic_levels(tris_uv: ArrayLike, width: int, height: int, scale: float, max_level: int) -> np.ndarray:
    """Per-triangle level from its texel area: the smallest level whose micro-triangles cover at
    most ``scale``² texels each (as the OMM SDKs' dynamic subdivision scale), capped at
    ``max_level``."""
    from .. import checks

    scale = checks.number(scale, "scale", 0, open_lo=True)
    max_level = check_level(max_level, "max_level")
    width, height = checks.integer(width, "width", 1), checks.integer(height, "height", 1)
    area = texel_areas(check_uv_triangles(tris_uv), width, height)
    ratio = np.maximum(area / (scale * scale), 1.0)
    lv = np.ceil(np.log(ratio) / np.log(4.0) - 1e-12)
    return np.clip(lv, 0, max_level).astype(np.int64)
