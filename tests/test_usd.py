"""OpenUSD stages as scenes (``omaps.scene.usd``, the extra ``omaps[usd]``): stages are written
here with usd-core's own API (pxr), never with omaps, and read as the same scene written as glTF:

* the palm as a .usdc (its two glTF primitives as two GeomSubsets of one mesh, the leaf's
  opacity the diffuse UsdUVTexture's ``outputs:a`` at the glTF alphaCutoff): the same triangles,
  trace figures and micromaps as the glTF palm; a field of palms as a PointInstancer traces as
  the same placements as glTF nodes and bakes the palm once;
* small stages: faceVarying indexed st, quads and a pentagon (glTF's fans), GeomSubset bindings,
  UsdTransform2d, wrap modes (black as a border of alpha 0), opacityThreshold 0 (BLEND), Z-up,
  a camera; polygons of random sizes (hypothesis) give sum(n - 2) triangles by the fan rule;
* errors: a missing texture (glTF's warning), a file outside the root, malformed .usda bytes
  (hypothesis: an InputError naming the file, nothing else), no usd-core (the install hint),
  a glTF output of a USD input; reading glTF never imports pxr.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from conftest import SCENES, needs_scenes, untimed
from gltf_files import png_bytes, write_quad_gltf
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.scene import SceneWarning, load_scene

needs_usd = pytest.mark.skipif(importlib.util.find_spec("pxr") is None,
                               reason="usd-core is not installed (pip install 'omaps[usd]')")
HINT = "pip install 'omaps[usd]'"


# -- writing stages with pxr ----------------------------------------------------------------------
def _stage(path, up="Y", mpu=1.0):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    return stage


def _mesh(stage, where, points, counts, indices, st=None, interp="vertex", st_indices=None, double=True,
          varname="st", orientation=None):
    from pxr import Sdf, UsdGeom, Vt

    m = UsdGeom.Mesh.Define(stage, where)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in np.ravel(indices)]))
    m.CreateSubdivisionSchemeAttr("none")
    m.CreateDoubleSidedAttr(double)
    if orientation:
        m.CreateOrientationAttr(orientation)
    if st is not None:
        pv = UsdGeom.PrimvarsAPI(m).CreatePrimvar(varname, Sdf.ValueTypeNames.TexCoord2dArray, interp)
        pv.Set(Vt.Vec2dArray.FromNumpy(np.asarray(st, np.float64)))
        if st_indices is not None:
            pv.SetIndices(Vt.IntArray([int(i) for i in st_indices]))
    return m


def _material(stage, where, texture=None, threshold=None, opacity=None, wrap=("repeat", "repeat"), channel="a",
              transform=None, scale=None, bias=None, varname="st"):
    """A UsdPreviewSurface material: opacity from ``texture``'s ``channel`` (its diffuse colour
    too), or the constant ``opacity``; ``transform``: a UsdTransform2d (scale, rotation,
    translation) between the st reader and the texture."""
    from pxr import Gf, Sdf, UsdShade

    mat = UsdShade.Material.Define(stage, where)
    surf = UsdShade.Shader.Define(stage, f"{where}/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    if threshold is not None:
        surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(threshold)
    if opacity is not None:
        surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(opacity)
    if texture is None:
        return mat
    reader = UsdShade.Shader.Define(stage, f"{where}/StReader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set(varname)
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    source = (reader, "result")
    if transform is not None:
        xf = UsdShade.Shader.Define(stage, f"{where}/Transform")
        xf.CreateIdAttr("UsdTransform2d")
        xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*transform[0]))
        xf.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(transform[1])
        xf.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*transform[2]))
        xf.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        source = (xf, "result")
    tex = UsdShade.Shader.Define(stage, f"{where}/Texture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(source[0].ConnectableAPI(), source[1])
    if wrap is not None:
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap[0])
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap[1])
    if scale is not None:
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*scale))
    if bias is not None:
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*bias))
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex.CreateOutput(channel, Sdf.ValueTypeNames.Float)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    if threshold is not None or opacity is None:
        surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(tex.ConnectableAPI(), channel)
    return mat


def _bind(prim_or_subset, mat):
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim_or_subset.GetPrim()).Bind(mat)


def _subset(mesh, name, faces):
    from pxr import UsdGeom, UsdShade, Vt

    sub = UsdGeom.Subset.Define(mesh.GetPrim().GetStage(), mesh.GetPath().AppendChild(name))
    sub.CreateElementTypeAttr("face")
    sub.CreateFamilyNameAttr("materialBind")
    sub.CreateIndicesAttr(Vt.IntArray([int(f) for f in faces]))
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    return sub


def _png(path, alpha):
    path.write_bytes(png_bytes(alpha))
    return path.name


def _blobs(seed=1, n=8, k=8):
    rng = np.random.default_rng(seed)
    return np.kron((rng.random((n, n)) > 0.5).astype(np.uint8) * 255, np.ones((k, k), np.uint8))


def _trace(tmp_path, name, path, schemes="none,sq16,tri3,vq4", size=64, extra=()):
    out = tmp_path / f"{name}.json"
    assert main(["trace", str(path), "--schemes", schemes, "--size", str(size), "--quiet", "--json", str(out),
                 *extra]) == 0
    return json.loads(out.read_text())


def _world_triangles(scene):
    """Every traced triangle's world positions (T, 3, 3) and UVs (T, 3, 2), instance by instance."""
    pos, uv = [], []
    for mi, m in scene.instances:
        for p in scene.meshes[mi].primitives:
            w = p.positions @ m[:3, :3].T + m[:3, 3]
            pos.append(w[p.triangles])
            uv.append(p.uvs[p.triangles])
    return np.concatenate(pos), np.concatenate(uv)


