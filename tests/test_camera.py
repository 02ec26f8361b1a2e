"""The tracer's camera: --camera values starting with '-', an up vector (roll), cameras stored in
the glTF file (--camera gltf[:N]), and a default view that shows the alpha-tested geometry."""

import json
import math
import struct

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import edit_json, write_quad_gltf
from omaps import trace
from omaps.cli import main
from omaps.cli.trace import bind_camera_value
from omaps.scene import load_scene
from omaps.schemes import parse_schemes


def _checker(n=8):
    return (np.indices((n, n)).sum(axis=0) % 2 * 255).astype(np.uint8)


def _quad(tmp_path, name="q.gltf", **kw):
    return write_quad_gltf(tmp_path / name, _checker(), sampler={"magFilter": 9728, "wrapS": 33071,
                                                                  "wrapT": 33071}, **kw)


# -- --camera values starting with '-' ----------------------------------------------------------

def test_bind_camera_value():
    v = "-70,130,-70:0,175,0:70"
    assert bind_camera_value(["trace", "s.glb", "--camera", v]) == ["trace", "s.glb", f"--camera={v}"]
    assert bind_camera_value(["trace", "--cam", v, "s.glb"]) == ["trace", f"--cam={v}", "s.glb"]
    assert bind_camera_value(["trace", "s.glb", "--camera", "-.5,1,2:0,0,0:40"])[-1] == "--camera=-.5,1,2:0,0,0:40"
    untouched = [["trace", "s.glb", "--camera", "1,2,3:0,0,0:40"], ["trace", "s.glb", "--camera", "--size"],
                 ["eval", "--camera", "-1"], ["trace", "s.glb", "--", "--camera", "-1,0,0:0,0,0:40"],
                 ["trace", "s.glb", "--ca", "-1,0,0:0,0,0:40"]]
    for argv in untouched:
        assert bind_camera_value(argv) == argv


@pytest.mark.parametrize("form", ["space", "equals", "abbreviated"])
def test_camera_value_starting_with_minus_through_main(tmp_path, form):
    f = _quad(tmp_path)
    j = tmp_path / "r.json"
    v = "-1,0.5,2:0.5,0.5,0:40"
    cam = {"space": ["--camera", v], "equals": [f"--camera={v}"], "abbreviated": ["--came", v]}[form]
    assert main(["trace", f, "--schemes", "none,sq8", "--size", "24", "--quiet", "--json", str(j)] + cam) == 0
    r = json.loads(j.read_text())
    assert r["camera"]["eye"] == [-1.0, 0.5, 2.0] and r["camera"]["fov"] == 40.0
    assert r["camera"]["view"] == {"chosen": "--camera"}
    assert r["schemes"]["none"]["candidates_per_primary_ray"] > 0


# -- the up vector -------------------------------------------------------------------------------

def _hits(prep, cam, n):
    run = trace.trace_scheme(prep, "none", cam.basis(n, n), n, n).primary
    return run.inst >= 0


def test_up_vector_rolls_the_image(tmp_path):
    """Looking down -z at the quad with up = +x shows the upright image turned a quarter
    counter-clockwise (+x, the upright image's right, is the rolled image's top)."""
    alpha = np.zeros((8, 8), np.uint8)
    alpha[1:7, 1:3] = 255  # an L: its stem on the left, its foot along the bottom
    alpha[5:7, 1:6] = 255
    f = write_quad_gltf(tmp_path / "l.gltf", alpha, sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33071})
    prep = trace.prepare(load_scene(f), parse_schemes("none"))
    eye, target = np.array([0.5, 0.5, 1.6]), np.array([0.5, 0.5, 0.0])
    n = 64
    upright = _hits(prep, trace.Camera(eye, target, 40.0), n)
    assert np.array_equal(upright, _hits(prep, trace.Camera(eye, target, 40.0, np.array([0.0, 1.0, 0.0])), n))
    rolled = _hits(prep, trace.Camera(eye, target, 40.0, np.array([1.0, 0.0, 0.0])), n)
    assert 300 < upright.sum() < n * n / 2
    assert np.mean(rolled == np.rot90(upright, 1)) > 0.995
    assert np.mean(rolled == upright) < 0.9 and np.mean(rolled == np.rot90(upright, -1)) < 0.9
    b = trace.Camera(eye, target, 40.0, np.array([1.0, 0.0, 5.0])).basis(n, n)  # up made orthogonal to forward
    np.testing.assert_allclose(b[9:12] / np.linalg.norm(b[9:12]), [1, 0, 0], atol=1e-12)
    with pytest.raises(ValueError):
        trace.Camera(eye, target, 40.0, np.array([0.0, 0.0, 2.0])).basis(n, n)


