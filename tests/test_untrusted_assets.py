"""Untrusted assets: a glTF never makes omaps read outside where it may (docs/guide/untrusted.md).

Every case goes through the command line (``omaps.cli.main.main``): a URI that leads out of the
root (an absolute path, ``..``, a symbolic link, percent-encoded ``..``, a ``file:`` URI), a URI
omaps never reads (``http:``, a Windows path, back-slashes), sizes over the cap; each refused one
exits 2 with a message naming the asset, the URI, where it leads and the option that allows it,
and writes nothing. ``--root`` and ``--allow-outside`` let the allowed ones through. The secret
file outside the asset's folder holds geometry of its own, so an output made from it would show.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from PIL import Image

from conftest import SCENES, needs_scenes
from gltf_files import QUAD_IDX, QUAD_POS, QUAD_UV, edit_json, png_bytes, write_quad_gltf
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.scene import load_scene

ALPHA = np.array([[0, 255], [255, 0]], np.uint8).repeat(8, 0).repeat(8, 1)
SECRET_POS = QUAD_POS * 7  # the outside buffer's quad: seven times larger


def quad_blob(positions=QUAD_POS) -> bytes:
    pos = np.ascontiguousarray(positions, np.float32).tobytes()
    idx = np.ascontiguousarray(QUAD_IDX, np.uint16).tobytes()
    return pos + np.ascontiguousarray(QUAD_UV, np.float32).tobytes() + idx + b"\0" * ((-len(idx)) % 4)


@pytest.fixture
def tree(tmp_path):
    """tmp/asset/scene.gltf (its buffer in asset/scene.bin, its image asset/leaf.png) and
    tmp/outside/ holding secret.bin (a buffer of another quad) and secret.png."""
    asset, outside = tmp_path / "asset", tmp_path / "outside"
    asset.mkdir()
    outside.mkdir()
    scene = write_quad_gltf(asset / "scene.gltf", ALPHA, bin_uri="scene.bin", image_uri="leaf.png")
    (outside / "secret.bin").write_bytes(quad_blob(SECRET_POS))
    (outside / "secret.png").write_bytes(png_bytes(ALPHA))
    return tmp_path, asset, outside, scene


def set_uri(scene, kind: str, uri: str):
    def fn(doc):
        doc[kind][0]["uri"] = uri
    return edit_json(scene, fn)


def run(capsys, *args) -> tuple[int, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main([str(a) for a in args])
    return rc, capsys.readouterr().err


def omm(capsys, scene, out, *options):
    return run(capsys, "omm", scene, "--level", "2", "--quiet", "-o", out, *options)


def outside_cases(outside):
    """(id, buffer URI) leading out of the asset's folder, and where each resolves."""
    secret = str(outside / "secret.bin")
    return {
        "absolute": (secret, "is an absolute path to"),
        "dotdot": ("../outside/secret.bin", "leads to"),
        "percent": ("%2e%2e/outside/%73ecret.bin", "leads to"),
        "file-uri": ("file://" + secret, "is a file: URI to"),
    }


@pytest.mark.parametrize("case", ["absolute", "dotdot", "percent", "file-uri", "symlink"])
def test_buffer_out_of_the_folder_refused_then_allowed(tree, capsys, case):
    tmp, asset, outside, scene = tree
    if case == "symlink":
        os.symlink(outside / "secret.bin", asset / "link.bin")
        uri, says = "link.bin", "leads to"
    else:
        uri, says = outside_cases(outside)[case]
    set_uri(scene, "buffers", uri)
    out = tmp / "out.glb"
    rc, err = omm(capsys, scene, out)
    assert rc == 2
    assert str(scene) in err and repr(uri) in err and says in err
    assert str((outside / "secret.bin").resolve()) in err  # where it resolves
    assert "(--root: a folder holding both; --allow-outside: if you trust this asset)" in err
    assert not out.exists() and not any(p.name.startswith(".omaps") for p in tmp.iterdir())
    # allowed: a root holding both, or no check at all; the output is made of the outside quad
    for options in (["--root", tmp], ["--allow-outside"]):
        rc, err = omm(capsys, scene, out, *options)
        assert rc == 0, err
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = load_scene(out, allow_outside=True)
        assert np.allclose(s.meshes[0].primitives[0].positions, SECRET_POS)
        out.unlink()


