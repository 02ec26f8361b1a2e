"""``omaps omm SCENE -o OUT.glb|OUT.gltf``: EXT_mesh_opacity_micromap (and OMAPS_pair_opacity_maps)
written into the scene, read back, verified, expanded and traced.

The extension's rules are checked here independently of omaps' reader: the JSON and binary
chunk are parsed with this file's own few lines (``_parse``), the usage histograms recounted from
the raw records, the index accessors decoded from their raw bytes. The Khronos validator runs
when ``npm ci --prefix tools`` has installed it (skipped otherwise)."""

import json
import os
import shutil
import struct
import subprocess

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gltf_files import write_quad_gltf
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.omm import OmmSettings, build
from omaps.omm.gltf_io import read_gltf
from omaps.omm.inputs import scene_spec, load_geometries
from omaps.scene.micromaps import encode_indices, index_component_type

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "..", "shared", "data", "scenes")
PALM = os.path.join(SCENES, "palm.glb")
VALIDATOR = os.path.join(ROOT, "tools", "node_modules", "gltf-validator")
needs_palm = pytest.mark.skipif(not os.path.exists(PALM), reason="../shared/data/scenes/palm.glb is absent")
needs_validator = pytest.mark.skipif(
    not os.path.isdir(VALIDATOR) or shutil.which("node") is None,
    reason="the glTF validator is not installed (run `npm ci --prefix tools`; needs node)")


# ---- an independent reader of what the extension stores --------------------------------------
def _parse(path):
    raw = open(path, "rb").read()
    if raw[:4] == b"glTF":
        n = struct.unpack_from("<I", raw, 12)[0]
        doc = json.loads(raw[20:20 + n])
        pos = 20 + n
        blen = struct.unpack_from("<I", raw, pos)[0]
        buffers = {0: raw[pos + 8:pos + 8 + blen]}
    else:
        doc = json.loads(raw)
        buffers = {}
    import base64
    for i, b in enumerate(doc["buffers"]):
        if "uri" in b and b["uri"].startswith("data:"):
            buffers[i] = base64.b64decode(b["uri"].split(",", 1)[1])
        elif "uri" in b:
            buffers[i] = open(os.path.join(os.path.dirname(path), b["uri"]), "rb").read()
    return doc, buffers


def _view(doc, buffers, vi):
    v = doc["bufferViews"][vi]
    off = v.get("byteOffset", 0)
    return buffers[v["buffer"]][off:off + v["byteLength"]]


