"""glTF loading: geometry, instances, materials, UV conventions, missing files."""

import math
import warnings

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import QUAD_UV, write_quad_gltf
from omaps.alpha_test import MaterialRules, passes
from omaps.cli import main
from omaps.errors import InputError
from omaps.scene import SceneWarning, load_scene
from omaps.scene.gltf import texture_transform_matrix


def test_quad_geometry_uvs_and_material(tmp_path):
    alpha = np.zeros((4, 8), np.uint8)
    alpha[0, :] = 255  # first image row = v in [0, 1/4]
    f = write_quad_gltf(tmp_path / "q.gltf", alpha, material={"alphaCutoff": 0.3},
                        sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33648})
    s = load_scene(f)
    assert len(s.meshes) == 1 and len(s.instances) == 1 and len(s.meshes[0].primitives) == 1
    m = s.meshes[0].primitives[0]
    np.testing.assert_array_equal(m.triangles, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(m.uvs, QUAD_UV)
    np.testing.assert_array_equal(s.meshes[0].merged["material"], [m.material, m.material])
    mat = s.materials[m.material]
    assert (mat.alpha_mode, mat.cutoff, mat.filter, mat.wrap_u, mat.wrap_v) == ("MASK", pytest.approx(0.3),
                                                                                "nearest", "clamp", "mirror")
    tex = s.textures[mat.texture]
    assert tex.alpha.shape == (4, 8) and tex.rgb.shape == (4, 8, 3) and tex.maxval == 255 and tex.problem is None
    # the stored values, not flipped: the top of the quad (y = 1) has v = 0, the first image row
    top = m.uvs[m.positions[:, 1] == 1]
    assert np.all(top[:, 1] == 0) and np.all(tex.alpha[0] == 255)
    assert s.counts() == {"instances": 1, "prototypes": 1, "triangles": 2, "alpha_triangles": 2,
                          "prototype_triangles": 2, "prototype_alpha_triangles": 2}


def test_instances_trs_and_bounds(tmp_path):
    q = [0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)]  # 90 degrees about y
    nodes = [{"translation": [10, 0, 0]}, {"rotation": q, "scale": [2, 2, 2]},
             {"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1]}]
    s = load_scene(write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), nodes=nodes))
    assert len(s.instances) == 3 and len(s.meshes) == 1
    x = np.array([1.0, 0, 0, 1])
    np.testing.assert_allclose(s.instances[0][1] @ x, [11, 0, 0, 1])
    np.testing.assert_allclose(s.instances[1][1] @ x, [0, 0, -2, 1], atol=1e-12)  # x -> -z, scaled
    np.testing.assert_allclose(s.instances[2][1] @ x, [1, 5, 0, 1])
    np.testing.assert_allclose(s.bounds(), [[0, 0, -2], [11, 6, 0]], atol=1e-12)
    assert s.counts()["triangles"] == 6


def test_texture_transform_is_applied(tmp_path):
    ext = {"offset": [0.25, 0.5], "rotation": 0.3, "scale": [2, 3]}
    s = load_scene(write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), uv_transform=ext))
    # the extension's definition: T * R * S with R = [[cos, sin], [-sin, cos]]
    c, sn = math.cos(0.3), math.sin(0.3)
    expect = (np.array([[c, sn], [-sn, c]]) @ (np.diag([2, 3]) @ QUAD_UV.T.astype(float))).T + [0.25, 0.5]
    np.testing.assert_allclose(s.meshes[0].primitives[0].uvs, expect, atol=1e-12)
    np.testing.assert_allclose(texture_transform_matrix({}), np.eye(2, 3))


def test_blend_is_alpha_tested_at_the_given_cutoff(tmp_path):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), material={"alphaMode": "BLEND"})
    s = load_scene(f)
    assert s.materials[0].alpha_mode == "BLEND" and s.alpha_tested()[0]
    # default (levels): T only at alpha 0, O only at alpha 1; the shader decides the rest at 0.5
    t = s.alpha_test(0)
    assert (t.rule, t.low, t.high, t.threshold, t.inclusive) == ("levels", 0.0, 255.0, 0.5 * 255, True)
    t = s.alpha_test(0, MaterialRules(blend="cutoff", blend_cutoff=0.1))
    assert (t.rule, t.threshold, t.inclusive) == ("test", pytest.approx(0.1 * 255), True)
    assert s.alpha_test(0, MaterialRules(blend_cutoff=0.1)).threshold == pytest.approx(0.1 * 255)
    assert not s.alpha_tested(MaterialRules(blend="skip"))[0]
    with pytest.raises(InputError, match="blend_cutoff must be in"):
        MaterialRules(blend_cutoff=2)


def test_missing_image_warns_and_falls_back_to_white(tmp_path):
    f = write_quad_gltf(tmp_path / "q.gltf", None, image_uri="gone.png", extra_images=["normal_gone.png"])
    with pytest.warns(SceneWarning) as rec:
        s = load_scene(f)
    text = " ".join(str(w.message) for w in rec)
    assert "gone.png" in text and "normal_gone.png" in text
    tex = s.textures[s.materials[0].texture]
    assert tex.alpha is None and "gone.png" in tex.problem
    # still alpha-tested, every texel unknown; the shader sees one texel of alpha 1, which passes
    t = s.alpha_test(0)
    assert t.rule == "unknown" and t.value.shape == (1, 1) and passes.py_func(t.value, t.threshold, t.inclusive).all()
    assert np.all(t.texel_states() == 2)
    assert len(s.warnings) == 2


def test_missing_buffer_is_an_error_naming_it(tmp_path, capsys):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), bin_uri="missing.bin")
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        with pytest.raises(InputError, match="'missing.bin' is missing") as e:
            load_scene(f)
    assert str(f) in str(e.value)
    assert main(["trace", f, "--size", "8"]) == 2
    assert "missing.bin" in capsys.readouterr().err


def test_external_buffer_loads(tmp_path):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), bin_uri="q.bin")
    assert len(load_scene(f).meshes[0].primitives[0].triangles) == 2


@pytest.mark.parametrize("content", [b"", b"{not json", b"glTF\x02\x00\x00\x00garbage"])
def test_bad_files_raise_input_error(tmp_path, content):
    p = tmp_path / "bad.gltf"
    p.write_bytes(content)
    with pytest.raises(InputError) as e:
        load_scene(p)
    assert str(p) in str(e.value)


def test_cli_reports_bad_scene(tmp_path, capsys):
    assert main(["trace", str(tmp_path / "none.glb")]) == 2
    assert "no such file" in capsys.readouterr().err


@needs_scenes
def test_smallpine_missing_normal_map_is_named():
    with pytest.warns(SceneWarning, match="M_TreeAtlas_normal.png"):
        s = load_scene(SCENES / "smallpine" / "scene.gltf")
    blend = [m for m in s.materials if m.alpha_mode == "BLEND"]
    assert blend and s.alpha_tested()[blend[0].index]
    assert s.counts()["triangles"] == 1650 and s.counts()["alpha_triangles"] == 1442


@needs_scenes
def test_shared_scene_counts():
    palm = load_scene(SCENES / "palm.glb").counts()
    assert (palm["triangles"], palm["alpha_triangles"]) == (4152, 3840)
    forest = load_scene(SCENES / "forest.glb").counts()
    assert (forest["triangles"], forest["alpha_triangles"]) == (1443372, 536080)
