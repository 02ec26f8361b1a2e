"""Every glTF file omaps writes names nothing outside itself (docs/guide/io.md "glTF outputs"):
a .glb holds every buffer and image in its binary chunk, a .gltf copies the files it names into
``OUT_files/`` beside it. Each output reads back (``--verify``, ``trace``) under the default root
policy after the input is gone and the output moved, and passes the Khronos validator.

The input here is written from scratch: a .gltf with its buffer in ``scene.bin`` and its images
in a subfolder (one named with a space), and the expected bytes are read from those files.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import struct

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import edit_json, png_bytes, write_quad_gltf
from omaps.cli.main import main
from omaps.scene import load_scene
from test_omm_gltf import needs_validator, run_validator

ALPHA = np.zeros((16, 16), np.uint8)
ALPHA[:, :8] = 255
ALPHA[3:5, 10:12] = 255
NORMAL = np.full((4, 4), 255, np.uint8)
SMALLPINE = SCENES / "smallpine" / "scene.gltf"


def make_asset(folder, extra=None):
    """folder/scene.gltf: buffer scene.bin, base colour textures/leaf.png, an emissive map
    'textures/My Glow.png' (URI percent-encoded), an occlusion map as a data URI."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "textures").mkdir(exist_ok=True)
    scene = write_quad_gltf(folder / "scene.gltf", ALPHA, bin_uri="scene.bin", image_uri="textures/leaf.png",
                            material={"alphaMode": "MASK"}, sampler={"magFilter": 9728})
    (folder / "textures" / "My Glow.png").write_bytes(png_bytes(NORMAL))

    def fn(doc):
        doc["images"] += [{"uri": "textures/My%20Glow.png"},
                          {"uri": "data:image/png;base64," + base64.b64encode(png_bytes(NORMAL[:2])).decode()}]
        doc["textures"] += [{"source": 1, "sampler": 0}, {"source": 2, "sampler": 0}]
        doc["materials"][0]["emissiveTexture"] = {"index": 1}
        doc["materials"][0]["emissiveFactor"] = [1, 1, 1]
        doc["materials"][0]["occlusionTexture"] = {"index": 2}
        if extra:
            extra(doc)
    edit_json(scene, fn)
    return folder / "scene.gltf"


def glb_parts(path):
    raw = open(path, "rb").read()
    magic, version, total = struct.unpack_from("<III", raw, 0)
    assert (magic, version, total) == (0x46546C67, 2, len(raw))
    n, kind = struct.unpack_from("<II", raw, 12)
    assert kind == 0x4E4F534A
    doc = json.loads(raw[20:20 + n])
    m, kind = struct.unpack_from("<II", raw, 20 + n)
    assert kind == 0x004E4942
    return doc, raw[28 + n:28 + n + m]


def view_bytes(doc, body, vi):
    v = doc["bufferViews"][vi]
    start = v.get("byteOffset", 0)
    return body[start:start + v["byteLength"]]


def src_view_bytes(src, vi):
    doc = json.loads(open(src).read())
    v = doc["bufferViews"][vi]
    blob = open(os.path.join(os.path.dirname(src), doc["buffers"][v["buffer"]]["uri"]), "rb").read()
    return blob[v.get("byteOffset", 0):v.get("byteOffset", 0) + v["byteLength"]]


def trace_ok(path, tmp_path, size=32, *extra):
    js = tmp_path / f"trace{len(os.listdir(tmp_path))}.json"
    rc = main(["trace", str(path), "--schemes", "none,omm", "--size", str(size), "--quiet", "--json", str(js),
               *extra])
    assert rc == 0
    rep = json.loads(js.read_text())["schemes"]
    assert rep["omm"]["differing_pixels"] == 0
    return rep


def no_uris(doc):
    return [(k, i) for k in ("buffers", "images") for i, x in enumerate(doc.get(k, [])) if "uri" in x]


def test_glb_output_holds_every_buffer_and_image(tmp_path, capsys):
    src = make_asset(tmp_path / "asset")
    out = tmp_path / "elsewhere" / "deep" / "baked.glb"
    out.parent.mkdir(parents=True)
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
    doc, body = glb_parts(out)
    assert no_uris(doc) == [] and len(doc["buffers"]) == 1 and doc["buffers"][0]["byteLength"] <= len(body)
    assert all(v["buffer"] == 0 for v in doc["bufferViews"])
    # the source's buffer views: the same bytes, at offsets the accessors' components allow
    for vi in range(3):
        assert view_bytes(doc, body, vi) == src_view_bytes(src, vi)
    for a in doc["accessors"]:
        v = doc["bufferViews"][a["bufferView"]]
        assert (v.get("byteOffset", 0) + a.get("byteOffset", 0)) % 4 == 0
    # the images: the files' bytes (and the data URI's), with their media type
    want = [(src.parent / "textures" / "leaf.png").read_bytes(), (src.parent / "textures" / "My Glow.png").read_bytes(),
            png_bytes(NORMAL[:2])]
    for im, raw in zip(doc["images"], want):
        assert im["mimeType"] == "image/png" and view_bytes(doc, body, im["bufferView"]) == raw
    # the input gone, the output moved: still whole
    shutil.rmtree(src.parent)
    moved = tmp_path / "moved.glb"
    os.rename(out, moved)
    scene = load_scene(moved)
    assert not scene.warnings
    assert main(["omm", "--verify", str(moved)]) == 0
    trace_ok(moved, tmp_path)