# -- the palm ------------------------------------------------------------------------------------
def _palm_usd(out_dir, instancer=None):
    """The palm as a .usdc beside its two textures: one mesh (both glTF primitives' vertices, each
    triangle a face), each primitive a GeomSubset bound to its material: the trunk opaque, the
    leaf's opacity its diffuse texture's outputs:a at the glTF alphaCutoff, wrap repeat (the
    palm's sampler). st = (u, 1 - v) as doubles. ``instancer``: (translations, quaternions
    (x, y, z, w), scales) for a PointInstancer /Field of the palm instead of one palm."""
    import pygltflib
    from pxr import Gf, UsdGeom, Vt

    from omaps.scene.gltf import load_scene as gltf_scene  # the glTF data, not the USD reader

    g = pygltflib.GLTF2().load(str(SCENES / "palm.glb"))
    scene = gltf_scene(SCENES / "palm.glb")
    (mesh,) = scene.meshes
    stage = _stage(out_dir / ("field.usdc" if instancer else "palm.usdc"))
    root = "/Field/Prototypes/Palm" if instancer else "/Palm"
    UsdGeom.Xform.Define(stage, root)
    pts, idx, st, ranges, base, first = [], [], [], [], 0, 0
    for p in mesh.primitives:
        pts.append(p.positions)
        idx.append(p.triangles + base)
        st.append(np.stack([p.uvs[:, 0], 1.0 - p.uvs[:, 1]], axis=1))
        ranges.append(range(first, first + len(p.triangles)))
        base += len(p.positions)
        first += len(p.triangles)
    idx = np.concatenate(idx)
    m = _mesh(stage, f"{root}/Mesh", np.concatenate(pts), [3] * len(idx), idx, np.concatenate(st))
    for k, p in enumerate(mesh.primitives):
        gm = scene.materials[p.material]
        tex = scene.textures[gm.texture]
        rgba = np.concatenate([tex.rgb, tex.alpha[..., None]], axis=2)
        name = f"{g.materials[p.material].name}.png"
        Image.fromarray(rgba, "RGBA").save(out_dir / name)
        mat = _material(stage, f"/Looks/M{k}", texture=f"./{name}",
                        threshold=gm.cutoff if gm.alpha_mode == "MASK" else None,
                        opacity=1.0 if gm.alpha_mode == "OPAQUE" else None)
        _bind(_subset(m, f"part{k}", ranges[k]), mat)
    if instancer:
        t, q, s = instancer
        pi = UsdGeom.PointInstancer.Define(stage, "/Field")
        pi.CreatePrototypesRel().SetTargets([root])
        pi.CreateProtoIndicesAttr(Vt.IntArray([0] * len(t)))
        pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(t, np.float32)))
        pi.CreateOrientationsfAttr(Vt.QuatfArray([Gf.Quatf(float(r[3]), float(r[0]), float(r[1]), float(r[2]))
                                                  for r in q]))
        pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.asarray(s, np.float32)))
    stage.GetRootLayer().Save()
    return stage.GetRootLayer().realPath


def _omm(tmp_path, name, path):
    out = tmp_path / f"omm_{name}"
    assert main(["omm", str(path), "-o", str(out), "--level", "4", "--quiet"]) == 0
    return out


