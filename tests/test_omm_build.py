"""OMM buffers: packing, special indices, reuse, promotion, files, and an independent read-back
checked against the baker and the texture."""

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import omm_decoder
import reference as ref
import omaps.rows
from omaps import birdcurve, promotion, states
from omaps.alpha_test import AlphaTest, StateRule
from omaps.bake import GROW_TEXEL, bake_micromap_rows, bake_micromaps, bake_square, dynamic_levels
from omaps.coverage import cell_fractions, micro_fractions
from omaps.errors import InputError
from omaps.omm import files, resolve
from omaps import omm_format
from omaps.omm.pipeline import Geometry, OmmSettings, build
from omaps.texture import AlphaTexture


def _alpha(rng, h=16, w=16):
    a = rng.integers(0, 256, size=(h, w)).astype(np.uint8)
    a[:, : w // 3] = 0
    a[: h // 4, :] = 255
    return AlphaTexture("t", a, 255)


def _cutoff(tex, cutoff, filter="nearest", wrap="clamp"):
    """omaps' cutoff rule: opaque iff alpha8 > cutoff * 255."""
    return StateRule("cutoff", cutoff=cutoff).alpha_test(tex, filter, wrap)


def _tris(rng, n=24):
    c = rng.uniform(0.1, 0.9, size=(n, 1, 2))
    return c + rng.uniform(-0.15, 0.15, size=(n, 3, 2))


# ---- packing -------------------------------------------------------------------------------

@given(st.integers(0, 4), st.sampled_from([1, 2]), st.integers(1, 3), st.randoms())
def test_pack_unpack_round_trip(level, fmt, m, r):
    hi = 3 if fmt == 2 else 1
    s = np.array([[r.randint(0, hi) for _ in range(4 ** level)] for _ in range(m)], dtype=np.uint8)
    p = omm_format.pack(s, fmt)
    assert p.shape == (m, omm_format.micromap_bytes(level, fmt))
    np.testing.assert_array_equal(omm_format.unpack(p, level, fmt), s)


def test_bit_positions_as_documented():
    s = np.zeros((1, 16), dtype=np.uint8)
    s[0, 5] = 3  # micro-triangle 5: byte 1, bits 2-3
    s[0, 0] = 2
    assert omm_format.pack(s, 2)[0].tolist() == [0b10, 0b1100, 0, 0]
    s2 = np.zeros((1, 16), dtype=np.uint8)
    s2[0, 9] = 1  # 2-state: byte 1, bit 1
    assert omm_format.pack(s2, 1)[0].tolist() == [0, 2]
    assert [omm_format.micromap_bytes(lv, 1) for lv in range(4)] == [1, 1, 2, 8]
    assert [omm_format.micromap_bytes(lv, 2) for lv in range(4)] == [1, 1, 4, 16]


# ---- special indices, reuse ----------------------------------------------------------------

def test_special_indices_and_reuse(rng):
    a = np.zeros((8, 8), dtype=np.uint8)
    a[:, 4:] = 255
    tex = AlphaTexture("half", a, 255)
    test = _cutoff(tex, 0.5)
    left = np.array([[0.05, 0.05], [0.4, 0.05], [0.05, 0.4]])  # all T
    right = left + [0.55, 0]  # all O
    straddle = np.array([[0.3, 0.1], [0.7, 0.1], [0.5, 0.6]])
    tris = np.stack([left, right, straddle, straddle, left])
    res = build([Geometry("g", test, tris)], OmmSettings(level=3))
    assert res.index.tolist()[:2] == [-1, -2] and res.index[4] == -1
    assert res.index[2] == res.index[3] == 0 and len(res.triangles) == 1
    st_ = res.summary["statistics"]
    assert (st_["micromaps_without_reuse"], st_["micromaps_after_special_indices"], st_["micromaps"]) == (5, 2, 1)
    no_dedup = build([Geometry("g", test, tris)], OmmSettings(level=3, dedup=False))
    assert no_dedup.index.tolist() == [-1, -2, 0, 1, -1]
    plain = build([Geometry("g", test, tris)], OmmSettings(level=3, special=False, dedup=False))
    assert plain.index.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(plain.micromap_states(0), 0)
    np.testing.assert_array_equal(plain.micromap_states(1), 1)
    assert res.usage == {"micromap_array": [{"count": 1, "subdivisionLevel": 3, "format": 2}],
                         "geometry": [{"count": 2, "subdivisionLevel": 3, "format": 2}]}
    # fully unknown triangle -> -3 / -4 by promotion
    ones = AlphaTest("u", np.ones((2, 2)), 0.5, True, rule="unknown")
    r2 = build([Geometry("u", ones, tris[:1])], OmmSettings(level=2, promotion="opaque"))
    r3 = build([Geometry("u", ones, tris[:1])], OmmSettings(level=2, promotion="transparent"))
    assert (r2.index[0], r3.index[0]) == (-4, -3)


@pytest.mark.parametrize("chunk", [None, 150])
def test_reuse_survives_hash_collisions(rng, monkeypatch, chunk):
    """Reuse finds identical micromaps by a 64-bit hash and then compares their bytes: with every
    hash forced equal (all collide) the buffers are those of a byte-keyed reuse, and every stored
    micromap is distinct."""
    from omaps.omm import pipeline

    tex = _alpha(rng, 32, 32)
    tris = np.concatenate([_tris(rng, 20)] * 3)  # each triangle three times
    test = _cutoff(tex, 0.5, "linear", "wrap")
    if chunk:
        monkeypatch.setattr(pipeline, "CHUNK_MICRO_TRIANGLES", chunk)
    whole = build([Geometry("g", test, tris)], OmmSettings(level=3))
    monkeypatch.setattr(omaps.rows, "row_hashes", lambda packed: np.zeros(len(packed), np.uint64))
    clash = build([Geometry("g", test, tris)], OmmSettings(level=3))
    for k in ("data", "triangles", "index"):
        np.testing.assert_array_equal(getattr(clash, k), getattr(whole, k))
    stored = [clash.micromap_states(i).tobytes() for i in range(len(clash.triangles))]
    assert len(set(stored)) == len(stored) and 1 < len(stored) <= 20  # hashes did collide
    np.testing.assert_array_equal(whole.index[:20], whole.index[20:40])


def test_packer_data_views_outlive_later_micromaps(rng):
    """``Packer.data`` is the packer's own bytes, not a copy: a view taken earlier keeps what it
    showed while micromaps are added (the data moves on to a buffer of its own), the records
    point into the latest data, and reuse still finds the earlier micromaps."""
    packer = omm_format.Packer()
    rows = rng.integers(0, 4, (6, 16)).astype(np.uint8)
    packer.add(rows[:3], 2)
    early = packer.data()
    shown = early.copy()
    ids = packer.add(np.concatenate([rows[3:], rows[:3]]), 2)
    np.testing.assert_array_equal(early, shown)
    data, rec = packer.data(), packer.record_array()
    assert ids[3:].tolist() == [0, 1, 2] and len(rec) == 6 and len(data) == 6 * 4
    for i in range(6):
        raw = data[rec["data_offset"][i]:rec["data_offset"][i] + 4]
        np.testing.assert_array_equal(omm_format.unpack(raw[None], 2, 2)[0], rows[i])
    del early
    packer.add(rows[:1] ^ 1, 2)  # grows in place again
    assert len(packer.data()) == 7 * 4 and packer.data()[:24].tolist() == data.tolist()


# ---- promotion -----------------------------------------------------------------------------

def test_fractions_agree_with_known_states(rng):
    """A T micro-triangle never has a passing sample, an O one never a failing one (the
    baker's conservativeness seen from the alpha test itself), for both filters and all wraps."""
    tex = _alpha(rng)
    tris = _tris(rng, 12) * 1.5 - 0.25
    for filter in ("nearest", "linear"):
        for wrap in ("clamp", "wrap", "mirror"):
            test = _cutoff(tex, 0.5, filter, wrap)
            for grow in (0.0, GROW_TEXEL):
                s, starts = bake_micromaps(test.grid(), tris, 3, grow)
                f = micro_fractions(test, tris, 3, starts)
                assert np.all(f[s == states.T] == 0) and np.all(f[s == states.O] == 1)
                assert (s == states.C).any()


def test_promotion_rules(rng):
    tex = _alpha(rng)
    test = _cutoff(tex, 0.5, "linear", "wrap")
    tris = _tris(rng)
    s, starts = bake_micromaps(test.grid(), tris, 4, GROW_TEXEL)
    f = micro_fractions(test, tris, 4, starts)
    c = s == states.C
    for fmt in (1, 2):
        out = {m: resolve.resolve(s, starts, 4, test, tris, fmt, m) for m in promotion.PROMOTIONS}
        base = 0 if fmt == 1 else 2
        for m, o in out.items():
            np.testing.assert_array_equal(o[~c], s[~c])  # T and O unchanged
        assert np.all(out["opaque"][c] == base + 1) and np.all(out["transparent"][c] == base)
        np.testing.assert_array_equal(out["nearest"][c] == base + 1, f[c] > 0.5)
        h = out["hashed"][c] == base + 1
        assert np.all(h[f[c] == 0] == 0) and np.all(h[f[c] == 1] == 1)
        # unbiased: the opaque share of C regions follows their mean opaque fraction
        assert abs(h.mean() - f[c].mean()) < 4 * np.sqrt(0.25 / c.sum())


def test_hashed_threshold_is_uniform_and_spatial():
    xs = np.random.default_rng(5).uniform(-100, 100, size=(20000, 2))
    h = np.array([promotion.hashed_threshold(x, y, 7) for x, y in xs])
    assert np.all((h > 0) & (h < 1))
    assert abs(h.mean() - 0.5) < 0.01 and abs((h < 0.25).mean() - 0.25) < 0.015
    assert promotion.hashed_threshold(3.2, 1.7, 7) == promotion.hashed_threshold(3.2 + 1e-4, 1.7, 7)
    assert promotion.hashed_threshold(3.2, 1.7, 7) != promotion.hashed_threshold(3.2, 1.7, 8)


def test_micro_vertices_follow_the_bird_curve():
    for level in range(0, 4):
        want = birdcurve.micro_triangles(level)
        for k in range(4 ** level):
            np.testing.assert_array_equal(np.array(birdcurve.micro_vertices(k, level)), want[k])


# ---- files: independent read-back ----------------------------------------------------------

def _check_against_baker_and_texture(folder, tex, tris, level, filter, wrap, cutoff, fmt, rng):
    """Read with the independent decoder; every micro-triangle must equal the baker's state with
    real geometry's growth (4-state: T/O exactly, C as 2/3); growth only ever turns the exact
    states into C, and on a subset the exact states are the brute-force reference's from the
    texture itself (nearest: a known state only where every texel it can read agrees; bilinear:
    from the exact extremes of the bilinear alpha)."""
    per_tri = omm_decoder.triangle_states(folder)
    grid = _cutoff(tex, cutoff, filter, wrap).grid()
    baked = bake_micromap_rows(grid, tris, level, GROW_TEXEL)
    exact = bake_micromap_rows(grid, tris, level)
    assert states.is_conservative(exact, baked)
    img = ref.texel_states(tex.alpha8, "cutoff", cutoff=cutoff)
    for t, (lv, got) in enumerate(per_tri):
        got = np.array(got if lv is not None else got * 4 ** level)
        want = baked[t]
        known = want != states.C
        np.testing.assert_array_equal(got[known], want[known])
        if fmt == 2:
            assert np.all(got[~known] >= 2)
        if t < 3:
            micro = birdcurve.uv_micro_triangles(tris[t], level)
            truth = ref.triangle_states(img, tris[t], level, filter, wrap) if filter == "nearest" else None
            for k in rng.choice(4 ** level, 40, replace=False):
                if truth is not None:
                    r = truth[tuple(sorted(map(tuple, np.round(micro[k], 12))))]
                else:  # bilinear: the exact extremes over the micro-triangle
                    lo, hi = ref.bilinear_extremes(tex.alpha8, wrap, wrap, list(micro[k] * tex.alpha8.shape[::-1]))
                    r = ref.exact_state(lo, hi, "cutoff", cutoff=cutoff)
                assert r == exact[t, k]


@pytest.mark.parametrize("fmt,filter,wrap", [("4state", "nearest", "clamp"), ("4state", "linear", "wrap"),
                                             ("2state", "linear", "mirror")])
def test_written_files_read_back_independently(tmp_path, rng, fmt, filter, wrap):
    tex = _alpha(rng, 12, 20)
    tris = _tris(rng)
    tris[1] = tris[0]  # a duplicate, to exercise reuse
    test = _cutoff(tex, 0.4, filter, wrap)
    res = build([Geometry("g", test, tris)], OmmSettings(format=fmt, level=3))
    files.write(tmp_path / "omm", res)
    folder = tmp_path / "omm"
    _check_against_baker_and_texture(folder, tex, tris, 3, filter, wrap, 0.4, omm_format.FORMAT_NAMES[fmt], rng)
    arr, geo = omm_decoder.usage_counts(folder)
    usage = json.loads((folder / "omm_usage.json").read_text())
    assert {(e["subdivisionLevel"], e["format"]): e["count"] for e in usage["micromap_array"]} == arr
    assert {(e["subdivisionLevel"], e["format"]): e["count"] for e in usage["geometry"]} == geo
    back = files.read(folder)
    np.testing.assert_array_equal(back.index, res.index)
    _, records, index, summary, _ = omm_decoder.read_folder(folder)
    assert index[0] == index[1]
    assert summary["statistics"]["triangles"] == len(tris)
    assert all(r[2] == omm_format.FORMAT_NAMES[fmt] for r in records)


def test_dynamic_levels_in_files(tmp_path, rng):
    tex = _alpha(rng, 32, 32)
    tris = _tris(rng, 10) * np.linspace(0.2, 1, 10)[:, None, None]
    test = _cutoff(tex, 0.5)
    res = build([Geometry("g", test, tris)], OmmSettings(dynamic_scale=1.0, max_level=5, special=False,
                                                         dedup=False))
    files.write(tmp_path / "o", res)
    per = omm_decoder.triangle_states(tmp_path / "o")
    want = dynamic_levels(tris, 32, 32, 1.0, 5)
    assert [lv for lv, _ in per] == want.tolist() and len(set(want.tolist())) > 1
    for t, (lv, s) in enumerate(per):
        baked = bake_micromap_rows(test.grid(), tris[t:t + 1], lv, GROW_TEXEL)[0]
        np.testing.assert_array_equal(np.array(s)[baked != 2], baked[baked != 2])


def test_writer_is_all_or_nothing(tmp_path, rng, monkeypatch):
    tex = _alpha(rng)
    res = build([Geometry("g", _cutoff(tex, 0.5), _tris(rng, 4))], OmmSettings(level=2))
    files.write(tmp_path / "o", res)
    before = sorted(os.listdir(tmp_path / "o"))
    calls = []

    real_open = open

    def failing_open(path, mode="r", *a, **k):
        calls.append(path)
        if "w" in mode and str(path).endswith("omm_index.bin"):
            raise OSError(28, "No space left on device")
        return real_open(path, mode, *a, **k)

    monkeypatch.setattr("builtins.open", failing_open)
    with pytest.raises(OSError):
        files.write(tmp_path / "o", res)
    with pytest.raises(OSError):
        files.write(tmp_path / "new", res)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path / "o")) == before  # the earlier output is intact
    assert not (tmp_path / "new").exists()
    assert [p for p in os.listdir(tmp_path) if p.startswith(".omaps")] == []
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "keep.txt").write_text("x")
    with pytest.raises(InputError, match="holds no omm.json"):
        files.write(tmp_path / "other", res)


