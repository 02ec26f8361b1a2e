"""``EXT_meshopt_compression``: the decoders (``omaps.scene.meshopt``) against the specification's
own worked examples and against meshoptimizer's C library (zeux's encoder and decoder, through
the ``meshoptimizer`` package), fuzzed; the palm with its vertex and index views compressed reads
and traces as the plain palm; what omaps writes from such a file it reads back; broken streams
are errors naming the file and the bufferView."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import SCENES, needs_scenes
from gltf_files import MESHOPT, glb_parts, meshoptify_glb, with_indices, write_glb_parts
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.scene import load_scene
from omaps.scene.meshopt import (MeshoptError, apply_filter, decode_attributes, decode_indices, decode_triangles,
                                 decode_view)

mo = pytest.importorskip("meshoptimizer", reason="meshoptimizer's C library (the reference codec) is not installed")
mo.encode_vertex_version(0)  # EXT_meshopt_compression's attribute codec
mo.encode_index_version(1)  # its triangle codec (header 0xe1)
SETTINGS = dict(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _zigzag(d: int) -> int:
    return (d << 1) & 0xFF if d >= 0 else ((~d) << 1 | 1) & 0xFF


# -- the specification's examples ---------------------------------------------------------------

def test_the_specifications_4_bit_sentinel_example():
    """Appendix A's example: 10 bytes of 4-bit deltas with two sentinels decode to the 16 deltas
    the text lists; built here into a stream of 16 elements of 4 bytes (the other 3 byte lanes
    all-zero groups), baseline 0x10 0 0 0 at the end of the 32-byte tail."""
    group = bytes([0x17, 0x5F, 0xF0, 0xBC, 0x77, 0xA9, 0x21, 0x00, 0x34, 0xB5])
    deltas = [-1, -4, -3, 26, -91, 0, -6, 6, -4, -4, 5, -5, 1, -1, 0, 0]
    stream = bytes([0xA0, 0b10]) + group + bytes([0, 0, 0]) + bytes(28) + bytes([0x10, 0, 0, 0])
    out = decode_attributes(stream, 16, 4).reshape(16, 4)
    assert out[:, 0].tolist() == [int(v) & 0xFF for v in 0x10 + np.cumsum(deltas)]
    assert not out[:, 1:].any()


def test_the_specifications_index_codes():
    """Mode 2 by its text: varint-7 values, the low bit choosing one of two baselines, the next
    bit a zigzag sign; a two-byte varint (0x81 0x04 = 0x201) included."""
    values = [(0, 5), (1, 100), (0, -2), (1, 0x201 >> 2), (0, 0)]  # (baseline, delta)
    stream = bytearray([0xD1])
    expected, last = [], [0, 0]
    for base, d in values:
        v = (((d << 1) if d >= 0 else ((~d) << 1 | 1)) << 1) | base
        while v >= 0x80:
            stream.append(0x80 | (v & 0x7F))
            v >>= 7
        stream.append(v)
        last[base] += d
        expected.append(last[base])
    got = decode_indices(bytes(stream) + bytes(4), len(values), 4)
    assert got.tolist() == expected


def test_the_triangle_codes_by_hand():
    """Mode 1 by its text: 0xf0 with a code table entry 0x00 (three new vertices), then 0x00
    (edge 0 and a new vertex), then 0x01 (edge 0 and vertex FIFO entry 1), then 0xfe with data
    byte 0xff and a varint (a = next, b and c explicit)."""
    aux = bytes(16)
    codes = bytes([0xF0, 0x00, 0x01, 0xFE])
    data = bytes([0xFF, 2 << 1, 1 << 1])  # b = last + 2 = 2, c = last + 1 = 3
    got = decode_triangles(bytes([0xE1]) + codes + data + aux, 12, 4).reshape(4, 3).tolist()
    # 1: (0, 1, 2); edges pushed (1,0), (2,1), (0,2): edge 0 is (0, 2)
    # 2: edge (0, 2) + next 3 -> (0, 2, 3); pushes (3, 2), (0, 3): edge 0 is (0, 3)
    # 3: edge (0, 3) + vertex FIFO 1 (the vertex pushed before 3: 2) -> (0, 3, 2)
    # 4: a = next 4, b = last + 2 = 2, c = b + 1 = 3
    assert got == [[0, 1, 2], [0, 2, 3], [0, 3, 2], [4, 2, 3]]


# -- against meshoptimizer's C library ----------------------------------------------------------

@settings(**SETTINGS)
@given(st.integers(1, 16).map(lambda k: 4 * k), st.integers(0, 700), st.integers(0, 2 ** 32 - 1),
       st.sampled_from(["random", "smooth", "constant"]))
def test_attributes_round_trip_through_the_reference_encoder(stride, count, seed, kind):
    rng = np.random.default_rng(seed)
    if kind == "random":
        data = rng.integers(0, 256, (count, stride), dtype=np.uint8)
    elif kind == "smooth":  # the small deltas the 2- and 4-bit groups hold, and their sentinels
        data = np.cumsum(rng.integers(-3, 4, (count, stride)), axis=0).astype(np.uint8)
    else:
        data = np.tile(rng.integers(0, 256, stride, dtype=np.uint8), (count, 1))
    enc = mo.encode_vertex_buffer(data, count, stride)
    assert enc[0] == 0xA0
    np.testing.assert_array_equal(decode_attributes(enc, count, stride), data.ravel())


@settings(**SETTINGS)
@given(st.integers(1, 400), st.integers(3, 3000), st.integers(0, 2 ** 32 - 1), st.sampled_from([2, 4]))
def test_triangles_decode_as_the_reference_decoder(ntri, nvert, seed, size):
    rng = np.random.default_rng(seed)
    nvert = min(nvert, 65535 if size == 2 else nvert)
    local = rng.random() < 0.5  # strip-like runs (edge and vertex FIFO hits) or scattered triangles
    base = np.minimum(np.arange(ntri) // 2, nvert - 3) if local else rng.integers(0, nvert - 2, ntri)
    tri = (base[:, None] + rng.permutation(3)[None, :] + rng.integers(0, 2, (ntri, 1))).clip(0, nvert - 1)
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])].astype(np.uint32)
    enc = mo.encode_index_buffer(tri.ravel(), tri.size, nvert)
    ref = np.asarray(mo.decode_index_buffer(tri.size, 4, enc), np.uint32).ravel()
    got = decode_triangles(enc, tri.size, size)
    np.testing.assert_array_equal(got, ref)
    # the same triangles, each maybe rotated (its winding kept)
    key = lambda t: sorted(tuple(np.roll(r, -int(np.argmin(r)))) for r in t)  # noqa: E731
    assert key(got.reshape(-1, 3)) == key(tri)


@settings(**SETTINGS)
@given(st.lists(st.integers(0, 70000), max_size=500), st.sampled_from([2, 4]))
def test_index_sequences_round_trip(values, size):
    idx = (np.array(values, np.int64) % (65536 if size == 2 else 1 << 32)).astype(np.uint32)
    enc = mo.encode_index_sequence(idx, len(idx), int(idx.max()) + 1 if len(idx) else 1)
    np.testing.assert_array_equal(decode_indices(enc, len(idx), size), idx)


@settings(**SETTINGS)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 300))
def test_filters_agree_with_the_reference_decoder(seed, n):
    """Octahedral and quaternion results within one unit of the C decoder's (the specification's
    tolerance), exponential exactly; each over valid inputs of every precision K."""
    rng = np.random.default_rng(seed)
    for stride, dt, kmax in ((4, np.int8, 8), (8, np.int16, 16)):
        one = (1 << (rng.integers(4, kmax + 1, n) - 1)) - 1
        a = np.stack([rng.integers(-one, one + 1), rng.integers(-one, one + 1), one,
                      rng.integers(-100, 100, n)], 1).astype(dt)
        ref = np.asarray(mo.decode_filter_oct(a.copy().view(np.uint8).ravel(), n, stride)).view(dt).reshape(n, 4)
        got = apply_filter(a.view(np.uint8).ravel(), n, stride, "OCTAHEDRAL").view(dt).reshape(n, 4)
        assert np.abs(ref.astype(int) - got.astype(int)).max() <= 1
        assert np.array_equal(ref[:, 3], got[:, 3])
    one = (1 << (rng.integers(4, 17, n) - 1)) - 1
    q = np.stack([rng.integers(-one, one + 1) for _ in range(3)] + [(one & ~3) | rng.integers(0, 4, n)], 1)
    q = q.astype(np.int16)
    ref = np.asarray(mo.decode_filter_quat(q.copy().view(np.uint8).ravel(), n, 8)).view(np.int16).reshape(n, 4)
    got = apply_filter(q.view(np.uint8).ravel(), n, 8, "QUATERNION").view(np.int16).reshape(n, 4)
    assert np.abs(ref.astype(int) - got.astype(int)).max() <= 1
    e, m = rng.integers(-100, 101, n), rng.integers(-(1 << 23), 1 << 23, n)
    x = ((e << 24) | (m & 0xFFFFFF)).astype(np.int64).astype(np.uint32).view(np.int32)
    ref = np.asarray(mo.decode_filter_exp(x.copy().view(np.uint8).ravel(), n, 4)).view(np.float32)
    got = apply_filter(x.view(np.uint8).ravel(), n, 4, "EXPONENTIAL").view(np.float32)
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(got, (m * 2.0 ** e).astype(np.float32))


def _reference(decode, *args):
    """The C decoder's bytes (4-byte indices; attributes as its float32 default, viewed as
    bytes), None when it refuses the stream."""
    try:
        return np.asarray(decode(*args)).view(np.uint8).ravel()
    except (RuntimeError, ValueError):
        return None


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(["ATTRIBUTES", "TRIANGLES", "INDICES"]),
       st.lists(st.tuples(st.integers(0, 10 ** 6), st.integers(0, 255)), max_size=6),
       st.integers(-40, 40))
def test_fuzzed_streams_fail_cleanly_or_decode_as_the_reference(seed, mode, flips, resize):
    """A valid stream with bytes changed and its end cut or extended: each decoder raises
    ``MeshoptError`` or gives exactly what the C decoder gives (never another exception; a stream
    omaps accepts, the C decoder accepts too)."""
    rng = np.random.default_rng(seed)
    if mode == "ATTRIBUTES":
        stride, count = 4 * int(rng.integers(1, 5)), int(rng.integers(0, 80))
        enc = mo.encode_vertex_buffer(np.cumsum(rng.integers(-9, 10, (count, stride)), 0).astype(np.uint8),
                                      count, stride)
    else:
        count = 3 * int(rng.integers(0, 60))
        tri = np.minimum(np.arange(count) // 3 + np.tile([0, 1, 2], count // 3), 200).astype(np.uint32)
        tri = (np.arange(count, dtype=np.uint32) // 2) if mode == "INDICES" else tri
        enc = (mo.encode_index_buffer(tri, count, 210) if mode == "TRIANGLES"
               else mo.encode_index_sequence(tri, count, 210))
    raw = bytearray(enc)
    for at, value in flips:
        if raw:
            raw[at % len(raw)] = value
    raw = raw[:max(0, len(raw) + resize)] if resize < 0 else raw + bytes(rng.integers(0, 256, resize, np.uint8))
    raw = bytes(raw)
    try:
        if mode == "ATTRIBUTES":
            got, ref = decode_attributes(raw, count, stride), _reference(mo.decode_vertex_buffer, count, stride, raw)
        elif mode == "TRIANGLES":
            got, ref = decode_triangles(raw, count, 4), _reference(mo.decode_index_buffer, count, 4, raw)
        else:
            got, ref = decode_indices(raw, count, 4), _reference(mo.decode_index_sequence, count, 4, raw)
    except MeshoptError:
        return
    assert ref is not None
    np.testing.assert_array_equal(got.view(np.uint8).ravel(), ref)


@pytest.mark.parametrize("ext, said", [
    ({"mode": "ATTRIBUTES", "byteStride": 6, "count": 2}, "not a multiple of 4 up to 256"),
    ({"mode": "TRIANGLES", "byteStride": 4, "count": 2}, "not a multiple of 3"),
    ({"mode": "INDICES", "byteStride": 1, "count": 8}, "not 2 or 4"),
    ({"mode": "TRIANGLES", "byteStride": 4, "count": 3, "filter": "OCTAHEDRAL"}, "only allowed with mode ATTRIBUTES"),
    ({"mode": "ATTRIBUTES", "byteStride": 12, "count": 1, "filter": "QUATERNION"}, "not 8, as QUATERNION needs"),
    ({"mode": "POINTS", "byteStride": 4, "count": 3}, "mode is 'POINTS'"),
    ({"mode": "ATTRIBUTES", "byteStride": 4, "count": True}, "count is True"),
])
def test_extension_objects_that_break_its_rules_are_refused(ext, said):
    n = ext["byteStride"] * ext["count"] if isinstance(ext["count"], int) else 4
    with pytest.raises(MeshoptError, match=said):
        decode_view(bytes(64), ext, int(n), None)


def test_the_later_attribute_codec_is_named_when_refused():
    with pytest.raises(MeshoptError, match="version 1 .*KHR_meshopt_compression"):
        decode_attributes(bytes([0xA1]) + bytes(40), 1, 4)


# -- in glTF files ------------------------------------------------------------------------------

def _trace(tmp_path, path, name, size="64"):
    out = tmp_path / f"{name}.json"
    assert main(["trace", str(path), "--schemes", "none,sq16,tri3,vq4", "--size", size, "--quiet",
                 "--json", str(out)]) == 0
    return json.loads(out.read_text())


def _same_figures(x, y):
    assert x["scene"]["triangles"] == y["scene"]["triangles"] and x["passed"] and y["passed"]
    for s in ("none", "sq16", "tri3", "vq4"):
        a, b = x["schemes"][s], y["schemes"][s]
        assert a["differing_pixels"] == 0
        assert a["alpha_tests_per_primary_ray"] == b["alpha_tests_per_primary_ray"], s


@needs_scenes
@pytest.mark.parametrize("fallback", [None, b"\x7f"], ids=["required", "used-with-fallback"])
def test_the_palm_compressed_reads_and_traces_as_the_plain_palm(tmp_path, fallback):
    """The palm's vertex views (ATTRIBUTES) and index views (TRIANGLES) compressed by
    meshoptimizer: the same positions, UVs and triangles as the plain palm written with the
    decoder's triangle order (TRIANGLES may rotate a triangle's corners), and the same alpha
    tests per ray for every scheme. With the extension only used, its fallback buffer holds
    garbage: it is never read."""
    packed, plain = tmp_path / "palm_meshopt.glb", tmp_path / "palm_plain.glb"
    with_indices(SCENES / "palm.glb", plain, meshoptify_glb(SCENES / "palm.glb", packed, fallback=fallback))
    a, b = load_scene(packed), load_scene(plain)
    assert a.counts() == b.counts()
    for pa, pb in zip(a.meshes[0].primitives, b.meshes[0].primitives):
        np.testing.assert_array_equal(pa.positions, pb.positions)
        np.testing.assert_array_equal(pa.uvs, pb.uvs)
        np.testing.assert_array_equal(pa.triangles, pb.triangles)
    if fallback is None:  # (the same scene either way: traced once)
        _same_figures(_trace(tmp_path, packed, "packed"), _trace(tmp_path, plain, "plain"))


@needs_scenes
def test_index_sequences_keep_the_palms_own_triangles(tmp_path):
    """INDICES keeps the order of every index: the palm so compressed is the palm, scene for
    scene (no twin needed)."""
    packed = tmp_path / "palm_indices.glb"
    meshoptify_glb(SCENES / "palm.glb", packed, index_mode="INDICES")
    a, b = load_scene(packed), load_scene(SCENES / "palm.glb")
    for pa, pb in zip(a.meshes[0].primitives, b.meshes[0].primitives):
        np.testing.assert_array_equal(pa.triangles, pb.triangles)
        np.testing.assert_array_equal(pa.uvs, pb.uvs)


@needs_scenes
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_what_omm_writes_from_a_compressed_palm_reads_back(tmp_path, suffix):
    """``omm -o`` of a compressed palm: its compressed views, their placeholder buffer and the
    new micromaps in one self-contained file that reads back with the same geometry and the
    micromaps the bake wrote (the placeholder stays without data, after buffer 0)."""
    packed = tmp_path / "palm_meshopt.glb"
    meshoptify_glb(SCENES / "palm.glb", packed)
    out = tmp_path / f"baked{suffix}"
    assert main(["omm", str(packed), "--level", "2", "-o", str(out), "--quiet"]) == 0
    back, src = load_scene(out), load_scene(packed)
    assert back.counts() == src.counts()
    for pa, pb in zip(back.meshes[0].primitives, src.meshes[0].primitives):
        np.testing.assert_array_equal(pa.uvs, pb.uvs)
        np.testing.assert_array_equal(pa.triangles, pb.triangles)
    assert back.micromaps is not None
    if suffix == ".glb":
        doc, _ = glb_parts(out)
        assert len(doc["buffers"]) == 2 and "uri" not in doc["buffers"][1]
        assert MESHOPT in doc["extensionsRequired"]


def _broken(tmp_path, fn):
    path = tmp_path / "broken.glb"
    doc, blob = glb_parts(tmp_path / "ok.glb")
    blob = bytearray(blob)
    fn(doc, blob)
    write_glb_parts(path, doc, blob)
    return path


@needs_scenes
@pytest.mark.parametrize("case, said", [
    ("bit flipped", r"bufferView \d+: EXT_meshopt_compression: it"),
    ("header", r"bufferView \d+: EXT_meshopt_compression: its triangle stream starts with 0x00"),
    ("cut", r"bufferView \d+: EXT_meshopt_compression: its"),
    ("placeholder read", "buffer 1 has no URI"),
    ("count", "is not byteStride"),
])
def test_broken_compressed_views_are_errors_naming_the_view(tmp_path, capsys, case, said):
    meshoptify_glb(SCENES / "palm.glb", tmp_path / "ok.glb")

    def fn(doc, blob):
        v = next(v for v in doc["bufferViews"] if v.get("extensions", {}).get(MESHOPT, {}).get("mode") == "TRIANGLES")
        ext = v["extensions"][MESHOPT]
        if case == "bit flipped":  # the triangle stream's data section: a code no triangle had
            blob[ext["byteOffset"] + 1: ext["byteOffset"] + ext["byteLength"] - 16] = \
                bytes([0xFF]) * (ext["byteLength"] - 17)
        elif case == "header":
            blob[ext["byteOffset"]] = 0
        elif case == "cut":
            ext["byteLength"] -= 7
        elif case == "placeholder read":
            del v["extensions"]
        else:
            ext["count"] += 3

    path = _broken(tmp_path, fn)
    assert main(["trace", str(path), "--schemes", "none", "--size", "16", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "Traceback" not in err
    import re

    assert re.search(said, err), err
    with pytest.raises(InputError):
        load_scene(path)
