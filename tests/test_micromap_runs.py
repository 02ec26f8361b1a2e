"""The baker's runs (``bake_micromap_runs``) are its states, bit for bit, at every level 0..12,
every filter and wrap mode, with and without growth; and the merged-subtree DAG built from runs
(``csm.Builder``, no states held) is byte for byte the one ``csm.build`` makes from the states."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from test_omm_bake import alpha_images, binary_images, state_images, triangle_sets, anyfloat, dyadic
from omaps.alpha_test import StateRule
from omaps.bake import micromap
from omaps.bake.micromap import GROW_TEXEL
from omaps.codecs import csm
from omaps.sampling import footprint_grid
from omaps.texture import AlphaTexture

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow])
levels = st.one_of(st.integers(0, 6), st.integers(7, 12))


def expand(runs, starts, level):
    """The states the runs stand for, checked to tile each triangle in order (plain numpy)."""
    out = []
    for t in range(len(starts) - 1):
        r = runs[starts[t]:starts[t + 1]].astype(np.int64)
        span = 4 ** (level - r[:, 0])
        first = r[:, 1] * span
        assert first[0] == 0 and np.array_equal(first[1:], np.cumsum(span)[:-1]) and span.sum() == 4 ** level
        out.append(np.repeat(r[:, 2], span))
    return np.stack(out).astype(np.uint8)


def _grid(img, kind, filter, wrap):
    if kind == "alpha":  # an exact bilinear grid: mixed cells decided by their extremes
        return StateRule("levels", t_max=60.0, o_min=200.0).alpha_test(AlphaTexture("t", img, 255), "linear",
                                                                       wrap).grid()
    return footprint_grid(img, filter, wrap)


@settings(max_examples=60, **SETTINGS)
@given(st.one_of(st.tuples(st.just("states"), st.one_of(state_images, binary_images)),
                 st.tuples(st.just("alpha"), alpha_images)),
       st.one_of(triangle_sets(dyadic), triangle_sets(anyfloat)), levels, st.sampled_from(["nearest", "linear"]),
       st.sampled_from(["clamp", "wrap", "mirror"]), st.sampled_from([0.0, GROW_TEXEL]))
def test_runs_are_the_states(image, tris, level, filter, wrap, grow):
    g = _grid(image[1], image[0], filter, wrap)
    runs, starts = micromap.bake_micromap_runs(g, tris, level, grow)
    flat = micromap.bake_micromap_rows(g, tris, level, grow)
    np.testing.assert_array_equal(expand(runs, starts, level), flat)
    # the runs follow the mixed nodes: never more than one per micro-triangle
    assert len(runs) <= flat.size
    # a buffer too small for any triangle: each baked again in a larger one, the same runs
    small, small_starts = micromap.bake_micromap_runs(g, tris, level, grow, capacity=1)
    np.testing.assert_array_equal(small, runs)
    np.testing.assert_array_equal(small_starts, starts)


@settings(max_examples=40, **SETTINGS)
@given(st.one_of(state_images, binary_images), st.lists(triangle_sets(anyfloat), min_size=1, max_size=3),
       st.integers(0, 7), st.integers(0, 2 ** 32 - 1))
def test_a_dag_from_runs_is_the_dag_of_the_states(img, sets, level, seed):
    """Several chunks of triangles, some repeated, added as they come: the nodes, the distinct
    maps' roots (sorted by their states) and each map's place equal ``csm.build`` over
    ``np.unique`` of the states; the packed blob is the same bytes."""
    g = footprint_grid(img, "linear", "wrap")
    rng = np.random.default_rng(seed)
    b = csm.Builder(level)
    roots, flats = [], []
    for tris in sets:
        tris = tris[rng.integers(0, len(tris), len(tris) + 1)]  # a triangle twice: a repeated map
        runs, starts = micromap.bake_micromap_runs(g, tris, level, GROW_TEXEL)
        roots.append(b.add(runs, starts))
        flats.append(micromap.bake_micromap_rows(g, tris, level, GROW_TEXEL))
    nodes, distinct, inverse = b.finish(np.concatenate(roots))
    flat = np.concatenate(flats)
    uniq, uinv = np.unique(flat, axis=0, return_inverse=True)
    want_nodes, want_roots = csm.build(uniq, level)
    np.testing.assert_array_equal(nodes, want_nodes)
    np.testing.assert_array_equal(distinct, want_roots)
    np.testing.assert_array_equal(inverse, uinv.ravel())
    assert csm.pack(nodes, distinct[inverse]) == csm.pack(want_nodes, want_roots[uinv.ravel()])


def test_runs_that_do_not_tile_a_map_are_refused():
    b = csm.Builder(1)
    for runs in ([[1, 0, 0], [1, 1, 0], [1, 3, 0]], [[1, 0, 0], [1, 1, 0], [1, 2, 0]], [[0, 0, 1], [1, 0, 0]]):
        try:
            b.add(np.array(runs), np.array([0, len(runs)]))
        except ValueError as exc:
            assert "do not tile" in str(exc)
        else:
            raise AssertionError(runs)
