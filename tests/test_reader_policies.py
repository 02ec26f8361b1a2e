"""Reader policies on messy scenes, through both commands: NaN / infinite / huge texture coordinates, a
MASK material whose image has no alpha channel (JPEG), missing files named exactly once, and a
trace whose check fails."""

import base64
import io
import json

import numpy as np
import pytest
from PIL import Image

from conftest import SCENES, needs_scenes
from gltf_files import QUAD_IDX, QUAD_POS, QUAD_UV, edit_json, write_quad_gltf
from omaps import trace
from omaps.cli import main
from omaps.scene import SceneWarning, load_scene
from omaps.schemes import parse_schemes

ALL_SCHEMES = "none,tri3,sq16,vq2,vq4,vq4x64"


def _corners_opaque(n=16):
    """Opaque only at the four corner texels: UV (0, 0), bilinear and wrapped, reads all four."""
    a = np.zeros((n, n), np.uint8)
    a[[0, 0, -1, -1], [0, -1, 0, -1]] = 255
    a[4:12, 4:12] = 255  # and a block in the middle, for the good triangle
    return a


# -- NaN, infinite and huge texture coordinates --------------------------------------------------------

def _bad_uv_quad(tmp_path, value):
    uv = QUAD_UV.copy()
    uv[1] = value  # vertex 1 belongs to triangle 0 only (triangles 0 1 2 and 0 2 3)
    return write_quad_gltf(tmp_path / "bad.gltf", _corners_opaque(), uvs=uv)


MESSAGE = "mesh 0 (mesh 0) primitive 0: 1 triangles have NaN, infinite or huge (beyond 2^30 texels) texture"


@pytest.mark.parametrize("value", [(np.nan, 0.5), (np.inf, 0.0), (0.3, -np.inf), (1e30, 0.0), (0.0, -1e9)])
def test_bad_uvs_trace_compares_equal(tmp_path, capsys, value):
    f = _bad_uv_quad(tmp_path, value)
    j = tmp_path / "r.json"
    assert main(["trace", f, "--schemes", ALL_SCHEMES, "--two-state", "all", "--shadows", "--size", "48",
                 "--quiet", "--json", str(j)]) == 0
    err = capsys.readouterr().err
    assert err.count(MESSAGE) == 1 and "bad.gltf" in err
    r = json.loads(j.read_text())
    assert r["passed"] is True and r["changed_visible_result"] == {}
    assert set(r["schemes"]) == set(ALL_SCHEMES.split(","))
    for n, s in r["schemes"].items():
        assert s["differing_pixels"] == 0 and s["differing_shadow_rays"] == 0, n
        assert s["deferred_differing_shadow_rays"] == 0, n
    assert r["schemes"]["none"]["candidates_per_primary_ray"] > 0.1  # the default view sees the quad
    assert any(MESSAGE in w for w in r["scene"]["warnings"])


@pytest.mark.parametrize("fmt, specials", [("4state", (-3, -4)), ("2state", (-1, -2))])
@pytest.mark.parametrize("value", [(np.nan, np.nan), (1e30, 1e30)])
def test_bad_uvs_omm_special_index(tmp_path, capsys, fmt, specials, value):
    f = _bad_uv_quad(tmp_path, value)
    out = tmp_path / "omm"
    assert main(["omm", f, "-o", str(out), "--level", "4", "--format", fmt, "--quiet"]) == 0
    assert capsys.readouterr().err.count(MESSAGE) == 1
    index = np.fromfile(out / "omm_index.bin", np.int32)
    assert len(index) == 2 and index[0] in specials  # the unknown triangle: one special index
    meta = json.loads((out / "omm.json").read_text())
    assert meta["geometries"][0]["unknown_triangles"] == 1
    assert any(MESSAGE in w for w in meta["warnings"])
    assert main(["omm", "--verify", str(out)]) == 0


def test_bad_uv_triangle_reads_the_texture_at_uv_origin(tmp_path):
    """What the any-hit shader sees on a triangle with a NaN coordinate: UV (0, 0) at every
    vertex -- the same hits as the quad written with those UVs, and its neighbour untouched."""
    pos = QUAD_POS[QUAD_IDX]  # six vertices, none shared
    idx = np.arange(6, dtype=np.uint16)
    uv_nan = QUAD_UV[QUAD_IDX].copy()
    uv_nan[1] = np.nan
    uv_zero = QUAD_UV[QUAD_IDX].copy()
    uv_zero[:3] = 0.0
    sampler = {"magFilter": 9729, "wrapS": 10497, "wrapT": 10497}
    with pytest.warns(SceneWarning, match="NaN, infinite or huge"):
        a = load_scene(write_quad_gltf(tmp_path / "nan.gltf", _corners_opaque(), positions=pos, uvs=uv_nan,
                                       indices=idx, sampler=sampler))
    b = load_scene(write_quad_gltf(tmp_path / "zero.gltf", _corners_opaque(), positions=pos, uvs=uv_zero,
                                   indices=idx, sampler=sampler))
    p = a.meshes[0].primitives[0]
    np.testing.assert_array_equal(p.tris_uv[0], 0.0)
    np.testing.assert_array_equal(p.tris_uv[1], b.meshes[0].primitives[0].tris_uv[1])
    assert p.unknown.tolist() == [True, False]
    cam = trace.Camera(np.array([0.5, 0.5, 2.0]), np.array([0.5, 0.5, 0.0]), 40.0).basis(48, 48)
    runs = []
    for scene in (a, b):
        prep = trace.prepare(scene, parse_schemes("none,sq16,tri3"))
        runs.append({n: trace.trace_scheme(prep, n, cam, 48, 48).primary for n in ("none", "sq16", "tri3")})
    ra, rb = runs
    assert trace.differing_pixels(ra["none"], rb["none"]) == 0
    assert trace.differing_pixels(ra["sq16"], ra["none"]) == 0 and trace.differing_pixels(ra["tri3"], ra["none"]) == 0
    assert np.count_nonzero(ra["none"].prim == 0) > 200  # the four corner texels read at (0, 0) are opaque
    assert np.all(ra["sq16"].tests[ra["none"].prim == 0] >= 1)  # unknown: its hits run the shader


