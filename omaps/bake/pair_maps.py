"""The corpus pair's maps (a texture covering the square of two triangles, ``omaps.pair``) and
the savings metric, on top of the two bakers.

``bake_square`` is the pair-square baker on the corpus pair, ``bake_pair_triangles`` the
micromap baker on its two triangles; neither grows regions (the corpus pair's regions are exact
and no ray is traced). ``known_fraction`` is the savings of a map with equal-area regions, and
``texel_limit`` the savings of a map whose regions are the footprint cells.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.bake import bake_square, known_fraction
    >>> from omaps.texture import load_alpha
    >>> grid = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8))).grid()
    >>> known_fraction(bake_square(grid, 4))
    1.0
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .. import checks, pair, states
from ..alpha_test import AlphaTest, as_grid
from ..errors import InputError
from ..sampling import FootprintGrid
from .micromap import bake_micromap_rows
from .square import bake_pair_squares

__all__ = ["bake_square", "bake_pair_triangles", "known_fraction", "texel_limit"]


def bake_square(grid: FootprintGrid | AlphaTest, n: int) -> np.ndarray:
    """The N x N square map of the corpus pair: states (N, N), ``map[j, i]``.

    ``grid``: a footprint grid (``AlphaTest.grid()``) or the ``AlphaTest`` itself; ``n`` a power
    of two from 1 to 128. A wrong argument raises an ``InputTypeError`` / ``InputError`` naming it."""
    return bake_pair_squares(as_grid(grid), pair.PAIR_CORNER_UV, np.ones(1, bool), n)[0]


def bake_pair_triangles(grid: FootprintGrid | AlphaTest, level: int) -> np.ndarray:
    """The per-triangle micromaps of the corpus pair: states (2, 4**level), A then B.

    ``grid``: a footprint grid or an ``AlphaTest``; ``level`` 0..12."""
    return bake_micromap_rows(as_grid(grid), pair.PAIR, level)


def known_fraction(map_states: ArrayLike) -> float:
    """Fraction of equal-area regions that skip the any-hit shader (``map_states``: any
    non-empty array of states 0 T, 1 O, 2 C)."""
    m = checks.array(map_states, "map_states", kinds="iu")
    if m.size == 0:
        raise InputError("map_states must not be empty", param="map_states")
    return float(np.count_nonzero(m != states.C)) / m.size


def texel_limit(grid: FootprintGrid | AlphaTest) -> float:
    """Area fraction of the texture whose footprint cell is known: the savings of a map whose
    regions are the cells (under ``nearest`` the most any map can save; under exact bilinear a
    finer map can save more, knowing the parts of a mixed cell on either side of the cut-off).
    ``grid``: a footprint grid or an ``AlphaTest``."""
    f, w = as_grid(grid).cells_within_texture()
    return float((w * (f != states.FLAG_C)).sum() / w.sum())
