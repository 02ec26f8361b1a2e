"""Maps baked with a scene's real UVs: exact against the brute-force reference, and
conservative for the hits the tracer looks up (sampled, with the tracer's own lookups and
alpha test, including points on cell and texel boundaries)."""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import reference as ref
from omaps import states
from omaps.bake import GROW_TEXEL, bake_micromap_rows, bake_pair_flags, or_downsample
from omaps.bake.square import flags_to_states
from omaps.codecs.registry import codec_names
from omaps.pair import CORNERS
from omaps.scene import Material, Mesh, Primitive, Scene, Texture
from omaps.scene.alpha import alpha_triangles, pair_corner_uvs
from omaps.schemes import parse_schemes
from omaps.trace.lookups import clamp_bary, shader_alpha_test, state_function
from omaps.trace.maps import build_scheme_maps
from omaps.trace.tables import base_tables, scheme_tables
from omaps.trace.two_state import decoded_pair_maps

T, O, C = states.T, states.O, states.C


def pair_scene(alpha, uv_a, uv_b, filt, wrap_u, wrap_v, cutoff=0.5, b_order=(0, 1, 2), factor=1.0,
               b_material=0):
    """A scene with one pair: triangle A = (0,0,0), (1,0,0), (1,1,0) and B = (0,0,0), (1,1,0),
    (0,1,0) (listed in ``b_order``), vertices not shared so each has its own UVs. ``b_material``
    1: B is a primitive of its own with another (equal) material, so it cannot pair with A."""
    pa = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float)
    pb = np.array([[0, 0, 0], [1, 1, 0], [0, 1, 0]], float)[list(b_order)]
    ua = np.asarray(uv_a, float)
    ub = np.asarray(uv_b, float)[list(b_order)]
    mat = Material(0, "m", "MASK", cutoff, (1, 1, 1, factor), 0, filt, wrap_u, wrap_v, 0, True)
    if b_material:
        prims = [Primitive(0, 0, pa, ua, np.array([[0, 1, 2]]), 0), Primitive(0, 1, pb, ub, np.array([[0, 1, 2]]), 1)]
        mats = [mat, Material(1, "m2", "MASK", cutoff, (1, 1, 1, factor), 0, filt, wrap_u, wrap_v, 0, True)]
    else:
        prims = [Primitive(0, 0, np.concatenate([pa, pb]), np.concatenate([ua, ub]), np.array([[0, 1, 2], [3, 4, 5]]),
                           0)]
        mats = [mat]
    return Scene("memory", [Mesh(0, "pair", prims)], [(0, np.eye(4))], mats,
                 [Texture("t", np.ascontiguousarray(alpha, dtype=np.uint8))])


def scene_tests(scene, at):
    """The alpha test of every alpha-tested material the triangles use."""
    return {int(m): scene.alpha_test(int(m)) for m in np.unique(at.material)}


def texel_states_ref(alpha, cutoff, factor=1.0):
    """glTF's rule, written out: opaque iff factor * alpha / 255 >= cutoff; a texel within 1e-6
    of the cut-off is unknown (a shader's float product may fall on either side)."""
    d = factor * alpha.astype(float) / 255 - cutoff
    out = np.where(d >= 0, O, T).astype(np.uint8)
    out[np.abs(d) <= 1e-6] = C
    return out


def combine(values):
    v = np.concatenate(values)
    return T if np.all(v == T) else (O if np.all(v == O) else C)


def bilinear_state(alpha, cutoff, poly, wrap):
    """glTF's rule on a region's exact bilinear alpha range (as ``texel_states_ref``)."""
    lo, hi = ref.bilinear_extremes(alpha, wrap, wrap, list(poly))
    tol = Fraction(1, 10 ** 6)
    lo, hi = lo / 255 - Fraction(cutoff), hi / 255 - Fraction(cutoff)
    return np.array([O if lo > tol else (T if hi < -tol else C)])


def reference_square(alpha, cutoff, uv_a, uv_b, n, filt, wrap_u):
    """Square map of the pair by brute force: each cell's parts in A and B, in texture space;
    nearest: the texels they overlap; linear: the exact bilinear extremes over them."""
    st_img = texel_states_ref(alpha, cutoff)
    h, w = st_img.shape
    scale = np.array([w, h], float)
    texels = ref.Addressed(st_img, wrap_u, 64)
    out = np.empty((n, n), np.uint8)
    corner_uv = {0: uv_a, 1: uv_b}
    for j in range(n):
        for i in range(n):
            vals = []
            for tri, pts in ((0, _cell_part(i, j, n, below=True)), (1, _cell_part(i, j, n, below=False))):
                if pts is None:
                    continue
                # barycentric weights of the triangle's own vertices for each (s, t)
                q = np.array([_bary(tri, s, t) @ corner_uv[tri] for s, t in pts]) * scale
                if filt == "linear":
                    vals.append(bilinear_state(alpha, cutoff, q, wrap_u))
                    continue
                xs, ys = ref.read_texels(q, filt)
                vals.append(texels[ys, xs])
            out[j, i] = combine(vals)
    return out