def _same_bins(a, b):
    names = sorted(p.name for p in a.iterdir() if p.suffix == ".bin")
    assert names and all((a / n).read_bytes() == (b / n).read_bytes() for n in names), names


@needs_usd
@needs_scenes
def test_the_palm_as_usd_reads_traces_and_bakes_as_the_gltf_palm(tmp_path):
    usd = _palm_usd(tmp_path)
    a, b = load_scene(usd), load_scene(SCENES / "palm.glb")
    assert len(a.meshes) == 1 and len(a.meshes[0].primitives) == len(b.meshes[0].primitives) == 2
    for pa, pb in zip(a.meshes[0].primitives, b.meshes[0].primitives):
        np.testing.assert_array_equal(pa.positions, pb.positions)
        np.testing.assert_array_equal(pa.uvs, pb.uvs)
        np.testing.assert_array_equal(pa.triangles, pb.triangles)
        ma, mb = a.materials[pa.material], b.materials[pb.material]
        assert (ma.alpha_mode, ma.cutoff, ma.wrap_u, ma.wrap_v, ma.double_sided) == \
            (mb.alpha_mode, mb.cutoff, mb.wrap_u, mb.wrap_v, mb.double_sided)
        assert pa.source == "/Palm/Mesh" and len(pa.faces) == len(pa.triangles)
    x, y = _trace(tmp_path, "usd", usd), _trace(tmp_path, "gltf", SCENES / "palm.glb")
    assert x["passed"] and untimed(x["schemes"]) == untimed(y["schemes"])
    assert x["schemes"]["none"]["alpha_tests_per_primary_ray"] > 0
    ou, og = _omm(tmp_path, "usd", usd), _omm(tmp_path, "gltf", SCENES / "palm.glb")
    _same_bins(ou, og)  # the same micromaps, triangle by triangle
    summary = json.loads((ou / "omm.json").read_text())
    assert summary["input"]["kind"] == "scene" and summary["input"]["path"] == os.path.abspath(usd)
    (leaf,) = summary["geometries"]
    assert leaf["prim"] == "/Palm/Mesh" and len(leaf["faces"]) == leaf["triangles"]
    first = len(a.meshes[0].primitives[0].triangles)  # the trunk's faces come first
    assert leaf["faces"] == list(range(first, first + leaf["triangles"]))


def _nodes_glb(usd, out):
    """The palm.glb with one node per placement of the stage's point instancer, each node's matrix
    the instance transform usd-core computes (``ComputeInstanceTransformsAtTime``)."""
    import pygltflib
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(usd))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Field"))
    mats = pi.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default())
    g = pygltflib.GLTF2().load(str(SCENES / "palm.glb"))
    (root,) = g.scenes[g.scene or 0].nodes
    mesh = g.nodes[root].mesh
    kids = []
    for m in mats:  # (a Gf matrix's rows are glTF's column-major matrix)
        g.nodes.append(pygltflib.Node(mesh=mesh, matrix=[float(x) for x in np.array(m).ravel()]))
        kids.append(len(g.nodes) - 1)
    g.scenes[g.scene or 0].nodes = kids
    g.save(str(out))
    return out


@needs_usd
@needs_scenes
def test_a_point_instancer_of_palms_traces_as_its_nodes_and_bakes_the_palm_once(tmp_path):
    """Nine palms as a PointInstancer (float positions, orientations and scales): the instances are
    the placements' T * R * S (an axis-angle reference); the trace figures are those of the
    same placements as glTF nodes, 0 differing pixels; ``omm`` bakes the palm once."""
    from test_gpu_instancing import _placements, _reference

    t, q, s = _placements(9, seed=5, spacing=6.0)
    usd = _palm_usd(tmp_path, (t, q, s))
    nodes = _nodes_glb(usd, tmp_path / "field_nodes.glb")
    a = load_scene(usd)
    assert len(a.instances) == 9 and len(a.meshes) == 1
    for k, (mi, m) in enumerate(a.instances):
        np.testing.assert_allclose(m, _reference(t[k], q[k], s[k]), rtol=1e-6, atol=1e-6)
    x = _trace(tmp_path, "usd", usd, "none,sq16,tri3")
    y = _trace(tmp_path, "gltf", nodes, "none,sq16,tri3")
    assert x["scene"]["instances"] == 9 and x["scene"]["prototypes"] == 1 and x["passed"]
    assert untimed(x["schemes"]) == untimed(y["schemes"])
    _same_bins(_omm(tmp_path, "field", usd), _omm(tmp_path, "palm", SCENES / "palm.glb"))


