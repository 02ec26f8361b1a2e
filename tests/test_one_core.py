"""One core under eval, trace and omm: one reader, one alpha test, one baker family, one stored
map layer -- checked by the layout of the code and by the commands agreeing on the same files."""

import ast
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf

from omaps import states
from omaps.alpha_test import MaterialRules
from omaps.cli import main
from omaps.omm import OmmSettings, build, pairs
from omaps.omm.inputs import scene_spec, load_geometries
from omaps.scene import alpha_triangles, load_scene
from omaps.schemes import parse_schemes
from omaps.trace.maps import build_scheme_maps

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "omaps"


def _imports(path: Path) -> set[str]:
    """Absolute names of the modules a source file imports."""
    tree = ast.parse(path.read_text())
    pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def _sources(folder: Path):
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def test_exactly_one_module_imports_pygltflib():
    users = [p.relative_to(ROOT).as_posix() for p in _sources(PACKAGE)
             if any(m == "pygltflib" or m.startswith("pygltflib.") for m in _imports(p))]
    assert users == ["omaps/scene/gltf.py"]


def test_tracer_and_omm_modules_do_not_import_each_other():
    """Neither the packages nor their commands: what both need is in the core (e.g. omaps.view)."""
    for a, b in (("trace", "omm"), ("omm", "trace")):
        for p in _sources(PACKAGE / a) + [PACKAGE / "cli" / f"{a}.py"]:
            bad = [m for m in _imports(p) if m == f"omaps.{b}" or m.startswith(f"omaps.{b}.")]
            assert not bad, f"{p.relative_to(ROOT)} imports {bad}"


def test_library_does_not_print_and_bench_imports_no_cli():
    for p in _sources(PACKAGE):
        if "cli" in p.relative_to(PACKAGE).parts:
            continue
        calls = [n for n in ast.walk(ast.parse(p.read_text()))
                 if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "print"]
        assert not calls, f"{p.relative_to(ROOT)} prints"
    for p in _sources(ROOT / "bench"):
        bad = [m for m in _imports(p) if m.startswith("omaps.cli")]
        assert not bad, f"{p.relative_to(ROOT)} imports {bad}"


def _requiring(tmp_path, ext):
    path = write_quad_gltf(tmp_path / "quad.gltf", np.full((4, 4), 255, np.uint8))
    doc = json.loads(Path(path).read_text())
    doc["extensionsUsed"] = [ext]
    doc["extensionsRequired"] = [ext]
    Path(path).write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("ext", ["KHR_meshopt_compression", "KHR_texture_basisu"])
