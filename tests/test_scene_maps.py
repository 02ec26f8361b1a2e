"""Maps baked with a scene's real UVs: exact against the brute-force reference, and
conservative for the hits the tracer looks up (sampled, with the tracer's own lookups and
alpha test, including points on cell and texel boundaries)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import reference as ref
from omaps import maps, scene_maps, states, trace
from omaps.codecs.registry import codec_names
from omaps.pairing import CORNERS
from omaps.sampling import footprint_grid
from omaps.scene import Material, Mesh, Scene, Texture

T, O, C = states.T, states.O, states.C


def pair_scene(alpha, uv_a, uv_b, filt, wrap_u, wrap_v, cutoff=0.5, b_order=(0, 1, 2), factor=1.0):
    """A scene with one pair: triangle A = (0,0,0), (1,0,0), (1,1,0) and B = (0,0,0), (1,1,0),
    (0,1,0) (listed in ``b_order``), vertices not shared so each has its own UVs."""
    pa = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], np.float32)
    pb = np.array([[0, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)[list(b_order)]
    pos = np.concatenate([pa, pb])
    uvs = np.concatenate([np.asarray(uv_a, float), np.asarray(uv_b, float)[list(b_order)]])
    mesh = Mesh("pair", pos, uvs, np.array([[0, 1, 2], [3, 4, 5]], np.int32), np.zeros(2, np.int32))
    rgba = np.zeros(alpha.shape + (4,), np.uint8)
    rgba[..., 3] = alpha
    mat = Material("m", "MASK", cutoff, (1, 1, 1, factor), 0, filt, wrap_u, wrap_v, True)
    return Scene("memory", [mesh], [(0, np.eye(4))], [mat], [Texture("t", rgba)])


def texel_states_ref(alpha, cutoff, factor=1.0):
    """glTF's rule, written out: opaque iff factor * alpha / 255 >= cutoff."""
    return np.where(factor * alpha.astype(float) / 255 >= cutoff, O, T).astype(np.uint8)


def combine(values):
    v = np.concatenate(values)
    return T if np.all(v == T) else (O if np.all(v == O) else C)


def reference_square(st_img, uv_a, uv_b, n, filt, wrap_u):
    """Square map of the pair by brute force: each cell's parts in A and B, in texture space."""
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
    at = scene_maps.alpha_triangles(scene)
    assert at.pair_second[0] == 1 and list(at.corners[0]) == [0, 1, 2] and list(at.corners[1]) == [0, 2, 3]
    gt = scene_maps.grid_table(scene)
    uv, has_b, mat = scene_maps.pair_corner_uvs(at)
    exact = scene_maps.flags_to_states(scene_maps.bake_square_flags(uv, has_b, mat, gt, n, eps=0.0))[0]
    expect = reference_square(texel_states_ref(alpha, 0.5), np.array(ua), np.array(ub), n, filt, wrap)
    np.testing.assert_array_equal(exact, expect)
    grown = scene_maps.flags_to_states(scene_maps.bake_square_flags(uv, has_b, mat, gt, n))[0]
    assert states.is_conservative(exact, grown)


@settings(max_examples=30)
@given(st.integers(0, 2 ** 32 - 1), uv_tri, st.sampled_from([0, 1, 2, 3]), filters, wraps)
def test_micromaps_without_growth_equal_the_corpus_baker(seed, ua, level, filt, wrap):
    rng = np.random.default_rng(seed)
    alpha = rng.integers(0, 256, (8, 16)).astype(np.uint8)
    scene = pair_scene(alpha, ua, ua, filt, wrap, wrap, cutoff=0.4)
    at = scene_maps.alpha_triangles(scene)
    gt = scene_maps.grid_table(scene)
    got = scene_maps.flags_to_states(scene_maps.bake_micro_flags(at.uv, at.material, gt, level, eps=0.0))
    grid = footprint_grid(texel_states_ref(alpha, 0.4), filt, wrap)
    np.testing.assert_array_equal(got, maps.bake_triangles(grid, at.uv, level))


def test_coarser_maps_are_or_of_finer(rng):
    alpha = rng.integers(0, 256, (16, 16)).astype(np.uint8)
    scene = pair_scene(alpha, [[0.1, 0.2], [0.9, 0.3], [0.7, 0.95]], [[0.1, 0.2], [0.7, 0.95], [0.05, 0.8]],
                       "linear", "wrap", "clamp")
    at = scene_maps.alpha_triangles(scene)
    gt = scene_maps.grid_table(scene)
    uv, has_b, mat = scene_maps.pair_corner_uvs(at)
    fine = scene_maps.bake_square_flags(uv, has_b, mat, gt, 16)
    for f in (2, 4, 8, 16):
        direct = scene_maps.bake_square_flags(uv, has_b, mat, gt, 16 // f)
        np.testing.assert_array_equal(scene_maps.or_downsample(fine, f), direct)


def test_lone_triangle_cells_beyond_it_are_dont_care():
    alpha = np.full((4, 4), 255, np.uint8)
    scene = pair_scene(alpha, [[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]], "nearest", "clamp", "clamp")
    scene.meshes[0].material[1] = 1  # B gets another material: no pair
    scene.materials.append(scene.materials[0])
    at = scene_maps.alpha_triangles(scene)
    assert len(at.pair_first) == 2 and at.paired_fraction == 0.0
    uv, has_b, mat = scene_maps.pair_corner_uvs(at)
    s = scene_maps.flags_to_states(scene_maps.bake_square_flags(uv, has_b, mat, scene_maps.grid_table(scene), 4))
    j, i = np.mgrid[0:4, 0:4]
    assert np.all(s[0][i >= j] == O) and np.all(s[0][i < j] == C)  # B's half unreachable


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
    at = scene_maps.alpha_triangles(scene)
    gt = scene_maps.grid_table(scene)
    built = scene_maps.build_scheme_maps(at, gt, ["none", "sq8", "sq2", "tri2"] + codec_names())
    base = trace.base_tables(scene, at, np.zeros(1, np.int32))
    for name, sm in built.items():
        tables = trace.scheme_tables(base, sm)
        fn = trace.state_function(sm)
        for tri in range(2):
            n = max(sm.param, 1) if sm.kind != "tri" else 8
            for b1, b2 in _points(n, at.corners[tri], rng, 150):
                c1, c2 = trace.clamp_bary(b1, b2)
                s = fn(tables.table, tri, c1, c2)
                if s == C:
                    continue
                assert trace.alpha_test(tables.table, tri, c1, c2) == (s == O), (name, tri, b1, b2)