@pytest.mark.parametrize("up, problem", [("0,0,1", "parallel"), ("0,0,0", "parallel"), ("1,2", "--camera up")])
def test_cli_camera_up_errors(tmp_path, capsys, up, problem):
    f = _quad(tmp_path)
    j = tmp_path / "r.json"
    assert main(["trace", f, "--camera", f"0.5,0.5,2:0.5,0.5,0:40:{up}", "--json", str(j), "--quiet"]) == 2
    assert problem in capsys.readouterr().err and not j.exists()


# -- cameras stored in the file ------------------------------------------------------------------

def _quat(axis, degrees):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = math.radians(degrees) / 2
    return [*(a * math.sin(h)).tolist(), math.cos(h)]


def _with_cameras(tmp_path, cameras, camera_nodes, name="cam.gltf"):
    """The quad plus ``cameras`` and nodes placing them (node dicts with a 'camera' key; a
    'parent' key makes the node a child of a new node with that translation)."""
    f = _quad(tmp_path, name)

    def fn(doc):
        doc["cameras"] = cameras
        for nd in camera_nodes:
            nd = dict(nd)
            parent = nd.pop("parent", None)
            doc["nodes"].append(nd)
            k = len(doc["nodes"]) - 1
            if parent is not None:
                doc["nodes"].append({"translation": parent, "children": [k]})
                k += 1
            doc["scenes"][0]["nodes"].append(k)
    return edit_json(f, fn)


PERSP = {"type": "perspective", "perspective": {"yfov": math.radians(40), "znear": 0.01, "aspectRatio": 2.0}}