@needs_usd
def test_instanceable_prims_share_their_prototypes_meshes_per_material_binding(tmp_path):
    """Three instanceable prims referencing one class: the two bound to material A share one mesh
    (baked once, named by the first instance's prim), the one bound to B gets its own."""
    from pxr import Gf, UsdGeom

    values, index = _poly_st(5)
    stage = _stage(tmp_path / "inst.usda")
    cls = stage.CreateClassPrim("/_Tree")
    _mesh(stage, "/_Tree/Leaf", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    tex = f"./{_png(tmp_path / 'leaf.png', _blobs())}"
    mats = {"A": _material(stage, "/Looks/A", texture=tex, threshold=0.5),
            "B": _material(stage, "/Looks/B", texture=tex, threshold=0.7)}
    for k, which in enumerate("AAB"):
        x = UsdGeom.Xform.Define(stage, f"/T{k}")
        x.AddTranslateOp().Set(Gf.Vec3d(0, 2.0 * k, 0))
        x.GetPrim().GetReferences().AddInternalReference(cls.GetPath())
        x.GetPrim().SetInstanceable(True)
        _bind(x, mats[which])
    stage.GetRootLayer().Save()
    scene = load_scene(tmp_path / "inst.usda")
    assert [mi for mi, _ in scene.instances] == [0, 0, 1] and len(scene.meshes) == 2
    assert [m.primitives[0].source for m in scene.meshes] == ["/T0/Leaf", "/T2/Leaf"]
    assert [scene.materials[m.primitives[0].material].cutoff for m in scene.meshes] == [pytest.approx(0.5),
                                                                                        pytest.approx(0.7)]
    np.testing.assert_allclose([m[:3, 3] for _, m in scene.instances], [[0, 0, 0], [0, 2, 0], [0, 4, 0]])
    out = _omm(tmp_path, "inst", tmp_path / "inst.usda")
    summary = json.loads((out / "omm.json").read_text())
    assert [g["prim"] for g in summary["geometries"]] == ["/T0/Leaf", "/T2/Leaf"]
    assert summary["statistics"]["triangles"] == 2 * len(scene.meshes[0].primitives[0].triangles)
    assert main(["omm", "--verify", str(out), "--quiet"]) == 0


@needs_usd
def test_a_usdz_package_reads_its_own_texture(tmp_path):
    from pxr import UsdUtils

    values, index = _poly_st(6)
    stage = _stage(tmp_path / "pkg.usdc")
    m = _mesh(stage, "/Poly", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    stage.GetRootLayer().Save()
    assert UsdUtils.CreateNewUsdzPackage(str(tmp_path / "pkg.usdc"), str(tmp_path / "pkg.usdz"))
    (tmp_path / "leaf.png").unlink()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_scene(tmp_path / "pkg.usdz")
    (tex,) = scene.textures
    np.testing.assert_array_equal(tex.alpha, _blobs())


# -- small stages --------------------------------------------------------------------------------
# a quad, a pentagon and a triangle side by side in the z = 0 plane; st per face corner, indexed
POLY_POINTS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [1.5, 0, 0], [2.5, 0, 0], [2.8, 0.7, 0], [2, 1.2, 0], [1.2, 0.7, 0],
                        [3, 0, 0], [4, 0, 0], [3.5, 1, 0]], np.float64)
POLY_COUNTS = [4, 5, 3]
POLY_INDICES = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]


def _poly_st(seed=0):
    rng = np.random.default_rng(seed)
    values = rng.uniform(-0.2, 1.2, (8, 2))
    index = rng.integers(0, 8, len(POLY_INDICES))
    return values, index


def _poly_gltf(path, alpha, st, flip=False, **kw):
    """The same polygons as glTF: a vertex per face corner (UV (s, 1 - t)), each polygon a fan,
    written out here corner by corner."""
    tris, start = [], 0
    for n in POLY_COUNTS:
        for k in range(1, n - 1):
            tris.append([start, start + k + 1, start + k] if flip else [start, start + k, start + k + 1])
        start += n
    pos = POLY_POINTS[POLY_INDICES]
    uv = np.stack([st[:, 0], 1.0 - st[:, 1]], axis=1)
    return write_quad_gltf(path, alpha, positions=pos, uvs=uv, indices=np.array(tris).ravel(), **kw)