def _bary(tri, s, t):
    # A = (0,0), (1,0), (1,1); B = (0,0), (1,1), (0,1) as vertex 0, 1, 2 (before b_order)
    return np.array([1 - s, s - t, t]) if tri == 0 else np.array([1 - t, s, t - s])


def _cell_part(i, j, n, below):
    s0, s1, t0, t1 = i / n, (i + 1) / n, j / n, (j + 1) / n
    rect = [(s0, t0), (s1, t0), (s1, t1), (s0, t1)]
    keep = [(s, t) for s, t in rect if (s >= t if below else t >= s)]
    if i == j:
        return [(s0, t0), (s1, t0), (s1, t1)] if below else [(s0, t0), (s1, t1), (s0, t1)]
    if (i > j) == below:
        return rect
    return None if len(keep) < 3 else keep


dyadic = st.integers(-8, 16).map(lambda k: k / 8)
uv_tri = st.lists(st.tuples(dyadic, dyadic), min_size=3, max_size=3).filter(
    lambda t: abs((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0])) > 0)
wraps = st.sampled_from(["wrap", "clamp", "mirror"])
filters = st.sampled_from(["nearest", "linear"])


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), uv_tri, uv_tri, st.sampled_from([1, 2, 4, 8]), filters, wraps)
def test_pair_square_map_matches_reference(seed, ua, ub, n, filt, wrap):
    rng = np.random.default_rng(seed)
    alpha = (rng.random((8, 8)) < 0.5).astype(np.uint8) * 255
    scene = pair_scene(alpha, ua, ub, filt, wrap, wrap)
    at = alpha_triangles(scene)
    assert at.pair_second[0] == 1 and list(at.corners[0]) == [0, 1, 2] and list(at.corners[1]) == [0, 2, 3]
    tests = scene_tests(scene, at)
    uv, has_b, mat = pair_corner_uvs(at)
    grid = tests[0].grid()
    exact = flags_to_states(bake_pair_flags(grid, uv, has_b, n, 0.0))[0]
    expect = reference_square(alpha, 0.5, np.array(ua), np.array(ub), n, filt, wrap)
    np.testing.assert_array_equal(exact, expect)
    grown = flags_to_states(bake_pair_flags(grid, uv, has_b, n, GROW_TEXEL))[0]
    assert states.is_conservative(exact, grown)
    # the tracer's stored map (grown like real geometry's) against the reference
    sm = build_scheme_maps(at, tests, parse_schemes(f"sq{n}"))[f"sq{n}"]
    traced = decoded_pair_maps(sm, at)[0]
    np.testing.assert_array_equal(traced, grown)
    assert states.is_conservative(expect, traced)


