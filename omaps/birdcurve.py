"""Micro-triangle order of VK_EXT_opacity_micromap / DXR 1.2 opacity micromaps ("bird curve").

A triangle (p0, p1, p2) -- barycentric weights (1-u-v, u, v) -- splits at its edge midpoints
m01, m12, m02 into four children, numbered and oriented as the specification's figure shows:

    child 0: (p0,  m01, m02)   corner at p0, same winding
    child 1: (m02, m12, m01)   the middle, flipped
    child 2: (m01, p1,  m12)   corner at p1, same winding
    child 3: (m12, m02, p2)    corner at p2, flipped

Applied recursively, micro-triangle k at level L lies inside micro-triangle k >> 2 at level L-1.
Everything here is in barycentric (u, v) space; ``uv_micro_triangles`` maps to texture space.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

MAX_LEVEL = 12

# The children's vertices (the figure above) among the parent's points 0 .. 5 = p0, p1, p2, m01,
# m12, m02: the one statement of the order, which every walk of the curve reads (``child``)
CHILD_VERTS = ((0, 3, 5), (5, 4, 3), (3, 1, 4), (4, 5, 2))
# the points as weights of p0, p1, p2; children as weights (rows: child vertex 0..2; columns: p0, p1, p2)
_POINTS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [.5, .5, 0], [0, .5, .5], [.5, 0, .5]])
_CHILDREN = _POINTS[np.array(CHILD_VERTS)]


@njit(cache=True, inline="always")
def child(c, p0, p1, p2, m01, m12, m02):
    """Vertices (p0, p1, p2) of child ``c`` of a triangle, given its vertices and edge midpoints
    (points of any one type: barycentric floats, the micromap baker's integer grid points)."""
    points = (p0, p1, p2, m01, m12, m02)
    a, b, d = CHILD_VERTS[c]
    return points[a], points[b], points[d]


@njit(cache=True, inline="always")
def micro_vertices(index, level):
    """Barycentric (b1, b2) of micro-triangle ``index``'s vertices (p0, p1, p2) at ``level``, as
    three pairs: the curve's base-4 digits from the top, each a ``child``."""
    p0 = (0.0, 0.0)
    p1 = (1.0, 0.0)
    p2 = (0.0, 1.0)
    for d in range(level - 1, -1, -1):
        p0, p1, p2 = child((index >> (2 * d)) & 3, p0, p1, p2, _mid(p0, p1), _mid(p1, p2), _mid(p0, p2))
    return p0, p1, p2


TABLE_LEVELS = 6  # ``vertex_table`` holds levels 0 .. 5 (1365 micro-triangles, 64 KiB)


@functools.cache
def vertex_table() -> np.ndarray:
    """The vertices of every micro-triangle of levels 0 .. TABLE_LEVELS - 1, one level after the
    other (level L from row (4**L - 1) / 3), as (b1, b2) of p0, p1, p2 per row: the values of
    ``micro_vertices`` (dyadic, so exact either way), computed once, for kernels that visit
    micro-triangles in no order (decoding the curve's digits costs a branch per level). Read it
    with ``table_vertices``."""
    return np.ascontiguousarray(np.concatenate([micro_triangles(level).reshape(-1, 6)
                                                for level in range(TABLE_LEVELS)]))


@njit(cache=True, inline="always")
def table_vertices(table, index, level):
    """``micro_vertices(index, level)`` from ``vertex_table()``: one row where the table holds the
    level; deeper, the curve's digits a group of TABLE_LEVELS - 1 levels at a time, each group's
    micro-triangle placed inside the one before (p0 + b1 (p1 - p0) + b2 (p2 - p0)). Every value
    is a multiple of 2**-level with at most 2 * MAX_LEVEL significant bits, so each step is exact
    and the result is the digit walk's to the last bit."""
    if level < TABLE_LEVELS:
        j = ((1 << (2 * level)) - 1) // 3 + index
        return (table[j, 0], table[j, 1]), (table[j, 2], table[j, 3]), (table[j, 4], table[j, 5])
    p0x, p0y, p1x, p1y, p2x, p2y = 0.0, 0.0, 1.0, 0.0, 0.0, 1.0
    rest = level
    while rest > 0:
        g = min(rest, TABLE_LEVELS - 1)
        rest -= g
        j = ((1 << (2 * g)) - 1) // 3 + ((index >> (2 * rest)) & ((1 << (2 * g)) - 1))
        ex, ey, fx, fy = p1x - p0x, p1y - p0y, p2x - p0x, p2y - p0y
        p0x, p0y, p1x, p1y, p2x, p2y = (p0x + table[j, 0] * ex + table[j, 1] * fx,
                                        p0y + table[j, 0] * ey + table[j, 1] * fy,
                                        p0x + table[j, 2] * ex + table[j, 3] * fx,
                                        p0y + table[j, 2] * ey + table[j, 3] * fy,
                                        p0x + table[j, 4] * ex + table[j, 5] * fx,
                                        p0y + table[j, 4] * ey + table[j, 5] * fy)
    return (p0x, p0y), (p1x, p1y), (p2x, p2y)


@njit(cache=True, inline="always")
def bary_point(b1, b2, x0, x1, x2):
    """One coordinate of the point of barycentric (b1, b2) -- the weights of p1 and p2 -- on a
    triangle whose vertices have coordinates x0, x1, x2: (1 - b1 - b2) x0 + b1 x1 + b2 x2, in
    that order of operations (every kernel maps its micro-triangles' points with it, so they
    agree to the last bit)."""
    return (1.0 - b1 - b2) * x0 + b1 * x1 + b2 * x2


@njit(cache=True, inline="always")
def _mid(a, b):
    return 0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])