def test_reader_rejects_broken_folders(tmp_path, rng):
    tex = _alpha(rng)
    res = build([Geometry("g", _cutoff(tex, 0.5), _tris(rng, 6))], OmmSettings(level=3))
    cases = {
        "omm_triangles.bin": (lambda b: b[:-3], "multiple of the 8-byte record"),
        "omm_data.bin": (lambda b: b[:-1], "reads bytes up to"),
        "omm_index.bin": (lambda b: b[:4] + np.int32(99).tobytes() + b[8:], "has index 99"),
        "omm_usage.json": (lambda b: b.replace(b'"count": ', b'"count": 1'), "usage counts"),
        "omm.json": (lambda b: b[:10], "not valid JSON"),
    }
    for name, (damage, msg) in cases.items():
        d = tmp_path / name.replace(".", "_")
        files.write(d, res)
        p = d / name
        p.write_bytes(damage(p.read_bytes()))
        with pytest.raises(InputError, match=msg) as e:
            files.read(d)
        assert name in str(e.value)
    files.write(tmp_path / "ok", res)
    os.remove(tmp_path / "ok" / "omm_data.bin")
    with pytest.raises(InputError, match="missing"):
        files.read(tmp_path / "ok")


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31), st.sampled_from(["nearest", "linear"]), st.sampled_from(["clamp", "wrap", "mirror"]),
       st.integers(0, 4), st.sampled_from(["4state", "2state"]))
