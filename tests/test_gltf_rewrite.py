"""Writing micromaps into a glTF file that already holds some (``omaps omm BAKED -o OUT``,
``omm --expand``): the replaced micromaps' accessors, buffer views and bytes leave the output,
every other reference is renumbered, every kept byte stays where its views find it.

The files are read here with plain JSON and struct reading (``gltf_files.glb_parts``), never
with omaps' reader; the unit tests of ``container.drop_unnamed`` label every view's bytes and
check each kept view still reads its own."""

import base64
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import SCENES, needs_scenes
from gltf_files import dracoify_glb, glb_parts, meshoptify_glb, write_quad_gltf
from omaps.cli.main import main
from omaps.scene.container import drop_unnamed


def _scene(tmp_path):
    alpha = np.zeros((16, 16), np.uint8)
    alpha[:, :7] = 255
    alpha[2:6, 9:13] = 255
    p = tmp_path / "quad.gltf"
    write_quad_gltf(p, alpha, material={"alphaMode": "MASK"}, sampler={"magFilter": 9728})
    return p


def _gltf_parts(path):
    doc = json.loads(open(path).read())
    return doc, [base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]


def _view_bytes(doc, buffers, vi):
    v = doc["bufferViews"][vi]
    off = v.get("byteOffset", 0)
    return buffers[v.get("buffer", 0)][off:off + v["byteLength"]]


def _comparable(doc):
    """The document less what names its source file."""
    doc = json.loads(json.dumps(doc))
    for item in doc["extensions"]["EXT_mesh_opacity_micromap"]["micromaps"]:
        item.get("extras", {}).get("omaps", {}).pop("source", None)
    return doc


@pytest.mark.parametrize("first", [["--from", "vq4"], ["--from", "csm3"], ["--level", "4"]])
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_baking_a_baked_file_again_leaves_no_old_data(tmp_path, first, suffix):
    """A.glb baked from the scene (with pair blocks, a merged DAG or plain micromaps), baked
    again at level 3, gives the very file the scene baked at level 3 gives: the same document
    (but the source's name) and the same bytes."""
    src = _scene(tmp_path)
    a, b, c = (tmp_path / f"{n}{suffix}" for n in "abc")
    assert main(["omm", str(src), "-o", str(a), "--quiet", *first]) == 0
    assert main(["omm", str(a), "-o", str(b), "--quiet", "--level", "3"]) == 0
    assert main(["omm", str(src), "-o", str(c), "--quiet", "--level", "3"]) == 0
    parts = glb_parts if suffix == ".glb" else _gltf_parts
    (_, ba), (db, bb), (dc, bc) = parts(a), parts(b), parts(c)
    assert len(ba if suffix == ".glb" else b"".join(ba)) > len(bc if suffix == ".glb" else b"".join(bc))
    assert _comparable(db) == _comparable(dc)
    assert bb == bc
    if suffix == ".gltf":  # the old micromaps' buffer (a data URI) is gone with them
        assert len(db["buffers"]) == len(dc["buffers"])
    assert main(["omm", "--verify", str(b)]) == 0


def test_expand_leaves_no_old_data(tmp_path):
    """``--expand`` of a file with pair blocks: the blocks' views and bytes leave; what stays
    is the scene's data and the new micromaps, each view reading what it read before."""
    src = _scene(tmp_path)
    a, b = tmp_path / "a.glb", tmp_path / "b.glb"
    assert main(["omm", str(src), "-o", str(a), "--quiet", "--from", "vq4"]) == 0
    assert main(["omm", str(a), "--expand", "-o", str(b), "--quiet"]) == 0
    da, ba = glb_parts(a)
    db, bb = glb_parts(b)
    assert "OMAPS_pair_opacity_maps" not in db.get("extensionsUsed", [])
    blocks = da["extensions"]["OMAPS_pair_opacity_maps"]["maps"][0]["blocks"]
    assert len(bb) < len(ba) - da["bufferViews"][blocks]["byteLength"] + 64
    n_scene = min(len(da["accessors"]), len(db["accessors"])) - 1  # the scene's own accessors come first
    for k in range(n_scene):
        va, vb = da["accessors"][k]["bufferView"], db["accessors"][k]["bufferView"]
        assert _view_bytes(da, [ba], va) == _view_bytes(db, [bb], vb)
    for ia, ib in zip(da["images"], db["images"]):
        assert _view_bytes(da, [ba], ia["bufferView"]) == _view_bytes(db, [bb], ib["bufferView"])
    assert main(["omm", "--verify", str(b)]) == 0


