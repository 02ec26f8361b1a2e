"""``EXT_mesh_gpu_instancing``: a node's mesh drawn once per element of its TRANSLATION,
ROTATION and SCALE accessors. The instances read are the accessors' transforms composed with the
node's (against an independent axis-angle reference), the same as the same placements written as
separate nodes; every command sees every instance (a field of palms traces as its nodes do), the
mesh is baked once; malformed instancing is a clear error naming the node."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import SCENES, needs_scenes, untimed
from gltf_files import instanced_field, write_quad_gltf
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.scene import load_scene

PARENT = {"translation": [1.0, -2.0, 0.5], "rotation": [0.0, 0.38268343, 0.0, 0.92387953],
          "scale": [1.5, 1.5, 1.5]}


def _placements(n, seed=0, spacing=2.5):
    """``n`` placements on a jittered grid: translations, unit quaternions (x, y, z, w: a random
    axis near +y, a random angle) and non-uniform scales, as float32."""
    rng = np.random.default_rng(seed)
    k = int(np.ceil(np.sqrt(n)))
    t = np.array([[spacing * (i % k), 0.0, spacing * (i // k)] for i in range(n)]) + rng.normal(0, 0.2, (n, 3))
    axis = rng.normal(0, 0.3, (n, 3)) + [0, 1, 0]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, 2 * np.pi, n)
    q = np.concatenate([axis * np.sin(angle / 2)[:, None], np.cos(angle / 2)[:, None]], axis=1)
    s = rng.uniform(0.7, 1.3, (n, 3))
    return t.astype(np.float32), q.astype(np.float32), s.astype(np.float32)


def _reference(t, q, s):
    """T * R * S from axis and angle (Rodrigues), not from the quaternion's matrix formula."""
    q = np.asarray(q, np.float64) / np.linalg.norm(q)
    angle = 2 * np.arctan2(np.linalg.norm(q[:3]), q[3])
    axis = q[:3] / (np.linalg.norm(q[:3]) or 1.0)
    kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(3) * np.cos(angle) + np.sin(angle) * kx + (1 - np.cos(angle)) * np.outer(axis, axis)
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(s, np.float64)[None, :]
    m[:3, 3] = t
    return m


def _quad_glb(tmp_path):
    """The test quad (an alpha-tested texture, kept as a data URI) as a .glb with a single mesh node."""
    import pygltflib

    alpha = np.kron((np.random.default_rng(1).random((8, 8)) > 0.5).astype(np.uint8) * 255, np.ones((8, 8), np.uint8))
    write_quad_gltf(tmp_path / "quad.gltf", alpha, material={"alphaMode": "MASK", "alphaCutoff": 0.5})
    g = pygltflib.GLTF2().load(str(tmp_path / "quad.gltf"))
    g.convert_buffers(pygltflib.BufferFormat.BINARYBLOB)
    g.save_binary(str(tmp_path / "quad.glb"))
    return tmp_path / "quad.glb"


@pytest.mark.parametrize("required", [True, False], ids=["required", "used"])
def test_instances_are_the_accessors_transforms_composed_with_the_node(tmp_path, required):
    t, q, s = _placements(7)
    inst, nodes = tmp_path / "inst.glb", tmp_path / "nodes.glb"
    instanced_field(_quad_glb(tmp_path), inst, nodes, t, q, s, PARENT, required=required)
    a, b = load_scene(inst), load_scene(nodes)
    parent = _reference(PARENT["translation"], PARENT["rotation"], PARENT["scale"])
    assert len(a.instances) == 7 and len(a.meshes) == 1
    for k, (mi, m) in enumerate(a.instances):
        assert mi == 0
        np.testing.assert_allclose(m, parent @ _reference(t[k], q[k], s[k]), atol=1e-6)
    # the same placements as child nodes: the same transforms, bit for bit
    assert [mi for mi, _ in a.instances] == [mi for mi, _ in b.instances]
    assert all(np.array_equal(x, y) for (_, x), (_, y) in zip(a.instances, b.instances))


def _edit(path, fn):
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    fn(g, next(n for n in g.nodes if n.extensions))
    g.save(str(path))


