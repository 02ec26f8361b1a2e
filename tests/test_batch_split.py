"""One scene's OMM bake split into pieces (``omaps.omm.split``, ``omaps batch omm --split``): the
buffers of ``build`` byte for byte whatever the pieces and the order they run in; the batch's
outputs (OMM folder, .glb, summary figures) identical to the unsplit batch's; bakes that cannot
split are refused before any work."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from gltf_files import grid_scene
from omaps import batch as engine
from omaps.alpha_test import StateRule
from omaps.cli.main import main
from omaps.errors import InputError
from omaps.omm import Geometry, OmmSettings, build, pipeline
from omaps.omm.split import bake_piece, build_split, plan_pieces, splittable
from omaps.texture import load_alpha
from conftest import SCENES, needs_scenes


def _alpha(seed=0, size=64):
    rng = np.random.default_rng(seed)
    a = (rng.random((size // 4, size // 4)) > 0.5).astype(np.uint8) * 255
    a = np.kron(a, np.ones((4, 4), np.uint8))
    a[::7, ::5] = 128  # some mid values: linear filtering has unknown regions to resolve
    return a


def _geometries(n=3, tris=300, seed=1):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        test = StateRule("cutoff").alpha_test(load_alpha(_alpha(seed + i)), "linear", "wrap")
        uv = rng.random((tris, 3, 2)) * 1.5 - 0.25
        uv[: tris // 4] = uv[0]  # repeated triangles: planned once (dedup), indexed many times
        unknown = (rng.random(tris) < 0.05) if i == 1 else None
        out.append(Geometry(f"g{i}", test, uv, unknown=unknown))
    return out


def _same(a, b):
    assert a.data.tobytes() == b.data.tobytes()
    assert a.triangles.tobytes() == b.triangles.tobytes()
    assert a.index.tobytes() == b.index.tobytes()
    assert a.usage == b.usage
    assert json.dumps(a.summary, sort_keys=True) == json.dumps(b.summary, sort_keys=True)


@pytest.mark.parametrize("settings", [
    OmmSettings(level=4),
    OmmSettings(level=3, format="2state", promotion="hashed", seed=5),
    OmmSettings(dynamic_scale=3.0, max_level=6),
    OmmSettings(level=2, special=False, dedup=False),
])
def test_split_bake_is_build_byte_for_byte(settings, monkeypatch):
    geoms = _geometries()
    monkeypatch.setattr(pipeline, "CHUNK_MICRO_TRIANGLES", 1 << 12)  # several of build's chunks per geometry
    ref = build(geoms, settings)
    for pieces in (1, 5, 64):
        _same(ref, build_split(geoms, settings, pieces=pieces))


def test_pieces_run_in_any_order_and_cover_every_triangle_once(monkeypatch):
    geoms = _geometries(tris=400)
    settings = OmmSettings(level=5)
    monkeypatch.setattr("omaps.omm.split.MIN_PIECE_MICRO_TRIANGLES", 1024)
    plans, work = plan_pieces(geoms, settings, 16)
    assert len(work) > 16
    for gi, p in enumerate(plans):  # consecutive ranges from 0 to the plan's length
        mine = [(w.a, w.b) for w in work if w.geometry == gi]
        assert mine[0][0] == 0 and mine[-1][1] == len(p.tris)
        assert all(b == a2 for (_, b), (a2, _) in zip(mine, mine[1:]))

    def backwards(jobs):  # every piece run, last first, as a pool might: results handed back in order
        done = [bake_piece(*j) for j in reversed(jobs)]
        yield from reversed(done)

    _same(build(geoms, settings), build_split(geoms, settings, backwards, pieces=16))


def test_bakes_that_do_not_split_say_why():
    assert splittable(OmmSettings(level=4)) is None
    assert "budget" in splittable(OmmSettings(budget=4096))
    assert "{source}" in splittable(OmmSettings(source="sq16"))  # the parameter (the command line: --from)
    with pytest.raises(InputError, match="budget"):
        plan_pieces(_geometries(n=1, tris=10), OmmSettings(budget=4096), 4)


# --- omaps batch omm --split --------------------------------------------------------------------

def _grid_scene(path, k=24, seed=3):
    return grid_scene(path, _alpha(seed), k, seed)


def _files(folder):
    return {os.path.relpath(os.path.join(r, f), folder): open(os.path.join(r, f), "rb").read()
            for r, _, fs in os.walk(folder) for f in fs}


def _figures(out):
    with open(os.path.join(out, "summary.json")) as f:
        return [(r["output"], r["status"], r.get("figures")) for r in json.load(f)["inputs"]]


def test_batch_split_serial_writes_the_unsplit_outputs(tmp_path):
    scenes = [_grid_scene(tmp_path / "a.gltf"), _grid_scene(tmp_path / "b.gltf", k=12, seed=4)]
    opts = ["--scheduler", "none", "--quiet", "--level", "5"]
    assert main(["batch", "omm", *scenes, "-o", str(tmp_path / "whole"), *opts]) == 0
    assert main(["batch", "omm", *scenes, "-o", str(tmp_path / "split"), "--split", *opts]) == 0
    for name in ("a", "b"):
        assert _files(tmp_path / "split" / name) == _files(tmp_path / "whole" / name)
    assert _figures(tmp_path / "split") == _figures(tmp_path / "whole")
    assert json.loads((tmp_path / "split" / "summary.json").read_text())["settings"]["split"] is True
    # --glb: the scene with its micromaps, byte for byte
    assert main(["batch", "omm", scenes[0], "-o", str(tmp_path / "g1"), "--glb", *opts]) == 0
    assert main(["batch", "omm", scenes[0], "-o", str(tmp_path / "g2"), "--glb", "--split", *opts]) == 0
    assert (tmp_path / "g1" / "a.glb").read_bytes() == (tmp_path / "g2" / "a.glb").read_bytes()


@pytest.mark.parametrize("extra, words", [(["--budget", "4096"], "budget"), (["--from", "sq16"], "--from")])
def test_batch_split_refuses_what_cannot_split(tmp_path, capsys, extra, words):
    scene = _grid_scene(tmp_path / "a.gltf", k=4)
    rc = main(["batch", "omm", scene, "-o", str(tmp_path / "out"), "--split", "--scheduler", "none", "--quiet",
               *extra])
    err = capsys.readouterr().err
    assert rc == 2 and "--split" in err and words in err, err
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="omm"):  # (the library: only omm splits)
        engine.plan_batch("eval", [scene], tmp_path / "out", {}, scheduler="none", split=True)


@needs_scenes
@pytest.mark.long
def test_batch_split_on_the_local_cluster_writes_the_unsplit_outputs(tmp_path):
    """The palm split into pieces on a LocalCluster (the CLI as a user runs it) against the
    serial unsplit batch: the same OMM files and figures."""
    scene = str(SCENES / "palm.glb")
    assert main(["batch", "omm", scene, "-o", str(tmp_path / "whole"), "--scheduler", "none", "--quiet"]) == 0
    r = subprocess.run([sys.executable, "-m", "omaps", "batch", "omm", scene, "-o", str(tmp_path / "split"),
                        "--scheduler", "local", "--split", "--quiet"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "split into pieces" in r.stdout
    assert _files(tmp_path / "split" / "palm") == _files(tmp_path / "whole" / "palm")
    assert _figures(tmp_path / "split") == _figures(tmp_path / "whole")