def test_root_that_does_not_hold_the_file_still_refuses(tree, capsys):
    tmp, asset, outside, scene = tree
    set_uri(scene, "buffers", "../outside/secret.bin")
    other = tmp / "other"
    other.mkdir()
    rc, err = omm(capsys, scene, tmp / "o.glb", "--root", asset)
    assert rc == 2 and "the --root folder" in err
    rc, err = omm(capsys, scene, tmp / "o.glb", "--root", tmp / "absent")
    assert rc == 2 and "--root" in err and "does not exist" in err


def test_system_file_is_neither_read_nor_sized(tree, capsys):
    tmp, asset, outside, scene = tree
    target = "/etc/hostname" if os.path.exists("/etc/hostname") else "/etc/passwd"
    set_uri(scene, "buffers", target)
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and "is an absolute path" in err and "byteLength says" not in err and "holds" not in err


@pytest.mark.parametrize("kind", ["images", "buffers"])
@pytest.mark.parametrize("uri, scheme", [("http://127.0.0.1:9/leaf.png", "an http:"),
                                         ("https://127.0.0.1:9/leaf.png", "an https:"),
                                         ("ftp://127.0.0.1:9/leaf.png", "a ftp:")])
def test_scheme_uris_are_never_fetched(tree, capsys, kind, uri, scheme):
    tmp, asset, outside, scene = tree
    set_uri(scene, kind, uri)
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and f"is {scheme} URI; omaps never fetches URIs" in err and "missing" not in err
    assert repr(uri) in err and str(scene) in err
    rc, err = omm(capsys, scene, tmp / "o.glb", "--allow-outside")
    if kind == "buffers":  # the geometry is not there: still an error
        assert rc == 2 and "never fetches" in err and not (tmp / "o.glb").exists()
    else:  # the image goes unread: a warning, the maps unknown; the output leaves it out (says so)
        assert rc == 0 and "never fetches" in err and "it is not read" in err and "missing" not in err
        assert "image 0: URI " in err and "left out of the output; texture 0 now names no image" in err
        doc = json.loads(main_json(tmp / "o.glb"))
        assert "images" not in doc and doc["textures"][0] == {"sampler": 0}


def main_json(glb) -> bytes:
    raw = open(glb, "rb").read()
    n = int.from_bytes(raw[12:16], "little")
    return raw[20:20 + n]


@pytest.mark.parametrize("uri", ["C:\\textures\\leaf.png", "C:/textures/leaf.png", "\\\\server\\share\\leaf.png",
                                 "textures\\leaf.png", "tex%5Cleaf.png", "//server/share/leaf.png"])
def test_windows_paths_and_backslashes_refused(tree, capsys, uri):
    tmp, asset, outside, scene = tree
    set_uri(scene, "images", uri)
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and repr(uri) in err and ("Windows" in err or "back-slashes" in err)
    assert not (tmp / "o.glb").exists()


def test_file_uri_image_refused_then_read_with_allow_outside(tree, capsys):
    tmp, asset, outside, scene = tree
    set_uri(scene, "images", "file://" + str(outside / "secret.png"))
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and "is a file: URI to" in err and "--allow-outside" in err
    rc, err = omm(capsys, scene, tmp / "o.glb", "--allow-outside")
    assert rc == 0 and "missing" not in err


def test_unused_outside_image_refused(tree, capsys):
    """An image nobody reads is still refused: a baked copy would name it."""
    tmp, asset, outside, scene = tree
    edit_json(scene, lambda doc: doc["images"].append({"uri": "../outside/secret.png"}))
    rc, err = omm(capsys, scene, tmp / "o.gltf")
    assert rc == 2 and "image 1" in err and "../outside/secret.png" in err
    assert not (tmp / "o.gltf").exists()


def test_output_never_names_a_file_outside_the_root(tree, capsys):
    """A .gltf baked into another folder names copies of the input's files beside it (in
    OUT_files/), never the input's own: it reads back under the default root, its own folder."""
    tmp, asset, outside, scene = tree
    (asset / "textures").mkdir()
    os.rename(asset / "leaf.png", asset / "textures" / "leaf.png")
    set_uri(scene, "images", "textures/leaf.png")
    out_dir = tmp / "baked" / "deep"
    out_dir.mkdir(parents=True)
    rc, err = omm(capsys, scene, out_dir / "scene.gltf")
    assert rc == 0, err
    doc = json.loads((out_dir / "scene.gltf").read_text())
    uris = [x["uri"] for x in doc["buffers"] + doc["images"] if not x.get("uri", "data:").startswith("data:")]
    assert sorted(uris) == ["scene_files/leaf.png", "scene_files/scene.bin"]
    root = os.path.realpath(out_dir)
    for u in uris:
        real = os.path.realpath(os.path.join(out_dir, u))
        assert real.startswith(root + os.sep), (u, real)
    rc, err = run(capsys, "omm", "--verify", out_dir / "scene.gltf")
    assert rc == 0, err