def test_gltf_camera_is_placed_by_its_node(tmp_path):
    """Camera 0: rolled 90 degrees about its view axis, under a translated parent; camera 1: turned
    90 degrees about +Y (looking along -x); camera 2 is placed by no node; camera 3 orthographic."""
    ortho = {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.01, "zfar": 10}}
    f = _with_cameras(tmp_path, [PERSP, PERSP, PERSP, ortho], [
        {"camera": 0, "translation": [0.0, 0.5, 1.5], "rotation": _quat([0, 0, 1], 90), "parent": [0.5, 0.0, 0.5]},
        {"camera": 1, "translation": [3.0, 0.5, 0.0], "rotation": _quat([0, 1, 0], 90)},
        {"camera": 3, "translation": [0.5, 0.5, 2.0]}])
    scene = load_scene(f)
    assert len(scene.cameras) == 4
    c0, c1, c2, c3 = scene.cameras
    np.testing.assert_allclose(c0.eye, [0.5, 0.5, 2.0], atol=1e-12)
    np.testing.assert_allclose(c0.forward, [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(c0.up, [-1, 0, 0], atol=1e-12)  # +Y turned 90 degrees about +Z
    np.testing.assert_allclose(c1.forward, [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(c1.up, [0, 1, 0], atol=1e-12)
    assert c0.problem is None and c1.problem is None and c0.aspect == 2.0
    assert c2.node is None and "not placed" in c2.problem
    assert "orthographic" in c3.problem
    cam = trace.gltf_camera(scene, 0)
    assert cam.fov == pytest.approx(40.0)
    want = trace.Camera(np.array([0.5, 0.5, 2.0]), np.array([0.5, 0.5, 0.0]), 40.0, np.array([-1.0, 0, 0]))
    np.testing.assert_allclose(cam.basis(40, 30), want.basis(40, 30), atol=1e-12)  # aspect from our image


def test_cli_gltf_camera(tmp_path, capsys):
    ortho = {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.01, "zfar": 10}}
    f = _with_cameras(tmp_path, [PERSP, ortho], [
        {"camera": 0, "translation": [0.5, 0.5, 2.0], "rotation": _quat([0, 0, 1], 90)},
        {"camera": 1, "translation": [0.5, 0.5, 2.0]}])
    j = tmp_path / "r.json"
    base = ["trace", f, "--schemes", "none,sq8", "--size", "32x24", "--quiet", "--json", str(j)]
    for form in (["--camera", "gltf"], ["--camera", "gltf:0"]):
        assert main(base + form) == 0
        r = json.loads(j.read_text())
        np.testing.assert_allclose(r["camera"]["eye"], [0.5, 0.5, 2.0], atol=1e-9)
        np.testing.assert_allclose(r["camera"]["up"], [-1, 0, 0], atol=1e-9)
        assert r["camera"]["fov"] == pytest.approx(40.0) and r["camera"]["view"] == {"chosen": "gltf:0"}
        assert r["schemes"]["none"]["candidates_per_primary_ray"] > 0.3
        j.unlink()
    # the same view given explicitly sees the same thing
    assert main(base + ["--camera", "0.5,0.5,2:0.5,0.5,0:40:-1,0,0"]) == 0
    explicit = json.loads(j.read_text())
    j.unlink()
    assert main(base + ["--camera", "gltf"]) == 0
    stored = json.loads(j.read_text())["schemes"]["none"]
    for k in ("candidates_per_primary_ray", "alpha_tests_per_primary_ray"):
        assert stored[k] == pytest.approx(explicit["schemes"]["none"][k], abs=0.01)
    j.unlink()
    capsys.readouterr()
    for cam, problem in (("gltf:2", "the file has 2 cameras (0-1)"), ("gltf:1", "orthographic"),
                         ("gltf:x", "camera index"), ("gltf:-1", "camera index")):
        assert main(base + ["--camera", cam]) == 2
        err = capsys.readouterr().err
        assert problem in err and not j.exists()
        if cam in ("gltf:2", "gltf:1"):
            assert "cam.gltf" in err


def test_cli_gltf_camera_in_a_file_without_cameras(tmp_path, capsys):
    f = _quad(tmp_path)
    assert main(["trace", f, "--camera", "gltf", "--size", "8", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "q.gltf" in err and "no cameras" in err


def test_node_with_a_missing_camera_is_an_error(tmp_path, capsys):
    f = _with_cameras(tmp_path, [PERSP], [{"camera": 3, "translation": [0, 0, 2]}])
    assert main(["trace", f, "--size", "8", "--quiet"]) == 2
    assert "camera 3 does not exist" in capsys.readouterr().err


# -- the default view ----------------------------------------------------------------------------

def _alpha_seen(prep, cam, w=96, h=64) -> float:
    """Share of pixels whose ray meets at least one alpha-tested triangle (scheme 'none')."""
    run = trace.trace_scheme(prep, "none", cam.basis(w, h), w, h).primary
    return float(np.mean(run.candidates > 0))


def _glb_json(path, fn, out):
    """A copy of a .glb with its JSON chunk edited by ``fn``."""
    data = open(path, "rb").read()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    fn(doc)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + n:]
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + rest
    with open(out, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
    return str(out)


def _all_mask(doc):
    for m in doc["materials"]:
        m["alphaMode"] = "MASK"


SHARED_SCENES = ["palm.glb", "smallpine/scene.gltf", "khronos/AlphaBlendModeTest/AlphaBlendModeTest.glb",
                 "forest.glb", "TextureSettingsTest, every material MASK"]


@needs_scenes
@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("name", SHARED_SCENES)
def test_default_view_shows_alpha_tested_geometry(tmp_path, name):
    if name.startswith("TextureSettingsTest"):
        src = SCENES / "khronos" / "TextureSettingsTest" / "TextureSettingsTest.glb"
        if not src.is_file():
            pytest.skip(f"{src} is absent")
        path = _glb_json(src, _all_mask, tmp_path / "mask.glb")
    else:
        path = SCENES / name
        if not path.is_file():
            pytest.skip(f"{path} is absent")
    scene = load_scene(path)
    assert scene.counts()["alpha_triangles"] > 0
    prep = trace.prepare(scene, parse_schemes("none"))
    cam, info = trace.choose_default_camera(prep, 96, 64)
    assert info["alpha_fraction"] >= trace.camera.MIN_ALPHA_FRACTION
    assert _alpha_seen(prep, cam) >= 0.01
    if name == "forest.glb":  # the grazing view across the forest is the one every published figure used
        lo, hi = scene.bounds()
        np.testing.assert_allclose(cam.eye, lo + (hi - lo) * [0.03, 0.12, 0.03])
        np.testing.assert_allclose(cam.target, lo + (hi - lo) * [0.97, 0.2, 0.97])
        assert info["chosen"] == "default" and cam.fov == 60.0


def test_default_view_looks_past_an_opaque_wall(tmp_path):
    """The alpha-tested quad hides behind an opaque wall on its front (+z) side: the preferred
    view from the front sees only the wall, so a fallback view that shows the quad is chosen."""
    f = _quad(tmp_path, "wall.gltf")

    def fn(doc):
        doc["materials"].append({"name": "wall", "alphaMode": "OPAQUE"})
        doc["meshes"].append({"primitives": [{"attributes": {"POSITION": 0}, "indices": 2, "material": 1}]})
        doc["nodes"].append({"mesh": 1, "translation": [-4.0, -4.0, 0.3], "scale": [9.0, 9.0, 1.0]})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
    edit_json(f, fn)
    scene = load_scene(f)
    prep = trace.prepare(scene, parse_schemes("none"))
    preferred = trace.default_camera(scene.bounds(), scene.alpha_bounds(), 96 / 64)
    assert _alpha_seen(prep, preferred) == 0  # the wall hides it
    cam, info = trace.choose_default_camera(prep, 96, 64)
    assert info["chosen"] != "default" and info["default_alpha_fraction"] == 0
    assert _alpha_seen(prep, cam) > 0.05


def test_default_view_of_a_scene_without_alpha_tested_geometry(tmp_path):
    f = write_quad_gltf(tmp_path / "o.gltf", _checker(), material={"alphaMode": "OPAQUE"})
    scene = load_scene(f)
    assert scene.alpha_bounds() is None
    prep = trace.prepare(scene, parse_schemes("none"))
    cam, info = trace.choose_default_camera(prep, 32, 32)
    assert info["chosen"] == "default"
    run = trace.trace_scheme(prep, None, cam.basis(32, 32), 32, 32).primary
    assert np.mean(run.inst >= 0) > 0.05  # all geometry framed


def test_alpha_bounds_transform_each_instance(tmp_path):
    f = write_quad_gltf(tmp_path / "i.gltf", _checker(), nodes=[
        {"translation": [10.0, 0.0, 0.0]}, {"translation": [0.0, 5.0, 0.0], "scale": [2.0, 2.0, 2.0]}])
    lo, hi = load_scene(f).alpha_bounds()
    np.testing.assert_allclose(lo, [0, 0, 0])
    np.testing.assert_allclose(hi, [11, 7, 0])


def test_default_view_of_a_flat_alpha_quad_on_the_ground(tmp_path):
    """A horizontal quad is wide but has no height: a grazing view would run along its plane, so
    it is framed from above."""
    f = write_quad_gltf(tmp_path / "flat.gltf", _checker(), nodes=[{"rotation": _quat([1, 0, 0], -90)}])
    scene = load_scene(f)
    lo, hi = scene.alpha_bounds()
    assert hi[1] - lo[1] < 1e-6
    prep = trace.prepare(scene, parse_schemes("none"))
    cam, info = trace.choose_default_camera(prep, 96, 64)
    f = (cam.target - cam.eye) / np.linalg.norm(cam.target - cam.eye)
    assert info["chosen"] == "default" and f[1] < -0.5
    assert _alpha_seen(prep, cam) > 0.05
