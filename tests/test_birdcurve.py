import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps import birdcurve


def _area(t):
    e1, e2 = t[1] - t[0], t[2] - t[0]
    return 0.5 * (e1[0] * e2[1] - e1[1] * e2[0])


def test_level2_matches_specification_figure():
    # The specification's level-2 figure, vertices numbered row by row from p2 (top) down to the
    # p0 (bottom-left) .. p1 (bottom-right) edge; each micro-triangle as its set of vertices.
    figure = {0: {6, 10, 11}, 1: {6, 7, 11}, 2: {7, 11, 12}, 3: {3, 6, 7}, 4: {3, 4, 7}, 5: {4, 7, 8},
              6: {4, 5, 8}, 7: {7, 8, 12}, 8: {8, 12, 13}, 9: {8, 9, 13}, 10: {9, 13, 14}, 11: {5, 8, 9},
              12: {2, 4, 5}, 13: {1, 2, 4}, 14: {1, 3, 4}, 15: {0, 1, 2}}

    def vertex_id(u, v):  # row r = 4 - 4v from the top, column = 4u within the row
        row = round(4 - 4 * v)
        col = round(4 * u)
        return row * (row + 1) // 2 + col

    tris = birdcurve.micro_triangles(2)
    for k, t in enumerate(tris):
        assert {vertex_id(u, v) for u, v in t} == figure[k], k


@pytest.mark.parametrize("level", range(0, 7))
def test_tiles_triangle_and_is_a_bijection(level):
    tris = birdcurve.micro_triangles(level)
    assert tris.shape == (4 ** level, 3, 2)
    areas = np.array([abs(_area(t)) for t in tris])
    assert np.allclose(areas, 0.5 / 4 ** level)
    # each centroid is found by bary_to_index, so the index -> triangle map is one-to-one
    cents = tris.mean(axis=1)
    idx = [birdcurve.bary_to_index(u, v, level) for u, v in cents]
    assert idx == list(range(4 ** level))


@pytest.mark.parametrize("level", range(1, 7))
def test_parent_is_index_shift(level):
    child = birdcurve.micro_triangles(level)
    parent = birdcurve.micro_triangles(level - 1)
    for k in range(len(child)):
        c = child[k].mean(axis=0)
        p = parent[k >> 2]
        # barycentric coordinates of the child's centroid in the parent triangle are all > 0
        m = np.array([p[1] - p[0], p[2] - p[0]]).T
        b = np.linalg.solve(m, c - p[0])
        assert b.min() > 0 and b.sum() < 1


def test_winding_of_children():
    # children 0 and 2 keep the parent's winding, 1 and 3 flip it (as the specification shows)
    tris = birdcurve.micro_triangles(1)
    signs = [np.sign(_area(t)) for t in tris]
    assert signs == [1, -1, 1, -1]


@settings(max_examples=300, deadline=None)
@given(st.floats(0, 1), st.floats(0, 1), st.integers(0, 8))
def test_bary_to_index_contains_point(u, v, level):
    if u + v > 1:
        u, v = 1 - u, 1 - v
    k = birdcurve.bary_to_index(u, v, level)
    assert 0 <= k < 4 ** level
    t = birdcurve.micro_triangles(level)[k]
    m = np.array([t[1] - t[0], t[2] - t[0]]).T
    b = np.linalg.solve(m, np.array([u, v]) - t[0])
    tol = 1e-9
    assert b.min() >= -tol and b.sum() <= 1 + tol


def test_level_out_of_range():
    with pytest.raises(ValueError):
        birdcurve.micro_triangles(13)
    with pytest.raises(ValueError):
        birdcurve.micro_triangles(-1)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 7), st.data())
def test_micro_vertices_walk_is_the_subdivision(level, data):
    """``birdcurve.micro_vertices`` (the digit walk the kernels use) gives micro-triangle k's
    vertices exactly as the whole subdivision does, and ``child`` on the micromap baker's integer
    grid points gives the same children scaled by 2**level."""
    k = data.draw(st.integers(0, 4 ** level - 1))
    want = birdcurve.micro_triangles(level)[k]
    np.testing.assert_array_equal(np.array(birdcurve.micro_vertices(k, level)), want)
    n = 1 << level
    p0, p1, p2 = (0, 0), (n, 0), (0, n)
    for d in range(level - 1, -1, -1):
        mid = lambda a, b: ((a[0] + b[0]) // 2, (a[1] + b[1]) // 2)  # noqa: E731
        p0, p1, p2 = birdcurve.child((k >> (2 * d)) & 3, p0, p1, p2, mid(p0, p1), mid(p1, p2), mid(p0, p2))
    np.testing.assert_array_equal(np.array([p0, p1, p2]) / n, want)


def test_vertex_table_is_the_digit_walk():
    """``table_vertices`` (the resolve's lookup) gives micro-triangles' vertices as the digit walk
    ``micro_vertices`` does, bit for bit, in the table's levels and past them (composed), up to
    the APIs' last level: the first and last micro-triangles of every level and 3,000 drawn at
    random."""

    @numba.njit
    def both(table, ks, level):
        got = np.empty((len(ks), 6))
        want = np.empty((len(ks), 6))
        for i in range(len(ks)):
            (got[i, 0], got[i, 1]), (got[i, 2], got[i, 3]), (got[i, 4], got[i, 5]) = \
                birdcurve.table_vertices(table, ks[i], level)
            (want[i, 0], want[i, 1]), (want[i, 2], want[i, 3]), (want[i, 4], want[i, 5]) = \
                birdcurve.micro_vertices(ks[i], level)
        return got, want

    table = birdcurve.vertex_table()
    assert len(table) == (4 ** birdcurve.TABLE_LEVELS - 1) // 3
    rng = np.random.default_rng(5)
    for level in range(birdcurve.MAX_LEVEL + 1):
        ks = np.concatenate([[0, 4 ** level - 1, 4 ** level // 3], rng.integers(0, 4 ** level, 3000)])
        got, want = both(table, ks, level)
        np.testing.assert_array_equal(got, want, err_msg=f"level {level}")
