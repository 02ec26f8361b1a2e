"""``omaps omm --from csmL``: the micromaps at level L, also stored as one merged DAG
(``merged_micromaps.bin`` in a folder, ``OMAPS_merged_micromaps`` in a glTF file), read back,
verified and expanded into standard micromaps.

The stored DAG is read here by this file's own descent of the blob's bits (``descend``, after
docs/FORMAT.md "Hierarchical micromaps"), independently of omaps' csm decoder, and compared with
every triangle's micromap as the baker gives it."""

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gltf_files import grid_scene
from omaps import omm_format, states
from omaps.alpha_test import StateRule
from omaps.bake.micromap import GROW_TEXEL, bake_micromaps
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.omm import Geometry, OmmSettings, build, read, write
from omaps.omm.gltf_io import read_gltf
from omaps.texture import load_alpha


def descend(blob: bytes, level: int, t: int, k: int) -> int:
    """State of micro-triangle k of micromap t: 32-bit node count N, W = bits of N + 2, node i's
    children at bits 32 + W (4 i + c), roots after the nodes; a reference below 3 is a state."""
    bits = np.unpackbits(np.frombuffer(blob, np.uint8), bitorder="little")

    def field(pos, w):
        return int(sum(int(bits[pos + j]) << j for j in range(w)))

    n = field(0, 32)
    w = int(n + 2).bit_length()
    ref = field(32 + w * (4 * n + t), w)
    for d in range(level):
        if ref < 3:
            break
        ref = field(32 + w * (4 * (ref - 3) + ((k >> (2 * (level - 1 - d))) & 3)), w)
    return ref


def leaf_test(rng, size=32):
    img = (rng.random((size, size)) > 0.5).astype(np.uint8) * 255
    img[: size // 2] = 255  # opaque and mixed regions both
    return StateRule("cutoff").alpha_test(load_alpha(img), "linear", "wrap")


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 4), st.integers(1, 12), st.integers(0, 2 ** 32 - 1), st.booleans())
def test_merged_micromaps_are_every_triangles_baked_states(level, n, seed, repeat):
    rng = np.random.default_rng(seed)
    test = leaf_test(rng)
    tris = rng.random((n, 3, 2)) * 1.2 - 0.1
    if repeat and n > 2:
        tris[-1] = tris[0]  # identical triangles: baked once, a root each
    unknown = rng.random(n) < 0.2
    g = Geometry("leaf", test, tris, unknown=unknown)
    res = build([g], OmmSettings(source=f"csm{level}"))
    plain = build([g], OmmSettings(level=level))
    # the standard micromaps are those of the texture at that level, buffer for buffer
    assert np.array_equal(res.index, plain.index) and np.array_equal(res.data, plain.data)
    assert np.array_equal(res.triangles, plain.triangles)
    info = res.summary["merged_micromaps"]
    assert info["level"] == level and info["micromaps"] == n and info["bytes"] == len(res.merged_micromaps)
    assert res.summary["settings"]["source"] == f"csm{level}"
    s3, starts = bake_micromaps(test.grid(), tris, np.full(n, level, np.int64), GROW_TEXEL)
    for t in range(n):
        want = np.full(4 ** level, states.C, np.uint8) if unknown[t] else s3[starts[t]:starts[t + 1]]
        got = [descend(res.merged_micromaps, level, t, k) for k in range(4 ** level)]
        assert got == want.tolist()


def test_merged_folder_round_trip_verify_and_broken_files(tmp_path, rng):
    test = leaf_test(rng)
    tris = rng.random((20, 3, 2))
    res = build([Geometry("leaf", test, tris)], OmmSettings(source="csm3"))
    folder = tmp_path / "out"
    write(folder, res)
    back = read(folder)
    assert back.merged_micromaps == res.merged_micromaps
    assert back.summary["merged_micromaps"] == res.summary["merged_micromaps"]
    path = folder / omm_format.MERGED_FILE
    good = path.read_bytes()
    # a reference past the nodes: the reader names the file
    bad = bytearray(good)
    bad[4:12] = b"\xff" * 8
    path.write_bytes(bytes(bad))
    with pytest.raises(InputError, match=omm_format.MERGED_FILE):
        read(folder)
    path.write_bytes(good[:5])
    with pytest.raises(InputError, match=omm_format.MERGED_FILE):
        read(folder)
    path.unlink()
    with pytest.raises(InputError, match="missing"):
        read(folder)
    path.write_bytes(good)
    summary = json.loads((folder / omm_format.SUMMARY_FILE).read_text())
    summary["merged_micromaps"]["micromaps"] = 19
    (folder / omm_format.SUMMARY_FILE).write_text(json.dumps(summary))
    with pytest.raises(InputError, match="micromaps is 19"):
        read(folder)


def test_merged_source_settings():
    assert OmmSettings(source="csm5").merged_level == 5 and OmmSettings().merged_level is None
    with pytest.raises(InputError, match="csmL fixes the level"):
        OmmSettings(source="csm5", dynamic_scale=2.0)
    with pytest.raises(InputError, match="not 'succinct4'"):
        OmmSettings(source="succinct4")