def test_required_extension_is_an_error_in_both_commands(tmp_path, capsys, ext):
    path = _requiring(tmp_path, ext)
    assert main(["trace", path, "--schemes", "none", "--size", "8", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert ext in err and "quad.gltf" in err
    assert main(["omm", path, "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert ext in err and "quad.gltf" in err
    assert not (tmp_path / "out").exists()


def _tracer_micromaps(path, level, rules=MaterialRules()):
    """The tracer's triL states per alpha triangle, keyed (mesh, primitive, triangle)."""
    scene = load_scene(path)
    at = alpha_triangles(scene, rules)
    tests = {int(m): scene.alpha_test(int(m), rules) for m in np.unique(at.material)}
    sm = build_scheme_maps(at, tests, parse_schemes(f"tri{level}"))[f"tri{level}"]
    rows = sm.data.reshape(-1, sm.row_bytes)[sm.rows]
    from omaps.codecs.raw import unpack_states

    st = unpack_states(rows, 4 ** level)
    mesh_of = np.repeat(np.arange(len(scene.meshes)), np.diff(at.base))
    keys = [(scene.meshes[m].index, scene.meshes[m].primitives[p].index, int(t))
            for m, p, t in zip(mesh_of, at.primitive, at.local)]
    return dict(zip(keys, st))


def _omm_micromaps(path, settings, rules=MaterialRules()):
    geoms, _, _ = load_geometries(scene_spec(path, rules))
    res = build(geoms, settings)
    out = {}
    t = 0
    for g in geoms:
        for k in range(len(g.tris_uv)):
            s = res.triangle_states(t)
            s = np.broadcast_to(s, (4 ** max(settings.level if settings.source == "texture" else 4, 0),)) \
                if len(s) == 1 else s
            out[(g.info["mesh"], g.info["primitive"], k)] = np.minimum(s, states.C)  # unknown-T/O -> C
            t += 1
    return out


def test_missing_image_gives_the_same_maps_and_names_the_file(tmp_path, capsys):
    path = write_quad_gltf(tmp_path / "quad.gltf", None, image_uri="leaf.png")
    tracer = _tracer_micromaps(path, 3)
    omm = _omm_micromaps(path, OmmSettings(level=3, special=False, dedup=False))
    capsys.readouterr()
    assert tracer.keys() == omm.keys() and len(tracer) == 2
    for k in tracer:
        np.testing.assert_array_equal(tracer[k], omm[k])
        assert np.all(tracer[k] == states.C)  # nothing is known about an image that is not there
    out = tmp_path / "omm"
    assert main(["omm", path, "-o", str(out), "--level", "3"]) == 0
    assert "leaf.png" in capsys.readouterr().err
    assert main(["trace", path, "--schemes", "none,tri3,sq8", "--size", "16", "--quiet",
                 "--json", str(tmp_path / "r.json")]) == 0
    assert "leaf.png" in capsys.readouterr().err
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["schemes"]["tri3"]["known_fraction"] == 0.0 == report["schemes"]["sq8"]["known_fraction"]
    assert json.loads((out / "omm.json").read_text())["statistics"]["known_fraction"] == 0.0


SCENE_FILES = {"palm": SCENES / "palm.glb", "smallpine": SCENES / "smallpine" / "scene.gltf"}


@needs_scenes
@pytest.mark.parametrize("name", sorted(SCENE_FILES))
def test_tracer_micromaps_equal_omm_micromaps(name):
    path = SCENE_FILES[name]
    tracer = _tracer_micromaps(path, 3)
    omm = _omm_micromaps(path, OmmSettings(level=3, special=False, dedup=False))
    assert tracer.keys() == omm.keys() and len(tracer) > 1000
    for k in tracer:
        np.testing.assert_array_equal(tracer[k], omm[k], err_msg=str(k))


@needs_scenes
@pytest.mark.parametrize("name", sorted(SCENE_FILES))
def test_tracer_square_maps_equal_the_omm_expansion(name):
    path = SCENE_FILES[name]
    rules = MaterialRules()
    scene = load_scene(path)
    at = alpha_triangles(scene, rules)
    tests = {int(m): scene.alpha_test(int(m), rules) for m in np.unique(at.material)}
    sm = build_scheme_maps(at, tests, parse_schemes("sq16"))["sq16"]
    maps16 = sm.codec.decode_many(sm.data.reshape(-1, sm.row_bytes))[sm.rows]  # per triangle: its pair's map
    expanded = pairs.expand(maps16, np.arange(at.count), at.corners)
    mesh_of = np.repeat(np.arange(len(scene.meshes)), np.diff(at.base))
    tracer = {(scene.meshes[m].index, scene.meshes[m].primitives[p].index, int(t)): expanded[i]
              for i, (m, p, t) in enumerate(zip(mesh_of, at.primitive, at.local))}
    omm = _omm_micromaps(path, OmmSettings(source="sq16", special=False, dedup=False))
    assert tracer.keys() == omm.keys()
    for k in tracer:
        np.testing.assert_array_equal(tracer[k], omm[k], err_msg=str(k))
    assert np.mean([np.mean(v != states.C) for v in tracer.values()]) > 0.2
    # the expansion is what the tracer's lookup reads: at random hits, the cell (pair.hit_st through
    # the corners, pair.uv_to_cell) of the pair's map equals the OMM's micro-triangle (bird curve)
    from omaps import birdcurve, pair

    rng = np.random.default_rng(5)
    keys = list(tracer)
    for i in rng.choice(at.count, 300, replace=False):
        b = rng.dirichlet([1, 1, 1])
        s, t = pair.hit_st(at.corners[i].ravel(), 0, b[1], b[2])
        cx, cy = pair.uv_to_cell(s, t, 16)
        want = maps16[i][cy, cx]
        got = omm[keys[i]][birdcurve.bary_to_index(b[1], b[2], 4)]
        assert got == want, (keys[i], b)