def test_gltf_output_copies_its_files_beside_it(tmp_path, capsys):
    src = make_asset(tmp_path / "asset")
    out_dir = tmp_path / "out"
    out = out_dir / "baked.gltf"
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    files = out_dir / "baked_files"
    uris = [x["uri"] for x in doc["buffers"] + doc["images"] if not x["uri"].startswith("data:")]
    assert sorted(uris) == ["baked_files/My_Glow.png", "baked_files/leaf.png", "baked_files/scene.bin"]
    assert sorted(os.listdir(files)) == ["My_Glow.png", "leaf.png", "omaps-files.json", "scene.bin"]
    for name, orig in (("scene.bin", "scene.bin"), ("leaf.png", "textures/leaf.png"),
                       ("My_Glow.png", "textures/My Glow.png")):
        assert (files / name).read_bytes() == (src.parent / orig).read_bytes()
    assert doc["images"][2]["uri"].startswith("data:image/png;base64,")  # a data URI stays one
    # the input gone, the output's folder moved: still whole
    shutil.rmtree(src.parent)
    moved = tmp_path / "moved"
    os.rename(out_dir, moved)
    assert not load_scene(moved / "baked.gltf").warnings
    assert main(["omm", "--verify", str(moved / "baked.gltf")]) == 0
    trace_ok(moved / "baked.gltf", tmp_path)
    # baked again from the moved output: its own files folder, the names kept
    again = tmp_path / "again" / "b.gltf"
    assert main(["omm", str(moved / "baked.gltf"), "-o", str(again), "--quiet"]) == 0
    assert sorted(os.listdir(again.parent / "b_files")) == sorted(os.listdir(moved / "baked_files"))


def test_names_made_safe_and_unique(tmp_path, capsys):
    """Two files of one name in two folders get two names; one file named twice is copied once;
    odd characters become '_', a leading dot goes."""
    def fn(doc):
        doc["images"] += [{"uri": "other/leaf.png"}, {"uri": "textures/leaf.png"}, {"uri": "odd/.%C3%A9t%C3%A9%3F.png"}]
        doc["textures"] += [{"source": 3}, {"source": 4}, {"source": 5}]
    asset = tmp_path / "asset"
    (asset / "other").mkdir(parents=True)
    (asset / "odd").mkdir()
    (asset / "other" / "leaf.png").write_bytes(png_bytes(NORMAL))
    (asset / "odd" / ".été?.png").write_bytes(png_bytes(ALPHA[:4]))
    src = make_asset(asset, fn)
    out = tmp_path / "o" / "x.gltf"
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    names = [im.get("uri") for im in doc["images"]]
    assert names[0] == names[4] == "x_files/leaf.png" and names[3] == "x_files/leaf-2.png"
    assert names[5] == "x_files/_t_.png"
    assert (out.parent / "x_files" / "leaf-2.png").read_bytes() == (asset / "other" / "leaf.png").read_bytes()
    assert (out.parent / "x_files" / "_t_.png").read_bytes() == (asset / "odd" / ".été?.png").read_bytes()
    for u in names[:2] + names[3:]:
        assert not u.startswith(("/", "..")) and ".." not in u.split("/")
    assert main(["omm", "--verify", str(out)]) == 0


def with_missing_image(doc):
    """Image 1 is a file that is missing, the source of a texture (3) of its own."""
    doc["images"].insert(1, {"uri": "textures/gone.png"})
    for t in doc["textures"][1:]:
        t["source"] += 1
    doc["textures"].append({"source": 1, "sampler": 0})
    doc["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"] = {"index": 3}


def test_missing_image_left_out_with_a_warning(tmp_path, capsys):
    """An image file that is missing (here a metallic-roughness map) cannot travel: the output leaves it out,
    says so, and the texture naming it names no image; the reader sees it absent, as before."""
    src = make_asset(tmp_path / "asset", with_missing_image)
    for name in ("m.glb", "m.gltf"):
        out = tmp_path / "o" / name
        capsys.readouterr()
        assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
        err = capsys.readouterr().err
        assert f"{src}: image 1: file 'textures/gone.png' is missing" in err and "left out of the output" in err
        assert "texture 3 now names no image" in err
        doc = glb_parts(out)[0] if name.endswith(".glb") else json.loads(out.read_text())
        assert len(doc["images"]) == 3 and "source" not in doc["textures"][3]
        assert [t["source"] for t in doc["textures"][:3]] == [0, 1, 2]  # the later images moved up
        assert doc["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"] == {"index": 3}
        assert "gone" not in json.dumps([doc["images"], doc["textures"]])
        if name.endswith(".glb"):
            assert no_uris(doc) == []
        assert main(["omm", "--verify", str(out)]) == 0
        trace_ok(out, tmp_path)