def check_extension_rules(path):
    """The extension's rules from its README, on the raw file. Returns per (mesh, primitive) the
    signed lookup values and the (data, records) of the one micromap array."""
    doc, buffers = _parse(path)
    assert "EXT_mesh_opacity_micromap" in doc["extensionsUsed"]
    arrays = doc["extensions"]["EXT_mesh_opacity_micromap"]["micromaps"]
    parsed = []
    for mm in arrays:
        data = _view(doc, buffers, mm["data"])
        assert "byteStride" not in doc["bufferViews"][mm["triangles"]]
        tri = _view(doc, buffers, mm["triangles"])
        assert len(tri) % 8 == 0
        rec = np.frombuffer(tri, dtype=[("off", "<u4"), ("level", "<u2"), ("fmt", "<u2")])
        assert len(mm["usageCounts"]) == len(mm["usageLevels"]) == len(mm["usageFormats"]) >= 1
        assert all(c >= 1 for c in mm["usageCounts"]) and set(mm["usageFormats"]) <= {1, 2}
        usage = {}
        for c, lv, f in zip(mm["usageCounts"], mm["usageLevels"], mm["usageFormats"]):
            usage[(lv, f)] = usage.get((lv, f), 0) + c
        recount = {}
        for r in rec:
            recount[(int(r["level"]), int(r["fmt"]))] = recount.get((int(r["level"]), int(r["fmt"])), 0) + 1
        assert usage == recount and sum(usage.values()) == len(rec)
        ends = []
        for r in rec:
            assert r["fmt"] in (1, 2)
            size = -(-(4 ** int(r["level"]) * int(r["fmt"])) // 8)
            assert r["off"] + size <= len(data)
            ends.append((int(r["off"]), int(r["off"]) + size))
        ends.sort()
        assert all(a[1] <= b[0] for a, b in zip(ends, ends[1:])), "data regions overlap"
        parsed.append((data, rec))
    lookups = {}
    for mi, mesh in enumerate(doc["meshes"]):
        for pi, p in enumerate(mesh["primitives"]):
            e = p.get("extensions", {}).get("EXT_mesh_opacity_micromap")
            if e is None:
                continue
            assert p.get("mode", 4) == 4
            acc = doc["accessors"][e["micromapIndices"]]
            n_tri = doc["accessors"][p["indices"]]["count"] // 3 if "indices" in p else \
                doc["accessors"][p["attributes"]["POSITION"]]["count"] // 3
            assert acc["type"] == "SCALAR" and acc["count"] == n_tri
            assert acc["componentType"] in (5121, 5123, 5125)  # unsigned: no INT warning from the validator
            bits = {5121: 8, 5123: 16, 5125: 32}[acc["componentType"]]
            raw = _view(doc, buffers, acc["bufferView"])[acc.get("byteOffset", 0):]
            v = np.frombuffer(raw, dtype={8: "<u1", 16: "<u2", 32: "<u4"}[bits])[:n_tri].astype(np.int64)
            v = np.where(v >= (1 << bits) - 4, v - (1 << bits), v)
            base = e.get("micromapBaseTriangle", 0)
            n_rec = len(parsed[e["micromap"]][1])
            assert np.all((v >= -4) & ((v < 0) | (v + base < n_rec)))
            lookups[(mi, pi)] = np.where(v >= 0, v + base, v)
    return doc, parsed, lookups


def run_validator(*paths):
    out = subprocess.run(["node", os.path.join(ROOT, "tools", "validate_gltf.mjs"), *map(str, paths)],
                         capture_output=True, text=True, timeout=300)
    reports = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    assert len(reports) == len(paths), out.stderr
    return reports


def quad_scene(tmp_path, name="quad.gltf"):
    alpha = np.zeros((16, 16), np.uint8)
    alpha[:, :8] = 255
    alpha[3:5, 10:12] = 255
    p = tmp_path / name
    write_quad_gltf(p, alpha, material={"alphaMode": "MASK"}, sampler={"magFilter": 9728})
    return p


# ---- tests ---------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_quad_round_trip(tmp_path, suffix):
    src = quad_scene(tmp_path)
    out = tmp_path / "sub" / f"baked{suffix}"
    assert main(["omm", str(src), "-o", str(out), "--quiet", "--level", "3"]) == 0
    doc, parsed, lookups = check_extension_rules(out)
    # the bake of the same scene, independently of the file: identical buffers
    geoms, _, _ = load_geometries(scene_spec(src))
    res = build(geoms, OmmSettings(level=3))
    data, rec = parsed[0]
    assert bytes(data) == res.data.tobytes()
    assert np.array_equal(rec["off"], res.triangles["data_offset"]) and np.array_equal(rec["level"], res.triangles["level"])
    assert np.array_equal(lookups[(0, 0)], res.index)
    back = read_gltf(out)
    assert np.array_equal(back.index, res.index) and np.array_equal(back.data, res.data)
    assert main(["omm", "--verify", str(out)]) == 0
    # the scene itself is kept: the same meshes, materials, images, nodes
    src_doc = json.loads(open(src).read())
    for key in ("meshes", "materials", "images", "nodes", "textures", "samplers"):
        a = [dict(x) for x in src_doc.get(key, [])]
        b = [dict(x) for x in doc.get(key, [])]
        for x in a + b:
            x.pop("extensions", None)
            for prim in x.get("primitives", []):
                prim.pop("extensions", None)
            if key == "images" and "bufferView" in x:  # a data URI moved into a GLB's binary chunk
                x.pop("bufferView"), x.pop("mimeType")
                x["uri"] = "moved"
            elif key == "images":
                x["uri"] = "moved" if x["uri"].startswith("data:") else x["uri"]
        assert a == b, key


def test_unknown_extensions_and_extras_kept(tmp_path):
    src = quad_scene(tmp_path)
    doc = json.loads(src.read_text())
    doc["extras"] = {"keep": [1, 2]}
    doc["meshes"][0]["primitives"][0]["extensions"] = {"VENDOR_thing": {"x": 1}}
    doc.setdefault("extensionsUsed", []).append("VENDOR_thing")
    doc["animations"] = []
    src.write_text(json.dumps(doc))
    out = tmp_path / "baked.glb"
    assert main(["omm", str(src), "-o", str(out), "--quiet"]) == 0
    d, _, _ = check_extension_rules(out)
    assert d["extras"] == {"keep": [1, 2]}
    assert d["meshes"][0]["primitives"][0]["extensions"]["VENDOR_thing"] == {"x": 1}
    assert "VENDOR_thing" in d["extensionsUsed"]
    # baking a baked file again replaces the micromaps, not adds to them
    out2 = tmp_path / "again.gltf"
    assert main(["omm", str(out), "-o", str(out2), "--quiet", "--level", "2"]) == 0
    d2, parsed2, _ = check_extension_rules(out2)
    assert len(d2["extensions"]["EXT_mesh_opacity_micromap"]["micromaps"]) == 1
    assert d2["extensionsUsed"].count("EXT_mesh_opacity_micromap") == 1
    assert set(parsed2[0][1]["level"]) <= {2}


def test_broken_extension_is_an_error_naming_the_file(tmp_path):
    src = quad_scene(tmp_path)
    out = tmp_path / "baked.gltf"
    assert main(["omm", str(src), "-o", str(out), "--quiet", "--level", "3"]) == 0
    doc = json.loads(out.read_text())
    doc["extensions"]["EXT_mesh_opacity_micromap"]["micromaps"][0]["usageCounts"][0] += 1
    bad = tmp_path / "bad.gltf"
    bad.write_text(json.dumps(doc))
    from omaps.scene import load_scene
    with pytest.raises(InputError, match="usage counts"):
        load_scene(bad)
    assert main(["omm", "--verify", str(bad)]) == 2
    doc = json.loads(out.read_text())
    acc = doc["meshes"][0]["primitives"][0]["extensions"]["EXT_mesh_opacity_micromap"]["micromapIndices"]
    doc["accessors"][acc]["count"] = 1
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="elements"):
        load_scene(bad)


