"""``trace --memory``: what each lookup reads, against a plain-Python reference of the layouts
docs/FORMAT.md states ("What a lookup reads"), over the lookups the tracer recorded."""

import json
import math
from collections import OrderedDict

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf
from omaps import birdcurve, trace
from omaps.cli import main
from omaps.codecs import succinct_decode, unpack_states
from omaps.scene import load_scene
from omaps.schemes import parse_schemes
from omaps.trace import memory
from omaps.trace.tables import T_MAP_OFFSET

LEVEL = 3
NAMES = ["none", f"tri{LEVEL}", f"succinct{LEVEL}", f"csm{LEVEL}", "succinct6", "csm6", "vq2", "vq4", "vq4x64", "sq16"]
W, H = 40, 32
CORNER_ST = {0: (0, 0), 1: (1, 0), 2: (1, 1), 3: (0, 1)}  # a corner code's place in the pair's square


@pytest.fixture(scope="module")
def palm():
    scene = load_scene(SCENES / "palm.glb")
    prep = trace.prepare(scene, parse_schemes(NAMES))
    cam = trace.Camera(np.array([-70.0, 130.0, -70.0]), np.array([0.0, 175.0, 0.0]), 70.0).basis(W, H)
    runs = {n: trace.trace_scheme(prep, n, cam, W, H) for n in NAMES}
    rec = {n: memory.record_lookups(prep, n, cam, W, H, runs[n].primary.calls) for n in NAMES if n != "none"}
    return prep, cam, runs, rec


# ---- the reference: per lookup its reads, each a list of (first byte, end byte) -------------------

