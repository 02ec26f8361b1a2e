"""The pair's square: one map over two triangles that share an edge.

The corpus convention, a texture covering the square of a pair of triangles:

UV (0, 0) is the first texel of the first image row. Triangle A = (0,0), (1,0), (1,1) and
triangle B = (0,0), (1,1), (0,1), each listed as its (p0, p1, p2). Square cell (i, j) of an N x N
map covers u in [i/N, (i+1)/N], v in [j/N, (j+1)/N] and is stored at ``map[j, i]`` (rows are v,
as in the image). docs/FORMAT.md states the same mapping.

Any pair of a mesh is the same square over its own (s, t) parameterisation: each vertex of its
triangles is given a corner of the square (``CORNERS`` codes, chosen by ``scene.pairing``), and a
point of the square maps to texture space through its triangle's UVs with ``pair_weights``. The
corpus pair is the pair whose corner UVs are the corners themselves (``PAIR_CORNER_UV``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

TRI_A = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
TRI_B = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
PAIR = np.stack([TRI_A, TRI_B])

# the square's corners by code; a triangle's vertices get codes from this table
CORNERS = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.int8)
CORNER_00, CORNER_10, CORNER_11, CORNER_01 = 0, 1, 2, 3
# corner codes of A's and B's vertices in the corpus convention (their own vertex order)
A_CORNERS = np.array([CORNER_00, CORNER_10, CORNER_11], dtype=np.int8)
B_CORNERS = np.array([CORNER_00, CORNER_11, CORNER_01], dtype=np.int8)
# UVs at A's corners (0,0), (1,0), (1,1), then B's (0,0), (1,1), (0,1): ``bake.square``'s layout
PAIR_CORNER_UV = np.concatenate([TRI_A, TRI_B])[None]


def corner_uvs(tris_uv, corners, first, second) -> tuple[np.ndarray, np.ndarray]:
    """Pairs' corner UVs (P, 6, 2) in ``bake.square``'s layout -- A's UVs at (0,0), (1,0), (1,1),
    then B's at (0,0), (1,1), (0,1), zeros without B -- and whether B exists, from triangles'
    UVs (T, 3, 2) and corner codes (T, 3), and each pair's A and B rows (``second`` -1: none)."""
    tris_uv = np.asarray(tris_uv, dtype=np.float64)
    corners = np.asarray(corners)
    first = np.asarray(first, dtype=np.int64)
    second = np.asarray(second, dtype=np.int64)
    out = np.zeros((len(first), 6, 2))
    # sorting the codes orders A's as 0, 1, 2 and B's as 0, 2, 3: exactly the layout's corners
    out[:, 0:3] = np.take_along_axis(tris_uv[first], np.argsort(corners[first], axis=1)[:, :, None], axis=1)
    has_b = second >= 0
    b = second[has_b]
    out[has_b, 3:6] = np.take_along_axis(tris_uv[b], np.argsort(corners[b], axis=1)[:, :, None], axis=1)
    return out, has_b


@njit(cache=True, inline="always")
def pair_weights(tri, s, t):
    """Weights of a square point (s, t) on the corners of triangle A (tri 0: (0,0), (1,0), (1,1),
    where t <= s) or B (tri 1: (0,0), (1,1), (0,1))."""
    if tri == 0:
        return 1.0 - s, s - t, t
    return 1.0 - t, s, t - s


@njit(cache=True, inline="always")
def square_uv(uv, o, tri, s, t):
    """Texture (u, v) of square point (s, t) through triangle ``tri``'s affine UV map: its
    corners' UVs at ``uv[o:o + 3]`` (``bake.square``'s layout), weighted by ``pair_weights``."""
    w0, w1, w2 = pair_weights(tri, s, t)
    u = w0 * uv[o, 0] + w1 * uv[o + 1, 0] + w2 * uv[o + 2, 0]
    v = w0 * uv[o, 1] + w1 * uv[o + 1, 1] + w2 * uv[o + 2, 1]
    return u, v


@njit(cache=True, inline="always")
def hit_st(corners, tri, b1, b2):
    """(s, t) of a hit with barycentrics (b1, b2) on triangle ``tri`` in its pair's square: the
    barycentric combination of the square corners of its three vertices (``corners`` a flat
    int8 array of codes, 3 per triangle)."""
    w0 = 1.0 - b1 - b2
    s = 0.0
    t = 0.0
    for k in range(3):
        w = w0 if k == 0 else (b1 if k == 1 else b2)
        c = corners[3 * tri + k]
        if c == 1 or c == 2:
            s += w
        if c >= 2:
            t += w
    return s, t


@njit(cache=True)
def uv_to_cell(u, v, n):
    """Square cell (i, j) of an n x n map holding (u, v); the far edges u = 1, v = 1 belong to
    the last cell, coordinates outside [0, 1] clamp."""
    i = int(np.floor(u * n))
    j = int(np.floor(v * n))
    return min(max(i, 0), n - 1), min(max(j, 0), n - 1)


@njit(cache=True)
def uv_to_hit(u, v):
    """(triangle, b1, b2) of a point (u, v) of the corpus pair's square (A where v <= u): the hit
    there, barycentrics the weights of the triangle's p1 and p2."""
    if v <= u:
        return 0, u - v, v
    return 1, u, v - u