def test_buffers_decode_to_the_baked_states(seed, filter, wrap, level, fmt):
    rng = np.random.default_rng(seed)
    tex = _alpha(rng, int(rng.integers(2, 12)), int(rng.integers(2, 12)))
    tris = _tris(rng, 6) * 2 - 0.5
    test = _cutoff(tex, 0.5, filter, wrap)
    res = build([Geometry("g", test, tris)], OmmSettings(format=fmt, level=level, promotion="hashed"))
    baked = bake_micromap_rows(test.grid(), tris, level, GROW_TEXEL)
    assert states.is_conservative(bake_micromap_rows(test.grid(), tris, level), baked)
    for t in range(len(tris)):
        got = np.broadcast_to(res.triangle_states(t), (4 ** level,))
        known = baked[t] != states.C
        np.testing.assert_array_equal(got[known], baked[t][known])


def test_resolve_regions_matches_the_micromap_resolution(rng):
    """The tracer's 2-state mode over any regions gives what 2-state OMM output holds."""
    tex = _alpha(rng)
    test = _cutoff(tex, 0.5, "linear", "wrap")
    tris = _tris(rng, 6)
    s, starts = bake_micromaps(test.grid(), tris, 3, GROW_TEXEL)
    f = micro_fractions(test, tris, 3, starts)
    cen = np.concatenate([birdcurve.uv_micro_triangles(t, 3).mean(axis=1) for t in tris]) * [16, 16]
    for m in promotion.PROMOTIONS:
        want = resolve.resolve(s, starts, 3, test, tris, omm_format.FORMAT_2_STATE, m, seed=3)
        np.testing.assert_array_equal(promotion.resolve_regions(s, f, cen, m, seed=3), want)