def test_texture_input_cannot_write_gltf(tmp_path):
    assert main(["omm", "a.png", "b.npy", "-o", str(tmp_path / "x.glb")]) == 2
    assert not (tmp_path / "x.glb").exists()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(-4, 70000), min_size=1, max_size=50))
def test_index_encoding_round_trip(values):
    v = np.array(values, np.int64)
    n_rec = int(max(v.max() + 1, 1))
    ct = index_component_type(n_rec)
    bits = {5121: 8, 5123: 16, 5125: 32}[ct]
    assert n_rec <= (1 << bits) - 4  # no record index collides with a special pattern
    u = np.frombuffer(encode_indices(v, ct), dtype={8: "<u1", 16: "<u2", 32: "<u4"}[bits]).astype(np.int64)
    back = np.where(u >= (1 << bits) - 4, u - (1 << bits), u)
    assert np.array_equal(back, v)


@needs_palm
@pytest.mark.long
def test_palm_glb_extension_verify_trace_and_expand(tmp_path):
    out = tmp_path / "palm.glb"
    assert main(["omm", PALM, "-o", str(out), "--quiet"]) == 0
    doc, parsed, lookups = check_extension_rules(out)
    geoms, _, _ = load_geometries(scene_spec(PALM))
    res = build(geoms, OmmSettings())
    assert np.array_equal(np.concatenate([lookups[(g.info["mesh"], g.info["primitive"])] for g in geoms]), res.index)
    assert bytes(parsed[0][0]) == res.data.tobytes()
    assert main(["omm", "--verify", str(out)]) == 0
    # trace: the stored micromaps change no pixel and save alpha tests
    js = tmp_path / "t.json"
    assert main(["trace", str(out), "--schemes", "none,omm,tri4", "--size", "96", "--quiet", "--json", str(js)]) == 0
    rep = json.loads(js.read_text())["schemes"]
    assert rep["omm"]["differing_pixels"] == 0
    none_t = rep["none"]["alpha_tests_per_primary_ray"]
    assert rep["omm"]["alpha_tests_per_primary_ray"] * 1.2 < none_t
    # the file's level-4 micromaps are the tracer's own tri4 bake: the same tests, ray by ray in sum
    assert rep["omm"]["alpha_tests_per_primary_ray"] == rep["tri4"]["alpha_tests_per_primary_ray"]


@needs_palm
@pytest.mark.long
def test_palm_from_vq2_pairs_expand_and_trace(tmp_path):
    baked = tmp_path / "palm_vq2.gltf"
    assert main(["omm", PALM, "-o", str(baked), "--from", "vq2", "--quiet"]) == 0
    doc, parsed, lookups = check_extension_rules(baked)
    maps = doc["extensions"]["OMAPS_pair_opacity_maps"]["maps"]
    assert maps[0]["codec"] == "vq2" and maps[0]["blockBytes"] == 32
    _, buffers = _parse(baked)
    assert len(_view(doc, buffers, maps[0]["blocks"])) == 32 * 1920  # 256 bits per pair
    assert main(["omm", "--verify", str(baked)]) == 0
    std = tmp_path / "std.glb"
    assert main(["omm", str(baked), "--expand", "-o", str(std)]) == 0
    d2, parsed2, lookups2 = check_extension_rules(std)
    assert "OMAPS_pair_opacity_maps" not in d2.get("extensionsUsed", [])
    # the expansion of the stored blocks equals the micromaps written beside them
    assert bytes(parsed2[0][0]) == bytes(parsed[0][0])
    assert lookups2.keys() == lookups.keys() and all(np.array_equal(lookups2[k], lookups[k]) for k in lookups)
    js = tmp_path / "t.json"
    assert main(["trace", str(baked), "--schemes", "none,omm,file:vq2,vq2", "--size", "64", "--quiet",
                 "--json", str(js)]) == 0
    rep = json.loads(js.read_text())["schemes"]
    assert rep["file:vq2"]["differing_pixels"] == 0 and rep["omm"]["differing_pixels"] == 0
    # the stored blocks are the tracer's own vq2 encoding of the same pairs
    assert rep["file:vq2"]["alpha_tests_per_primary_ray"] == rep["vq2"]["alpha_tests_per_primary_ray"]
    assert rep["omm"]["alpha_tests_per_primary_ray"] == rep["vq2"]["alpha_tests_per_primary_ray"]
    assert main(["trace", str(baked), "--schemes", "none,file:vq4", "--size", "16", "--quiet"]) == 2


