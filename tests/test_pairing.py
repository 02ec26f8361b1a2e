"""Triangle pairing: valid, maximal, maximum on small meshes (brute force), square corners."""

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps.scene.pairing import CORNERS, adjacency, is_valid_matching, pair_triangles, weld


def grid_mesh(nx, ny, keep=None, materials=None):
    """Triangles of an nx x ny grid of quads (two triangles each), vertices duplicated per
    quad (as after a UV split) so pairing must weld by position."""
    pos, tris, mats = [], [], []
    k = 0
    for j in range(ny):
        for i in range(nx):
            q = [(i, j, 0), (i + 1, j, 0), (i + 1, j + 1, 0), (i, j + 1, 0)]
            for t in ([0, 1, 2], [0, 2, 3]) if (i + j) % 2 == 0 else ([0, 1, 3], [1, 2, 3]):
                if keep is None or keep[k]:
                    base = len(pos)
                    pos += [q[x] for x in t]
                    tris.append([base, base + 1, base + 2])
                    mats.append(0 if materials is None else materials[k])
                k += 1
    return np.array(tris, np.int64).reshape(-1, 3), np.array(pos, np.float32).reshape(-1, 3), np.array(mats, np.int32)


def brute_force_max(n, edges):
    best = 0
    for r in range(len(edges), 0, -1):
        if r <= best:
            break
        for combo in itertools.combinations(edges, r):
            used = [v for e in combo for v in e]
            if len(used) == len(set(used)):
                return r
    return best


def _area2(c):
    (x1, y1), (x2, y2) = c[1] - c[0], c[2] - c[0]
    return abs(int(x1) * int(y2) - int(y1) * int(x2))


def check_pairing(tris, pos, mats, p):
    w = weld(pos)
    n = len(tris)
    seen = np.zeros(n, int)
    for a, b in zip(p.first, p.second):
        seen[a] += 1
        ca = p.corners[a]
        assert sorted(ca) == [0, 1, 2]
        if b < 0:
            continue
        seen[b] += 1
        assert mats[a] == mats[b]
        shared = set(w[tris[a]]) & set(w[tris[b]])
        assert len(shared) == 2
        cb = p.corners[b]
        assert sorted(cb) == [0, 2, 3]
        # a shared vertex sits at the same corner in both triangles; the third ones at (1,0), (0,1)
        for va, cva in zip(w[tris[a]], ca):
            for vb, cvb in zip(w[tris[b]], cb):
                if va == vb:
                    assert cva == cvb and cva in (0, 2)
        # the square is the quad: the (s, t) map is continuous and one-to-one over it
        sa = CORNERS[ca]
        sb = CORNERS[cb]
        assert _area2(sa) == 1 and _area2(sb) == 1
    assert np.all(seen == 1)


def test_grid_is_fully_paired():
    tris, pos, mats = grid_mesh(5, 4)
    p = pair_triangles(tris, pos, mats)
    assert p.n_pairs == 20 and p.paired_fraction == 1.0
    check_pairing(tris, pos, mats, p)


def test_materials_split_pairs():
    tris, pos, _ = grid_mesh(2, 1)
    p = pair_triangles(tris, pos, np.array([0, 1, 1, 0]))
    # each quad's two triangles differ in material, and so do the two across the quads' shared edge
    assert p.n_pairs == 0 and len(p.first) == 4 and np.all(p.corners == [0, 1, 2])


def test_selection_leaves_others_out():
    tris, pos, mats = grid_mesh(2, 2)
    sel = np.array([True, True, False, False, True, True, True, False])
    p = pair_triangles(tris, pos, mats, sel)
    assert sorted(np.concatenate([p.first, p.second[p.second >= 0]])) == list(np.flatnonzero(sel))
    assert np.all(p.corners[~sel] == -1) and np.all(p.pair_of[~sel] == -1)


@settings(max_examples=150)
@given(st.integers(1, 4), st.integers(1, 3), st.data())
def test_random_meshes_valid_maximal_and_maximum(nx, ny, data):
    n = 2 * nx * ny
    keep = data.draw(st.lists(st.booleans(), min_size=n, max_size=n))
    mats = data.draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    tris, pos, mats = grid_mesh(nx, ny, keep, mats)
    if len(tris) == 0:
        return
    p = pair_triangles(tris, pos, mats)
    check_pairing(tris, pos, mats, p)
    off, nb = adjacency(tris, mats, weld(pos), np.ones(len(tris), bool))
    mate = np.full(len(tris), -1)
    for a, b in zip(p.first, p.second):
        if b >= 0:
            mate[a], mate[b] = b, a
    assert is_valid_matching(off, nb, mate)
    free = np.flatnonzero(mate < 0)
    for v in free:  # maximal: no two free neighbours
        assert not np.any(mate[nb[off[v]:off[v + 1]]] < 0)
    edges = [(v, u) for v in range(len(tris)) for u in nb[off[v]:off[v + 1]] if v < u]
    if len(edges) <= 14:
        assert p.n_pairs == brute_force_max(len(tris), edges)


def test_augmenting_paths_fix_a_bad_greedy_start():
    # a strip of 6 triangles: a path graph 0-1-2-3-4-5; matching (1,2), (3,4) leaves 0 and 5 free
    from omaps.scene.pairing import augment_paths

    off = np.array([0, 1, 3, 5, 7, 9, 10])
    nb = np.array([1, 0, 2, 1, 3, 2, 4, 3, 5, 4])
    mate = np.array([-1, 2, 1, 4, 3, -1])
    mate = augment_paths(off, nb, mate, 10)
    assert is_valid_matching(off, nb, mate) and np.all(mate >= 0)