def stored_micromaps(sm, level):
    """The tracer's micromap of every alpha triangle, read from its stored rows as docs/FORMAT.md
    lays them out: micro-triangle k at bits 2*(k mod 4) of byte k div 4 of the row."""
    k = np.arange(4 ** level)
    out = np.empty((len(sm.rows), 4 ** level), np.uint8)
    for t, r in enumerate(sm.rows):
        row = sm.data[int(r) * sm.row_bytes:(int(r) + 1) * sm.row_bytes]
        out[t] = (row[k // 4] >> (2 * (k % 4))) & 3
    return out


@settings(max_examples=30)
@given(st.integers(0, 2 ** 32 - 1), uv_tri, st.sampled_from([0, 1, 2, 3]), filters, wraps)
def test_tracer_micromaps_are_the_corpus_baker_grown(seed, ua, level, filt, wrap):
    """The tracer's triL maps of a scene are the micromap baker's on the texel states written out
    here (with real geometry's growth), which only ever turn the exact states into C."""
    rng = np.random.default_rng(seed)
    alpha = rng.integers(0, 256, (8, 16)).astype(np.uint8)
    alpha[0, 0] = 102  # exactly at the cut-off 0.4: unknown
    scene = pair_scene(alpha, ua, ua, filt, wrap, wrap, cutoff=0.4)
    at = alpha_triangles(scene)
    tests = scene_tests(scene, at)
    img = texel_states_ref(alpha, 0.4)
    assert img[0, 0] == C
    np.testing.assert_array_equal(tests[0].texel_states(), img)
    sm = build_scheme_maps(at, tests, parse_schemes(f"tri{level}"))[f"tri{level}"]
    got = stored_micromaps(sm, level)
    grid = tests[0].grid()  # its texel states are the ones written out above
    np.testing.assert_array_equal(got, bake_micromap_rows(grid, at.uv, level, GROW_TEXEL))
    assert states.is_conservative(bake_micromap_rows(grid, at.uv, level), got)
    assert sm.distinct_maps == 1  # A and B have the same UVs: one map, shared


def test_coarser_maps_are_or_of_finer(rng):
    alpha = rng.integers(0, 256, (16, 16)).astype(np.uint8)
    scene = pair_scene(alpha, [[0.1, 0.2], [0.9, 0.3], [0.7, 0.95]], [[0.1, 0.2], [0.7, 0.95], [0.05, 0.8]],
                       "linear", "wrap", "clamp")
    at = alpha_triangles(scene)
    grid = scene_tests(scene, at)[0].grid()
    uv, has_b, mat = pair_corner_uvs(at)
    fine = bake_pair_flags(grid, uv, has_b, 16, GROW_TEXEL)
    for f in (2, 4, 8, 16):
        direct = bake_pair_flags(grid, uv, has_b, 16 // f, GROW_TEXEL)
        np.testing.assert_array_equal(or_downsample(fine, f), direct)


def test_lone_triangle_cells_beyond_it_are_dont_care():
    alpha = np.full((4, 4), 255, np.uint8)
    scene = pair_scene(alpha, [[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]], "nearest", "clamp", "clamp",
                       b_material=1)  # B gets another material: no pair
    at = alpha_triangles(scene)
    assert len(at.pair_first) == 2 and at.paired_fraction == 0.0
    uv, has_b, mat = pair_corner_uvs(at)
    assert has_b.tolist() == [False, False]
    tests = scene_tests(scene, at)
    s = flags_to_states(bake_pair_flags(tests[0].grid(), uv[:1], has_b[:1], 4, GROW_TEXEL))
    j, i = np.mgrid[0:4, 0:4]
    assert np.all(s[0][i >= j] == O) and np.all(s[0][i < j] == C)  # B's half unreachable
    traced = decoded_pair_maps(build_scheme_maps(at, tests, parse_schemes("sq4"))["sq4"], at)
    np.testing.assert_array_equal(traced[0], s[0])


# ---- the tracer's lookups against its alpha test ---------------------------------------------

def _points(n, corners, rng, count):
    """Barycentric (b1, b2) as float32 pairs: random, the vertices and edge midpoints, and points
    whose (s, t) lies on the map's cell boundaries (and on texel-aligned dyadic values)."""
    pts = [rng.random((count, 2))]
    pts.append(np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0, 0.5], [0.5, 0.5]]))
    sq = CORNERS[corners].astype(float)  # (3, 2) square corners of vertices 0, 1, 2
    m = np.array([sq[1] - sq[0], sq[2] - sq[0]]).T  # (s, t) = sq0 + m @ (b1, b2)
    k = rng.integers(0, 4 * n + 1, (count, 2)) / (4 * n)
    b = np.linalg.solve(m, (k - sq[0]).T).T
    pts.append(b)
    b = np.concatenate(pts)
    b = b[(b[:, 0] >= 0) & (b[:, 1] >= 0) & (b.sum(axis=1) <= 1)]
    return b.astype(np.float32)


@settings(max_examples=40)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from([(0, 1, 2), (1, 2, 0), (2, 1, 0)]), filters, wraps, wraps,
       st.sampled_from([0.25, 0.5, 0.7]), st.booleans())
@pytest.mark.long
def test_tracer_lookups_agree_with_the_alpha_test(seed, b_order, filt, wu, wv, cutoff, dyadic_uvs):
    rng = np.random.default_rng(seed)
    alpha = rng.integers(0, 256, (8, 8)).astype(np.uint8)
    alpha[rng.random((8, 8)) < 0.4] = 0
    if dyadic_uvs:  # texel-aligned: cell edges fall on texel edges
        ua = rng.integers(-8, 17, (3, 2)) / 8
        ub = np.array([ua[0], ua[2], rng.integers(-8, 17, 2) / 8])
    else:
        ua = rng.uniform(-1, 2, (3, 2))
        ub = np.array([ua[0], ua[2], rng.uniform(-1, 2, 2)])
    scene = pair_scene(alpha, ua, ub, filt, wu, wv, cutoff, b_order)
    at = alpha_triangles(scene)
    tests = scene_tests(scene, at)
    # (wavelet3's fast effort: its medium search takes seconds a scene, and the lookups are the test)
    codecs = [c + "-fast" if c == "wavelet3" else c for c in codec_names()]
    built = build_scheme_maps(at, tests, parse_schemes(["none", "sq8", "sq2", "tri2"] + codecs))
    base = base_tables(tests, len(scene.materials), at, np.zeros(1, np.int32))
    for name, sm in built.items():
        tables = scheme_tables(base, sm)
        fn = state_function(sm)
        for tri in range(2):
            n = max(sm.param, 1) if sm.kind != "micromap" else 8
            for b1, b2 in _points(n, at.corners[tri], rng, 150):
                c1, c2 = clamp_bary(b1, b2)
                s = fn(tables.table, tri, c1, c2)
                if s == C:
                    continue
                assert shader_alpha_test(tables.table, tri, c1, c2) == (s == O), (name, tri, b1, b2)
