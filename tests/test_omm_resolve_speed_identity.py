"""The fast opaque-fraction sampler (``coverage.micro_hits_with``: taps read without addressing
inside the texture or, on a wrap axis, one period of it, or once per region at its edge; points
counted in branch-free blocks) and the 4-state / 2-state resolve built on it give exactly what
the definition gives: ``alpha_test.sample_passes`` at every sample point of a micro-triangle,
one point at a time, and ``omaps.promotion``'s rule on that fraction."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import TEXTURES, needs_shared
from omaps import coverage, promotion
from omaps.alpha_test import AlphaTest, StateRule, sample_passes
from omaps.bake import GROW_TEXEL, bake_micromaps
from omaps import omm_format
from omaps.omm import resolve
from omaps.sampling import FILTERS, WRAP_MODES
from omaps.texture import load_alpha

SAMPLES = coverage.sample_points()
TAPS = np.empty((coverage.TAPS, coverage.TAPS))  # the kernel's scratch


def _points(corners, k):
    """Texel coordinates of a micro-triangle's 4**k sample points, one by one as documented."""
    qax, qay, qbx, qby, qcx, qcy = corners
    first = (4 ** k - 1) // 3
    for w1, w2 in SAMPLES[first:first + 4 ** k]:
        w0 = 1.0 - w1 - w2
        yield w0 * qax + w1 * qbx + w2 * qcx, w0 * qay + w1 * qby + w2 * qcy


def _reference_hits(test, corners, k):
    filt, mu, mv = test.codes()
    return sum(bool(sample_passes(test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, x, y))
               for x, y in _points(corners, k))


def _test(values, threshold, inclusive, filt, wrap_u, wrap_v):
    return AlphaTest("t", values, threshold, inclusive, filt, wrap_u, wrap_v)


@settings(max_examples=300)
@given(st.integers(1, 9), st.integers(1, 9), st.randoms(use_true_random=False), st.sampled_from(FILTERS),
       st.sampled_from(WRAP_MODES), st.sampled_from(WRAP_MODES), st.booleans(), st.booleans(),
       st.integers(0, coverage.MAX_SAMPLE_LEVEL), st.sampled_from([0.02, 0.3, 1.0, 4.0, 30.0]))