def test_gltf_from_csm_verify_expand_and_a_broken_dag(tmp_path, rng, capsys):
    alpha = (rng.random((32, 32)) > 0.5).astype(np.uint8) * 255
    src = grid_scene(tmp_path / "grid.gltf", alpha, k=8)
    baked, std, plain = tmp_path / "baked.glb", tmp_path / "std.glb", tmp_path / "plain.glb"
    assert main(["omm", str(src), "--from", "csm3", "-o", str(baked), "--quiet"]) == 0
    assert main(["omm", str(src), "--level", "3", "-o", str(plain), "--quiet"]) == 0
    assert main(["omm", "--verify", str(baked)]) == 0
    assert "micromaps against the merged micromaps" in capsys.readouterr().out
    res, ref = read_gltf(baked), read_gltf(plain)
    n = len(ref.index)
    assert res.merged_micromaps is not None and res.summary["merged_micromaps"]["micromaps"] == n
    # the DAG holds every triangle's T/O/C states; the standard micromaps resolve its C
    for t in range(n):
        s = np.broadcast_to(ref.triangle_states(t), (64,))
        dag = np.array([descend(res.merged_micromaps, 3, t, k) for k in range(64)])
        assert np.array_equal(s[dag < 2], dag[dag < 2]) and np.all(s[dag == 2] >= 2)
    assert main(["omm", str(baked), "--expand", "-o", str(std)]) == 0
    assert "csm3 merged micromaps" in capsys.readouterr().out
    out = read_gltf(std)
    assert out.merged_micromaps is None
    assert all(np.array_equal(out.triangle_states(t), ref.triangle_states(t)) for t in range(n))
    # a glTF file whose DAG is broken: exit 2, the file named
    from gltf_files import glb_parts, write_glb_parts

    doc, blob = glb_parts(baked)
    view = doc["bufferViews"][doc["extensions"]["OMAPS_merged_micromaps"]["dag"]]
    blob = bytearray(blob)
    blob[view["byteOffset"] + 4:view["byteOffset"] + 12] = b"\xff" * 8
    broken = tmp_path / "broken.glb"
    write_glb_parts(broken, doc, bytes(blob))
    assert main(["omm", "--verify", str(broken)]) == 2
    err = capsys.readouterr().err
    assert "broken.glb" in err and "OMAPS_merged_micromaps" in err
    assert not os.path.exists(tmp_path / "std2.glb")
    assert main(["omm", str(broken), "--expand", "-o", str(tmp_path / "std2.glb")]) == 2
    assert not os.path.exists(tmp_path / "std2.glb")


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 3), st.lists(st.integers(0, 2 ** 32 - 1), min_size=1, max_size=6))
def test_unpack_gives_the_dag_pack_writes_again(level, seeds):
    from omaps.codecs import csm_decode, csm_encode, csm_pack, csm_unpack

    maps = np.array([np.random.default_rng(s).integers(0, 3, 4 ** level) for s in seeds], np.uint8)
    maps[::2] = maps[0]  # repeated maps share their root
    blob, n_nodes = csm_encode(maps, level)
    nodes, roots = csm_unpack(blob, level, len(maps))
    assert nodes.shape == (n_nodes, 4) and csm_pack(nodes, roots) == blob
    assert np.array_equal(csm_decode(csm_pack(nodes, roots[::-1]), level, len(maps)), maps[::-1])
    with pytest.raises(InputError):
        csm_unpack(blob[:3], level, len(maps))


def test_trace_file_csm_reads_the_stored_dag(tmp_path, rng):
    """``trace --schemes file:csm`` reads the DAG the file stores: the tests, known fraction, bytes
    and lines read of the tracer's own csmL of that level, and no pixel changed."""
    alpha = (rng.random((32, 32)) > 0.5).astype(np.uint8) * 255
    src = grid_scene(tmp_path / "grid.gltf", alpha, k=10)
    baked = tmp_path / "baked.glb"
    assert main(["omm", str(src), "--from", "csm4", "-o", str(baked), "--quiet"]) == 0
    js = tmp_path / "t.json"
    assert main(["trace", str(baked), "--schemes", "none,file:csm,csm4", "--size", "48", "--memory", "--quiet",
                 "--json", str(js)]) == 0
    rep = json.loads(js.read_text())["schemes"]
    got, own = rep["file:csm"], rep["csm4"]
    assert got["differing_pixels"] == 0 and rep["none"]["alpha_tests_per_primary_ray"] > 0
    for key in ("alpha_tests_per_primary_ray", "known_fraction", "map_bytes", "map_lines_per_ray", "distinct_maps"):
        assert got[key] == own[key], key
    plain = tmp_path / "plain.glb"
    assert main(["omm", str(src), "-o", str(plain), "--quiet"]) == 0
    assert main(["trace", str(plain), "--schemes", "none,file:csm", "--size", "8", "--quiet"]) == 2