def test_files_folder_not_written_by_omaps_is_left_alone(tmp_path, capsys):
    src = make_asset(tmp_path / "asset")
    out = tmp_path / "o" / "x.gltf"
    (tmp_path / "o" / "x_files").mkdir(parents=True)
    (tmp_path / "o" / "x_files" / "mine.txt").write_text("keep")
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "x_files" in err and "not replacing it" in err
    assert not out.exists() and os.listdir(tmp_path / "o" / "x_files") == ["mine.txt"]
    assert sorted(os.listdir(tmp_path / "o")) == ["x_files"]  # no temporary left behind
    # omaps's own folder is replaced whole: a stale file goes
    shutil.rmtree(tmp_path / "o" / "x_files")
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
    (tmp_path / "o" / "x_files" / "stale.png").write_bytes(b"old")
    assert main(["omm", str(src), "-o", str(out), "--quiet", "--level", "2"]) == 0
    assert "stale.png" not in os.listdir(tmp_path / "o" / "x_files")
    assert sorted(os.listdir(tmp_path / "o")) == ["x.gltf", "x_files"]


def test_expand_output_is_self_contained(tmp_path, capsys):
    src = make_asset(tmp_path / "asset")
    baked = tmp_path / "b" / "vq.gltf"
    assert main(["omm", str(src), "-o", str(baked), "--quiet", "--from", "vq4"]) == 0
    shutil.rmtree(src.parent)
    for name in ("std.glb", "std.gltf"):
        out = tmp_path / "e" / name
        assert main(["omm", str(baked), "--expand", "-o", str(out)]) == 0
        if name.endswith(".glb"):
            assert no_uris(glb_parts(out)[0]) == []
        else:
            doc = json.loads(out.read_text())
            assert all(x["uri"].startswith(("data:", "std_files/")) for x in doc["buffers"] + doc["images"])
        assert main(["omm", "--verify", str(out)]) == 0


@needs_validator
def test_khronos_validator_clean(tmp_path):
    """The outputs validate with no error and no warning: of the clean input (which validates so
    too), and of the input naming a missing file (an error of the input's own)."""
    src = make_asset(tmp_path / "asset")
    gone = make_asset(tmp_path / "gone", with_missing_image)
    outs = [tmp_path / "o" / "v.glb", tmp_path / "o" / "v.gltf", tmp_path / "o" / "g.glb", tmp_path / "o" / "g.gltf"]
    for o in outs:
        assert main(["omm", str(src if o.name[0] == "v" else gone), "-o", str(o), "--quiet"]) == 0
    ref, bad, *reps = run_validator(src, gone, *outs)
    assert ref["numErrors"] == 0 and ref["numWarnings"] == 0, ref["messages"]
    assert bad["numErrors"] == 1 and bad["messages"][0]["pointer"] == "/images/1/uri", bad["messages"]
    for rep in reps:
        assert rep["numErrors"] == 0 and rep["numWarnings"] == 0, rep["messages"]


@needs_scenes
@pytest.mark.long
def test_smallpine_round_trip(tmp_path, capsys):
    """The real scene (a .gltf with scene.bin, textures/*.png, and a normal map that is missing):
    baked to a .glb naming no file, and to a .gltf moved elsewhere; both traced."""
    out = tmp_path / "x.glb"
    assert main(["omm", str(SMALLPINE), "-o", str(out), "--quiet", "--level", "3"]) == 0
    err = capsys.readouterr().err
    assert "M_TreeAtlas_normal.png" in err and "left out of the output" in err
    doc, body = glb_parts(out)
    assert no_uris(doc) == []
    src_doc = json.loads(SMALLPINE.read_text())
    kept = [im["uri"] for im in src_doc["images"] if "M_TreeAtlas_normal" not in im["uri"]]
    assert len(doc["images"]) == len(kept)
    for im, uri in zip(doc["images"], kept):
        assert view_bytes(doc, body, im["bufferView"]) == (SMALLPINE.parent / uri).read_bytes()
    trace_ok(out, tmp_path, 48)
    gl = tmp_path / "g" / "x.gltf"
    assert main(["omm", str(SMALLPINE), "-o", str(gl), "--quiet", "--level", "3"]) == 0
    moved = tmp_path / "moved"
    os.rename(gl.parent, moved)
    trace_ok(moved / "x.gltf", tmp_path, 48)
