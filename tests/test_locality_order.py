"""The bakers' visiting order (``bake.micromap.locality_order``): a permutation that groups
triangles by texture tile along a Morton curve, and the states do not depend on it."""

import numpy as np

from omaps.alpha_test import StateRule
from omaps.bake.micromap import GROW_TEXEL, TILE, bake_micromaps, locality_order
from omaps.texture import load_alpha


def _morton(x, y):
    """Morton key of tile (x, y), bit by bit (independent of the kernel's bit spreading)."""
    k = 0
    for b in range(16):
        k |= ((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1)
    return k


def test_is_a_permutation_for_any_coordinates():
    rng = np.random.default_rng(3)
    for tris in (rng.uniform(-5, 5, (2000, 3, 2)), np.full((4, 3, 2), 1e300), np.zeros((0, 3, 2)),
                 rng.uniform(0, 1, (1, 3, 2))):
        o = locality_order(tris, 300, 70)
        assert sorted(o.tolist()) == list(range(len(tris)))


def test_tiles_follow_the_morton_curve():
    rng = np.random.default_rng(4)
    w = h = 256  # 16 tiles of TILE texels a side
    tris = rng.uniform(0.05, 0.95, (3000, 1, 2)) + rng.uniform(-0.01, 0.01, (3000, 3, 2))  # inside: no wrap
    o = locality_order(tris, w, h)
    c = tris.sum(axis=1) * [w / (3.0 * TILE), h / (3.0 * TILE)]  # the centroid in tiles, as the kernel rounds it
    tiles = np.clip(np.floor(c).astype(int), 0, w // TILE - 1)
    keys = [_morton(int(tx), int(ty)) for tx, ty in tiles[o]]
    assert keys == sorted(keys)
    same = np.array(keys[1:]) == np.array(keys[:-1])  # input order within a tile
    assert np.all(o[1:][same] > o[:-1][same])


def test_states_do_not_depend_on_the_order():
    rng = np.random.default_rng(5)
    alpha = (rng.uniform(0, 1, (64, 64)) * 255).astype(np.uint8)
    grid = StateRule("cutoff").alpha_test(load_alpha(alpha), "linear", "clamp").grid()
    tris = rng.uniform(0.05, 0.95, (400, 1, 2)) + rng.uniform(-0.05, 0.05, (400, 3, 2))
    perm = rng.permutation(len(tris))
    a, sa = bake_micromaps(grid, tris, 3, GROW_TEXEL)
    b, sb = bake_micromaps(grid, tris[perm], 3, GROW_TEXEL)
    assert np.array_equal(a.reshape(len(tris), -1)[perm], b.reshape(len(tris), -1))
