"""Uncompressed symbolic maps: square maps over a pair and per-triangle micromaps.

Each region's state is conservative: T (O) only when every footprint cell a hit in it can read
is T (O), cells counting when their interiors overlap the region's.
"""

from __future__ import annotations

import numpy as np

from . import birdcurve, pair, raster, states
from .errors import InputError
from .sampling import FootprintGrid

MAX_SQUARE = 128
MAX_TRI_LEVEL = 8


def check_square_size(n) -> int:
    if not isinstance(n, (int, np.integer)) or n < 1 or n > MAX_SQUARE or (n & (n - 1)):
        raise InputError(f"square map size must be a power of two from 1 to {MAX_SQUARE}, got {n!r}")
    return int(n)


def check_tri_level(level, max_level=MAX_TRI_LEVEL) -> int:
    if not isinstance(level, (int, np.integer)) or not 0 <= level <= max_level:
        raise InputError(f"subdivision level must be an integer from 0 to {max_level}, got {level!r}")
    return int(level)


def _to_texel(grid: FootprintGrid, uv: np.ndarray) -> np.ndarray:
    return uv * np.array([grid.width, grid.height], dtype=np.float64)


def bake_square(grid: FootprintGrid, n: int) -> np.ndarray:
    """The N x N square map of the corpus convention: states (N, N), ``map[j, i]``."""
    n = check_square_size(n)
    return raster.region_states(grid, _to_texel(grid, pair.square_cells(n))).reshape(n, n)


def check_uv_triangles(tris_uv) -> np.ndarray:
    """Validate UV triangles (T, 3, 2): finite, non-degenerate (positive area in texture space)."""
    t = np.asarray(tris_uv, dtype=np.float64)
    if t.ndim != 3 or t.shape[1:] != (3, 2):
        raise InputError(f"UV triangles must have shape (T, 3, 2), got {t.shape}")
    finite = np.isfinite(t).all(axis=(1, 2))
    if not finite.all():
        raise InputError(f"UV triangle {int(np.flatnonzero(~finite)[0])} has NaN or infinite coordinates")
    e1 = t[:, 1] - t[:, 0]
    e2 = t[:, 2] - t[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    scale = np.maximum(np.abs(t).max(axis=(1, 2)), 1.0)
    degenerate = area2 <= 1e-12 * scale * scale
    if degenerate.any():
        raise InputError(f"UV triangle {int(np.flatnonzero(degenerate)[0])} is degenerate (zero area)")
    return t


def bake_triangles(grid: FootprintGrid, tris_uv, level: int) -> np.ndarray:
    """Micromaps of UV triangles (T, 3, 2): states (T, 4**level) in bird-curve order."""
    level = check_tri_level(level)
    t = check_uv_triangles(tris_uv)
    bary = birdcurve.micro_triangles(level)  # (M, 3, 2)
    w0 = 1.0 - bary[..., 0] - bary[..., 1]
    # (T, M, 3, 2): micro-triangle vertices in UV
    uv = (w0[None, ..., None] * t[:, None, None, 0] + bary[None, ..., 0, None] * t[:, None, None, 1]
          + bary[None, ..., 1, None] * t[:, None, None, 2])
    polys = _to_texel(grid, uv.reshape(-1, 3, 2))
    return raster.region_states(grid, polys).reshape(len(t), -1)


def bake_pair_triangles(grid: FootprintGrid, level: int) -> np.ndarray:
    """The per-triangle micromaps of the corpus pair: states (2, 4**level), A then B."""
    return bake_triangles(grid, pair.PAIR, level)


def known_fraction(map_states: np.ndarray) -> float:
    """Fraction of equal-area regions that skip the any-hit shader."""
    m = np.asarray(map_states)
    return float(np.count_nonzero(m != states.C)) / m.size


def texel_limit(grid: FootprintGrid) -> float:
    """Area fraction of the texture whose footprint cell is known: what an infinitely fine map
    could save (every region map is at most this)."""
    f, w = grid.cells_within_texture()
    return float((w * (f != states.FLAG_C)).sum() / w.sum())
