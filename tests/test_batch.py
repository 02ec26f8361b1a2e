"""``omaps batch``: per input the single command's outputs byte for byte, the summary, errors
recorded, resume (a finished input is skipped; a batch killed mid-way is re-run without redoing
what it finished), and the Dask schedulers (one LocalCluster in this file)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from omaps.cli.main import main
from conftest import SCENES, TEXTURES, needs_scenes, needs_shared

SCHEMES = "sq16,tri3,vq2"
OLD_NS = 946684800 * 10**9  # 2000-01-01: a time stamp a test gives outputs, which only a rewrite changes


def _textures(folder, n=4, size=64, seed=0):
    """n RGBA textures with random blobs of alpha (distinct, seeded)."""
    rng = np.random.default_rng(seed)
    os.makedirs(folder, exist_ok=True)
    paths = []
    for i in range(n):
        a = (rng.random((size // 8, size // 8)) > 0.5).astype(np.uint8) * 255
        a = np.kron(a, np.ones((8, 8), np.uint8))
        rgba = np.dstack([np.full_like(a, 90)] * 3 + [a])
        p = os.path.join(folder, f"t{i:02d}.png")
        Image.fromarray(rgba, "RGBA").save(p)
        paths.append(p)
    return paths


def _summary(outdir):
    with open(os.path.join(outdir, "summary.json")) as f:
        s = json.load(f)
    with open(os.path.join(outdir, "summary.csv")) as f:
        rows = list(csv.DictReader(f))
    return s, rows


def _single_eval(path, out, *opts):
    assert main(["eval", str(path), "--json", str(out), "--quiet", *opts]) == 0
    return open(out, "rb").read()


def test_eval_serial_identical_and_corrupt_input_recorded(tmp_path, capsys):
    src = tmp_path / "tex"
    paths = _textures(src)
    (src / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n not a png at all")
    out = tmp_path / "out"
    rc = main(["batch", "eval", str(src), "-o", str(out), "--scheduler", "none", "--schemes", SCHEMES, "--quiet"])
    assert rc == 1  # one input failed; the others completed
    s, rows = _summary(out)
    by = {os.path.basename(r["input"]): r for r in s["inputs"]}
    assert by["broken.png"]["status"] == "error" and "broken.png" in by["broken.png"]["error"]
    assert by["broken.png"]["output"] is None
    assert not (out / "broken.json").exists() and not (out / ".batch" / "broken.json").exists()
    for p in paths:
        name = os.path.splitext(os.path.basename(p))[0]
        assert by[os.path.basename(p)]["status"] == "ok"
        single = _single_eval(p, tmp_path / f"{name}.json", "--schemes", SCHEMES)
        assert (out / f"{name}.json").read_bytes() == single  # the single command's output, byte for byte
        savings = json.loads(single)["textures"][0]["schemes"]
        assert by[os.path.basename(p)]["figures"]["savings"] == {k: v["savings"] for k, v in savings.items()}
    assert s["totals"]["ok"] == 4 and s["totals"]["error"] == 1 and s["totals"]["inputs"] == 5
    mean = np.mean([by[os.path.basename(p)]["figures"]["savings"]["sq16"] for p in paths])
    assert s["totals"]["mean_savings"]["sq16"] == pytest.approx(mean)
    assert [r["status"] for r in rows][-1].startswith("4 ok") and rows[-1]["input"] == "(total)"
    assert rows[0]["input"].endswith("broken.png") and rows[0]["status"] == "error"
    assert float(rows[1]["savings:sq16"]) == by["t00.png"]["figures"]["savings"]["sq16"]
    assert "broken.png" in capsys.readouterr().err
    assert not [f for f in os.listdir(out) if f.startswith(".omaps-")]  # no temporary left


def test_resume_skips_finished_inputs_and_redoes_changed_ones(tmp_path):
    src = tmp_path / "tex"
    _textures(src, n=3)
    out = tmp_path / "out"
    args = ["batch", "eval", str(src), "-o", str(out), "--scheduler", "none", "--schemes", "sq16", "--quiet"]
    assert main(args) == 0
    for f in ("t00.json", "t02.json"):  # an old time stamp, which only a rewrite changes (whatever the clock)
        os.utime(out / f, ns=(OLD_NS, OLD_NS))
    (out / "t01.json").unlink()  # an output gone: that input is done again, the others are skipped
    assert main(args) == 0
    s, _ = _summary(out)
    resumed = {os.path.basename(r["input"]): bool(r.get("resumed")) for r in s["inputs"]}
    assert resumed == {"t00.png": True, "t01.png": False, "t02.png": True}
    assert os.stat(out / "t00.json").st_mtime_ns == os.stat(out / "t02.json").st_mtime_ns == OLD_NS
    assert (out / "t01.json").is_file()
    assert s["totals"]["ok"] == 3 and s["totals"]["resumed"] == 2
    # other options: nothing is skipped (the markers record the options)
    assert main(args[:-3] + ["--schemes", "sq32", "--quiet"]) == 0
    s, _ = _summary(out)
    assert s["totals"]["resumed"] == 0 and "sq32" in s["inputs"][0]["figures"]["savings"]


def test_killed_batch_resumes_without_redoing_finished_inputs(tmp_path):
    """Killed (SIGKILL) while its third input runs, two finished: the re-run skips those two. The
    moment is an event: the batch's test-only gate (``omaps.batch.task.TEST_GATE``) holds each input
    at its start until the test releases it, so the kill never depends on the machine's speed."""
    from interrupts import gate_env, held, release, wait_for, went_on_unreleased

    src = tmp_path / "tex"
    _textures(src, n=8, seed=3)
    out, gate = tmp_path / "out", tmp_path / "gate"
    cmd = [sys.executable, "-m", "omaps", "batch", "eval", str(src), "-o", str(out), "--scheduler", "none",
           "--schemes", "sq16", "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=gate_env(os.environ, gate))
    markers = out / ".batch"

    def finished():  # markers in place (one being written is still under its hidden temporary name)
        names = os.listdir(markers) if markers.is_dir() else []
        return sorted(f for f in names if f.endswith(".json") and not f.startswith(".omaps-"))

    try:
        for name in ("t00", "t01"):  # (serial: in order, each one's marker written before the next starts)
            wait_for(lambda: f"input-{name}" in held(gate), f"input {name} held", proc)
            release(gate, f"input-{name}")
        wait_for(lambda: "input-t02" in held(gate), "input t02 held", proc)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not went_on_unreleased(gate), went_on_unreleased(gate)
    done = finished()
    assert done == ["t00.json", "t01.json"] and not (out / "summary.json").exists()
    for f in done:  # every marked input has its whole output
        json.loads((out / f).read_text())
    for f in done:  # an old time stamp, which only a rewrite changes (whatever the clock)
        os.utime(out / f, ns=(OLD_NS, OLD_NS))
    (out / ".omaps-0123456789ab.json").write_text("{")  # what a kill while writing leaves
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s, _ = _summary(out)
    assert s["totals"]["ok"] == 8 and s["totals"]["resumed"] == len(done)
    assert {f: os.stat(out / f).st_mtime_ns for f in done} == {f: OLD_NS for f in done}  # not redone
    assert not [f for f in os.listdir(out) if f.startswith(".omaps-")]  # the killed input left nothing


def test_batch_errors_before_work(tmp_path, capsys):
    src = tmp_path / "tex"
    _textures(src, n=1)
    assert main(["batch", "eval", str(src), "-o", str(tmp_path / "o"), "--scheduler", "none",
                 "--csv", str(tmp_path / "x.csv")]) == 2
    assert main(["batch", "eval", str(src), "-o", str(tmp_path / "o"), "--scheduler", "bogus"]) == 2
    assert main(["batch", "eval", str(tmp_path / "nothing*.png"), "-o", str(tmp_path / "o"),
                 "--scheduler", "none"]) == 2
    assert main(["batch", "eval", str(src), "-o", str(tmp_path / "o"), "--scheduler", "none", "--schemes", "sq3"]) == 2
    assert main(["batch", "omm", str(src), "-o", str(tmp_path / "o"), "--level", "3", "--dynamic", "2"]) == 2
    err = capsys.readouterr().err
    assert "power of two from 1 to 128, got 3" in err and "--level, --dynamic and --budget exclude" in err
    assert "--csv is not available" in err and "--scheduler must be" in err and "no file matches" in err
    assert not (tmp_path / "o").exists()
    from omaps.cli.trace import bind_camera_value  # omaps batch trace binds --camera as omaps trace does

    assert bind_camera_value(["batch", "trace", "s.glb", "--camera", "-7,1,2:0,0,0:60"])[-1] == "--camera=-7,1,2:0,0,0:60"


@needs_scenes
@pytest.mark.long
def test_omm_serial_identical_to_single_runs(tmp_path):
    """The shared palm and smallpine scenes: one folder per scene, file by file equal to omaps omm."""
    out = tmp_path / "out"
    scenes = [str(SCENES / "palm.glb"), str(SCENES / "smallpine" / "scene.gltf")]
    assert main(["batch", "omm", *scenes, "-o", str(out), "--scheduler", "none", "--quiet"]) == 0
    for scene, name in zip(scenes, ("palm", "smallpine")):  # a scene.gltf: named by its folder
        single = tmp_path / f"single_{name}"
        assert main(["omm", scene, "-o", str(single), "--quiet"]) == 0
        files = sorted(os.listdir(single))
        assert sorted(os.listdir(out / name)) == files and "omm.json" in files
        for f in files:
            assert (out / name / f).read_bytes() == (single / f).read_bytes(), f"{name}/{f} differs"
    # --glb: the scene with EXT_mesh_opacity_micromap, as omaps omm SCENE -o NAME.glb writes it
    assert main(["batch", "omm", scenes[0], "-o", str(out / "glb"), "--glb", "--scheduler", "none", "--quiet"]) == 0
    assert main(["omm", scenes[0], "-o", str(tmp_path / "single.glb"), "--quiet"]) == 0
    assert (out / "glb" / "palm.glb").read_bytes() == (tmp_path / "single.glb").read_bytes()
    s, _ = _summary(out / "glb")
    assert s["inputs"][0]["figures"]["triangles"] == 3840 and s["inputs"][0]["output"] == "palm.glb"


@needs_scenes
def test_trace_serial_matches_single_run(tmp_path):
    out = tmp_path / "out"
    opts = ["--schemes", "none,sq16", "--size", "48", "--jobs", "1", "--quiet"]
    assert main(["batch", "trace", str(SCENES / "palm.glb"), "-o", str(out), "--scheduler", "none", *opts]) == 0
    assert main(["trace", str(SCENES / "palm.glb"), "--json", str(tmp_path / "single.json"), *opts]) == 0
    a, b = json.loads((out / "palm.json").read_text()), json.loads((tmp_path / "single.json").read_text())
    def untimed(d):  # every figure but the timings (seconds, rays per second)
        if isinstance(d, dict):
            return {k: untimed(v) for k, v in d.items() if k not in ("timings", "timing") and "per_second" not in k}
        return d

    assert untimed(a) == untimed(b) and a["passed"]
    s, _ = _summary(out)
    assert s["inputs"][0]["figures"]["alpha_tests_per_primary_ray"]["sq16"] == \
        a["schemes"]["sq16"]["alpha_tests_per_primary_ray"]


@needs_shared
@pytest.mark.long
def test_local_cluster_eval_equals_single_eval_on_the_folder(tmp_path):
    """The one LocalCluster of the tests (subprocess: the CLI as a user runs it)."""
    out = tmp_path / "out"
    folder = tmp_path / "textures"  # every fourth real texture (links): the cluster's work, not the corpus, is tested
    folder.mkdir()
    for p in sorted(TEXTURES.iterdir())[::4]:
        (folder / p.name).symlink_to(p)
    r = subprocess.run([sys.executable, "-m", "omaps", "batch", "eval", str(folder), "-o", str(out),
                        "--scheduler", "local", "--schemes", "sq16,tri3", "--min-size", "64", "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode in (0, 1), r.stderr
    assert main(["eval", str(folder), "--schemes", "sq16,tri3", "--min-size", "64", "--quiet",
                 "--json", str(tmp_path / "all.json")]) in (0, 1)
    whole = {t["name"]: t["schemes"] for t in json.loads((tmp_path / "all.json").read_text())["textures"]}
    s, _ = _summary(out)
    ok = [x for x in s["inputs"] if x["status"] == "ok"]
    assert len(ok) == len(whole) >= 10
    for x in ok:
        name = json.loads((out / x["output"]).read_text())["textures"][0]["name"]
        assert x["figures"]["savings"] == {k: v["savings"] for k, v in whole[name].items()}
    assert all(x["status"] in ("ok", "skipped") for x in s["inputs"]) or s["totals"]["error"] > 0
    assert s["totals"]["skipped"] == len(s["inputs"]) - len(ok) - s["totals"]["error"]


WORKER_ENVIRONMENT = """
import json, sys

def environment():
    import os
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "NUMBA_NUM_THREADS", "OMP_NUM_THREADS")}

if __name__ == "__main__":
    if sys.argv[1] == "omaps":  # omaps's local cluster
        from omaps.batch.engine import dask_client
        cluster = dask_client("local")
    else:  # Dask's own, with whatever configuration Dask reads
        import contextlib
        from distributed import Client, LocalCluster

        @contextlib.contextmanager
        def plain():
            with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0") as c:
                with Client(c) as client:
                    yield client
        cluster = plain()
    with cluster as client:
        print(json.dumps(list(client.run(environment).values())))
"""


def _worker_environments(tmp_path, which, **env):
    """Each worker's MALLOC_TRIM_THRESHOLD_, NUMBA_NUM_THREADS and OMP_NUM_THREADS, on omaps's
    local cluster (``which`` "omaps") or on a plain Dask LocalCluster of one worker ("dask")."""
    probe = tmp_path / "probe.py"
    probe.write_text(WORKER_ENVIRONMENT)
    env = {k: v for k, v in dict(os.environ, **env).items() if k != "MALLOC_TRIM_THRESHOLD_"}
    r = subprocess.run([sys.executable, str(probe), which], capture_output=True, text=True, timeout=120, env=env,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.long
def test_local_workers_compute_on_one_core_with_the_default_allocator(tmp_path):
    """Each local worker runs numba and OpenMP on one thread, and glibc's allocator keeps its
    defaults: Dask's default worker environment sets MALLOC_TRIM_THRESHOLD_, which turns off
    the adaptive mmap threshold, so every large array would be mapped and faulted in afresh."""
    envs = _worker_environments(tmp_path, "omaps")
    assert len(envs) == os.cpu_count()
    for env in envs:
        assert env == {"MALLOC_TRIM_THRESHOLD_": None, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


@pytest.mark.long
def test_the_guides_worker_configuration_keeps_the_default_allocator(tmp_path):
    """The batch guide's Dask configuration file for other clusters' workers, as written, unsets
    MALLOC_TRIM_THRESHOLD_ in a plain Dask worker (Dask's own cluster, not omaps's settings)."""
    import re
    from pathlib import Path

    guide = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "batch.md").read_text()
    (block,) = re.findall(r"^```yaml\n(.*?)^```", guide, re.M | re.S)
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "omaps.yaml").write_text(block)
    (tmp_path / "empty").mkdir()
    default = _worker_environments(tmp_path, "dask", DASK_CONFIG=str(tmp_path / "empty"))
    guided = _worker_environments(tmp_path, "dask", DASK_CONFIG=str(tmp_path / "config"))
    assert default[0]["MALLOC_TRIM_THRESHOLD_"] is not None  # Dask's default sets it (else this checks nothing)
    assert guided[0]["MALLOC_TRIM_THRESHOLD_"] is None


def test_batch_eval_skips_images_without_alpha_found_in_a_folder(tmp_path, capsys):
    """As ``omaps eval`` on a folder: an image found there without an alpha channel (a
    screenshot) is recorded as skipped, with why, not run into an error; named alone, it is an
    error; with --channel it is read."""
    src = tmp_path / "src"
    _textures(src, n=2)
    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(tmp_path / "src" / "shot.png")
    out = tmp_path / "out"
    assert main(["batch", "eval", str(src), "-o", str(out), "--scheduler", "none", "--schemes", "sq4"]) == 0
    said = capsys.readouterr()
    assert "1 skipped (images without an alpha channel" in said.out + said.err
    recs = {os.path.basename(r["input"]): r for r in _summary(out)[0]["inputs"]}
    assert recs["shot.png"]["status"] == "skipped" and "no alpha channel, mode RGB" in recs["shot.png"]["reason"]
    assert sum(r["status"] == "ok" for r in recs.values()) == 2
    assert main(["batch", "eval", str(src / "shot.png"), "-o", str(tmp_path / "one"), "--scheduler", "none",
                 "--schemes", "sq4"]) == 1
    assert main(["batch", "eval", str(src), "-o", str(tmp_path / "all"), "--scheduler", "none", "--schemes", "sq4",
                 "--channel", "R"]) == 0
    assert {r["status"] for r in _summary(tmp_path / "all")[0]["inputs"]} == {"ok"}