def test_an_unknown_extension_keeps_the_old_data(tmp_path):
    """An extension omaps does not know may name any view: nothing is removed, the output is
    still whole and verified."""
    src = _scene(tmp_path)
    doc = json.loads(src.read_text())
    doc["meshes"][0]["primitives"][0]["extensions"] = {"VENDOR_views": {"view": 0}}
    doc.setdefault("extensionsUsed", []).append("VENDOR_views")
    src.write_text(json.dumps(doc))
    a, b = tmp_path / "a.glb", tmp_path / "b.glb"
    assert main(["omm", str(src), "-o", str(a), "--quiet", "--level", "3"]) == 0
    assert main(["omm", str(a), "-o", str(b), "--quiet", "--level", "3"]) == 0
    da, ba = glb_parts(a)
    db, bb = glb_parts(b)
    assert len(db["bufferViews"]) > len(da["bufferViews"]) and len(bb) > len(ba)
    assert db["meshes"][0]["primitives"][0]["extensions"]["VENDOR_views"] == {"view": 0}
    assert main(["omm", "--verify", str(b)]) == 0


@needs_scenes
@pytest.mark.parametrize("packing", ["meshopt", "draco"])
def test_compressed_scenes_baked_again(tmp_path, packing):
    """The palm with its views compressed by meshoptimizer (a fallback buffer of garbage beside
    the binary chunk) or its primitives by Draco, baked with pair blocks, then again: the file the
    compressed palm baked once gives, every view (and compressed range) with the same bytes."""
    src = tmp_path / f"palm_{packing}.glb"
    if packing == "meshopt":
        pytest.importorskip("meshoptimizer", reason="meshoptimizer (the reference encoder) is not installed")
        meshoptify_glb(SCENES / "palm.glb", src, fallback=b"\xab" * 64)
    else:
        pytest.importorskip("DracoPy", reason="DracoPy (the Draco encoder) is not installed")
        dracoify_glb(SCENES / "palm.glb", src)
    a, b, c = (tmp_path / f"{n}.glb" for n in "abc")
    assert main(["omm", str(src), "-o", str(a), "--quiet", "--from", "sq16"]) == 0
    assert main(["omm", str(a), "-o", str(b), "--quiet", "--level", "3"]) == 0
    assert main(["omm", str(src), "-o", str(c), "--quiet", "--level", "3"]) == 0
    (_, ba), (db, bb), (dc, bc) = glb_parts(a), glb_parts(b), glb_parts(c)
    assert len(ba) > len(bb) and len(bb) <= len(bc)
    # the same document but where the views lie (a compressed file's bytes no view covers, the
    # meshopt fallback's garbage, are not carried into a re-written one), each view's bytes equal
    assert len(db["bufferViews"]) == len(dc["bufferViews"])
    for k, (vb, vc) in enumerate(zip(db["bufferViews"], dc["bufferViews"])):
        assert _view_bytes(db, [bb], k) == _view_bytes(dc, [bc], k)
        for h_b, h_c in ((vb, vc), (vb.get("extensions", {}).get("EXT_meshopt_compression"),
                                     vc.get("extensions", {}).get("EXT_meshopt_compression"))):
            if h_b is not None:
                assert {**h_b, "byteOffset": 0} == {**h_c, "byteOffset": 0}
                if h_b["buffer"] == 0:
                    off_b, off_c = h_b.get("byteOffset", 0), h_c.get("byteOffset", 0)
                    assert bb[off_b:off_b + h_b["byteLength"]] == bc[off_c:off_c + h_c["byteLength"]]
    same = {k for k in dc if k not in ("bufferViews", "buffers")}
    assert {k: _comparable(db)[k] for k in same} == {k: _comparable(dc)[k] for k in same}
    assert db["buffers"][1:] == dc["buffers"][1:]
    assert main(["omm", "--verify", str(b)]) == 0


def _labelled(n_views, spans):
    """A body whose every byte says which view first covers it, and a document of views."""
    body = bytearray(b"\xee" * (max(e for _, e in spans) + 5))
    for k, (s, e) in enumerate(spans):
        for i in range(s, e):
            body[i] = (body[i] + 7 * k + i) % 251
    views = [{"buffer": 0, "byteOffset": s, "byteLength": e - s} for s, e in spans]
    return bytes(body), views


