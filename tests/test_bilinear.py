"""Exact bilinear: every baker decides a region from the extremes of the bilinear alpha over it.

Checked against tests/reference.py's exact brute force (candidate points in rational
arithmetic, not omaps' clipping): a known state never contradicts the exact extremes, and a
region the exact extremes decide with any margin is decided by omaps too. Hypothesis draws
textures with ties (alpha equal to the cut-off along texel edges), triangles anywhere (UVs far
outside [0, 1]), every wrap mode and non-power-of-two sizes."""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference as ref
from conftest import SHARED, needs_shared
from omaps import birdcurve, states
from omaps.alpha_test import AlphaTest, StateRule, material_test
from omaps.bake import bake_micromap_rows, bake_pair_squares, bake_square
from omaps.bake.micromap import GROW_TEXEL
from omaps.pair import pair_weights
from omaps.sampling import footprint_grid, sample_texture, wrap_code
from omaps.texture import AlphaTexture, load_alpha

WRAPS = ["clamp", "wrap", "mirror"]
# alphas around the corpus cut-off 127.5: 127 and 128 average to it exactly on texel edges
ALPHAS = [0, 60, 127, 128, 200, 255]
textures = st.integers(1, 7).flatmap(
    lambda w: st.integers(1, 7).flatmap(lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from(ALPHAS))))
dyadic = st.integers(-24, 40).map(lambda k: k / 16)
anyfloat = st.floats(-2.0, 3.0, allow_nan=False, allow_infinity=False)
RULES = [dict(mode="cutoff", cutoff=0.5), dict(mode="levels", t_max=60.0, o_min=200.0)]


def _test(alpha8, rule, wrap):
    kw = {k: v for k, v in rule.items() if k != "mode"}
    return StateRule(rule["mode"], **kw).alpha_test(AlphaTexture("t", alpha8, 255), "linear", wrap)


def _margin(lo, hi, rule):
    """How far the exact range is inside a decision: > 0 when T or O with room to spare."""
    if rule["mode"] == "levels":
        return max(Fraction(rule["o_min"]) - lo, hi - Fraction(rule["t_max"])) * -1
    c = Fraction(rule["cutoff"]) * 255
    return max(lo - c, c - hi)


def check_regions(alpha8, polys_texel, got, rule, wrap, slack, extremes=None):
    """Each region's state against the exact extremes: never a contradiction; known whenever the
    exact range clears the rule by more than ``slack``. ``extremes``: the regions' exact (lo, hi)
    when the caller has them (another baker's states of the same regions); returned."""
    if extremes is None:
        extremes = [ref.bilinear_extremes(alpha8, wrap, wrap, list(poly)) for poly in polys_texel]
    for poly, g, (lo, hi) in zip(polys_texel, got, extremes):
        want = ref.exact_state(lo, hi, **rule)
        if g != states.C:
            assert g == want, (poly, lo, hi, g)
        elif want != states.C:
            assert _margin(lo, hi, rule) <= slack, (poly, lo, hi, want)
    return extremes


@st.composite
def triangles(draw, coord):
    t = np.array([[draw(coord), draw(coord)] for _ in range(3)])
    e1, e2 = t[1] - t[0], t[2] - t[0]
    assume(abs(e1[0] * e2[1] - e1[1] * e2[0]) > 1e-3)
    return t


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(textures, st.one_of(triangles(dyadic), triangles(anyfloat)), st.integers(0, 3), st.sampled_from(WRAPS),
       st.sampled_from(RULES))
