"""The deck's square pair maps as today's per-triangle micromaps, and back.

With the corpus pair convention (``omaps.pair``: A = (0,0),(1,0),(1,1), B = (0,0),(1,1),(0,1)),
the level-L micro-triangles of A and B lie on the grid of lines u = k/N, v = k/N and
u - v = k/N (N = 2^L): the first two are the N x N map's cell edges, the third cuts each cell
along its diagonal. So every cell holds exactly two micro-triangles -- both of A below the pair's
diagonal, both of B above it, one of each on it -- and an N x N map expands into the pair's two
level-L micromaps without loss: each micro-triangle takes its cell's state. Merging the two
micromaps back into a square map (OR of the two flags per cell) is what a square bake gives.

For an arbitrary mesh, pair k is triangles 2k (A) and 2k+1 (B), each mapped through its own
barycentrics (a hit's square position follows ``pair.hit_to_uv``); a lone last triangle has no
B, and cells only B would cover stay C.
"""

from __future__ import annotations

import functools

import numpy as np

from .. import states
from ..errors import InputError
from ..maps import check_square_size
from ..sampling import FootprintGrid
from . import bake


def level_of_size(n: int) -> int:
    n = check_square_size(n)
    return n.bit_length() - 1


@functools.lru_cache(maxsize=None)
def micro_cells(level: int) -> np.ndarray:
    """Flat cell index j*N + i of every micro-triangle of A (row 0) and B (row 1), shape
    (2, 4**level), from each micro-triangle's centroid (interior to its cell)."""
    from ..birdcurve import micro_triangles

    n = 1 << level
    c = micro_triangles(level).mean(axis=1)  # barycentric centroids (b1, b2)
    out = np.empty((2, len(c)), dtype=np.int64)
    for tri in (0, 1):
        u, v = (c[:, 0] + c[:, 1], c[:, 1]) if tri == 0 else (c[:, 0], c[:, 0] + c[:, 1])
        i = np.minimum(np.floor(u * n).astype(np.int64), n - 1)
        j = np.minimum(np.floor(v * n).astype(np.int64), n - 1)
        out[tri] = j * n + i
    out.setflags(write=False)
    return out


def expand(square_maps: np.ndarray) -> np.ndarray:
    """Square maps (P, N, N) -> the pairs' micromaps (P, 2, 4**log2 N): A then B."""
    m = np.asarray(square_maps)
    if m.ndim != 3 or m.shape[1] != m.shape[2]:
        raise InputError(f"square maps must have shape (P, N, N), got {m.shape}")
    cells = micro_cells(level_of_size(m.shape[1]))
    return m.reshape(len(m), -1)[:, cells]


def merge(micromaps: np.ndarray, has_b: np.ndarray | None = None) -> np.ndarray:
    """The pairs' micromaps (P, 2, 4**L) -> square maps (P, N, N): each cell the OR of its two
    micro-triangles' flags. ``has_b[p]`` False: pair p has no triangle B (its cells stay C)."""
    mm = np.asarray(micromaps)
    p, _, m = mm.shape
    level = (m.bit_length() - 1) // 2
    n = 1 << level
    cells = micro_cells(level)
    flags = states.STATE_TO_FLAG[mm]
    if has_b is not None:
        flags[~np.asarray(has_b, dtype=bool), 1] = 0
    acc = np.zeros((p, n * n), dtype=np.uint8)
    for tri in (0, 1):
        for half in (0, 1):  # no cell twice within a half, so the fancy-indexed OR loses nothing
            sel = _half_select(level, tri, half)
            acc[:, cells[tri][sel]] |= flags[:, tri][:, sel]
    return states.FLAG_TO_STATE[acc].reshape(p, n, n)


@functools.lru_cache(maxsize=None)
def _half_select(level: int, tri: int, half: int) -> np.ndarray:
    """Micro-triangles of one triangle split into two sets, each holding at most one
    micro-triangle per cell (so a fancy-indexed OR never drops a write)."""
    cells = micro_cells(level)[tri]
    first = np.zeros(len(cells), dtype=bool)
    _, idx = np.unique(cells, return_index=True)
    first[idx] = True
    return first if half == 0 else ~first


def pair_triangles(tris_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (T, 3, 2) as pairs (ceil(T/2), 2, 3, 2) and which pairs have a B."""
    t = np.asarray(tris_uv, dtype=np.float64)
    n = len(t)
    p = (n + 1) // 2
    out = np.empty((p, 2, 3, 2))
    out.reshape(-1, 3, 2)[:n] = t
    has_b = np.ones(p, dtype=bool)
    if n % 2:
        out[-1, 1] = t[-1]  # a stand-in, baked but masked out of the merge
        has_b[-1] = False
    return out, has_b


def bake_squares(grid: FootprintGrid, tris_uv, n: int, sat=None) -> tuple[np.ndarray, np.ndarray]:
    """Square N x N maps of the mesh's pairs (P, N, N) and ``has_b`` (P,)."""
    level = level_of_size(n)
    pairs, has_b = pair_triangles(tris_uv)
    s, _ = bake.bake_levels(grid, pairs.reshape(-1, 3, 2), level, sat)
    return merge(s.reshape(len(pairs), 2, -1), has_b), has_b


def unpair(pair_micromaps: np.ndarray, n_triangles: int) -> np.ndarray:
    """(P, 2, M) pair micromaps -> (T, M) per-triangle micromaps (drops a lone pair's B)."""
    return np.asarray(pair_micromaps).reshape(-1, pair_micromaps.shape[-1])[:n_triangles]



def square_fractions(test, pair_uv: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Opaque fraction (n, n) and texel-space centroid (n, n, 2) of each cell of a pair's square
    map (``pair_uv`` (2, 3, 2): triangles A and B), from its two micro-triangles at level log2 n
    (equal areas of the pair's square), for the 2-state resolution of a square map's C cells."""
    from ..birdcurve import micro_triangles
    from .alpha_test import opaque_fractions

    level = level_of_size(n)
    tris = np.asarray(pair_uv, dtype=np.float64)
    starts = bake.micro_starts(np.full(2, level))
    f = opaque_fractions(test, tris, level, starts).reshape(2, -1)
    c = micro_triangles(level).mean(axis=1)  # barycentric centroids
    w0 = 1.0 - c[:, 0] - c[:, 1]
    scale = np.array([test.width, test.height], dtype=np.float64)
    cen = (w0[None, :, None] * tris[:, None, 0] + c[None, :, 0, None] * tris[:, None, 1]
           + c[None, :, 1, None] * tris[:, None, 2]) * scale  # (2, M, 2)
    cells = micro_cells(level)
    frac = np.zeros(n * n)
    cxy = np.zeros((n * n, 2))
    for t in (0, 1):
        np.add.at(frac, cells[t], f[t] / 2)
        np.add.at(cxy, cells[t], cen[t] / 2)
    return frac.reshape(n, n), cxy.reshape(n, n, 2)