@needs_usd
@pytest.mark.parametrize("orientation", ["rightHanded", "leftHanded"])
def test_face_varying_indexed_st_and_polygon_fans_read_as_gltf(tmp_path, orientation):
    values, index = _poly_st()
    stage = _stage(tmp_path / "poly.usda")
    m = _mesh(stage, "/Poly", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index,
              orientation=orientation)
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    stage.GetRootLayer().Save()
    gl = _poly_gltf(tmp_path / "poly.gltf", _blobs(), values[index], flip=orientation == "leftHanded")
    a, b = load_scene(tmp_path / "poly.usda"), load_scene(gl)
    (pa,), (pb,) = a.meshes[0].primitives, b.meshes[0].primitives
    np.testing.assert_array_equal(pa.positions[pa.triangles], pb.positions[pb.triangles].astype(np.float64))
    np.testing.assert_allclose(pa.uvs[pa.triangles], pb.uvs[pb.triangles], atol=1e-7)  # (glTF's are float32)
    assert pa.faces.tolist() == [0, 0, 1, 1, 1, 2]
    ma, mb = a.materials[pa.material], b.materials[pb.material]
    assert (ma.alpha_mode, ma.cutoff, ma.wrap_u, ma.filter) == (mb.alpha_mode, mb.cutoff, mb.wrap_u, mb.filter)


@needs_usd
@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(counts=st.lists(st.integers(0, 9), min_size=1, max_size=12))
def test_polygons_of_any_size_triangulate_by_the_fan_rule(tmp_path_factory, counts):
    d = tmp_path_factory.mktemp("fan")
    n = int(sum(counts))
    pts = np.random.default_rng(n).uniform(-1, 1, (max(n, 1), 3)).astype(np.float32).astype(np.float64)
    stage = _stage(d / "fan.usda")
    _mesh(stage, "/Fan", pts, counts, np.arange(n))
    stage.GetRootLayer().Save()
    if sum(c - 2 for c in counts if c >= 3) == 0:
        scene = load_scene(d / "fan.usda")
        assert sum(len(p.triangles) for m in scene.meshes for p in m.primitives) == 0
        return
    (p,) = load_scene(d / "fan.usda").meshes[0].primitives
    want, faces, start = [], [], 0
    for f, c in enumerate(counts):
        want += [pts[[start, start + k, start + k + 1]] for k in range(1, c - 1)]
        faces += [f] * max(c - 2, 0)
        start += c
    assert len(p.triangles) == sum(max(c - 2, 0) for c in counts)
    np.testing.assert_array_equal(p.positions[p.triangles], np.array(want))
    assert p.faces.tolist() == faces


@needs_usd
def test_geom_subsets_bind_their_faces_and_thresholds_give_alpha_modes(tmp_path):
    """Face 0 (the quad) bound by a subset to a threshold-0.3 material, face 1 (the pentagon) to
    threshold 0 (BLEND), the rest to the mesh's material: opaque (no opacity connection)."""
    values, index = _poly_st(1)
    stage = _stage(tmp_path / "subsets.usda")
    m = _mesh(stage, "/Poly", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    tex = f"./{_png(tmp_path / 'leaf.png', _blobs())}"
    _bind(_subset(m, "cut", [0]), _material(stage, "/Looks/Cut", texture=tex, threshold=0.3))
    _bind(_subset(m, "blend", [1]), _material(stage, "/Looks/Blend", texture=tex, threshold=0.0))
    _bind(m, _material(stage, "/Looks/Solid"))
    _material(stage, "/Looks/Half", opacity=0.5)
    stage.GetRootLayer().Save()
    scene = load_scene(tmp_path / "subsets.usda")
    modes = [(scene.materials[p.material].alpha_mode, scene.materials[p.material].cutoff, p.faces.tolist())
             for p in scene.meshes[0].primitives]
    assert modes == [("MASK", pytest.approx(0.3), [0, 0]), ("BLEND", 0.5, [1, 1, 1]), ("OPAQUE", 0.5, [2])]
    gl = _poly_gltf(tmp_path / "cut.gltf", _blobs(), values[index], material={"alphaCutoff": 0.3})
    want = load_scene(gl).meshes[0].primitives[0]
    got = scene.meshes[0].primitives[0]
    np.testing.assert_allclose(got.uvs[got.triangles], want.uvs[want.triangles][:2], atol=1e-7)
    # a constant opacity below 1 at threshold 0 is blended, at a threshold alpha-tested
    stage = _stage(tmp_path / "half.usda")
    m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3])
    _bind(m, _material(stage, "/Looks/Half", opacity=0.5))
    stage.GetRootLayer().Save()
    mat = load_scene(tmp_path / "half.usda").materials[-1]
    assert (mat.alpha_mode, mat.base_colour[3], mat.texture) == ("BLEND", 0.5, -1)