# -- a MASK material whose image has no alpha channel ----------------------------------------------

def _jpeg_uri():
    buf = io.BytesIO()
    Image.fromarray(np.full((8, 8, 3), 120, np.uint8), "RGB").save(buf, format="JPEG")
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode()


def test_mask_material_with_a_jpeg_texture_warns(tmp_path, capsys):
    f = write_quad_gltf(tmp_path / "jpeg.gltf", np.zeros((2, 2), np.uint8))
    edit_json(f, lambda doc: doc["images"][0].update(uri=_jpeg_uri()))
    with pytest.warns(SceneWarning, match=r"material 0 \(leaf\) is MASK but its base colour image .* has no alpha"):
        scene = load_scene(f)
    assert scene.textures[0].has_alpha is False and np.all(scene.textures[0].alpha == 255)
    j = tmp_path / "r.json"
    assert main(["trace", f, "--schemes", "none,sq8", "--size", "16", "--quiet", "--json", str(j)]) == 0
    assert capsys.readouterr().err.count("has no alpha channel") == 1
    r = json.loads(j.read_text())
    assert r["schemes"]["sq8"]["alpha_tests_per_primary_ray"] == 0 < r["schemes"]["none"]["candidates_per_primary_ray"]
    assert main(["omm", f, "-o", str(tmp_path / "omm"), "--level", "2", "--quiet"]) == 0
    assert capsys.readouterr().err.count("has no alpha channel") == 1
    assert np.all(np.fromfile(tmp_path / "omm" / "omm_index.bin", np.int32) == -2)  # alpha 1: all opaque


# -- missing files: one warning each per run -------------------------------------------------------

def test_each_missing_file_warns_once(tmp_path, capsys):
    """normal.png: the normal map of two materials (three image entries, one of them repeated);
    leaf.png: a base colour of two materials and also listed as an unused image."""
    f = write_quad_gltf(tmp_path / "m.gltf", None, image_uri="leaf.png", extra_images=("normal.png", "normal.png",
                                                                                        "leaf.png"))

    def fn(doc):
        doc["textures"] += [{"source": 1}, {"source": 2}]
        doc["materials"][0]["normalTexture"] = {"index": 1}
        doc["materials"].append({**doc["materials"][0], "name": "leaf2", "normalTexture": {"index": 2}})
        doc["meshes"][0]["primitives"].append({**doc["meshes"][0]["primitives"][0], "material": 1})
        doc["nodes"].append({"mesh": 0, "translation": [2.0, 0.0, 0.0]})
        doc["scenes"][0]["nodes"].append(1)
    edit_json(f, fn)
    with pytest.warns(SceneWarning) as rec:
        scene = load_scene(f)
    messages = [str(w.message) for w in rec]
    assert sum("normal.png" in m for m in messages) == 1 and sum("leaf.png" in m for m in messages) == 1
    assert len(scene.warnings) == 2
    assert main(["trace", f, "--schemes", "none,tri2", "--size", "8", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("normal.png") == 1 and err.count("leaf.png") == 1
    assert main(["omm", f, "-o", str(tmp_path / "omm"), "--level", "2", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("normal.png") == 1 and err.count("leaf.png") == 1


@needs_scenes
def test_smallpine_missing_normal_map_warns_once_per_command(tmp_path, capsys):
    f = str(SCENES / "smallpine" / "scene.gltf")
    assert main(["trace", f, "--schemes", "none,sq8", "--size", "16", "--quiet"]) == 0
    assert capsys.readouterr().err.count("M_TreeAtlas_normal.png") == 1
    assert main(["omm", f, "-o", str(tmp_path / "omm"), "--level", "1", "--quiet"]) == 0
    assert capsys.readouterr().err.count("M_TreeAtlas_normal.png") == 1


# -- a trace whose check fails ---------------------------------------------------------------------

def test_failed_trace_writes_complete_outputs_and_says_so(tmp_path, capsys, monkeypatch):
    """Exit 1 when a scheme changes the visible result (here: the comparison is made to report
    differences), after writing every output asked for, whole, with passed: false."""
    import omaps.trace.metrics as metrics

    real = metrics.differing_pixels
    monkeypatch.setattr(metrics, "differing_pixels", lambda a, b: real(a, b) + (a is not b))
    f = write_quad_gltf(tmp_path / "q.gltf", _corners_opaque())
    j, hm, rd = tmp_path / "r.json", tmp_path / "h.png", tmp_path / "r.png"
    assert main(["trace", f, "--schemes", "none,sq8", "--size", "16", "--quiet", "--json", str(j),
                 "--heatmap", str(hm), "--render", str(rd)]) == 1
    assert "a scheme changed the visible result: sq8 (1)" in capsys.readouterr().err
    r = json.loads(j.read_text())
    assert r["passed"] is False and r["changed_visible_result"] == {"sq8": 1}
    assert Image.open(rd).size == (16, 16) and Image.open(hm).size[0] > 16
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.png", "q.gltf", "r.json", "r.png"]
