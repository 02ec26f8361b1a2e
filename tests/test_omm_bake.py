"""The fast micromap baker gives exactly the states of rasterising every micro-triangle with
the cell-by-cell rasteriser ``reference_raster.polygon_flags`` (with and without growth), and
the brute-force reference's."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference as ref
import reference_raster
from conftest import needs_shared, real_textures
from omaps import birdcurve, raster, states
from omaps.bake import micromap
from omaps.bake.micromap import GROW_TEXEL
from omaps.errors import InputError
from omaps.sampling import footprint_grid
from omaps.alpha_test import StateRule
from omaps.texture import AlphaTexture, load_alpha

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


def raster_rows(grid, tris_uv, level, grow=0.0):
    """Micromaps (T, 4**level) by rasterising each micro-triangle on its own with
    ``reference_raster.polygon_flags`` (no tree walk, no summed-area table): the slow baker the
    fast one must equal. Vertices as the baker computes them: b0 * p0 + b1 * p1 + b2 * p2, times the
    texture size, plus the grid offset."""
    t = np.asarray(tris_uv, dtype=np.float64)
    bary = birdcurve.micro_triangles(level)
    w0 = 1.0 - bary[..., 0] - bary[..., 1]
    uv = (w0[None, ..., None] * t[:, None, None, 0] + bary[None, ..., 0, None] * t[:, None, None, 1]
          + bary[None, ..., 1, None] * t[:, None, None, 2])
    polys = uv.reshape(-1, 3, 2) * np.array([grid.width, grid.height], dtype=np.float64) + grid.offset
    flags = np.array([reference_raster.polygon_flags(*grid.kernel_args(), np.ascontiguousarray(p), grow)
                      for p in polys], dtype=np.uint8)
    assert np.all(flags > 0)  # every region reads something
    return states.FLAG_TO_STATE[flags].reshape(len(t), -1)


@st.composite
def triangle_sets(draw, coord):
    return np.stack([_triangle(draw, coord) for _ in range(draw(st.integers(1, 3)))])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(state_images, binary_images), st.one_of(triangle_sets(dyadic), triangle_sets(anyfloat)),
       st.integers(0, 5), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
@pytest.mark.long
def test_identical_to_the_raster(img, tris, level, filter, wrap):
    """Arbitrary float coordinates too: the kernel repeats the reference raster's arithmetic,
    without growth and with real geometry's growth."""
    g = footprint_grid(img, filter, wrap)
    for grow in (0.0, GROW_TEXEL):
        np.testing.assert_array_equal(micromap.bake_micromap_rows(g, tris, level, grow),
                                      raster_rows(g, tris, level, grow))


alpha_images = st.integers(1, 8).flatmap(
    lambda w: st.integers(1, 8).flatmap(
        lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from([0, 60, 127, 128, 200, 255]))))


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(alpha_images, st.one_of(triangle_sets(dyadic), triangle_sets(anyfloat)), st.integers(0, 4),
       st.sampled_from(WRAPS), st.sampled_from(["cutoff", "levels"]))
def test_exact_bilinear_grids_identical_to_the_raster(alpha8, tris, level, wrap, mode):
    """On exact bilinear grids (mixed cells decided by their extremes), with real geometry's
    growth: the tree walk, the shared vertex flags and the rasteriser's shortcuts (a region
    proven known from its bounding box, cell by cell) give the cell-by-cell raster's flags."""
    rule = StateRule("cutoff", cutoff=0.5) if mode == "cutoff" else StateRule("levels", t_max=60.0, o_min=200.0)
    g = rule.alpha_test(AlphaTexture("t", alpha8, 255), "linear", wrap).grid()
    assert g.exact
    np.testing.assert_array_equal(micromap.bake_micromap_rows(g, tris, level, GROW_TEXEL),
                                  raster_rows(g, tris, level, GROW_TEXEL))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state_images, triangle_sets(dyadic), st.integers(0, 3), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_matches_brute_force_reference(img, tris, level, filter, wrap):
    got = micromap.bake_micromap_rows(footprint_grid(img, filter, wrap), tris, level)
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
    for grow in (0.0, GROW_TEXEL):
        s, starts = micromap.bake_micromaps(g, tris, levels, grow)
        assert starts[-1] == len(s) == sum(4 ** int(x) for x in levels)
        for t, lv in enumerate(levels):
            np.testing.assert_array_equal(s[starts[t]:starts[t + 1]], raster_rows(g, tris[t:t + 1], int(lv), grow)[0])


def test_levels_beyond_the_reference_limit(rng):
    """Levels 9..12 (too many micro-triangles for the raster): each micro-triangle's state
    refines its level-8 ancestor's, and tiny triangles stay exact against the reference at
    level 9."""
    img = rng.integers(0, 3, size=(6, 5)).astype(np.uint8)
    g = footprint_grid(img, "linear", "wrap")
    tri = np.array([[[0.1, 0.2], [0.9, 0.35], [0.3, 0.95]]])
    coarse = micromap.bake_micromap_rows(g, tri, 8)[0]
    for level in (9, 10):
        fine = micromap.bake_micromap_rows(g, tri, level)[0]
        parent = np.repeat(coarse, 4 ** (level - 8))
        assert np.all((parent == states.C) | (fine == parent))
    small = np.array([[[0.5, 0.5], [0.5 + 1 / 64, 0.5], [0.5, 0.5 + 1 / 64]]])
    got = micromap.bake_micromap_rows(g, small, 9)[0]
    micro = birdcurve.uv_micro_triangles(small[0], 9) * np.array([5.0, 6.0])  # texel coordinates
    texels = ref.Addressed(img, "wrap", 4)
    for k in rng.choice(4 ** 9, 300, replace=False):
        assert got[k] == ref.region_state(texels, micro[k], "linear")
    assert micromap.bake_micromap_rows(g, tri, 12).shape == (1, 4 ** 12)


