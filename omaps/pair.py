"""The corpus convention: a texture covering the square of a pair of triangles.

UV (0, 0) is the first texel of the first image row. Triangle A = (0,0), (1,0), (1,1) and
triangle B = (0,0), (1,1), (0,1), each listed as its (p0, p1, p2). Square cell (i, j) of an N x N
map covers u in [i/N, (i+1)/N], v in [j/N, (j+1)/N] and is stored at ``map[j, i]`` (rows are v,
as in the image). docs/FORMAT.md states the same mapping.
"""

from __future__ import annotations

import numpy as np
from numba import njit

TRI_A = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
TRI_B = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
PAIR = np.stack([TRI_A, TRI_B])


@njit(cache=True)
def hit_to_uv(triangle, b1, b2):
    """(u, v) of a hit with barycentrics (b1, b2) -- the weights of p1 and p2 -- on triangle
    0 (A) or 1 (B)."""
    if triangle == 0:
        return b1 + b2, b2
    return b1, b1 + b2


@njit(cache=True)
def uv_to_cell(u, v, n):
    """Square cell (i, j) of an n x n map holding (u, v); the far edges u = 1, v = 1 belong to
    the last cell, coordinates outside [0, 1] clamp."""
    i = int(np.floor(u * n))
    j = int(np.floor(v * n))
    return min(max(i, 0), n - 1), min(max(j, 0), n - 1)


@njit(cache=True)
def hit_to_cell(triangle, b1, b2, n):
    u, v = hit_to_uv(triangle, b1, b2)
    return uv_to_cell(u, v, n)


def square_cells(n: int) -> np.ndarray:
    """The n*n cells as rectangles in UV, shape (n*n, 4, 2), in map order (j-major)."""
    j, i = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    u0 = (i / n).ravel()
    u1 = ((i + 1) / n).ravel()
    v0 = (j / n).ravel()
    v1 = ((j + 1) / n).ravel()
    return np.stack([np.stack([u0, v0], -1), np.stack([u1, v0], -1),
                     np.stack([u1, v1], -1), np.stack([u0, v1], -1)], axis=1)


@njit(cache=True)
def uv_to_hit(u, v):
    """Inverse of ``hit_to_uv``: (triangle, b1, b2) of a point of the square (A where v <= u)."""
    if v <= u:
        return 0, u - v, v
    return 1, u, v - u
