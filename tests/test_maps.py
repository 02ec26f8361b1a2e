"""Baked maps against the independent brute-force reference, and the T/O/C properties."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference as ref
from conftest import needs_shared, real_textures
from omaps import bake, birdcurve, states
from omaps.alpha_test import StateRule
from omaps.errors import InputError
from omaps.sampling import footprint_grid
from omaps.pair import PAIR_CORNER_UV
from omaps.texture import AlphaTexture, load_alpha

FILTERS = ["nearest", "linear"]
WRAPS = ["clamp", "wrap", "mirror"]


def _key(t):
    return tuple(sorted(map(tuple, np.round(t, 12))))


def check_square(st_img, n, filter, wrap):
    g = footprint_grid(st_img, filter, wrap)
    got = bake.bake_square(g, n)
    want = ref.square_map(st_img, n, filter, wrap)
    np.testing.assert_array_equal(got, want)
    # growth (real geometry's) only ever turns a known cell into C
    grown = bake.bake_pair_squares(g, PAIR_CORNER_UV, np.ones(1, bool), n, bake.GROW_TEXEL)[0]
    assert states.is_conservative(got, grown)


def check_triangles(st_img, tris_uv, level, filter, wrap):
    g = footprint_grid(st_img, filter, wrap)
    got = bake.bake_micromap_rows(g, tris_uv, level)
    mt = [birdcurve.uv_micro_triangles(t, level) for t in tris_uv]
    for t_i, tri in enumerate(tris_uv):
        want = ref.triangle_states(st_img, tri, level, filter, wrap)
        h, w = st_img.shape
        for k in range(4 ** level):
            assert got[t_i, k] == want[_key(mt[t_i][k])], (t_i, k)
    # growth (real geometry's) only ever turns a known micro-triangle into C
    assert states.is_conservative(got, bake.bake_micromap_rows(g, tris_uv, level, bake.GROW_TEXEL))


state_images = st.integers(1, 12).flatmap(
    lambda w: st.integers(1, 12).flatmap(
        lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from([0, 1, 2]))))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state_images, st.sampled_from([1, 2, 4, 8, 16]), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_square_matches_reference_random(img, n, filter, wrap):
    check_square(img, n, filter, wrap)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state_images, st.integers(0, 3), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_pair_triangles_match_reference_random(img, level, filter, wrap):
    from omaps.pair import PAIR
    check_triangles(img, PAIR, level, filter, wrap)


dyadic = st.integers(-40, 56).map(lambda k: k / 16)  # UVs in [-2.5, 3.5], outside [0, 1] too


@st.composite
def uv_triangles(draw):
    t = np.array([[draw(dyadic), draw(dyadic)] for _ in range(3)])
    e1, e2 = t[1] - t[0], t[2] - t[0]
    assume(abs(e1[0] * e2[1] - e1[1] * e2[0]) > 1e-9)
    return t


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.large_base_example])
@given(state_images, uv_triangles(), st.integers(0, 2), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_arbitrary_uv_triangles_match_reference(img, tri, level, filter, wrap):
    """Real-UV triangles reach outside [0, 1]: exercises wrap / clamp / mirror with negative
    and non-power-of-two coordinates."""
    check_triangles(img, tri[None], level, filter, wrap)


@settings(max_examples=60, deadline=None)
@given(state_images, st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_savings_monotone_and_bounded_by_texel(img, filter, wrap):
    g = footprint_grid(img, filter, wrap)
    limit = bake.texel_limit(g)
    prev = -1.0
    for n in (1, 2, 4, 8, 16, 32):
        s = bake.known_fraction(bake.bake_square(g, n))
        assert s >= prev
        assert s <= limit + 1e-12
        prev = s
    prev = -1.0
    for level in range(0, 5):
        s = bake.known_fraction(bake.bake_pair_triangles(g, level))
        assert s >= prev
        assert s <= limit + 1e-12
        prev = s


@settings(max_examples=60, deadline=None)
@given(state_images, st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_refinement_is_conservative_refinement(img, filter, wrap):
    """A known region stays known with the same state in every child (T/O never flip)."""
    g = footprint_grid(img, filter, wrap)
    a = bake.bake_square(g, 4)
    b = bake.bake_square(g, 8)
    parent = np.repeat(np.repeat(a, 2, 0), 2, 1)
    assert np.all((parent == states.C) | (b == parent))
    t3 = bake.bake_pair_triangles(g, 3)
    t4 = bake.bake_pair_triangles(g, 4)
    parent = np.repeat(t3, 4, axis=1)  # child k has parent k >> 2
    assert np.all((parent == states.C) | (t4 == parent))


def test_fine_square_equals_texel_limit(rng):
    img = rng.integers(0, 3, size=(16, 8)).astype(np.uint8)
    g = footprint_grid(img)
    assert bake.known_fraction(bake.bake_square(g, 64)) == pytest.approx(bake.texel_limit(g))
    sq = bake.bake_square(g, 16)  # 16 cells across 8 texels: each texel is a 2x1 block of cells
    np.testing.assert_array_equal(sq, np.repeat(img, 2, axis=1))


def test_uniform_textures():
    for s in (states.T, states.O):
        g = footprint_grid(np.full((5, 7), s, np.uint8), "linear", "mirror")
        assert np.all(bake.bake_square(g, 8) == s)
        assert np.all(bake.bake_pair_triangles(g, 3) == s)


def test_cutoff_linear_is_conservative_against_sampling(rng):
    """Sample the bilinear alpha at many points of each known region: it must agree."""
    a = rng.integers(0, 256, size=(9, 11)).astype(np.uint8)
    a[:, :5] = 255
    a[:3, :] = 0
    tex = AlphaTexture("t", a, 255)
    rule = StateRule("cutoff", cutoff=0.5)
    for wrap in WRAPS:
        g = footprint_grid(rule.classify(tex), "linear", wrap)
        n = 8
        sq = bake.bake_square(g, n)
        pad = np.pad(a.astype(float), 2, mode=ref.PAD_MODES[wrap])
        pts = rng.uniform(0, 1, size=(20000, 2))
        x = pts[:, 0] * 11 - 0.5
        y = pts[:, 1] * 9 - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        v = ((1 - fx) * (1 - fy) * pad[y0 + 2, x0 + 2] + fx * (1 - fy) * pad[y0 + 2, x0 + 3]
             + (1 - fx) * fy * pad[y0 + 3, x0 + 2] + fx * fy * pad[y0 + 3, x0 + 3])
        cell = sq[np.minimum((pts[:, 1] * n).astype(int), n - 1), np.minimum((pts[:, 0] * n).astype(int), n - 1)]
        assert np.all(v[cell == states.O] > 127.5)
        assert np.all(v[cell == states.T] <= 127.5)
        assert (cell != states.C).any()


def test_bad_parameters():
    g = footprint_grid(np.zeros((4, 4), np.uint8))
    for n in (0, 3, 12, 256, -4):
        with pytest.raises(InputError, match="power of two"):
            bake.bake_square(g, n)
    for level in (-1, 13, 2.5):
        with pytest.raises(InputError, match="level must be an integer from 0 to 12"):
            bake.bake_pair_triangles(g, level)
    with pytest.raises(InputError, match="NaN"):
        bake.bake_micromap_rows(g, np.array([[[0, 0], [np.nan, 0], [0, 1]]]), 2)
    with pytest.raises(InputError, match="NaN or infinite"):
        bake.bake_micromap_rows(g, np.array([[[0, 0], [1, 0], [0, np.inf]]]), 2)
    # a triangle with no UV area (on the texel row y = 1.2): without growth its micro-triangles
    # read nothing, an error; grown, each reads the texels of row 1 its x-span touches
    img = np.array([[0, 1, 2, 0], [0, 0, 1, 1], [2, 2, 2, 2], [1, 0, 1, 0]], np.uint8)
    gm = footprint_grid(img)
    flat = np.array([[[0, 0], [1, 0], [0, 1]], [[0.1, 0.3], [0.9, 0.3], [0.3, 0.3]]])
    with pytest.raises(InputError, match="UV triangle 1 has micro-triangles with no area"):
        bake.bake_micromap_rows(gm, flat, 2)
    grown = bake.bake_micromap_rows(gm, flat, 2, bake.GROW_TEXEL)
    assert grown.shape == (2, 16)
    for k, m in enumerate(birdcurve.uv_micro_triangles(flat[1], 2) * 4):
        x0, x1 = m[:, 0].min() - bake.GROW_TEXEL, m[:, 0].max() + bake.GROW_TEXEL
        row = img[1, max(int(np.floor(x0)), 0):int(np.ceil(x1))]
        assert grown[1, k] == (row[0] if np.all(row == row[0]) else states.C), k
    assert len(set(grown[1].tolist())) > 1
    with pytest.raises(InputError, match="shape"):
        bake.bake_micromap_rows(g, np.zeros((2, 4, 2)), 2)


# ---- real textures ------------------------------------------------------------------------

REAL = real_textures(min_size=64)


@needs_shared
def test_real_corpus_present():
    assert len(REAL) == 46, "the shared corpus should hold 46 textures of at least 64 px"


@needs_shared
@pytest.mark.parametrize("path", REAL, ids=lambda p: p.stem)
def test_real_textures_match_reference(path):
    tex = load_alpha(path)
    img = ref.texel_states(tex.alpha8)
    # square maps and the pair's micromaps, nearest (the corpus rule)
    for n in (16, 64):
        check_square(img, n, "nearest", "clamp")
    from omaps.pair import PAIR
    check_triangles(img, PAIR, 3, "nearest", "clamp")


@needs_shared
@pytest.mark.parametrize("path", REAL[::5], ids=lambda p: p.stem)
def test_real_textures_cutoff_linear_wrap_match_reference(path):
    tex = load_alpha(path)
    img = ref.texel_states(tex.alpha8, "cutoff", cutoff=0.25)
    check_square(img, 32, "linear", "wrap")
    from omaps.pair import PAIR
    check_triangles(img, PAIR, 2, "linear", "mirror")
