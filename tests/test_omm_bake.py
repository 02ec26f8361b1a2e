"""The fast OMM baker gives exactly maps.bake_triangles' states, and the brute-force reference's."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference as ref
from conftest import needs_shared, real_textures
from omaps import birdcurve, maps, states
from omaps.errors import InputError
from omaps.omm import bake
from omaps.sampling import footprint_grid
from omaps.texture import load_alpha

FILTERS = ["nearest", "linear"]
WRAPS = ["clamp", "wrap", "mirror"]

state_images = st.integers(1, 10).flatmap(
    lambda w: st.integers(1, 10).flatmap(
        lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from([0, 1, 2]))))
binary_images = st.integers(1, 10).flatmap(
    lambda w: st.integers(1, 10).flatmap(
        lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from([0, 1]))))

dyadic = st.integers(-40, 56).map(lambda k: k / 16)
anyfloat = st.floats(-2.5, 3.5, allow_nan=False, allow_infinity=False)


def _triangle(draw, coord):
    t = np.array([[draw(coord), draw(coord)] for _ in range(3)])
    e1, e2 = t[1] - t[0], t[2] - t[0]
    assume(abs(e1[0] * e2[1] - e1[1] * e2[0]) > 1e-3)
    return t


@st.composite
def triangle_sets(draw, coord):
    return np.stack([_triangle(draw, coord) for _ in range(draw(st.integers(1, 3)))])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(state_images, binary_images), st.one_of(triangle_sets(dyadic), triangle_sets(anyfloat)),
       st.integers(0, 5), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_identical_to_bake_triangles(img, tris, level, filter, wrap):
    """Arbitrary float coordinates too: the kernel repeats the reference raster's arithmetic."""
    g = footprint_grid(img, filter, wrap)
    np.testing.assert_array_equal(bake.bake(g, tris, level), maps.bake_triangles(g, tris, level))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state_images, triangle_sets(dyadic), st.integers(0, 3), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_matches_brute_force_reference(img, tris, level, filter, wrap):
    got = bake.bake(footprint_grid(img, filter, wrap), tris, level)
    for t_i, tri in enumerate(tris):
        want = ref.triangle_states(img, tri, level, filter, wrap)
        micro = birdcurve.uv_micro_triangles(tri, level)
        for k in range(4 ** level):
            assert got[t_i, k] == want[tuple(sorted(map(tuple, np.round(micro[k], 12))))]


@settings(max_examples=40, deadline=None)
@given(state_images, triangle_sets(dyadic), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_mixed_levels_in_one_call(img, tris, filter, wrap):
    g = footprint_grid(img, filter, wrap)
    levels = np.arange(len(tris)) % 4
    s, starts = bake.bake_levels(g, tris, levels)
    assert starts[-1] == len(s) == sum(4 ** int(x) for x in levels)
    for t, lv in enumerate(levels):
        np.testing.assert_array_equal(s[starts[t]:starts[t + 1]], maps.bake_triangles(g, tris[t:t + 1], int(lv))[0])


def test_levels_beyond_the_reference_limit(rng):
    """Levels 9..12 (maps.bake_triangles stops at 8): each micro-triangle's state refines its
    level-8 ancestor's, and tiny triangles stay exact against the reference at level 9."""
    img = rng.integers(0, 3, size=(6, 5)).astype(np.uint8)
    g = footprint_grid(img, "linear", "wrap")
    tri = np.array([[[0.1, 0.2], [0.9, 0.35], [0.3, 0.95]]])
    coarse = bake.bake(g, tri, 8)[0]
    for level in (9, 10):
        fine = bake.bake(g, tri, level)[0]
        parent = np.repeat(coarse, 4 ** (level - 8))
        assert np.all((parent == states.C) | (fine == parent))
    small = np.array([[[0.5, 0.5], [0.5 + 1 / 64, 0.5], [0.5, 0.5 + 1 / 64]]])
    got = bake.bake(g, small, 9)[0]
    micro = birdcurve.uv_micro_triangles(small[0], 9) * np.array([5.0, 6.0])  # texel coordinates
    texels = ref.Addressed(img, "wrap", 4)
    for k in rng.choice(4 ** 9, 300, replace=False):
        assert got[k] == ref.region_state(texels, micro[k], "linear")
    assert bake.bake(g, tri, 12).shape == (1, 4 ** 12)


def test_summed_area_table_counts(rng):
    img = rng.integers(0, 3, size=(7, 9)).astype(np.uint8)
    g = footprint_grid(img, "nearest", "clamp")
    sat = bake.flag_table(g)
    f = g.flags
    assert sat[-1, -1, 0] == np.count_nonzero(f & 1) and sat[-1, -1, 1] == np.count_nonzero(f & 2)
    assert sat[3, 4, 0] == np.count_nonzero(f[:3, :4] & 1)


def test_dynamic_levels():
    # texel areas 8, 32, 2048 on a 64 x 64 texture with scale 2 (micro-triangles of <= 4 texels)
    s = 1 / 64
    tris = np.array([[[0, 0], [4 * s, 0], [0, 4 * s]], [[0, 0], [8 * s, 0], [0, 8 * s]],
                     [[0, 0], [1, 0], [0, 1]]])
    lv = bake.dynamic_levels(tris, 64, 64, 2.0, 8)
    # 8 / 4^1 = 2 <= 4 -> level 1; 32 / 4^2 = 2 -> 2; 2048 / 4^5 = 2 -> 5
    np.testing.assert_array_equal(lv, [1, 2, 5])
    np.testing.assert_array_equal(bake.dynamic_levels(tris, 64, 64, 2.0, 3), [1, 2, 3])
    np.testing.assert_array_equal(bake.dynamic_levels(tris, 64, 64, 100.0, 8), [0, 0, 0])
    with pytest.raises(InputError, match="positive"):
        bake.dynamic_levels(tris, 64, 64, 0.0, 8)


def test_bad_levels():
    g = footprint_grid(np.zeros((2, 2), np.uint8))
    tri = np.array([[[0, 0], [1, 0], [0, 1]]], dtype=float)
    for level in (-1, 13, 2.5):
        with pytest.raises(InputError, match="level must be an integer from 0 to 12"):
            bake.bake(g, tri, level)


@needs_shared
@pytest.mark.parametrize("path", real_textures(min_size=64)[::9], ids=lambda p: p.stem)
def test_real_textures_identical(path, rng):
    tex = load_alpha(path)
    img = ref.texel_states(tex.alpha8, "cutoff", cutoff=0.5)
    c = rng.random((40, 1, 2))
    tris = c + rng.normal(0, 12 / tex.width, (40, 3, 2))
    for filter, wrap in (("nearest", "clamp"), ("linear", "wrap"), ("linear", "mirror")):
        g = footprint_grid(img, filter, wrap)
        for level in (3, 5):
            np.testing.assert_array_equal(bake.bake(g, tris, level), maps.bake_triangles(g, tris, level))