@needs_usd
@pytest.mark.parametrize("transform", [((2.0, 0.5), 0.0, (0.25, -0.5)), ((1.5, 1.5), 30.0, (0.1, 0.2))])
def test_a_transform2d_moves_st_as_its_scale_rotation_and_translation_say(tmp_path, transform):
    values, index = _poly_st(2)
    stage = _stage(tmp_path / "xf.usda")
    m = _mesh(stage, "/Poly", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5,
                       transform=transform))
    stage.GetRootLayer().Save()
    (sx, sy), deg, (tx, ty) = transform
    st0 = values[index]
    r = math.radians(deg)
    s = st0 * [sx, sy]
    st1 = np.stack([s[:, 0] * math.cos(r) - s[:, 1] * math.sin(r) + tx,
                    s[:, 0] * math.sin(r) + s[:, 1] * math.cos(r) + ty], axis=1)
    gl = _poly_gltf(tmp_path / "xf.gltf", _blobs(), st1)
    (pa,), (pb,) = load_scene(tmp_path / "xf.usda").meshes[0].primitives, load_scene(gl).meshes[0].primitives
    np.testing.assert_allclose(pa.uvs[pa.triangles], pb.uvs[pb.triangles], atol=1e-6)


@needs_usd
def test_wrap_modes_and_black_as_a_transparent_border(tmp_path):
    alpha = _blobs()
    name = _png(tmp_path / "leaf.png", alpha)
    stage = _stage(tmp_path / "wrap.usda")
    for k, wrap in enumerate([("repeat", "clamp"), ("mirror", "repeat"), ("black", "clamp"), None]):
        m = _mesh(stage, f"/Q{k}", POLY_POINTS[:4] + [2 * k, 0, 0], [4], [0, 1, 2, 3],
                  [[-0.5, -0.5], [1.5, -0.5], [1.5, 1.5], [-0.5, 1.5]])
        _bind(m, _material(stage, f"/Looks/W{k}", texture=f"./{name}", threshold=0.5, wrap=wrap))
    stage.GetRootLayer().Save()
    scene = load_scene(tmp_path / "wrap.usda")
    mats = [scene.materials[mesh.primitives[0].material] for mesh in scene.meshes]
    assert [(m.wrap_u, m.wrap_v) for m in mats] == [("wrap", "clamp"), ("mirror", "wrap"), ("clamp", "clamp"),
                                                     ("clamp", "clamp")]
    plain, black, meta = (scene.textures[m.texture] for m in (mats[0], mats[2], mats[3]))
    assert plain.alpha.shape == alpha.shape
    assert black.alpha.shape == (alpha.shape[0], alpha.shape[1] + 2)  # a border column each side (s only)
    assert not black.alpha[:, 0].any() and not black.alpha[:, -1].any()
    np.testing.assert_array_equal(black.alpha[:, 1:-1], alpha)
    assert meta.alpha.shape == (alpha.shape[0] + 2, alpha.shape[1] + 2)  # useMetadata: black both ways
    # the border's coordinates: s in [0, 1] lands on the image's own texels
    p = scene.meshes[2].primitives[0]
    w = black.alpha.shape[1]
    u = np.array([[-0.5], [1.5]]) * (w - 2) / w + 1 / w
    np.testing.assert_allclose(sorted(set(p.uvs[:, 0])), u.ravel())


