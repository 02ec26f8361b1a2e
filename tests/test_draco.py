"""``KHR_draco_mesh_compression``: a primitive's geometry read from its Draco data (Google's decoder,
DracoPy), its accessors' empty fallback ignored. A Draco scene reads and traces exactly as the
plain scene written from the decoded data; the palm as Draco traces as the plain palm within
Draco's quantisation, with the same triangle counts; broken Draco data is an error naming the
file and primitive."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import DRACO, draco_bytes, dracoify_glb, edit_json, write_draco_gltf, write_quad_gltf
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.scene import load_scene


def _grid(k=10, seed=3):
    """A k x k vertex grid with scattered UVs, and an alpha texture of blobs."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(k, dtype=np.float32), np.arange(k, dtype=np.float32))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(k * k, np.float32)], axis=1) * 0.37
    uv = (rng.random((k * k, 2)) * 1.2 - 0.1).astype(np.float32)
    v = np.arange(k * k).reshape(k, k)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel()
    idx = np.stack([np.stack([a, b, c], 1), np.stack([b, d, c], 1)], 1).reshape(-1)
    alpha = np.kron((rng.random((8, 8)) > 0.5).astype(np.uint8) * 255, np.ones((8, 8), np.uint8))
    return pos, uv, idx, alpha


def _decoded(pos, uv, idx, **bits):
    import DracoPy

    data, ids = draco_bytes(pos, uv, idx, **bits)
    m = DracoPy.decode(data)
    return (m.get_attribute_by_unique_id(ids["POSITION"])["data"], m.get_attribute_by_unique_id(ids["TEXCOORD_0"])
            ["data"], np.asarray(m.faces).ravel())


@pytest.mark.parametrize("required", [True, False], ids=["required", "used"])
def test_a_draco_scene_reads_and_traces_as_the_plain_scene_of_its_decoded_data(tmp_path, required):
    pos, uv, idx, alpha = _grid()
    draco = write_draco_gltf(tmp_path / "draco.gltf", alpha, pos, uv, idx, required=required, bits=11, uv_bits=10)
    dp, duv, didx = _decoded(pos, uv, idx, bits=11, uv_bits=10)
    plain = write_quad_gltf(tmp_path / "plain.gltf", alpha, positions=dp, uvs=duv, indices=didx)
    a, b = load_scene(draco), load_scene(plain)
    pa, pb = a.meshes[0].primitives[0], b.meshes[0].primitives[0]
    assert np.array_equal(pa.triangles, pb.triangles) and len(pa.triangles) == len(idx) // 3
    np.testing.assert_array_equal(pa.positions, pb.positions)
    np.testing.assert_array_equal(pa.uvs, pb.uvs)
    assert np.abs(pa.uvs - uv).max() < 2.0 ** -9  # (10-bit UVs over a range of 1.2)
    opts = ["--schemes", "none,sq16,tri3", "--size", "64", "--quiet"]
    for name, path in (("draco", draco), ("plain", plain)):
        assert main(["trace", path, "--json", str(tmp_path / f"{name}.json"), *opts]) == 0
    x, y = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("draco", "plain"))
    assert x["schemes"] == {k: {**v, **{t: x["schemes"][k][t] for t in v if "second" in t or "per_second" in t
                                        or t in ("timings", "timing")}} for k, v in y["schemes"].items()}
    assert x["passed"]


@pytest.mark.parametrize("case, said", [
    ("garbage", "cannot be decoded"),
    ("no position", "names no POSITION attribute"),
    ("missing id", "is not in its Draco data"),
    ("view", "bufferView"),
    ("fan", "triangles or a strip"),
])
def test_broken_draco_data_is_an_error_naming_the_primitive(tmp_path, case, said):
    pos, uv, idx, alpha = _grid(k=4)
    path = write_draco_gltf(tmp_path / "draco.gltf", alpha, pos, uv, idx)

    def fn(doc):
        prim = doc["meshes"][0]["primitives"][0]
        ext = prim["extensions"][DRACO]
        if case == "garbage":
            doc["buffers"][-1]["uri"] = "data:application/octet-stream;base64,RFJBQ08AAAAAAAAAAAAAAAA="
            doc["buffers"][-1]["byteLength"] = 16
            doc["bufferViews"][-1]["byteLength"] = 16
        elif case == "no position":
            del ext["attributes"]["POSITION"]
        elif case == "missing id":
            ext["attributes"]["TEXCOORD_0"] = 77
        elif case == "view":
            ext["bufferView"] = 99
        elif case == "fan":
            prim["mode"] = 6
    edit_json(path, fn)
    with pytest.raises(InputError) as e:
        load_scene(path)
    text = str(e.value)
    assert path in text and said in text and "mesh 0" in text, text


@needs_scenes
def test_the_palm_as_draco_traces_as_the_plain_palm(tmp_path):
    """The palm's primitives in Draco (14-bit positions, 12-bit UVs): the same triangle counts,
    0 differing pixels, and alpha tests per ray within 2 % of the plain palm's (the quantised
    geometry moves silhouettes by a fraction of a pixel: at 128 x 128, candidates per ray 0.480
    against 0.484, sq16 0.303 against 0.308); an ``omm`` bake of as many micro-triangles."""
    draco = tmp_path / "palm_draco.glb"
    dracoify_glb(SCENES / "palm.glb", draco)
    opts = ["--schemes", "none,sq16,tri3,vq4", "--size", "128", "--quiet"]
    for name, path in (("draco", draco), ("plain", SCENES / "palm.glb")):
        assert main(["trace", str(path), "--json", str(tmp_path / f"{name}.json"), *opts]) == 0
    x, y = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("draco", "plain"))
    assert x["scene"]["triangles"] == y["scene"]["triangles"] and x["passed"]
    for s in ("none", "sq16", "tri3", "vq4"):
        a, b = x["schemes"][s]["alpha_tests_per_primary_ray"], y["schemes"][s]["alpha_tests_per_primary_ray"]
        assert abs(a - b) <= 0.02 * b, (s, a, b)
    for name, path in (("draco", draco), ("plain", SCENES / "palm.glb")):
        assert main(["omm", str(path), "-o", str(tmp_path / f"omm_{name}"), "--level", "4", "--quiet"]) == 0
    a, b = (json.loads((tmp_path / f"omm_{n}" / "omm.json").read_text())["statistics"] for n in ("draco", "plain"))
    assert a["triangles"] == b["triangles"] and a["micro_triangles"] == b["micro_triangles"]
