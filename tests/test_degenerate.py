"""Zero-UV-area triangles (common in real assets): their footprint is a segment or a point, and
every baker, codec, ``--from``, 2-state and ``--dynamic`` bakes them from the texels they touch
-- never from stand-in UVs, never aborting the bake -- and the tracer still sees nothing change."""

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import omm_decoder
from gltf_files import write_quad_gltf
from omaps import states
from omaps.alpha_test import StateRule
from omaps.bake import GROW_TEXEL, bake_micromap_rows, bake_pair_squares
from omaps.birdcurve import uv_micro_triangles
from omaps.cli.main import main
from omaps.codecs import get_codec
from omaps.pair import pair_weights
from omaps.sampling import sample_texture, wrap_code
from omaps.texture import AlphaTexture

N = 6  # vertices per side of the grid mesh


def degenerate_grid():
    """A (N-1)^2-quad grid in z = 0 whose UVs collapse: rows 2 and 3 share their v (a strip of
    zero-area triangles, footprints are segments), and four vertices around one quad share one UV
    (footprints are points). Returns positions, uvs, indices and the degenerate triangles."""
    xs, ys = np.meshgrid(np.arange(N), np.arange(N))
    pos = np.stack([xs.ravel(), ys.ravel(), np.zeros(N * N)], axis=1).astype(np.float32)
    u = xs.ravel() / (N - 1)
    v = 1 - ys.ravel() / (N - 1)
    v[ys.ravel() == 3] = v[ys.ravel() == 2][0]
    uv = np.stack([u, v], axis=1)
    for x, y in ((3, 4), (4, 4), (3, 5), (4, 5)):
        uv[y * N + x] = [0.61, 0.17]
    idx = []
    for y in range(N - 1):
        for x in range(N - 1):
            a, b, c, d = y * N + x, y * N + x + 1, (y + 1) * N + x + 1, (y + 1) * N + x
            idx += [a, b, c, a, c, d]
    idx = np.array(idx, np.uint16)
    t = uv[idx.reshape(-1, 3)]
    area = np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0]))
    return pos, uv.astype(np.float32), idx, np.flatnonzero(area == 0)


def alpha_image(seed=3, size=24):
    rng = np.random.default_rng(seed)
    a = np.where(rng.random((size, size)) < 0.5, 0, 255).astype(np.uint8)
    a[:8] = 255
    return a


@pytest.fixture
def scene(tmp_path):
    pos, uv, idx, deg = degenerate_grid()
    assert len(deg) >= 10
    path = write_quad_gltf(tmp_path / "grid.gltf", alpha_image(), positions=pos, uvs=uv, indices=idx)
    return path, deg


@pytest.mark.parametrize("args", [["--level", "3"], ["--from", "vq4"], ["--from", "vq2"], ["--from", "vq4x64"],
                                  ["--from", "sq16"], ["--format", "2state"], ["--from", "vq4", "--format", "2state"],
                                  ["--dynamic", "1", "--max-level", "9"]])
def test_omm_of_degenerate_uvs_verifies(scene, tmp_path, args):
    """``--verify`` re-bakes every micro-triangle from the scene and checks every known state
    against the alpha test; with ``--dynamic`` a zero-area triangle gets level 0."""
    path, deg = scene
    out = tmp_path / "omm"
    assert main(["omm", str(path), "-o", str(out), *args, "--quiet"]) == 0
    assert main(["omm", "--verify", str(out)]) == 0
    if "--dynamic" in args:
        per = omm_decoder.triangle_states(out)
        for t in deg:
            lv, st_ = per[t]
            assert lv in (None, 0), (t, lv)  # a special index or level 0
        s = json.loads((out / "omm.json").read_text())
        assert max(int(k) for k in s["statistics"]["levels"]) <= 9


@pytest.mark.long
def test_trace_of_degenerate_uvs_changes_nothing(scene, tmp_path):
    path, _ = scene
    rc = main(["trace", str(path), "--schemes", "none,tri3,sq16,vq2,vq4,vq4x64", "--size", "48", "--shadows",
               "--camera", "2.5,2.5,6:2.5,2.5,0:60", "--json", str(tmp_path / "t.json"), "--quiet"])
    assert rc == 0
    r = json.loads((tmp_path / "t.json").read_text())
    assert r["passed"]


# ---- the bakers on degenerate triangles and needles, against the shader's own fetch -------------

ALPHAS = [0, 100, 127, 128, 200, 255]
coords = st.floats(-1.5, 2.5, allow_nan=False, allow_infinity=False)