@needs_usd
def test_a_z_up_stage_in_centimetres_traces_as_its_y_up_glTF_in_metres(tmp_path):
    values, index = _poly_st(3)
    stage = _stage(tmp_path / "zup.usda", up="Z", mpu=0.01)
    zup = POLY_POINTS[:, [0, 2, 1]] * [100, 100, 100]  # glTF's (x, y, z) is USD's (x, -z, y) in cm
    zup[:, 1] *= -1
    m = _mesh(stage, "/Poly", zup, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    stage.GetRootLayer().Save()
    gl = _poly_gltf(tmp_path / "yup.gltf", _blobs(), values[index])
    pa, ua = _world_triangles(load_scene(tmp_path / "zup.usda"))
    pb, ub = _world_triangles(load_scene(gl))
    np.testing.assert_allclose(pa, pb, atol=1e-12)
    np.testing.assert_allclose(ua, ub, atol=1e-7)
    cam = ["--camera", "1.8,0.6,3:1.8,0.6,0:40"]
    x = _trace(tmp_path, "zup", tmp_path / "zup.usda", "none,sq16", 48, cam)
    y = _trace(tmp_path, "yup", gl, "none,sq16", 48, cam)
    assert untimed(x["schemes"]) == untimed(y["schemes"])


@needs_usd
def test_a_usd_camera_is_a_scene_camera_as_a_gltf_one(tmp_path):
    from pxr import Gf, UsdGeom

    stage = _stage(tmp_path / "cam.usda")
    values, index = _poly_st(4)
    m = _mesh(stage, "/Poly", POLY_POINTS, POLY_COUNTS, POLY_INDICES, values, "faceVarying", index)
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(1.5, 0.5, 4.0))
    cam.AddRotateYOp().Set(10.0)
    cam.CreateFocalLengthAttr(35.0)
    cam.CreateVerticalApertureAttr(20.0)
    cam.CreateHorizontalApertureAttr(20.0)
    stage.GetRootLayer().Save()
    (c,) = load_scene(tmp_path / "cam.usda").cameras
    assert c.problem is None and c.name == "/Cam"
    assert c.yfov == pytest.approx(2 * math.atan(20.0 / 70.0))
    r = math.radians(10.0)
    np.testing.assert_allclose(c.eye, [1.5, 0.5, 4.0])
    np.testing.assert_allclose(c.forward, [-math.sin(r), 0, -math.cos(r)], atol=1e-12)
    np.testing.assert_allclose(c.up, [0, 1, 0], atol=1e-12)
    x = _trace(tmp_path, "cam", tmp_path / "cam.usda", "none,sq16", 32, ["--camera", "gltf:0"])
    assert x["camera"]["view"]["chosen"] == "gltf:0" and x["passed"]
    np.testing.assert_allclose(x["camera"]["eye"], c.eye)


# -- errors --------------------------------------------------------------------------------------
@needs_usd
def test_a_missing_texture_is_glTFs_warning(tmp_path):
    stage = _stage(tmp_path / "miss.usda")
    m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3], [[0, 0], [1, 0], [1, 1], [0, 1]])
    _bind(m, _material(stage, "/Looks/Leaf", texture="./gone.png", threshold=0.5))
    stage.GetRootLayer().Save()
    gl = write_quad_gltf(tmp_path / "miss.gltf", None, image_uri="gone.png")
    with pytest.warns(SceneWarning) as wu:
        a = load_scene(tmp_path / "miss.usda")
    with pytest.warns(SceneWarning) as wg:
        load_scene(gl)
    said = [str(w.message).split(": ", 1)[1] for w in wu]
    assert said == [str(w.message).split(": ", 1)[1].replace("'gone.png'", "'./gone.png'") for w in wg], said
    mat = a.materials[a.meshes[0].primitives[0].material]
    assert a.textures[mat.texture].problem is not None and mat.alpha_mode == "MASK"


@needs_usd
def test_a_texture_outside_the_root_is_refused(tmp_path):
    (tmp_path / "asset").mkdir()
    _png(tmp_path / "secret.png", _blobs())
    path = tmp_path / "asset" / "out.usda"
    stage = _stage(path)
    m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3], [[0, 0], [1, 0], [1, 1], [0, 1]])
    _bind(m, _material(stage, "/Looks/Leaf", texture="../secret.png", threshold=0.5))
    stage.GetRootLayer().Save()
    with pytest.raises(InputError) as e:
        load_scene(path)
    assert str(path) in str(e.value) and "outside" in str(e.value) and "../secret.png" in str(e.value)
    assert set(e.value.params) == {"root", "allow_outside"}
    assert load_scene(path, root=tmp_path).textures[0].problem is None
    # a referenced layer outside the root: refused before it is opened
    other = _stage(tmp_path / "other.usda")
    _mesh(other, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3])
    other.GetRootLayer().Save()
    ref = tmp_path / "asset" / "ref.usda"
    stage = _stage(ref)
    stage.DefinePrim("/R").GetReferences().AddReference("../other.usda", "/Q")
    stage.GetRootLayer().Save()
    with pytest.raises(InputError, match="outside"):
        load_scene(ref)
    assert len(load_scene(ref, allow_outside=True).meshes) == 1