@pytest.mark.long
def test_micromaps_match_exact_extremes(alpha8, tri, level, wrap, rule):
    grid = _test(alpha8, rule, wrap).grid()
    h, w = alpha8.shape
    micro = birdcurve.uv_micro_triangles(tri, level) * [w, h]
    exact = bake_micromap_rows(grid, tri[None], level)[0]
    extremes = check_regions(alpha8, micro, exact, rule, wrap, Fraction(1, 10 ** 9))
    grown = bake_micromap_rows(grid, tri[None], level, GROW_TEXEL)[0]
    assert states.is_conservative(exact, grown)  # growth only ever adds C
    check_regions(alpha8, micro, grown, rule, wrap, Fraction(1, 1000), extremes)  # the same regions


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(textures, st.sampled_from([1, 2, 4, 8]), st.sampled_from(WRAPS), st.sampled_from(RULES))
def test_square_maps_match_exact_extremes(alpha8, n, wrap, rule):
    got = bake_square(_test(alpha8, rule, wrap).grid(), n)
    want = ref.bilinear_square_map(alpha8, n, wrap, **rule)
    known = got != states.C
    np.testing.assert_array_equal(got[known], want[known])
    h, w = alpha8.shape
    for j, i in zip(*np.nonzero(~known & (want != states.C))):
        x0, x1, y0, y1 = i * w / n, (i + 1) * w / n, j * h / n, (j + 1) * h / n
        lo, hi = ref.bilinear_extremes(alpha8, wrap, wrap, [[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        assert _margin(lo, hi, rule) <= Fraction(1, 10 ** 9)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(textures, st.lists(st.tuples(anyfloat, anyfloat), min_size=6, max_size=6), st.sampled_from(WRAPS))
def test_pair_squares_of_any_uvs_are_conservative_under_sampling(alpha8, uv, wrap):
    """A real pair's square (its own affine UV maps, growth): every known cell agrees with the
    shader's own bilinear fetch at points all over the cell, edges and corners included."""
    rule = RULES[0]
    test = _test(alpha8, rule, wrap)
    corner = np.array(uv)[None]
    n = 4
    got = bake_pair_squares(test.grid(), corner, np.array([True]), n, GROW_TEXEL)[0]
    h, w = alpha8.shape
    mu = mv = wrap_code(wrap)
    k = np.linspace(0, 1, 9)
    for j in range(n):
        for i in range(n):
            if got[j, i] == states.C:
                continue
            for a in k:
                for b in k:
                    s, t = (i + a) / n, (j + b) / n
                    tri = 0 if t < s or (t == s and i >= j) else 1  # a hit in A has t <= s, so i >= j
                    w0, w1, w2 = pair_weights(tri, s, t)
                    p = w0 * corner[0, 3 * tri] + w1 * corner[0, 3 * tri + 1] + w2 * corner[0, 3 * tri + 2]
                    v = sample_texture(test.value, 1, mu, mv, p[0] * w, p[1] * h)
                    assert (v > test.threshold) == (got[j, i] == states.O)


def test_a_ramp_is_known_on_each_side_of_the_cut_off():
    """alpha 0 | 255 in two texels, bilinear, clamp: the taps disagree across the middle, but
    the exact test knows every region on one side of alpha = 127.5 (x = 1 in texels). Cells are
    1/4 texel wide: cell 3 ends on x = 1 (its maximum is the cut-off: T under 'opaque iff alpha >
    127.5'), cell 4 starts there (its minimum is the cut-off: not O, so C)."""
    test = _test(np.array([[0, 255]], np.uint8), RULES[0], "clamp")
    got = bake_square(test.grid(), 8)
    assert (got[:, :4] == states.T).all() and (got[:, 4] == states.C).all() and (got[:, 5:] == states.O).all()
    ors = bake_square(footprint_grid(test.texel_states(), "linear", "clamp"), 8)  # taps only
    assert (ors[:, 2:6] == states.C).all()  # x in [0.5, 1.5]: between the two texel centres


def test_ties_on_a_texel_edge_follow_the_rule():
    """alpha 127 | 128: the bilinear alpha equals the cut-off 127.5 exactly on the line x = 1.
    Under 'opaque iff alpha > 127.5' a region ending on that line is T (its maximum is the
    cut-off), one starting on it is C (its minimum is the cut-off), one clear of it is O; with
    growth (real geometry) both tie regions are C."""
    test = _test(np.array([[127, 128]], np.uint8), RULES[0], "clamp")
    left = np.array([[[0.25, 0.1], [0.5, 0.1], [0.5, 0.9]]])  # u in [0.25, 0.5]: x in [0.5, 1]
    right = np.array([[[0.5, 0.1], [0.75, 0.1], [0.5, 0.9]]])  # x in [1, 1.5]
    clear = right + [0.125, 0.0]
    across = left + [0.125, 0.0]
    got = [bake_micromap_rows(test.grid(), t, 0)[0, 0] for t in (left, right, clear, across)]
    assert got == [states.T, states.C, states.O, states.C]
    grown = [bake_micromap_rows(test.grid(), t, 0, GROW_TEXEL)[0, 0] for t in (left, right, clear)]
    assert grown == [states.C, states.C, states.O]
    # glTF's inclusive rule (alpha >= cut-off) with its tolerance: the tie is C on both sides
    gl = material_test("m", "MASK", 127.5 / 255, 1.0, np.array([[127, 128]], np.uint8), 255, "linear", "clamp",
                       "clamp")
    assert [bake_micromap_rows(gl.grid(), t, 0)[0, 0] for t in (left, right)] == [states.C, states.C]


@pytest.mark.parametrize("wrap", WRAPS)
def test_far_outside_the_texture_and_npot(wrap, rng):
    """UVs up to +-40 texture widths on a 5 x 3 texture: the addressing of the taps, not just
    the flags, follows the wrap mode."""
    alpha8 = rng.choice(np.array(ALPHAS, np.uint8), size=(3, 5))
    rule = RULES[0]
    grid = _test(alpha8, rule, wrap).grid()
    for _ in range(6):
        c = rng.uniform(-40, 40, 2)
        tri = c + rng.uniform(-0.3, 0.3, (3, 2))
        micro = birdcurve.uv_micro_triangles(tri, 2) * [5, 3]
        got = bake_micromap_rows(grid, tri[None], 2)[0]
        check_regions(alpha8, micro, got, rule, wrap, Fraction(1, 10 ** 6))


def test_exact_is_never_less_known_than_the_taps(rng):
    """Where all the taps a region reads agree, it was known before; it stays known, the same."""
    alpha8 = rng.choice(np.array(ALPHAS, np.uint8), size=(16, 16))
    test = _test(alpha8, RULES[0], "wrap")
    tris = rng.uniform(-0.5, 1.5, (40, 3, 2))
    taps = bake_micromap_rows(footprint_grid(test.texel_states(), "linear", "wrap"), tris, 3, GROW_TEXEL)
    exact = bake_micromap_rows(test.grid(), tris, 3, GROW_TEXEL)
    assert states.is_conservative(exact, taps)
    assert (exact != states.C).sum() > (taps != states.C).sum()


def test_unknown_and_nearest_tests_are_not_refined():
    v = np.array([[0, 255]], np.uint8)
    unknown = AlphaTest("u", v, 127.5, filter="linear", rule="unknown")
    assert not unknown.grid().exact
    assert not StateRule("cutoff").alpha_test(AlphaTexture("t", v, 255), "nearest").grid().exact


@needs_shared
def test_real_leaf_against_exact_extremes(rng):
    """A real foliage mask: 30 random small triangles at level 2 against the exact reference."""
    path = SHARED / "data" / "textures" / "q009-vegetation__oak_oak_leaf.png"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    tex = load_alpha(path)
    rule = RULES[0]
    test = StateRule("cutoff").alpha_test(tex, "linear", "clamp")
    h, w = tex.alpha8.shape
    centres = rng.uniform(0.05, 0.95, (30, 1, 2))
    tris = centres + rng.uniform(-0.01, 0.01, (30, 3, 2))
    got = bake_micromap_rows(test.grid(), tris, 2, GROW_TEXEL)
    for t in range(len(tris)):
        micro = birdcurve.uv_micro_triangles(tris[t], 2) * [w, h]
        check_regions(tex.alpha8, micro, got[t], rule, "clamp", Fraction(1, 1000))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(textures, st.one_of(triangles(dyadic), triangles(anyfloat)), st.sampled_from(WRAPS))
def test_the_benchmarks_float_reference_agrees_with_the_rational_one(alpha8, tri, wrap):
    h, w = alpha8.shape
    t = tri * [w, h]
    lo, hi = ref.bilinear_extremes(alpha8, wrap, wrap, list(t))
    got = ref.bilinear_extremes_many(alpha8.astype(np.float64), wrap_code(wrap), t[None])[0]
    assert abs(got[0] - float(lo)) < 1e-9 and abs(got[1] - float(hi)) < 1e-9