def test_square_fractions(rng):
    """The corpus pair's square cells: a known cell's fraction agrees with its state, the centre
    is the cell's, and (nearest) the fraction is the share of the cell's K x K points whose texel
    passes the test, counted here from the alpha values."""
    from omaps.coverage import CELL_SAMPLES
    from omaps.pair import PAIR_CORNER_UV

    tex = _alpha(rng)
    test = _cutoff(tex, 0.5, "linear", "clamp")
    f, c = cell_fractions(test, PAIR_CORNER_UV, np.ones(1, bool), 8)
    f, c = f[0], c[0]
    sq = bake_square(test.grid(), 8)
    assert np.all(f[sq == states.T] == 0) and np.all(f[sq == states.O] == 1)
    assert 0 < f[sq == states.C].mean() < 1
    j, i = np.mgrid[0:8, 0:8]
    np.testing.assert_allclose(c[..., 0], (i + 0.5) * 2, atol=1e-9)  # the cell centre
    np.testing.assert_allclose(c[..., 1], (j + 0.5) * 2, atol=1e-9)
    two = promotion.resolve_regions(sq, f, c, "nearest")
    np.testing.assert_array_equal(two[sq != states.C], sq[sq != states.C])
    np.testing.assert_array_equal(two[sq == states.C], f[sq == states.C] > 0.5)
    # nearest: point (s, t) of the corpus pair reads texel (floor(16 s), floor(16 t)), never on an edge
    f_near, _ = cell_fractions(_cutoff(tex, 0.5), PAIR_CORNER_UV, np.ones(1, bool), 8)
    k = CELL_SAMPLES
    offs = (np.arange(k) + 0.5) / k
    for jj in range(8):
        for ii in range(8):
            xs = np.floor((ii + offs) / 8 * 16).astype(int)
            ys = np.floor((jj + offs) / 8 * 16).astype(int)
            want = np.mean(tex.alpha8[np.ix_(ys, xs)] > 0.5 * 255)
            assert f_near[0, jj, ii] == pytest.approx(want), (ii, jj)