@needs_usd
def test_a_glTF_output_of_a_usd_input_is_refused_naming_the_parameter(tmp_path, capsys):
    import omaps

    stage = _stage(tmp_path / "q.usda")
    m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3], [[0, 0], [1, 0], [1, 1], [0, 1]])
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    stage.GetRootLayer().Save()
    with pytest.raises(InputError) as e:
        omaps.bake_omms(tmp_path / "q.usda", tmp_path / "out.glb")
    assert e.value.params == ("output",) and "USD" in str(e.value)
    assert main(["omm", str(tmp_path / "q.usda"), "-o", str(tmp_path / "out.glb"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "-o" in err[0], err


@needs_usd
def test_a_texture_scale_is_the_alpha_factor_and_a_bias_is_refused(tmp_path):
    tex = f"./{_png(tmp_path / 'leaf.png', _blobs())}"
    for name, kw in (("scaled", {"scale": (1, 1, 1, 0.5)}), ("biased", {"bias": (0, 0, 0, 0.25)})):
        stage = _stage(tmp_path / f"{name}.usda")
        m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3], [[0, 0], [1, 0], [1, 1], [0, 1]])
        _bind(m, _material(stage, "/Looks/Leaf", texture=tex, threshold=0.5, **kw))
        stage.GetRootLayer().Save()
    scene = load_scene(tmp_path / "scaled.usda")
    gl = load_scene(write_quad_gltf(tmp_path / "scaled.gltf", _blobs(), material={
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 1, 1, 0.5]}}))
    assert scene.materials[-1].base_colour[3] == gl.materials[0].base_colour[3] == 0.5
    assert scene.alpha_test(len(scene.materials) - 1).threshold == gl.alpha_test(0).threshold
    with pytest.raises(InputError) as e:
        load_scene(tmp_path / "biased.usda")
    assert str(tmp_path / "biased.usda") in str(e.value) and "inputs:bias" in str(e.value)


@needs_usd
def test_st_indices_out_of_range_are_an_input_error_naming_the_mesh(tmp_path):
    stage = _stage(tmp_path / "idx.usda")
    m = _mesh(stage, "/Q", POLY_POINTS[:4], [4], [0, 1, 2, 3], [[0, 0], [1, 0]], "faceVarying", [0, 1, 5, 1])
    _bind(m, _material(stage, "/Looks/Leaf", texture=f"./{_png(tmp_path / 'leaf.png', _blobs())}", threshold=0.5))
    stage.GetRootLayer().Save()
    with pytest.raises(InputError, match="mesh /Q: primvar 'st': its indices name value 5 of 2"):
        load_scene(tmp_path / "idx.usda")


HEADER = b"#usda 1.0\n(\n    metersPerUnit = 1\n)\n\n"
VALID = HEADER + b"""def Mesh "Q"
{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "faceVarying")
    int[] primvars:st:indices = [0, 1, 2, 3]
}
"""


@needs_usd
@settings(max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(st.binary(max_size=200),
                      st.tuples(st.integers(0, len(VALID) - 1), st.binary(min_size=1, max_size=8)).map(
                          lambda c: VALID[:c[0]] + c[1] + VALID[c[0] + len(c[1]):]),
                      st.integers(0, len(VALID)).map(lambda k: VALID[:k])))
def test_malformed_usda_is_an_input_error_naming_the_file(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fuzz") / "bad.usda"
    path.write_bytes(data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(path)
    except InputError as exc:
        assert str(path) in str(exc)
        return
    for mesh in scene.meshes:  # what loads is a scene the rest can use
        for p in mesh.primitives:
            assert p.triangles.max(initial=-1) < len(p.positions)


def test_without_usd_core_a_stage_is_an_input_error_with_the_install_hint(tmp_path, monkeypatch, capsys):
    path = tmp_path / "x.usda"
    path.write_bytes(VALID)
    monkeypatch.setitem(sys.modules, "pxr", None)  # import pxr fails
    with pytest.raises(InputError) as e:
        load_scene(path)
    assert str(path) in str(e.value) and HINT in str(e.value)
    assert main(["trace", str(path), "--schemes", "none", "--size", "16", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and HINT in err[0] and "Traceback" not in err[0], err


def test_reading_gltf_never_imports_pxr(tmp_path):
    gl = write_quad_gltf(tmp_path / "q.gltf", _blobs())
    code = ("import sys, omaps, omaps.scene; from omaps.scene import load_scene; load_scene(sys.argv[1]); "
            "import omaps.jobs, omaps.trace; assert 'pxr' not in sys.modules, 'pxr imported'")
    subprocess.run([sys.executable, "-c", code, gl], check=True)