@needs_validator
@needs_palm
@pytest.mark.parametrize("scene, args, suffixes", [
    ("palm.glb", ["--level", "3", "--format", "2state", "--promote", "hashed"], (".glb", ".gltf")),
    ("smallpine/scene.gltf", ["--from", "vq4"], (".glb", ".gltf")), ("forest.glb", [], (".glb",))])
@pytest.mark.long
def test_khronos_validator(tmp_path, scene, args, suffixes):
    """The outputs validate like their input: palm.glb with 0 errors and 0 warnings; forest carries
    its input's own errors (normals of zero length) and nothing more -- the extension's data adds
    no error or warning; smallpine's missing normal-map file (an error of the input) is left out of
    its outputs, which have no error."""
    src = os.path.join(SCENES, scene)
    outs = [tmp_path / f"out{suffix}" for suffix in suffixes]
    for o in outs:
        assert main(["omm", src, "-o", str(o), "--quiet", *args]) == 0
        check_extension_rules(o)
    ref, *reps = run_validator(src, *outs)
    if scene == "palm.glb":
        assert ref["numErrors"] == 0
    errors = [(m["code"], m["pointer"]) for m in ref["messages"] if m["severity"] == 0]
    missing = [k for k in errors if k[0] == "IO_ERROR" and k[1].startswith("/images/")]
    assert bool(missing) == (scene == "smallpine/scene.gltf"), errors  # its file left out of the outputs
    for rep in reps:
        assert [(m["code"], m["pointer"]) for m in rep["messages"] if m["severity"] == 0] == \
            [k for k in errors if k not in missing], rep["messages"]
        assert rep["numErrors"] == ref["numErrors"] - len(missing), rep["messages"]
        assert rep["numWarnings"] <= ref["numWarnings"], rep["messages"]


@needs_validator
@needs_palm
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_khronos_validator_on_a_file_baked_again(tmp_path, suffix):
    """The palm baked with pair blocks and a merged DAG, baked again: no error, and no object
    the validator finds unused but those a single bake leaves (the micromaps' own views and
    index accessors, which the validator does not know the extension of)."""
    first, again, once = (tmp_path / f"{n}{suffix}" for n in ("first", "again", "once"))
    assert main(["omm", PALM, "-o", str(first), "--quiet", "--from", "csm3"]) == 0
    assert main(["omm", str(first), "-o", str(again), "--quiet", "--from", "sq16"]) == 0
    assert main(["omm", PALM, "-o", str(once), "--quiet", "--from", "sq16"]) == 0
    f, a, o = run_validator(first, again, once)
    assert f["numErrors"] == a["numErrors"] == o["numErrors"] == 0
    assert a["unused"] == o["unused"]  # (the first bake's micromaps would show here, unused)


@pytest.mark.parametrize("args", [["--dynamic", "1", "--max-level", "5"], ["--level", "0", "--no-special"],
                                  ["--format", "2state"]])
def test_trace_reads_stored_levels_and_formats(tmp_path, args):
    """Per-record levels (--dynamic), level 0 and 2-state records, traced:
    a 4-state file changes no pixel; a 2-state one runs no alpha test at all."""
    src = quad_scene(tmp_path)
    out = tmp_path / "q.glb"
    assert main(["omm", str(src), "-o", str(out), "--quiet", *args]) == 0
    js = tmp_path / "t.json"
    rc = main(["trace", str(out), "--schemes", "none,omm", "--size", "48", "--quiet", "--json", str(js)])
    rep = json.loads(js.read_text())["schemes"]
    if "2state" in args:
        assert rep["omm"]["alpha_tests_per_primary_ray"] == 0
    else:
        assert rc == 0 and rep["omm"]["differing_pixels"] == 0
        assert rep["omm"]["alpha_tests_per_primary_ray"] <= rep["none"]["alpha_tests_per_primary_ray"]