def test_drop_unnamed_renumbers_every_reference():
    spans = [(0, 12), (16, 40), (40, 48), (64, 100), (100, 104), (104, 120), (128, 160), (160, 170)]
    body, views = _labelled(len(spans), spans)
    doc = {
        "asset": {"version": "2.0"},
        "bufferViews": views,
        "buffers": [{"byteLength": len(body)}],
        "accessors": [{"bufferView": 0, "count": 1}, {"bufferView": 1, "count": 1},
                      {"bufferView": 2, "count": 1},
                      {"bufferView": 3, "count": 1, "sparse": {"indices": {"bufferView": 4},
                                                              "values": {"bufferView": 5}}},
                      {"bufferView": 6, "count": 1}, {"count": 1}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 3}, "indices": 4,
                                    "targets": [{"POSITION": 5}],
                                    "extensions": {"KHR_draco_mesh_compression": {"bufferView": 7,
                                                                                  "attributes": {"POSITION": 2}}}}]}],
        "nodes": [{"mesh": 0, "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 4}}}}],
        "skins": [{"joints": [0], "inverseBindMatrices": 3}],
        "animations": [{"samplers": [{"input": 5, "output": 3}], "channels": []}],
        "extensionsUsed": ["KHR_draco_mesh_compression", "EXT_mesh_gpu_instancing"],
    }
    before = {k: _view_bytes(doc, [body], k) for k in range(len(views))}
    # accessors 1 and 2 (views 1, 2) go; view 1 is also asked for by itself
    new_body = drop_unnamed(doc, accessors={1, 2}, views={1}, body=body)
    assert len(doc["accessors"]) == 4 and len(doc["bufferViews"]) == 6
    assert [a.get("bufferView") for a in doc["accessors"]] == [0, 1, 4, None]
    sparse = doc["accessors"][1]["sparse"]
    assert (sparse["indices"]["bufferView"], sparse["values"]["bufferView"]) == (2, 3)
    prim = doc["meshes"][0]["primitives"][0]
    assert prim["attributes"] == {"POSITION": 0, "TEXCOORD_0": 1} and prim["indices"] == 2
    assert prim["targets"] == [{"POSITION": 3}]
    assert prim["extensions"]["KHR_draco_mesh_compression"] == {"bufferView": 5, "attributes": {"POSITION": 2}}
    assert doc["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] == {"TRANSLATION": 2}
    assert doc["skins"][0]["inverseBindMatrices"] == 1
    assert doc["animations"][0]["samplers"][0] == {"input": 3, "output": 1}
    for new, old in enumerate([0, 3, 4, 5, 6, 7]):
        assert _view_bytes(doc, [new_body], new) == before[old]
        assert doc["bufferViews"][new]["byteOffset"] % 16 == spans[old][0] % 16
    assert len(new_body) <= len(body) - (48 - 16) + 16


def test_drop_unnamed_keeps_what_is_still_named_and_unknown_extensions():
    spans = [(0, 8), (8, 16)]
    body, views = _labelled(2, spans)
    doc = {"bufferViews": views, "buffers": [{"byteLength": len(body)}],
           "accessors": [{"bufferView": 0}, {"bufferView": 0}, {"bufferView": 1}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]}
    same = json.loads(json.dumps(doc))
    # accessor 1 is a primitive's indices: it stays, and so does its view
    assert drop_unnamed(doc, accessors={1}, views={0}, body=body) == body
    assert doc == same
    doc["meshes"][0]["primitives"][0]["extensions"] = {"VENDOR_x": {"accessor": 2}}
    same = json.loads(json.dumps(doc))
    assert drop_unnamed(doc, accessors={2}, views={1}, body=body) == body
    assert doc == same


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 300), st.integers(1, 80), st.booleans()), min_size=1, max_size=12))
def test_drop_unnamed_moves_bytes_and_nothing_else(views):
    """Random views, some removed: every kept view reads its bytes, at its offset modulo 16;
    the body loses at least the bytes only removed views covered, less padding."""
    spans = [(s, s + n) for s, n, _ in views]
    body, vs = _labelled(len(spans), spans)
    gone = {k for k, (_, _, g) in enumerate(views) if g}
    doc = {"bufferViews": vs, "buffers": [{"byteLength": len(body)}]}
    before = [_view_bytes(doc, [body], k) for k in range(len(vs))]
    kept = [k for k in range(len(vs)) if k not in gone]
    new_body = drop_unnamed(doc, views=gone, body=body)
    assert len(doc.get("bufferViews", [])) == len(kept)
    for new, old in enumerate(kept):
        assert _view_bytes(doc, [new_body], new) == before[old]
        assert doc["bufferViews"][new]["byteOffset"] % 16 == spans[old][0] % 16
    covered_kept = np.zeros(len(body), bool)
    covered_gone = np.zeros(len(body), bool)
    for k, (s, e) in enumerate(spans):
        (covered_gone if k in gone else covered_kept)[s:e] = True
    only_gone = int((covered_gone & ~covered_kept).sum())
    assert len(new_body) <= len(body) - only_gone + 15 * (len(kept) + 1)
    assert len(new_body) <= len(body)