def micro_triangles(level: int) -> np.ndarray:
    """Vertices of the 4**level micro-triangles in curve order, as barycentric (u, v):
    array (4**level, 3, 2). Vertex order is each micro-triangle's own (p0, p1, p2)."""
    if not isinstance(level, (int, np.integer)) or not 0 <= level <= MAX_LEVEL:
        raise ValueError(f"subdivision level must be an integer in 0..{MAX_LEVEL}, got {level!r}")
    tris = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])  # (p0, p1, p2) in (u, v)
    for _ in range(level):
        # (n, 4, 3, 2): child c vertex i = sum_j _CHILDREN[c, i, j] * parent vertex j
        tris = np.einsum("cij,njd->ncid", _CHILDREN, tris).reshape(-1, 3, 2)
    return tris


def uv_micro_triangles(tri_uv: np.ndarray, level: int) -> np.ndarray:
    """Micro-triangles of a triangle with texture coordinates ``tri_uv`` (3, 2) = (p0, p1, p2)."""
    b = micro_triangles(level)
    tri_uv = np.asarray(tri_uv, dtype=np.float64)
    return bary_point.py_func(b[..., 0, None], b[..., 1, None], tri_uv[0], tri_uv[1], tri_uv[2])


@njit(cache=True)
def bary_to_index(u, v, level):
    """Index of the micro-triangle containing barycentric (u, v) (weights of p1, p2).

    Walks the subdivision: at each level the point's barycentrics in the current triangle pick a
    child (a weight above 1/2 means a corner, otherwise the middle), then are re-expressed in
    that child's own vertex order. Points on shared edges go to one of the touching children;
    out-of-range input is clamped onto the triangle.
    """
    u = min(max(u, 0.0), 1.0)
    v = min(max(v, 0.0), 1.0)
    w = 1.0 - u - v
    if w < 0.0:
        s = u + v
        u /= s
        v /= s
        w = 0.0
    idx = 0
    for _ in range(level):
        # weights (w, u, v) of (p0, p1, p2)
        if w >= 0.5:
            c = 0
            w, u, v = 2.0 * w - 1.0, 2.0 * u, 2.0 * v
        elif u >= 0.5:
            c = 2
            # child 2 = (m01, p1, m12): p1 weight grows, m01 carries p0's weight
            w, u, v = 2.0 * w, 2.0 * u - 1.0, 2.0 * v
        elif v >= 0.5:
            c = 3
            # child 3 = (m12, m02, p2): new p0 = m12 (takes u), new p1 = m02 (takes w)
            w, u, v = 2.0 * u, 2.0 * w, 2.0 * v - 1.0
        else:
            c = 1
            # child 1 = (m02, m12, m01): new p0 = m02, p1 = m12, p2 = m01
            w, u, v = 1.0 - 2.0 * u, 1.0 - 2.0 * w, 1.0 - 2.0 * v
        idx = idx * 4 + c
    return idx