def _bits_to_bytes(base, a, b):
    return (base + a // 8, base + (b - 1) // 8 + 1)


def _align(n):
    return -(-n // 64) * 64


def _bit(data, i):
    return (int(data[i // 8]) >> (i % 8)) & 1


def _field(data, pos, n):
    return sum(_bit(data, pos + b) << b for b in range(n))


def ref_reads(layout, sm, prep, tri, b1, b2):
    """The reads of one lookup, from the layouts' description alone."""
    at = prep.alpha
    if sm.kind == "micromap":
        k = int(birdcurve.bary_to_index(b1, b2, sm.param))
        if layout == "own":
            a = tri * sm.row_bytes + k // 4
            return [[(a, a + 1)]]
        idx, offs, _ = ref_standard_omm(sm)
        reads = [[(4 * tri, 4 * tri + 4)]]
        if idx[tri] < 0:
            return reads
        rec_base = _align(4 * len(sm.rows))
        data_base = rec_base + _align(8 * len(offs))
        r = idx[tri]
        return reads + [[(rec_base + 8 * r, rec_base + 8 * r + 8)], [(data_base + offs[r] + k // 4,) * 2]]
    if sm.kind == "square":
        p = int(at.pair[tri])
        bb, n = sm.codec.block_bytes, sm.codec.map_size
        w = (1 - b1 - b2, b1, b2)
        s = sum(w[j] * CORNER_ST[int(at.corners[tri][j])][0] for j in range(3))
        t = sum(w[j] * CORNER_ST[int(at.corners[tri][j])][1] for j in range(3))
        i, j = min(max(math.floor(s * n), 0), n - 1), min(max(math.floor(t * n), 0), n - 1)
        reads = []
        if layout == "own":
            a = p * bb
        else:
            reads.append([(4 * p, 4 * p + 4)])
            a = _align(4 * len(at.pair_first)) + bb * int(sm.rows[tri])
        if sm.codec.name.startswith("sq"):
            return reads + [[(a + (j * n + i) // 4,) * 2]]
        if sm.codec.name == "vq4x64":
            q = a + 64 * (2 * (j // 32) + i // 32)
            return reads + [[(q, q + 64)]]
        return reads + [[(a, a + bb)]]
    if sm.kind == "succinct":
        return ref_succinct(layout, sm, tri, b1, b2)
    return ref_csm(sm, tri, b1, b2)


_OMM = {}


def ref_standard_omm(sm):
    """Index entry per triangle (-1..-3 for uniform maps), data offset per record: records in
    order of first use over the distinct micromaps, identical ones once."""
    if id(sm) not in _OMM:
        n = len(sm.data) // sm.row_bytes
        rows = sm.data.reshape(n, sm.row_bytes)
        st = unpack_states(rows, 4 ** sm.param)
        seen, offs, per_row = {}, [], []
        for r in range(n):
            if (st[r] == st[r, 0]).all():
                per_row.append(-1 - int(st[r, 0]))
                continue
            key = rows[r].tobytes()
            if key not in seen:
                seen[key] = len(offs)
                offs.append(sm.row_bytes * len(offs))
            per_row.append(seen[key])
        _OMM[id(sm)] = (np.array(per_row)[sm.rows], offs, None)
    return _OMM[id(sm)]


def ref_succinct(layout, sm, tri, b1, b2):
    level = sm.param
    starts = sm.extra[T_MAP_OFFSET]
    sizes = np.diff(np.append(starts, len(sm.data) - 1))
    row = int(sm.rows[tri])
    at = int(starts[row]) if layout == "shared" else int(sizes[sm.rows[:tri]].sum())
    base = _align(4 * len(sm.rows)) + at
    blob = sm.data[starts[row]:]
    k = int(birdcurve.bary_to_index(b1, b2, level))
    w = ((4 ** level - 1) // 3).bit_length()
    n_t = _field(blob, 0, w)
    t0, d0 = w, w + n_t
    s0 = d0 + w * (n_t // 64)
    reads = [[(4 * tri, 4 * tri + 4)]]
    if w:
        reads.append([_bits_to_bytes(base, 0, t0 + (1 if n_t else 0))])

    def rank(i):
        return (_field(blob, d0 + w * (i // 64 - 1), w) if i >= 64 else 0) + sum(
            _bit(blob, t0 + b) for b in range(64 * (i // 64), i))

    pos = 0
    for d in range(level):
        if pos >= n_t or not _bit(blob, t0 + pos):
            break
        pos = 1 + 4 * rank(pos) + (k >> (2 * (level - 1 - d)) & 3)
        q = min(pos, n_t)
        read = []
        if t0 + min(pos + 1, n_t) > t0 + 64 * (q // 64):
            read.append(_bits_to_bytes(base, t0 + 64 * (q // 64), t0 + min(pos + 1, n_t)))
        if q >= 64:
            read.append(_bits_to_bytes(base, d0 + w * (q // 64 - 1), d0 + w * (q // 64)))
        reads.append(read)
    leaf = pos - rank(min(pos, n_t))
    reads.append([_bits_to_bytes(base, s0 + 2 * leaf, s0 + 2 * leaf + 2)])
    # the descent ends at the state decode gives
    assert _field(blob, s0 + 2 * leaf, 2) == succinct_decode(blob, level)[k]
    return reads


def ref_csm(sm, tri, b1, b2):
    level = sm.param
    data = sm.data
    k = int(birdcurve.bary_to_index(b1, b2, level))
    n = _field(data, 0, 32)
    w = (n + 2).bit_length()
    pos = 32 + w * (4 * n + tri)
    reads = [[_bits_to_bytes(0, pos, pos + w)]]
    ref = _field(data, pos, w)
    d = 0
    while ref >= 3 and d < level:
        pos = 32 + w * (4 * (ref - 3) + (k >> (2 * (level - 1 - d)) & 3))
        reads.append([_bits_to_bytes(0, pos, pos + w)])
        ref = _field(data, pos, w)
        d += 1
    return reads


def _lines(read):
    return [line for a, b in read for line in range(a // 64, (max(b, a + 1) - 1) // 64 + 1)]


def reference(layout, sm, prep, lk, cache_lines):
    """Reads per lookup, distinct lines per pixel and the tiles' LRU misses, in plain Python."""
    reads, per_pixel, accesses = [], np.zeros((lk.height, lk.width), int), {}
    for y in range(lk.height):
        for x in range(lk.width):
            p = y * lk.width + x
            seq = []
            for j in range(lk.start[p], lk.start[p + 1]):
                rr = ref_reads(layout, sm, prep, int(lk.tri[j]), float(lk.b1[j]), float(lk.b2[j]))
                reads.append(len(rr))
                for read in rr:
                    seq += _lines(read)
            per_pixel[y, x] = len(set(seq))
            accesses[(y, x)] = seq
    misses = 0
    for ty in range(0, lk.height, 8):
        for tx in range(0, lk.width, 8):
            cache = OrderedDict()
            for y in range(ty, min(ty + 8, lk.height)):
                for x in range(tx, min(tx + 8, lk.width)):
                    for line in accesses[(y, x)]:
                        if line in cache:
                            cache.move_to_end(line)
                            continue
                        misses += 1
                        cache[line] = True
                        if len(cache) > cache_lines:
                            cache.popitem(last=False)
    return np.array(reads), per_pixel, misses


@needs_scenes
@pytest.mark.parametrize("name", [n for n in NAMES if n != "none"])
def test_counts_match_a_plain_python_reference(palm, name):
    prep, _, runs, rec = palm
    lk, _ = rec[name]
    sm = prep.maps[name]
    assert lk.count == runs[name].primary.calls.sum() > 50  # every lookup the traced run made
    for layout, lay in memory.layouts(sm, prep.alpha).items():
        reads, starts, _, lines = memory.touches(lay, lk)
        ref_reads_, ref_pixels, ref_misses = reference(layout, sm, prep, lk, 4 * 1024 // 64)
        np.testing.assert_array_equal(reads, ref_reads_, err_msg=f"{name} {layout}")
        np.testing.assert_array_equal(memory.lines_per_ray(lk, starts, lines), ref_pixels, err_msg=f"{name} {layout}")
        assert memory.lru_misses(lk, starts, lines, 4) == ref_misses, (name, layout)


@needs_scenes
def test_recorded_lookups_are_the_traced_ones(palm):
    prep, _, runs, rec = palm
    for n, (lk, primary) in rec.items():
        r = runs[n].primary
        np.testing.assert_array_equal(primary.tests, r.tests)
        np.testing.assert_array_equal(primary.prim, r.prim)
        np.testing.assert_array_equal(np.diff(lk.start).reshape(H, W), r.calls)
        # lookups resolved to C are exactly the alpha tests (less repeats of one candidate)
        assert (lk.state == 2).sum() >= r.tests.sum()
    sm = prep.maps[f"tri{LEVEL}"]
    lk = rec[f"tri{LEVEL}"][0]
    st = unpack_states(sm.data.reshape(-1, sm.row_bytes), 4 ** LEVEL)
    k = np.array([birdcurve.bary_to_index(b1, b2, LEVEL) for b1, b2 in zip(lk.b1, lk.b2)])
    np.testing.assert_array_equal(lk.state, st[sm.rows[lk.tri], k])


@needs_scenes
def test_properties(palm):
    prep, cam, runs, _ = palm
    out = {n: memory.scheme_memory(prep, n, runs[n], cam, W, H, cache_kib=2) for n in NAMES}
    assert out["none"]["own"]["map_lines_per_ray"] == 0 and out["none"]["own"]["map_reads_per_lookup"] == 0
    for n, m in out.items():
        if n == "none":
            continue
        for lay in ("own", "shared"):
            r = m[lay]
            assert r["map_reads_per_lookup"] >= 1, (n, lay)
            # a read touches at most two lines (a field across a line boundary)
            assert r["map_lines_per_ray"] <= 2 * r["map_reads_per_lookup"] * m["lookups_per_primary_ray"] + 1e-9
            assert r["cache_misses_per_ray"] <= 2 * r["map_reads_per_lookup"] * m["lookups_per_primary_ray"] + 1e-9
        assert m["shared"]["map_bytes"] <= m["own"]["map_bytes"], n
    assert out["vq4"]["own"]["map_reads_per_lookup"] == 1 and out["vq4"]["shared"]["map_reads_per_lookup"] == 2
    # a pair's block stored with it: one line per lookup at most
    assert out["vq4"]["own"]["map_lines_per_ray"] <= out["vq4"]["lookups_per_primary_ray"]
    assert out[f"csm{LEVEL}"]["own"]["map_reads_per_lookup"] <= LEVEL + 1
    assert out[f"succinct{LEVEL}"]["own"]["map_reads_per_lookup"] <= LEVEL + 3
    assert out[f"tri{LEVEL}"]["shared"]["map_reads_per_lookup"] <= 3
    # a huge cache misses each tile's distinct lines once; a tiny one at least as often
    lk, _ = memory.record_lookups(prep, "vq4", cam, W, H, runs["vq4"].primary.calls)
    lay = memory.layouts(prep.maps["vq4"], prep.alpha)["shared"]
    _, starts, _, lines = memory.touches(lay, lk)
    big = memory.lru_misses(lk, starts, lines, 1 << 14)
    tiles = 0
    for ty in range(0, H, 8):
        for tx in range(0, W, 8):
            px = [y * W + x for y in range(ty, min(ty + 8, H)) for x in range(tx, min(tx + 8, W))]
            tiles += len({int(v) for p in px for v in lines[starts[lk.start[p]]:starts[lk.start[p + 1]]]})
    assert big == tiles <= memory.lru_misses(lk, starts, lines, 0.0625)


@needs_scenes
def test_cli_memory_and_frontier(tmp_path, capsys):
    j, png = tmp_path / "r.json", tmp_path / "f.png"
    assert main(["trace", str(SCENES / "palm.glb"), "--size", "32x24", "--schemes", f"none,tri{LEVEL},csm{LEVEL},vq4",
                 "--memory", "--cache-kib", "4", "--json", str(j), "--plot-frontier", str(png), "--jobs", "1",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "what a lookup reads" in out and "shared lines" in out and "own misses" in out
    assert "tex lines" in out and "own total" in out and "texture layout: RGBA8 texels" in out
    r = json.loads(j.read_text())
    for n, v in r["schemes"].items():
        assert v["differing_pixels"] == 0
        assert {"map_reads_per_lookup", "map_lines_per_ray"} <= set(v)
        assert {"map_bytes", "map_reads_per_lookup", "map_lines_per_ray", "cache_misses_per_ray",
                "total_lines_per_ray"} <= set(v["memory"]["shared"])
        mem = v["memory"]
        assert v["texture_lines_per_ray"] == mem["texture_lines_per_ray"] <= r["schemes"]["none"]["texture_lines_per_ray"]
        assert v["total_lines_per_ray"] == mem["own"]["total_lines_per_ray"]
        for lay in ("own", "shared"):
            assert mem[lay]["total_lines_per_ray"] == mem[lay]["map_lines_per_ray"] + mem["texture_lines_per_ray"]
    assert r["schemes"][f"tri{LEVEL}"]["memory"]["shared"]["layout"].startswith("standard OMMs")
    # each layout's gaps to the fronts, recomputed by brute force over the report's points
    pts = [(v["alpha_tests_per_primary_ray"], v["memory"][lay]) for n, v in r["schemes"].items() if n != "none"
           for lay in ("own", "shared")]
    for t, m in pts:
        least_bytes = min(o["map_bytes"] for u, o in pts if u <= t)
        least_lines = min(o["map_lines_per_ray"] for u, o in pts if u <= t)
        assert m["bytes_gap"] == pytest.approx(m["map_bytes"] / least_bytes) and m["bytes_gap"] >= 1
        assert m["lines_gap"] == pytest.approx(m["map_lines_per_ray"] / least_lines) and m["lines_gap"] >= 1
        assert m["both_fronts_gap"] == max(m["bytes_gap"], m["lines_gap"])
    assert min(m["bytes_gap"] for _, m in pts) == 1 and min(m["lines_gap"] for _, m in pts) == 1
    assert "bytes_gap" not in r["schemes"]["none"]["memory"]["own"]
    from PIL import Image

    assert Image.open(png).size[0] > 1000  # two panels


def test_cli_cache_needs_memory(tmp_path, capsys):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8))
    assert main(["trace", f, "--cache-kib", "8"]) == 2
    assert "--memory" in capsys.readouterr().err
