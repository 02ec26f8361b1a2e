"""Square pair maps expand into the pair's two micromaps at level log2 N without loss."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import reference as ref
from omaps import bake, pair, states
from omaps.codecs.registry import get_codec
from omaps.omm import pairs
from omaps.sampling import footprint_grid
from omaps.codecs.bits import kernel_bytes

FILTERS = ["nearest", "linear"]
WRAPS = ["clamp", "wrap", "mirror"]
state_images = st.integers(1, 9).flatmap(
    lambda w: st.integers(1, 9).flatmap(
        lambda h: arrays(np.uint8, (h, w), elements=st.sampled_from([0, 1, 2]))))


@pytest.mark.parametrize("level", range(0, 6))
def test_every_micro_triangle_lies_in_its_cell(level, rng):
    """Points spread over each micro-triangle (not only its centroid) all map to the cell
    ``micro_cells`` gives, through the pair's own hit -> cell mapping; and every cell holds
    exactly two micro-triangles: both of A below the diagonal, both of B above, one each on it."""
    n = 1 << level
    cells = np.stack([pairs.micro_cells(level), pairs.micro_cells(level, tuple(pair.B_CORNERS))])
    from omaps.birdcurve import micro_triangles

    tri = micro_triangles(level)
    w = rng.dirichlet([1, 1, 1], size=50) * 0.98 + 0.02 / 3  # strictly inside
    for t in (0, 1):
        pts = np.einsum("sk,mkd->msd", w, tri)
        for m in range(len(tri)):
            for b1, b2 in pts[m]:
                i, j = ref.hit_to_cell(t, b1, b2, n)
                assert j * n + i == cells[t, m]
    count_a = np.bincount(cells[0], minlength=n * n).reshape(n, n)
    count_b = np.bincount(cells[1], minlength=n * n).reshape(n, n)
    j, i = np.mgrid[0:n, 0:n]
    np.testing.assert_array_equal(count_a + count_b, 2)
    np.testing.assert_array_equal(count_a, np.where(i > j, 2, np.where(i == j, 1, 0)))


@settings(max_examples=60, deadline=None)
@given(state_images, st.integers(0, 5), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_square_map_is_the_merge_of_the_direct_bake(img, level, filter, wrap):
    """Corpus pair: bake_square(N) equals the cell-wise merge of the two triangles' direct
    micromaps at level log2 N (each cell = the union of its two micro-triangles)."""
    g = footprint_grid(img, filter, wrap)
    n = 1 << level
    direct = bake.bake_micromap_rows(g, pair.PAIR, level)
    np.testing.assert_array_equal(pairs.merge(direct[None])[0], bake.bake_square(g, n))


@settings(max_examples=60, deadline=None)
@given(state_images, st.integers(0, 5), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_expansion_equals_per_micro_triangle_cell_lookup(img, level, filter, wrap):
    """Expanded micromaps read, micro-triangle by micro-triangle, the cell a hit at its centroid
    reads (ref.hit_to_cell); a known micro-triangle's state is never contradicted by the direct
    bake (the expansion is the square map, exactly, and the direct bake can only know more)."""
    g = footprint_grid(img, filter, wrap)
    n = 1 << level
    sq = bake.bake_square(g, n)
    ex = pairs.expand(sq[None], *pairs.corpus_pairing(2)[:2])  # (2, 4**level): A, B
    from omaps.birdcurve import micro_triangles

    c = micro_triangles(level).mean(axis=1)
    for t in (0, 1):
        for m, (b1, b2) in enumerate(c):
            i, j = ref.hit_to_cell(t, b1, b2, n)
            assert ex[t, m] == sq[j, i]
    direct = bake.bake_micromap_rows(g, pair.PAIR, level)
    assert states.is_conservative(direct, ex)


@st.composite
def dyadic_meshes(draw):
    k = st.integers(-16, 40).map(lambda v: v / 16)
    tris = []
    for _ in range(draw(st.integers(1, 3))):
        t = np.array([[draw(k), draw(k)] for _ in range(3)])
        e1, e2 = t[1] - t[0], t[2] - t[0]
        assume(abs(e1[0] * e2[1] - e1[1] * e2[0]) > 1e-3)
        tris.append(t)
    return np.stack(tris)


def corpus_corner_uv(tris):
    """Triangles 2k (A) and 2k+1 (B) of a mesh as pairs in the corpus convention: each
    triangle's vertices (p0, p1, p2) are its square corners in ``pair.A_CORNERS`` /
    ``pair.B_CORNERS`` order, so the corner UVs (P, 6, 2) are the two triangles' UVs as listed."""
    p = (len(tris) + 1) // 2
    uv = np.zeros((p, 6, 2))
    uv[:, 0:3] = tris[0::2]
    uv[:len(tris) // 2, 3:6] = tris[1::2]
    return uv, np.arange(p) < len(tris) // 2


def _cell_polygons(tri_a, tri_b, n):
    """Independent construction: cell (i, j) of a general pair as UV polygons, each part mapped
    through its own triangle (A: b1 = u - v, b2 = v; B: b1 = u, b2 = v - u)."""
    def to_uv(tri, b1, b2):
        return tri[0] + b1 * (tri[1] - tri[0]) + b2 * (tri[2] - tri[0])

    out = {}
    for j in range(n):
        for i in range(n):
            u0, u1, v0, v1 = i / n, (i + 1) / n, j / n, (j + 1) / n
            polys = []
            if i > j:  # all in A
                polys.append(("A", [to_uv(tri_a, u - v, v) for u, v in ((u0, v0), (u1, v0), (u1, v1), (u0, v1))]))
            elif i < j:
                if tri_b is not None:
                    polys.append(("B", [to_uv(tri_b, u, v - u) for u, v in ((u0, v0), (u1, v0), (u1, v1), (u0, v1))]))
            else:  # the diagonal splits the cell: A below (v <= u), B above
                polys.append(("A", [to_uv(tri_a, u - v, v) for u, v in ((u0, v0), (u1, v0), (u1, v1))]))
                if tri_b is not None:
                    polys.append(("B", [to_uv(tri_b, u, v - u) for u, v in ((u0, v0), (u1, v1), (u0, v1))]))
            out[(i, j)] = [np.array(p) for _, p in polys]
    return out


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state_images, dyadic_meshes(), st.integers(0, 3), st.sampled_from(FILTERS), st.sampled_from(WRAPS))
def test_general_pairs_against_cell_polygons(img, tris, level, filter, wrap):
    """An arbitrary mesh's pair maps equal an independent bake of each cell as polygons mapped
    through the pair's triangles (brute-force reference), lone last triangle included."""
    g = footprint_grid(img, filter, wrap)
    n = 1 << level
    uv, has_b = corpus_corner_uv(tris)
    sq = bake.bake_pair_squares(g, uv, has_b, n)
    assert len(sq) == (len(tris) + 1) // 2
    h, w = img.shape
    texels = ref.Addressed(img, wrap, 4 + 4 * max(w, h))
    for p in range(len(sq)):
        a = tris[2 * p]
        b = tris[2 * p + 1] if 2 * p + 1 < len(tris) else None
        assert has_b[p] == (b is not None)
        for (i, j), polys in _cell_polygons(a, b, n).items():
            if not polys:
                assert sq[p, j, i] == states.C
                continue
            got = [ref.region_state(texels, poly * np.array([w, h]), filter) for poly in polys]
            want = got[0] if all(x == got[0] for x in got) else states.C
            assert sq[p, j, i] == want, (p, i, j)