def test_summed_area_table_counts(rng):
    img = rng.integers(0, 3, size=(7, 9)).astype(np.uint8)
    g = footprint_grid(img, "nearest", "clamp")
    sat = micromap.flag_table(g)
    f = g.flags
    assert sat[-1, -1, 0] == np.count_nonzero(f & 1) and sat[-1, -1, 1] == np.count_nonzero(f & 2)
    assert sat[3, 4, 0] == np.count_nonzero(f[:3, :4] & 1)


def test_dynamic_levels():
    # texel areas 8, 32, 2048 on a 64 x 64 texture with scale 2 (micro-triangles of <= 4 texels)
    s = 1 / 64
    tris = np.array([[[0, 0], [4 * s, 0], [0, 4 * s]], [[0, 0], [8 * s, 0], [0, 8 * s]],
                     [[0, 0], [1, 0], [0, 1]]])
    lv = micromap.dynamic_levels(tris, 64, 64, 2.0, 8)
    # 8 / 4^1 = 2 <= 4 -> level 1; 32 / 4^2 = 2 -> 2; 2048 / 4^5 = 2 -> 5
    np.testing.assert_array_equal(lv, [1, 2, 5])
    np.testing.assert_array_equal(micromap.dynamic_levels(tris, 64, 64, 2.0, 3), [1, 2, 3])
    np.testing.assert_array_equal(micromap.dynamic_levels(tris, 64, 64, 100.0, 8), [0, 0, 0])
    with pytest.raises(InputError, match="scale must be > 0"):
        micromap.dynamic_levels(tris, 64, 64, 0.0, 8)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (5, 3, 2), elements=st.floats(-4, 4, allow_nan=False)), st.integers(1, 4096),
       st.integers(1, 4096))
def test_texel_areas_are_the_triangles_areas(tris, w, h):
    """Half the cross product of two edges in texel space, computed in exact fractions: the
    kernel differs by its float64 rounding only."""
    from fractions import Fraction

    got = micromap.texel_areas(tris, w, h)
    for t, a in zip(tris, got):
        (x0, y0), (x1, y1), (x2, y2) = ((Fraction(u) * w, Fraction(v) * h) for u, v in t)
        exact = abs((x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)) / 2
        big = 1 + max(abs(c) for c in (x0, y0, x1, y1, x2, y2))  # a float64 product's rounding: ~2^-53 big^2
        assert abs(Fraction(a) - exact) <= Fraction(2) ** -46 * big ** 2


def test_bad_levels():
    g = footprint_grid(np.zeros((2, 2), np.uint8))
    tri = np.array([[[0, 0], [1, 0], [0, 1]]], dtype=float)
    for level in (-1, 13, 2.5):
        with pytest.raises(InputError, match="level must be an integer from 0 to 12"):
            micromap.bake_micromap_rows(g, tri, level)


@needs_shared
@pytest.mark.parametrize("path", real_textures(min_size=64)[::9], ids=lambda p: p.stem)
def test_real_textures_identical(path, rng):
    tex = load_alpha(path)
    img = ref.texel_states(tex.alpha8, "cutoff", cutoff=0.5)
    c = rng.random((40, 1, 2))
    tris = c + rng.normal(0, 12 / tex.width, (40, 3, 2))
    for filter, wrap in (("nearest", "clamp"), ("linear", "wrap"), ("linear", "mirror")):
        g = footprint_grid(img, filter, wrap)
        for level, grow in ((3, 0.0), (3, GROW_TEXEL), (5, GROW_TEXEL)):
            np.testing.assert_array_equal(micromap.bake_micromap_rows(g, tris, level, grow),
                                          raster_rows(g, tris, level, grow))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(state_images, binary_images), st.one_of(triangle_sets(dyadic), triangle_sets(anyfloat)),
       st.integers(0, 3), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_region_states_are_the_cell_by_cell_raster(img, tris, level, filter, wrap):
    """``raster.region_states`` (each region through ``raster.rows_flag`` on its own) is the
    cell-by-cell rasteriser's answer, on exact grids too."""
    alpha = np.array([0.0, 255.0, 100.0])[img]  # T, O, C under the bounds below
    for g in (footprint_grid(img, filter, wrap), footprint_grid(img, filter, wrap, values=alpha,
                                                                 bounds=np.array([150.0, 0, 50.0, 1]))):
        micro = np.concatenate([birdcurve.uv_micro_triangles(t, level) for t in tris])
        texel = micro * np.array([g.width, g.height], dtype=np.float64)
        want = np.array([reference_raster.polygon_flags(*g.kernel_args(), np.ascontiguousarray(p) + g.offset)
                         for p in texel], dtype=np.uint8)
        assume(np.all(want > 0))
        np.testing.assert_array_equal(raster.region_states(g, texel), states.FLAG_TO_STATE[want])
