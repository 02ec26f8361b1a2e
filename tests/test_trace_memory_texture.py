"""``trace --memory``'s texture side: the 64-byte lines of alpha texture the alpha tests fetch,
against a plain-Python reference of the layout docs/FORMAT.md states ("What a lookup reads":
RGBA8 texels in 4x4 tiles, one line per tile, each texture from a line of its own, mip 0) with
the taps worked out by hand per recorded lookup."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf
from reference import _address as reference_address
from omaps import states, trace
from omaps.scene import load_scene
from omaps.schemes import parse_schemes
from omaps.trace import memory
from omaps.trace.tables import (T_MAT_FILTER, T_MAT_H, T_MAT_TEX_START, T_MAT_W, T_MAT_WRAP_U, T_MAT_WRAP_V,
                                T_TRI_MAT, T_TRI_UV)

W, H = 36, 28
SCHEMES = ["none", "tri2", "tri4", "csm4", "vq4", "sq8"]
# (magFilter, wrapS, wrapT) of the small scene's sampler: GL codes
SAMPLERS = {"linear-wrap": (9729, 10497, 10497), "nearest-clamp": (9728, 33071, 33071),
            "linear-mirror-clamp": (9729, 33648, 33071)}


# ---- the reference: taps and lines by hand --------------------------------------------------------

def ref_address(i, n, mode):
    """Texel index i on an axis of n texels: 0 wrap, 1 clamp, 2 mirror (glTF's REPEAT,
    CLAMP_TO_EDGE, MIRRORED_REPEAT), as the bilinear reference addresses its taps."""
    return reference_address(i, n, ("wrap", "clamp", "mirror")[mode])


def ref_taps(filt, mode_u, mode_v, w, h, x, y):
    """The texels a fetch at texel coordinate (x, y) reads: nearest the texel under the point,
    linear the 2x2 texels whose centres surround it."""
    if filt == 0:
        return {(ref_address(math.floor(x), w, mode_u), ref_address(math.floor(y), h, mode_v))}
    x0, y0 = math.floor(x - 0.5), math.floor(y - 0.5)
    return {(ref_address(x0 + dx, w, mode_u), ref_address(y0 + dy, h, mode_v)) for dx in (0, 1) for dy in (0, 1)}


def ref_bases(textures, used):
    """Per material its texture's first line: the distinct textures of the materials ``used``, in
    material order, each ceil(w / 4) x ceil(h / 4) lines after the one before."""
    first, seen, pos = {}, {}, 0
    for m in sorted(used):
        key = textures[m]
        if key not in seen:
            seen[key] = pos
            w, h = key[1], key[2]
            pos += -(-w // 4) * -(-h // 4)
        first[m] = seen[key]
    return first, pos * 64


def ref_lines(lk, mat, uv, tex):
    """Per pixel the set of texture lines: every lookup ending in C reads its taps; texel (x, y)
    of material m lies in line first[m] + (y // 4) * ceil(w / 4) + x // 4."""
    first, _ = ref_bases({m: t[0] for m, t in tex.items()}, {int(m) for m in mat})  # every alpha triangle's
    out = np.zeros((lk.height, lk.width), int)
    per_pixel = []
    for p in range(lk.width * lk.height):
        lines = set()
        for j in range(lk.start[p], lk.start[p + 1]):
            if lk.state[j] != states.C:
                continue
            t = int(lk.tri[j])
            m = int(mat[t])
            (_, w, h), filt, mu, mv = tex[m]
            b1, b2 = float(lk.b1[j]), float(lk.b2[j])
            w0 = 1.0 - b1 - b2
            u = w0 * uv[t, 0] + b1 * uv[t, 2] + b2 * uv[t, 4]
            v = w0 * uv[t, 1] + b1 * uv[t, 3] + b2 * uv[t, 5]
            for x, y in ref_taps(filt, mu, mv, w, h, u * w, v * h):
                lines.add(first[m] + (y // 4) * -(-w // 4) + x // 4)
        out[p // lk.width, p % lk.width] = len(lines)
        per_pixel.append(lines)
    return out, per_pixel


def tex_of(prep):
    """Per material of the small scene its (texture key, w, h), filter and wrap codes, from its
    alpha test (not from the tracer's tables)."""
    out = {}
    for m, test in prep.tests.items():
        h, w = np.asarray(test.value).shape
        f, mu, mv = test.codes()
        out[m] = ((id(test.value), w, h), f, mu, mv)
    return out


# ---- a small scene: three layers of a grid of small triangles with scattered UVs --------------------

def layered_grid(path, sampler, k=12, seed=5):
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(k, dtype=np.float32), np.arange(k, dtype=np.float32))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(k * k, np.float32)], axis=1)
    uv = (rng.random((k * k, 2)) * 1.3 - 0.15).astype(np.float32)  # past [0, 1]: the wrap modes matter
    v = np.arange(k * k).reshape(k, k)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel()
    idx = np.stack([np.stack([a, b, c], 1), np.stack([b, d, c], 1)], 1).reshape(-1)
    # 37 x 23 texels: neither side a multiple of the tile
    alpha = np.where(rng.random((23, 37)) < 0.45, 0, 255).astype(np.uint8)
    alpha[5:15, 8:30] = 255
    nodes = [{"translation": [0.3 * i, 0.2 * i, -1.5 * i]} for i in range(3)]
    mag, ws, wt = sampler
    return write_quad_gltf(str(path), alpha, positions=pos, uvs=uv, indices=idx, nodes=nodes,
                           sampler={"magFilter": mag, "wrapS": ws, "wrapT": wt})


@pytest.fixture(scope="module", params=sorted(SAMPLERS))
def small(request, tmp_path_factory):
    path = layered_grid(tmp_path_factory.mktemp("tex") / "g.gltf", SAMPLERS[request.param])
    prep = trace.prepare(load_scene(path), parse_schemes(SCHEMES))
    cam = trace.Camera(np.array([6.0, 6.0, 9.0]), np.array([6.0, 6.0, 0.0]), 50.0).basis(W, H)
    runs = {n: trace.trace_scheme(prep, n, cam, W, H) for n in SCHEMES}
    rec = {n: memory.record_lookups(prep, n, cam, W, H, runs[n].primary.calls)[0] for n in SCHEMES}
    return prep, cam, runs, rec


def _check_against_reference(prep, rec):
    tex = tex_of(prep)
    mat = prep.base[T_TRI_MAT]
    uv = np.asarray(prep.base[T_TRI_UV], np.float64).reshape(-1, 6)
    layout = memory.texture_layout(prep.base)
    _, ref_bytes = ref_bases({m: t[0] for m, t in tex.items()}, {int(m) for m in np.unique(mat)})
    assert layout.texture_bytes == ref_bytes
    out = {}
    for n, lk in rec.items():
        starts, lines = memory.texture_touches(layout, prep.base, lk)
        got = memory.lines_per_ray(lk, starts, lines)
        want, sets = ref_lines(lk, mat, uv, tex)
        np.testing.assert_array_equal(got, want, err_msg=n)
        for p, s in enumerate(sets):  # the very lines, not their count alone
            assert {int(v) for v in lines[starts[lk.start[p]]:starts[lk.start[p + 1]]]} == s, (n, p)
        assert memory.texture_lines_per_ray(layout, prep.base, lk) == pytest.approx(want.sum() / want.size)
        out[n] = sets
    return out


def test_texture_lines_match_a_plain_python_reference(small):
    prep, _, runs, rec = small
    sets = _check_against_reference(prep, rec)
    assert rec["none"].count == runs["none"].primary.calls.sum() > W * H  # several layers per ray
    # a scheme's alpha tests are some of none's, so its lines per ray are some of none's
    for n in SCHEMES:
        assert all(s <= t for s, t in zip(sets[n], sets["none"])), n
    assert sum(map(len, sets["tri4"])) < sum(map(len, sets["none"]))


def test_scheme_memory_totals(small):
    prep, cam, runs, _ = small
    out = {n: memory.scheme_memory(prep, n, runs[n], cam, W, H) for n in SCHEMES}
    none = out["none"]["texture_lines_per_ray"]
    assert none > 0
    assert out["none"]["texture_layout"].startswith("RGBA8 texels (4 bytes) in 4x4 tiles")
    for n, m in out.items():
        assert m["texture_lines_per_ray"] <= none, n
        for lay in ("own", "shared"):
            assert m[lay]["total_lines_per_ray"] == m[lay]["map_lines_per_ray"] + m["texture_lines_per_ray"]
    assert out["none"]["own"]["total_lines_per_ray"] == none
    # the same maps at the same level: the same alpha tests, the same texture lines
    assert out["tri4"]["texture_lines_per_ray"] == out["csm4"]["texture_lines_per_ray"]


@needs_scenes
def test_palm_against_the_reference():
    scene = load_scene(SCENES / "palm.glb")
    names = ["none", "tri4", "vq4"]
    prep = trace.prepare(scene, parse_schemes(names))
    cam = trace.Camera(np.array([-70.0, 130.0, -70.0]), np.array([0.0, 175.0, 0.0]), 70.0).basis(W, H)
    rec = {}
    for n in names:
        run = trace.trace_scheme(prep, n, cam, W, H)
        rec[n] = memory.record_lookups(prep, n, cam, W, H, run.primary.calls)[0]
    sets = _check_against_reference(prep, rec)
    assert sum(map(len, sets["none"])) > 50
    for n in names:
        assert all(s <= t for s, t in zip(sets[n], sets["none"])), n


# ---- the layout's arithmetic on a hand-made example ------------------------------------------------

def _base(textures, mats, tri_mat, tri_uv):
    """Tracer tables of hand-made textures ((w, h) each, laid one after another in the texel
    table), materials (texture, filter, wrap u, wrap v) and triangles (material, 6 UVs)."""
    starts, pos = [], 0
    for w, h in textures:
        starts.append(pos)
        pos += w * h
    return {T_MAT_TEX_START: np.array([starts[t] for t, *_ in mats], np.int64),
            T_MAT_W: np.array([textures[t][0] for t, *_ in mats], np.int64),
            T_MAT_H: np.array([textures[t][1] for t, *_ in mats], np.int64),
            T_MAT_FILTER: np.array([m[1] for m in mats], np.int64),
            T_MAT_WRAP_U: np.array([m[2] for m in mats], np.int64),
            T_MAT_WRAP_V: np.array([m[3] for m in mats], np.int64),
            T_TRI_MAT: np.array(tri_mat, np.int32), T_TRI_UV: np.array(tri_uv, np.float64).ravel()}


def _lookups(calls, width=1):
    """Lookups of hand-made filter calls: per pixel a list of (triangle, state); barycentrics
    (0, 0), so the hit is the triangle's vertex 0 exactly."""
    start = np.concatenate([[0], np.cumsum([len(c) for c in calls])]).astype(np.int64)
    flat = [c for cs in calls for c in cs]
    tri = np.array([t for t, _ in flat], np.int64)
    zeros = np.zeros(len(flat), np.float64)
    return memory.Lookups(start, tri, zeros, zeros.copy(), np.array([s for _, s in flat], np.uint8), width,
                          len(calls) // width)


def test_layout_arithmetic_by_hand():
    # texture 0: 10 x 6 texels, 3 x 2 tiles (lines 0..5, the last column and row of tiles padded);
    # texture 1: 5 x 5, 2 x 2 tiles (lines 6..9); material 2 reads texture 0 again (no new lines)
    base = _base([(10, 6), (5, 5)],
                 [(0, 0, 1, 1), (1, 1, 0, 0), (0, 1, 1, 1), (0, 1, 2, 2)],
                 [0, 1, 2, 2, 3, 0],
                 [[0.75, 0.5] * 3,  # t0, material 0 nearest: texel (7, 3): tile (1, 0), line 1
                  [0.01, 0.99] * 3,  # t1, material 1 linear wrap at (0.05, 4.95): taps x 4, 0; y 4, 0
                  [0.75, 0.5] * 3,  # t2, material 2 linear clamp at (7.5, 3): taps x 7, 8; y 2, 3
                  [0.99, 0.99] * 3,  # t3: at (9.9, 5.94): taps x 9, 9 (clamped); y 5, 5: line 5
                  [0.01, 0.01] * 3,  # t4, material 3 linear mirror at (0.1, 0.06): taps x 0, 0; y 0, 0
                  [0.5, 0.9] * 3])  # t5, material 0 nearest at (5, 5.4): texel (5, 5): tile (1, 1), line 4
    lay = memory.texture_layout(base)
    assert lay.first_line.tolist() == [0, 6, 0, 0] and lay.tiles_x.tolist() == [3, 2, 3, 3]
    assert lay.texture_bytes == (6 + 4) * 64
    c = states.C
    # pixel 0: t0; pixel 1: t1 (texture 1: tiles (1, 1), (0, 1), (1, 0), (0, 0)); pixel 2: t2 and t3;
    # pixel 3: t4 and t5 O and T (decided: no fetch); pixel 4: t5 twice (one line); pixel 5: nothing
    lk = _lookups([[(0, c)], [(1, c)], [(2, c), (3, c)], [(4, c), (5, states.O), (0, states.T)],
                   [(5, c), (5, c)], []], width=3)
    starts, lines = memory.texture_touches(lay, base, lk)
    per = [sorted({int(v) for v in lines[starts[lk.start[p]]:starts[lk.start[p + 1]]]}) for p in range(6)]
    assert per == [[1], [6, 7, 8, 9], [1, 2, 5], [0], [4], []]
    np.testing.assert_array_equal(memory.lines_per_ray(lk, starts, lines), [[1, 4, 3], [1, 1, 0]])
    assert memory.texture_lines_per_ray(lay, base, lk) == 10 / 6
    # every lookup decided: no texture line at all
    lk.state[:] = states.O
    assert memory.texture_lines_per_ray(lay, base, lk) == 0


# ---- properties over random textures, samplers, hits and states ---------------------------------

@settings(max_examples=60, deadline=None)
@given(st.data())
def test_texture_lines_properties(data):
    n_tex = data.draw(st.integers(1, 3))
    textures = [(data.draw(st.integers(1, 13)), data.draw(st.integers(1, 13))) for _ in range(n_tex)]
    mats = [(data.draw(st.integers(0, n_tex - 1)), data.draw(st.integers(0, 1)), data.draw(st.integers(0, 2)),
             data.draw(st.integers(0, 2))) for _ in range(data.draw(st.integers(1, 4)))]
    n_tri = data.draw(st.integers(1, 6))
    coord = st.floats(-2.0, 3.0, allow_nan=False)
    tri_mat = [data.draw(st.integers(0, len(mats) - 1)) for _ in range(n_tri)]
    tri_uv = [[data.draw(coord) for _ in range(6)] for _ in range(n_tri)]
    base = _base(textures, mats, tri_mat, tri_uv)
    n_pix = data.draw(st.integers(1, 6))
    calls = [[data.draw(st.integers(0, n_tri - 1)) for _ in range(data.draw(st.integers(0, 4)))] for _ in range(n_pix)]
    n = sum(map(len, calls))
    bary = st.floats(0.0, 1.0, allow_nan=False)
    b = np.array([data.draw(st.tuples(bary, bary)) for _ in range(n)], np.float64).reshape(-1, 2)
    over = b.sum(axis=1) > 1  # onto the triangle, as the filter clamps them
    b[over] /= b.sum(axis=1)[over, None]
    decided = np.array([data.draw(st.booleans()) for _ in range(n)], bool)
    lk = _lookups([[(t, states.C) for t in cs] for cs in calls], width=n_pix)
    lk.b1[:], lk.b2[:] = b[:, 0], b[:, 1]
    lay = memory.texture_layout(base)
    tex = {m: ((t, *textures[t]), f, mu, mv) for m, (t, f, mu, mv) in enumerate(mats)}
    uv = np.array(tri_uv, np.float64)
    starts, lines = memory.texture_touches(lay, base, lk)
    every = memory.lines_per_ray(lk, starts, lines)
    want, sets_all = ref_lines(lk, base[T_TRI_MAT], uv, tex)
    np.testing.assert_array_equal(every, want)
    # a line lies inside the textures' lines; a ray with an alpha test reads at least one line, at
    # most four per test
    assert (lines >= 0).all() and (lines < lay.texture_bytes // 64).all()
    counts = np.diff(lk.start).reshape(every.shape)
    assert ((every >= (counts > 0)) & (every <= 4 * counts)).all()
    # a map only removes alpha tests: the decided lookups' lines go, never come
    lk.state[decided] = states.O
    s2, l2 = memory.texture_touches(lay, base, lk)
    some = memory.lines_per_ray(lk, s2, l2)
    assert (some <= every).all()
    _, sets_some = ref_lines(lk, base[T_TRI_MAT], uv, tex)
    assert all(a <= c for a, c in zip(sets_some, sets_all))
    lk.state[:] = states.T
    assert memory.texture_lines_per_ray(lay, base, lk) == 0