def test_sizes_over_the_cap(tree, capsys, monkeypatch):
    tmp, asset, outside, scene = tree
    blob = (asset / "scene.bin").read_bytes()
    # byteLength beyond the file: refused before reading
    edit_json(scene, lambda doc: doc["buffers"][0].update(byteLength=len(blob) + 100))
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and f"holds {len(blob)} bytes, byteLength says {len(blob) + 100}" in err
    # byteLength over the cap (environment variable)
    edit_json(scene, lambda doc: doc["buffers"][0].update(byteLength=10 ** 12))
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and "byteLength 1000000000000 is over the size cap of 2147483648" in err
    edit_json(scene, lambda doc: doc["buffers"][0].update(byteLength=len(blob)))
    monkeypatch.setenv("OMAPS_MAX_ASSET_BYTES", str(len(blob) - 1))
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and "over the size cap" in err and "OMAPS_MAX_ASSET_BYTES" in err
    monkeypatch.setenv("OMAPS_MAX_ASSET_BYTES", "2000")
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 0, err
    # an image file over the cap
    (asset / "leaf.png").write_bytes(png_bytes(np.random.default_rng(0).integers(0, 256, (64, 64), np.uint8)))
    rc, err = omm(capsys, scene, tmp / "o2.glb")
    assert rc == 2 and "image 0" in err and "'leaf.png' holds" in err and "over the size cap" in err
    # a data URI over the cap (the file holding it is too): refused before decoding
    set_uri(scene, "images", "data:image/png;base64," + base64.b64encode(b"\0" * 3000).decode())
    rc, err = omm(capsys, scene, tmp / "o3.glb")
    assert rc == 2 and "over the size cap of 2000" in err
    monkeypatch.setenv("OMAPS_MAX_ASSET_BYTES", "lots")
    rc, err = omm(capsys, scene, tmp / "o4.glb")
    assert rc == 2 and "OMAPS_MAX_ASSET_BYTES is 'lots'" in err


def test_library_keywords(tree):
    tmp, asset, outside, scene = tree
    set_uri(scene, "buffers", "../outside/secret.bin")
    with pytest.raises(InputError, match="allow_outside") as e:  # the keywords, in Python terms
        load_scene(scene)
    assert "--" not in str(e.value) and set(e.value.params) == {"root", "allow_outside"}
    import omaps

    for kw in ({"root": tmp}, {"allow_outside": True}):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = omaps.load_scene(scene, **kw)
        assert np.allclose(s.meshes[0].primitives[0].positions, SECRET_POS)
    with pytest.raises(InputError, match="over the size cap of 10"):
        load_scene(scene, allow_outside=True, max_bytes=10)


def test_decompression_bomb_is_an_error(tree, capsys, monkeypatch):
    tmp, asset, outside, scene = tree
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)  # the 16 x 16 leaf is over it (a warning in Pillow)
    rc, err = omm(capsys, scene, tmp / "o.glb")
    assert rc == 2 and str(scene) in err and "image 0 ('leaf.png')" in err and "decompression-bomb" in err
    assert not (tmp / "o.glb").exists()


def test_trace_refuses_too(tree, capsys):
    tmp, asset, outside, scene = tree
    set_uri(scene, "buffers", "../outside/secret.bin")
    rc, err = run(capsys, "trace", scene, "--size", "8", "--schemes", "none", "--quiet", "--json", tmp / "t.json")
    assert rc == 2 and "--allow-outside" in err and not (tmp / "t.json").exists()
    rc, err = run(capsys, "trace", scene, "--size", "8", "--schemes", "none", "--quiet", "--json", tmp / "t.json",
                  "--root", tmp)
    assert rc == 0, err


