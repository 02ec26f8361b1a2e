"""The corpus pair's barycentric -> (u, v) -> square cell mapping of docs/FORMAT.md."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

import reference as ref
from omaps import pair

bary = st.tuples(st.floats(0, 1), st.floats(0, 1)).filter(lambda b: b[0] + b[1] <= 1)


@given(st.integers(0, 1), bary, st.sampled_from([1, 2, 4, 16, 32, 128]))
def test_hit_to_cell_is_the_point_of_the_triangle(tri, b, n):
    b1, b2 = b
    p = pair.PAIR[tri]
    u, v = (1 - b1 - b2) * p[0] + b1 * p[1] + b2 * p[2]  # the hit's position on the triangle
    assert np.allclose(ref.hit_to_uv(tri, b1, b2), (u, v))
    i, j = ref.hit_to_cell(tri, b1, b2, n)
    assert 0 <= i < n and 0 <= j < n
    assert i / n - 1e-12 <= u <= (i + 1) / n + 1e-12 and j / n - 1e-12 <= v <= (j + 1) / n + 1e-12
    # the kernels' mapping (any pair's corner codes, here the corpus pair's) is the same, exactly
    s, t = pair.hit_st(np.concatenate([pair.A_CORNERS, pair.B_CORNERS]), tri, b1, b2)
    assert (s, t) == ref.hit_to_uv(tri, b1, b2)
    assert pair.uv_to_cell(s, t, n) == (i, j)


@given(st.floats(0, 1), st.floats(0, 1))
def test_uv_to_hit_inverts(u, v):
    t, b1, b2 = pair.uv_to_hit(u, v)
    assert b1 >= 0 and b2 >= 0 and b1 + b2 <= 1 + 1e-12
    assert np.allclose(ref.hit_to_uv(t, b1, b2), (u, v))
    assert (t == 0) == (v <= u)  # A lies below the diagonal


def test_square_cells_order():
    cells = ref.square_cells(4)
    assert cells.shape == (16, 4, 2)
    np.testing.assert_allclose(cells[1], [[0.25, 0], [0.5, 0], [0.5, 0.25], [0.25, 0.25]])  # (i=1, j=0)
    np.testing.assert_allclose(cells[4, 0], [0, 0.25])  # row j = 1 starts at index 4


@given(st.integers(0, 1), bary, st.lists(st.floats(-4, 4), min_size=12, max_size=12))
def test_square_uv_is_the_triangles_affine_map(tri, b, coords):
    """``pair.square_uv`` (what both square kernels map a point of the square with): the point
    of the square on triangle ``tri`` (the corpus pair's (s, t) of a hit there) goes to the
    hit's UV, the barycentric combination of that triangle's corner UVs."""
    b1, b2 = b
    uv = np.array(coords).reshape(6, 2)
    s, t = ref.hit_to_uv(tri, b1, b2)
    want = (1 - b1 - b2) * uv[3 * tri] + b1 * uv[3 * tri + 1] + b2 * uv[3 * tri + 2]
    np.testing.assert_allclose(pair.square_uv(uv, 3 * tri, tri, s, t), want, atol=1e-12)