def test_hits_are_the_shaders_test_point_by_point(h, w, r, filt, wrap_u, wrap_v, inclusive, integer, k, size):
    """Any texture (integer or real values, ties on the threshold), any sampler, regions inside,
    across and outside the texture, small (one block of taps) and large (texel by texel): the
    full count is the reference's, and a count stopped early sits on the same side of any
    ``need``."""
    rng = np.random.default_rng(r.randint(0, 2 ** 32))
    if integer:
        values = rng.integers(0, 4, size=(h, w)).astype(np.uint8)  # many taps equal to the threshold
        threshold = 2.0
    else:
        values = rng.uniform(0, 1, size=(h, w))
        threshold = float(rng.uniform(0.2, 0.8))
    test = _test(values, threshold, inclusive, filt, wrap_u, wrap_v)
    c = rng.uniform(-1.5, 1.5, 2) * [w, h] + [w / 2, h / 2]
    if rng.random() < 0.3:  # periods away (a wrap axis reads the texture whole periods over)
        c += rng.integers(-4, 5, 2) * [w, h]
    corners = tuple(float(v) for v in (c + rng.uniform(-size, size, (3, 2))).ravel())
    if rng.random() < 0.2:  # on texel edges and sample-cell edges
        corners = tuple(float(np.round(v * 2) / 2) for v in corners)
    filt_c, mu, mv = test.codes()
    n = 4 ** k
    full = _reference_hits(test, corners, k)
    args = (test.value, float(test.threshold), bool(test.inclusive), filt_c, mu, mv, corners, SAMPLES, k)
    assert coverage.micro_hits_with(*args, n + 1, TAPS) == full
    for need in {1, n // 2, n // 2 + 1, n, max(1, full), full + 1, int(rng.integers(1, n + 2))}:
        if need >= 1:
            got = coverage.micro_hits_with(*args, need, TAPS)
            assert (got >= need) == (full >= need), (need, got, full)


def reference_promote(fraction, promo, threshold):
    """The documented promotion rule: whether a C region of this opaque fraction becomes O."""
    return {"opaque": True, "transparent": False, "nearest": fraction > 0.5, "hashed": fraction > threshold}[promo]


@given(st.sampled_from(promotion.PROMOTIONS), st.floats(0.0, 1.0, exclude_min=True, exclude_max=True),
       st.integers(0, coverage.MAX_SAMPLE_LEVEL), st.data())
def test_the_rule_as_a_cut_and_as_a_count(promo, threshold, k, data):
    """``promotion.promotion_cut`` (on fractions, scalar and array) and ``promotion.hits_needed``
    (on sample counts, what the resolve stops at) are the documented rule."""
    n = 4 ** k
    hits = data.draw(st.integers(0, n))
    mode = promotion.promotion_code(promo)
    want = reference_promote(hits / n, promo, threshold)
    assert (hits / n > promotion.promotion_cut(mode, threshold)) == want
    assert (hits >= promotion.hits_needed(mode, threshold, n)) == want
    assert bool(np.atleast_1d(hits / n > promotion.promotion_cut.py_func(mode, np.array([threshold])))[0]) == want
    assert promotion.resolve_regions([2], [hits / n], [[0.0, 0.0]], promo).tolist() == [
        int(reference_promote(hits / n, promo, promotion.hashed_threshold(0.0, 0.0, 0)))]


def _reference_resolve(states3, starts, level, test, tris_uv, fmt, promo, seed):
    """The documented rule, micro-triangle by micro-triangle, in Python."""
    tris = coverage.texel_triangles(test, tris_uv)
    ks = coverage.sample_levels(tris, np.full(len(tris), level))
    out = np.array(states3, copy=True)
    for t in range(len(tris)):
        for i in range(starts[t + 1] - starts[t]):
            if states3[starts[t] + i] != 2:
                continue
            q = coverage.micro_corners(tris[t], i, level)
            frac = _reference_hits(test, q, int(ks[t])) / 4 ** int(ks[t])
            cx, cy = (q[0] + q[2] + q[4]) / 3.0, (q[1] + q[3] + q[5]) / 3.0
            opaque = reference_promote(frac, promo, promotion.hashed_threshold(cx, cy, seed))
            if fmt == omm_format.FORMAT_2_STATE:
                out[starts[t] + i] = 1 if opaque else 0
            else:
                out[starts[t] + i] = 3 if opaque else 2
    return out


@pytest.mark.parametrize("filt,wrap", [("linear", "clamp"), ("linear", "mirror"), ("linear", "wrap"),
                                       ("nearest", "wrap")])
@pytest.mark.parametrize("promo", ["nearest", "hashed"])
def test_resolve_is_the_rule_on_sampled_fractions(filt, wrap, promo):
    rng = np.random.default_rng(5)
    alpha = rng.integers(0, 256, size=(12, 10)).astype(np.uint8)
    alpha[:, :3] = 0
    test = StateRule("cutoff", cutoff=0.5).alpha_test(load_alpha(alpha), filt, wrap)
    tris = rng.uniform(-0.2, 1.2, (12, 1, 2)) + rng.uniform(-0.4, 0.4, (12, 3, 2))
    tris[::3] += [2.0, -1.0]  # whole periods away
    level = 3
    states3, starts = bake_micromaps(test.grid(), tris, level, GROW_TEXEL)
    assert (states3 == 2).sum() > 50  # the rule is exercised
    for fmt in (omm_format.FORMAT_4_STATE, omm_format.FORMAT_2_STATE):
        out, counts = resolve.resolve_counted(states3, starts, level, test, tris, fmt, promo, seed=9)
        want = _reference_resolve(states3, starts, level, test, tris, fmt, promo, 9)
        np.testing.assert_array_equal(out, want)
        for t in range(len(tris)):
            s3 = states3[starts[t]:starts[t + 1]]
            o = out[starts[t]:starts[t + 1]]
            assert counts[t, :3].tolist() == np.bincount(s3, minlength=3).tolist()
            assert counts[t, 3:].tolist() == np.bincount(o[s3 == 2], minlength=4).tolist()
        # in place (the pipeline's way): the same states and counts, written over the T/O/C ones
        inplace = states3.copy()
        out2, counts2 = resolve.resolve_counted(inplace, starts, level, test, tris, fmt, promo, seed=9, out=inplace)
        assert out2 is inplace
        np.testing.assert_array_equal(out2, want)
        np.testing.assert_array_equal(counts2, counts)


@needs_shared
def test_oak_case_resolve_is_the_rule():
    """The issue's oak leaf (bilinear, clamp, cut-off 0.5, level 4, ~150-texel triangles): a
    sample of its triangles resolved as the rule says."""
    leaf = TEXTURES / "q009-vegetation__oak_oak_leaf.png"
    if not leaf.is_file():
        pytest.skip(f"{leaf} is absent")
    rng = np.random.default_rng(12)
    tris = rng.uniform(0.05, 0.95, (6, 1, 2)) + rng.uniform(-0.05, 0.05, (6, 3, 2))
    test = StateRule("cutoff", cutoff=0.5).alpha_test(load_alpha(leaf), "linear", "clamp")
    states3, starts = bake_micromaps(test.grid(), tris, 4, GROW_TEXEL)
    assert (states3 == 2).any()
    out = resolve.resolve(states3, starts, 4, test, tris, omm_format.FORMAT_4_STATE)
    np.testing.assert_array_equal(out, _reference_resolve(states3, starts, 4, test, tris,
                                                          omm_format.FORMAT_4_STATE, "nearest", 0))