def test_batch_records_the_refusal(tree):
    """``omaps batch omm`` over a folder holding a bad asset: its error is in the summary, the
    good one is baked, and no output holds the outside file's bytes."""
    tmp, asset, outside, scene = tree
    set_uri(scene, "buffers", "../outside/secret.bin")
    good = tmp / "asset" / "good"
    good.mkdir()
    write_quad_gltf(good / "good.gltf", ALPHA)
    out = tmp / "batch"
    r = subprocess.run([sys.executable, "-m", "omaps.cli", "batch", "omm", str(asset), "-o", str(out), "--glb",
                        "--level", "2", "--scheduler", "none", "--quiet"], capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    by_input = {os.path.basename(x["input"]): x for x in summary["inputs"]}
    assert by_input["good.gltf"]["status"] == "ok"
    bad = by_input["scene.gltf"]
    assert bad["status"] == "error" and "../outside/secret.bin" in bad["error"] and "allow_outside" in bad["error"]
    secret = (outside / "secret.bin").read_bytes()[:48]  # the outside quad's positions
    for root, _, files in os.walk(out):
        for f in files:
            assert secret not in open(os.path.join(root, f), "rb").read(), f
    # the batch's root is the folder given: a scene may name a file elsewhere in it
    (asset / "shared.bin").write_bytes(quad_blob())
    write_quad_gltf(good / "uses_shared.gltf", ALPHA)
    edit_json(good / "uses_shared.gltf", lambda doc: doc["buffers"][0].update(uri="../shared.bin"))
    r = subprocess.run([sys.executable, "-m", "omaps.cli", "batch", "omm", str(good), str(asset / "shared.bin"),
                        "-o", str(tmp / "b2"), "--glb", "--level", "2", "--scheduler", "none", "--quiet"],
                       capture_output=True, text=True)
    summary = json.loads((tmp / "b2" / "summary.json").read_text())
    status = {os.path.basename(x["input"]): x["status"] for x in summary["inputs"]}
    assert status["uses_shared.gltf"] == "error"  # the folder given is good/: shared.bin lies outside it
    r = subprocess.run([sys.executable, "-m", "omaps.cli", "batch", "omm", str(asset), "-o", str(tmp / "b3"),
                        "--glb", "--level", "2", "--scheduler", "none", "--quiet"], capture_output=True, text=True)
    summary = json.loads((tmp / "b3" / "summary.json").read_text())
    status = {os.path.basename(x["input"]): x["status"] for x in summary["inputs"]}
    assert status["uses_shared.gltf"] == "ok" and status["scene.gltf"] == "error"


# -- the real assets bake exactly as before ----------------------------------------------------------

# sha256 of `omaps omm SCENE --level 4 -o OUT.glb`, captured before the URI policy existed;
# captured again when the pipeline began visiting triangles in locality order (records in another
# order; every triangle's states checked equal to the earlier output's, and the statistics, but for
# the last digits of smallpine's known_area_fraction, a sum in another order); smallpine's again
# when outputs became self-contained (its scene.bin and images now inside the .glb, its missing
# normal map left out; every accessor's, image's and micromap's bytes checked equal to the earlier
# output's, the JSON equal but for the buffers, buffer views and that image). palm.glb's is unchanged.
REAL_GLB = {
    "palm.glb": "130e34afd0a992f1d5eea450b1354eb702e72f1b182a3682a1261901e0b0527b",
    "smallpine/scene.gltf": "5d98205dac4a50ac642f5780f6766fb64ae66bc2fb5eba0017140b9409fe7673",
}


def normalised_glb_hash(path, src_dir) -> str:
    """sha256 of a .glb, which names no file (the output holds every buffer and image): the same
    whatever folder it was written in and whatever ``--root`` or ``--allow-outside`` said."""
    raw = open(path, "rb").read()
    n = int.from_bytes(raw[12:16], "little")
    doc = json.loads(raw[20:20 + n])
    assert not [x for x in doc.get("buffers", []) + doc.get("images", []) if "uri" in x]
    return hashlib.sha256(raw).hexdigest()


@needs_scenes
@pytest.mark.parametrize("name", sorted(REAL_GLB))
def test_real_scenes_bake_as_before(tmp_path, capsys, name):
    src = SCENES / name
    got = {}
    for options in ([], ["--allow-outside"], ["--root", str(SCENES)]):
        out = tmp_path / f"o{len(got)}.glb"
        rc, err = run(capsys, "omm", src, "--level", "4", "--quiet", "-o", out, *options)
        assert rc == 0, err
        got[tuple(options)] = normalised_glb_hash(out, src.parent)
    assert set(got.values()) == {REAL_GLB[name]}, got


@needs_scenes
def test_khronos_scenes_read_under_the_policy():
    scenes = sorted((SCENES / "khronos").glob("*/*.gl*"))
    assert scenes
    for p in scenes:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = load_scene(p)
            b = load_scene(p, allow_outside=True)
        assert a.counts() == b.counts() and not [w for w in a.warnings if "outside" in w or "fetch" in w]