@st.composite
def degenerate_triangles(draw):
    """A point, a segment (two equal corners or three collinear), or a needle (area ~1e-9)."""
    p = np.array([draw(coords), draw(coords)])
    q = np.array([draw(coords), draw(coords)])
    kind = draw(st.sampled_from(["point", "twin", "collinear", "needle"]))
    if kind == "point":
        return np.array([p, p, p])
    if kind == "twin":
        return np.array([p, q, q] if draw(st.booleans()) else [p, p, q])
    f = draw(st.floats(0.0, 1.0))
    r = p + f * (q - p)
    if kind == "needle":
        r = r + draw(st.floats(-1e-9, 1e-9)) * np.array([q[1] - p[1], p[0] - q[0]])
    return np.array([p, q, r])


def _fetch_agrees(test, uv, state):
    """The shader's fetch at a UV point agrees with a known state."""
    h, w = test.value.shape
    mu, mv = wrap_code(test.wrap_u), wrap_code(test.wrap_v)
    v = sample_texture(test.value, 1 if test.filter == "linear" else 0, mu, mv, uv[0] * w, uv[1] * h)
    return state == states.C or (v > test.threshold) == (state == states.O)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(1, 6).flatmap(lambda w: st.integers(1, 6).flatmap(
           lambda h: st.lists(st.sampled_from(ALPHAS), min_size=w * h, max_size=w * h).map(
               lambda a: np.array(a, np.uint8).reshape(h, w)))),
       degenerate_triangles(), st.integers(0, 3), st.sampled_from(["nearest", "linear"]),
       st.sampled_from(["clamp", "wrap", "mirror"]))
def test_degenerate_micromaps_agree_with_the_shader_along_them(alpha8, tri, level, filt, wrap):
    """Every micro-triangle of a degenerate or needle triangle (with real geometry's growth)
    reads something, and a known one agrees with the shader's fetch at points all along it."""
    test = StateRule("cutoff").alpha_test(AlphaTexture("t", alpha8, 255), filt, wrap)
    got = bake_micromap_rows(test.grid(), tri[None], level, GROW_TEXEL)[0]
    micro = uv_micro_triangles(tri, level)
    ws = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0], [0, 0.5, 0.5],
                   [0.5, 0, 0.5], [0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]])
    for k in range(len(micro)):
        for wt in ws:
            assert _fetch_agrees(test, wt @ micro[k], got[k])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(degenerate_triangles(), degenerate_triangles(), st.sampled_from(["vq2", "vq4", "vq4x64", "sq16"]),
       st.sampled_from(["nearest", "linear"]))
def test_degenerate_pairs_through_every_codec_are_conservative(ta, tb, codec, filt):
    """A pair of degenerate triangles: its square map, encoded and decoded by every codec, keeps
    only states the shader's fetch agrees with."""
    alpha8 = alpha_image(5, 8)
    test = StateRule("cutoff").alpha_test(AlphaTexture("t", alpha8, 255), filt, "wrap")
    c = get_codec(codec)
    n = c.map_size
    corner = np.concatenate([ta[[0, 1, 2]], tb[[0, 2, 1]]])[None]  # A at (0,0),(1,0),(1,1); B at (0,0),(1,1),(0,1)
    sq = bake_pair_squares(test.grid(), corner, np.array([True]), n, GROW_TEXEL)
    _, dec = c.encode_many(sq)  # checked conservative inside too
    assert states.is_conservative(sq, dec)
    for j in range(0, n, max(1, n // 8)):
        for i in range(0, n, max(1, n // 8)):
            for a in (0.0, 0.5, 1.0):
                s, t = (i + a) / n, (j + 0.5) / n
                tri = 0 if t < s or (t == s and i >= j) else 1
                w = np.array(pair_weights(tri, s, t))
                uv = w @ corner[0, 3 * tri:3 * tri + 3]
                assert _fetch_agrees(test, uv, dec[0, j, i])


def test_verify_checks_known_states_against_the_alpha_test(scene, tmp_path):
    """The alpha-test check of ``--verify`` on its own: a known state flipped in the buffers (T
    <-> O) is caught by the shader's own test at points of the micro-triangle, re-bake aside."""
    from omaps.omm import files
    from omaps.omm.inputs import load_geometries
    from omaps.omm.verify import _check_known_states

    path, _ = scene
    out = tmp_path / "omm"
    assert main(["omm", str(path), "-o", str(out), "--level", "2", "--no-special", "--no-dedup", "--quiet"]) == 0
    res = files.read(out)
    geoms, _, _ = load_geometries(res.summary["input"])
    assert _check_known_states(res, geoms) == []
    raw = np.unpackbits(res.data[:, None], axis=1, bitorder="little").reshape(-1, 2)
    st_ = raw[:, 0] + 2 * raw[:, 1]
    k = int(np.flatnonzero(st_ < 2)[0])
    st_[k] ^= 1  # T <-> O
    bits = np.stack([st_ & 1, st_ >> 1], axis=1).astype(np.uint8).reshape(-1, 8)
    res.data[:] = np.packbits(bits, axis=1, bitorder="little").ravel()
    problems = _check_known_states(res, geoms)
    assert len(problems) == 1 and "contradicted by the alpha test" in problems[0]