@pytest.mark.parametrize("source,dynamic", [("texture", None), ("texture", 1.0), ("sq4", None), ("vq2", None)])
def test_chunked_baking_gives_the_same_buffers(rng, monkeypatch, source, dynamic):
    """Large inputs are baked a chunk of triangles at a time (pairs never split): the buffers
    must not depend on where the chunks fall."""
    from omaps.omm import pipeline

    tex = _alpha(rng, 32, 32)
    tris = _tris(rng, 13) * np.linspace(0.3, 1, 13)[:, None, None]
    test = _cutoff(tex, 0.5, "linear", "wrap")
    s = OmmSettings(level=3, dynamic_scale=dynamic, max_level=4, source=source, effort="fast")
    whole = build([Geometry("g", test, tris)], s)
    monkeypatch.setattr(pipeline, "CHUNK_MICRO_TRIANGLES", 150)
    parts = build([Geometry("g", test, tris)], s)
    for k in ("data", "triangles", "index"):
        np.testing.assert_array_equal(getattr(parts, k), getattr(whole, k))
    assert parts.pair_blocks == whole.pair_blocks
    a, b = parts.summary["statistics"], whole.summary["statistics"]
    assert a.pop("known_area_fraction") == pytest.approx(b.pop("known_area_fraction"), rel=1e-12)
    assert a == b, {k: (a[k], b[k]) for k in a if a[k] != b[k]}