def test_expand_merge_round_trip(rng):
    for level in range(0, 7):
        n = 1 << level
        sq = rng.integers(0, 3, size=(4, n, n)).astype(np.uint8)
        pair_of, corners, _ = pairs.corpus_pairing(8)
        ex = pairs.expand(sq, pair_of, corners)
        assert ex.shape == (8, 4 ** level)
        np.testing.assert_array_equal(pairs.merge(ex.reshape(4, 2, -1)), sq)


def test_codec_source_is_conservative_and_exact_after_decoding():
    """vq2 (16 x 16): the expanded micromaps are exactly the decoded map's cells and only ever
    lose knowledge against the uncompressed square map."""
    from omaps.alpha_test import StateRule
    from omaps.corpus.procedural import default_corpus

    codec = get_codec("vq2")
    for tex in default_corpus()[:3]:
        g = footprint_grid(StateRule("cutoff").classify(tex), "linear", "wrap")
        sq = bake.bake_square(g, codec.map_size)
        dec = codec.decode(codec.encode(sq, "best", "fast"))
        pair_of, corners, _ = pairs.corpus_pairing(2)
        ex = pairs.expand(dec[None], pair_of, corners)
        np.testing.assert_array_equal(pairs.merge(ex[None])[0], dec)
        assert states.is_conservative(pairs.expand(sq[None], pair_of, corners), ex)
        lookups = [codec.lookup(kernel_bytes(codec.encode(sq, "best", "fast")), i, j)
                   for j in range(16) for i in range(16)]
        np.testing.assert_array_equal(np.array(lookups).reshape(16, 16), dec)


def test_raster_and_fast_baker_agree_on_pairs(rng):
    img = rng.integers(0, 3, size=(8, 8)).astype(np.uint8)
    g = footprint_grid(img, "linear", "mirror")
    tris = rng.uniform(-0.5, 1.5, size=(5, 3, 2))
    uv, has_b = corpus_corner_uv(tris)
    assert has_b.tolist() == [True, True, False]
    sq = bake.bake_pair_squares(g, uv, has_b, 8)
    both = uv.copy()
    both[-1, 3:6] = tris[-1]  # a stand-in B for the lone triangle, baked but left out of the merge
    s, _ = bake.bake_micromaps(g, both.reshape(-1, 3, 2), 3)
    direct = s.reshape(3, 2, -1)
    direct[-1, 1] = states.C  # the lone triangle's stand-in B does not count
    merged = pairs.merge(direct, has_b)
    np.testing.assert_array_equal(sq, merged)
