"""Pictures of maps in the deck's colours (T cyan, O magenta, C green), as RGB arrays."""

from __future__ import annotations

import numpy as np
from numba import njit

from . import birdcurve, pair, states


def colourise(map_states: np.ndarray) -> np.ndarray:
    return states.COLOURS[np.asarray(map_states)]


def square_image(sq: np.ndarray, size: int) -> np.ndarray:
    """An N x N map (rows = v) drawn at ``size`` pixels, nearest-neighbour."""
    n_rows, n_cols = sq.shape
    ys = (np.arange(size) * n_rows) // size
    xs = (np.arange(size) * n_cols) // size
    return colourise(sq[np.ix_(ys, xs)])


@njit(cache=True)
def _pair_tri_lookup(tri_maps, level, size):
    out = np.empty((size, size), dtype=np.uint8)
    for y in range(size):
        v = (y + 0.5) / size
        for x in range(size):
            u = (x + 0.5) / size
            t, b1, b2 = pair.uv_to_hit(u, v)
            out[y, x] = tri_maps[t, birdcurve.bary_to_index(b1, b2, level)]
    return out


def pair_triangle_image(tri_maps: np.ndarray, size: int) -> np.ndarray:
    """The pair's two micromaps (2, 4**L) drawn over the square, each pixel looked up through
    the bird curve as a ray hit would be."""
    level = int(round(np.log(tri_maps.shape[1]) / np.log(4)))
    return colourise(_pair_tri_lookup(np.ascontiguousarray(tri_maps), level, size))


def scheme_image(kind: str, map_states: np.ndarray, size: int) -> np.ndarray:
    """A scheme's map of the corpus pair drawn over the square (``Scheme.kind``)."""
    if kind == "micromap":
        return pair_triangle_image(map_states, size)
    return square_image(map_states, size)