def _attrs(node):
    return node.extensions["EXT_mesh_gpu_instancing"]["attributes"]


@pytest.mark.parametrize("case, said", [
    ("counts", "attributes' counts differ"),
    ("none", "has no TRANSLATION, ROTATION or SCALE attribute"),
    ("accessor", "TRANSLATION"),
    ("integer rotation", "ROTATION (accessor"),
    ("nan", "holds a NaN or an infinity"),
    ("not an object", "EXT_mesh_gpu_instancing"),
])
def test_malformed_instancing_is_an_error_naming_the_node(tmp_path, case, said):
    t, q, s = _placements(4)
    if case == "nan":
        t[2, 1] = np.nan
    inst = tmp_path / "inst.glb"
    instanced_field(_quad_glb(tmp_path), inst, None, t, q, s)

    def edit(g, node):
        if case == "counts":
            g.accessors[_attrs(node)["SCALE"]].count = 3
        elif case == "none":
            node.extensions["EXT_mesh_gpu_instancing"]["attributes"] = {}
        elif case == "accessor":
            _attrs(node)["TRANSLATION"] = 999
        elif case == "integer rotation":  # int16 not normalised (the same bytes hold 8 per instance)
            g.accessors[_attrs(node)["ROTATION"]].componentType = 5122
            g.accessors[_attrs(node)["ROTATION"]].count = 8
        elif case == "not an object":
            node.extensions["EXT_mesh_gpu_instancing"] = [1, 2]

    if case != "nan":
        _edit(inst, edit)
    with pytest.raises(InputError) as e:
        load_scene(inst)
    text = str(e.value)
    assert str(inst) in text and said in text, text
    assert "node " in text and "EXT_mesh_gpu_instancing" in text, text


def test_a_malformed_instancing_node_exits_2_with_one_line(tmp_path, capsys):
    t, q, s = _placements(3)
    inst = tmp_path / "inst.glb"
    instanced_field(_quad_glb(tmp_path), inst, tmp_path / "nodes.glb", t, q, s)
    _edit(inst, lambda g, node: setattr(g.accessors[_attrs(node)["SCALE"]], "count", 2))
    assert main(["trace", str(inst), "--schemes", "none,sq16", "--size", "16", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "counts differ" in err[0], err


@needs_scenes
def test_a_field_of_palms_traces_as_its_nodes_and_bakes_the_palm_once(tmp_path):
    """Sixteen palms as one instancing node and as sixteen nodes: the same trace figures (every
    scheme, every instance traced), 0 differing pixels; ``omm`` bakes the palm once: the field's
    micromaps are the lone palm's."""
    t, q, s = _placements(16, seed=5, spacing=6.0)
    inst, nodes = tmp_path / "field_instanced.glb", tmp_path / "field_nodes.glb"
    instanced_field(SCENES / "palm.glb", inst, nodes, t, q, s, PARENT)
    opts = ["--schemes", "none,sq16,tri3", "--size", "96", "--quiet"]
    for name, path in (("inst", inst), ("nodes", nodes)):
        assert main(["trace", str(path), "--json", str(tmp_path / f"{name}.json"), *opts]) == 0
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("inst", "nodes"))
    assert a["scene"]["instances"] == 16 and a["scene"]["prototypes"] == 1
    assert untimed(a) == untimed(b) and a["passed"]
    assert a["schemes"]["none"]["alpha_tests_per_primary_ray"] > 0
    for name, path in (("inst", inst), ("palm", SCENES / "palm.glb")):
        assert main(["omm", str(path), "-o", str(tmp_path / f"omm_{name}"), "--level", "4", "--quiet"]) == 0
    one, field = (json.loads((tmp_path / f"omm_{n}" / "omm.json").read_text()) for n in ("palm", "inst"))
    for k in ("micromaps", "data_bytes", "triangles", "micro_triangles"):
        assert field["statistics"][k] == one["statistics"][k], k
    data = sorted(p.name for p in (tmp_path / "omm_palm").iterdir() if p.suffix == ".bin")
    assert data and all((tmp_path / "omm_inst" / f).read_bytes() == (tmp_path / "omm_palm" / f).read_bytes()
                        for f in data)