def test_records_follow_the_documented_order(rng):
    """FORMAT.md, "Order": records come in the order the pack stage first meets each micromap,
    the triangles visited by the 16 x 16-texel tile of their centroid along a Morton curve, input
    order within a tile (computed here from that statement, not with omaps' function)."""
    tris = _tris(rng, 300)
    res = build([Geometry("g", _cutoff(_alpha(rng, 256, 256), 0.5, "linear"), tris)], OmmSettings(level=3))

    def morton(x, y):
        return sum(((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1) for b in range(8))

    tile = np.clip(np.floor(tris.mean(axis=1) * 256 / 16), 0, 15).astype(int)  # 16 tiles of 16 texels per side
    visit = sorted(range(len(tris)), key=lambda t: (morton(*tile[t]), t))
    used = [int(i) for i in res.index[visit] if i >= 0]
    assert len(res.triangles) > 20
    assert list(dict.fromkeys(used)) == list(range(len(res.triangles)))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["4state", "2state"]), st.booleans(), st.booleans(),
       st.sampled_from(["nearest", "hashed"]))
def test_repeated_triangles_are_baked_once_with_the_same_result(seed, fmt, dynamic, with_unknown, promote):
    """Identical triangles (UVs, level, unknown flag) are baked and resolved once: the buffers and
    statistics are what baking every triangle gives (the search for repeats switched off)."""
    rng = np.random.default_rng(seed)
    base = _tris(rng, 12)
    tris = base[rng.integers(0, len(base), 40)]  # repeats, in any order
    unknown = rng.random(len(tris)) < 0.2 if with_unknown else None
    test = _cutoff(_alpha(rng), 0.5, "linear")
    s = OmmSettings(format=fmt, level=3, dynamic_scale=1.5 if dynamic else None, max_level=4, promotion=promote)
    got = build([Geometry("g", test, tris, unknown=unknown)], s)
    with pytest.MonkeyPatch.context() as mp:  # every triangle its own: no reuse of a bake
        mp.setattr(omaps.rows, "first_occurrences", lambda r: (np.arange(len(r)), np.arange(len(r))))
        want = build([Geometry("g", test, tris, unknown=unknown)], s)
    np.testing.assert_array_equal(got.index, want.index)
    np.testing.assert_array_equal(got.data, want.data)
    np.testing.assert_array_equal(got.triangles, want.triangles)
    a, b = got.summary["statistics"], want.summary["statistics"]
    assert a.pop("known_area_fraction") == pytest.approx(b.pop("known_area_fraction"), rel=1e-12)
    assert a == b and got.usage == want.usage


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 30), st.integers(1, 300), st.integers(0, 3), st.data())
def test_uniform_rows_are_the_rows_of_one_state(n, k, state, data):
    """``format.uniform_rows`` (special indices) against numpy: a row is uniform iff every entry
    equals its first; rows with one entry changed anywhere are not."""
    rows = np.full((n, k), state, np.uint8)
    for i in range(n):
        if data.draw(st.booleans()):
            rows[i, data.draw(st.integers(0, k - 1))] = data.draw(st.integers(0, 3))
    np.testing.assert_array_equal(omm_format.uniform_rows(rows), (rows == rows[:, :1]).all(axis=1))
