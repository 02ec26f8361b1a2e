"""The deck's square pair maps as today's per-triangle micromaps, and back.

A pair's level-L micro-triangles lie on the grid of lines s = k/N, t = k/N and s - t = k/N
(N = 2^L) of its square, whatever the vertex order of its triangles: the subdivision lines of a
triangle are parallel to its edges, and the pair's edges map to those three families. So every
cell holds exactly two micro-triangles and an N x N map expands into the pair's two level-L
micromaps without loss: each micro-triangle takes the state of the cell holding its centroid
(``pair.hit_st`` of the triangle's corner codes). Merging the corpus pair's two micromaps back
(OR of the two flags per cell) is what a square bake gives.
"""

from __future__ import annotations

import functools

import numpy as np

from .. import pair, states
from ..bake.square import check_square_size
from ..birdcurve import micro_triangles
from ..errors import InputError
from ..checks import typed

__all__ = ["level_of_size", "micro_cells", "expand", "merge", "corpus_pairing"]


def level_of_size(n: int) -> int:
    n = check_square_size(n)
    return n.bit_length() - 1


@functools.lru_cache(maxsize=None)
def micro_cells(level: int, corners: tuple = tuple(pair.A_CORNERS)) -> np.ndarray:
    """Flat cell index j*N + i of every micro-triangle of a triangle whose vertices have these
    corner codes, from each micro-triangle's centroid (interior to its cell): (4**level,)."""
    n = 1 << level
    c = micro_triangles(level).mean(axis=1)  # barycentric centroids (b1, b2)
    w = np.stack([1.0 - c[:, 0] - c[:, 1], c[:, 0], c[:, 1]], axis=1)
    xy = w @ pair.CORNERS[list(corners)].astype(np.float64)  # (s, t)
    i = np.minimum(np.floor(xy[:, 0] * n).astype(np.int64), n - 1)
    j = np.minimum(np.floor(xy[:, 1] * n).astype(np.int64), n - 1)
    out = j * n + i
    out.setflags(write=False)
    return out


@typed
def expand(square_maps: np.ndarray, pair_of: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Square maps (P, N, N) -> micromaps (T, 4**log2 N) of triangles: triangle t in pair
    ``pair_of[t]`` with corner codes ``corners[t]`` (3,)."""
    m = np.asarray(square_maps)
    if m.ndim != 3 or m.shape[1] != m.shape[2]:
        raise InputError(f"square maps must have shape (P, N, N), got {m.shape}")
    level = level_of_size(m.shape[1])
    flat = m.reshape(len(m), -1)
    kinds, kind_of = np.unique(np.asarray(corners, dtype=np.int8).reshape(-1, 3), axis=0, return_inverse=True)
    pair_of = np.asarray(pair_of)
    out = np.empty((len(kind_of), 4 ** level), dtype=m.dtype)
    for k, key in enumerate(kinds):
        rows = np.flatnonzero(kind_of.ravel() == k)
        out[rows] = flat[pair_of[rows]][:, micro_cells(level, tuple(int(x) for x in key))]
    return out


@typed
def merge(micromaps: np.ndarray, has_b: np.ndarray | None = None) -> np.ndarray:
    """The corpus pairs' micromaps (P, 2, 4**L) -> square maps (P, N, N): each cell the OR of its
    two micro-triangles' flags. ``has_b[p]`` False: pair p has no triangle B (its cells stay C)."""
    from ..checks import array

    mm = array(micromaps, "micromaps", ndim=3, kinds="iu")
    p, two, m = mm.shape
    level = (m.bit_length() - 1) // 2
    n = 1 << level
    if two != 2 or m != 4 ** level or (mm.size and (mm.min() < 0 or mm.max() > states.C)):
        raise InputError(f"micromaps must be states 0..2 of shape (P, 2, 4**L), got {mm.shape}", param="micromaps")
    flags = states.STATE_TO_FLAG[mm]
    if has_b is not None:
        hb = array(has_b, "has_b", shape=(p,), kinds="biu")
        flags[~hb.astype(bool), 1] = 0
    acc = np.zeros((p, n * n), dtype=np.uint8)
    rows = np.arange(p)[:, None]
    for tri, corners in ((0, tuple(pair.A_CORNERS)), (1, tuple(pair.B_CORNERS))):
        # cells repeat (two micro-triangles each): ``at`` ORs every write, a fancy index would not
        np.bitwise_or.at(acc, (rows, micro_cells(level, corners)[None, :]), flags[:, tri])
    return states.FLAG_TO_STATE[acc].reshape(p, n, n)


def corpus_pairing(n_triangles: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangles 2k (A) and 2k+1 (B) as pairs in the corpus convention, each in its own vertex
    order: (pair_of (T,), corners (T, 3), pairs (P, 2) with -1 for a lone last triangle)."""
    t = np.arange(n_triangles)
    corners = np.where((t % 2 == 0)[:, None], pair.A_CORNERS, pair.B_CORNERS).astype(np.int8)
    p = (n_triangles + 1) // 2
    pairs = np.full((p, 2), -1, np.int64)
    pairs.reshape(-1)[:n_triangles] = t
    return t // 2, corners.reshape(-1, 3), pairs
