"""Faults a library-sized batch meets on a real cluster, injected when the test decides (never by
timing): a worker killed mid-job, the scheduler killed mid-job, an input that kills every worker
it runs on, the output disk full mid-job. Each on a real loopback cluster (``dask scheduler`` and
``dask worker`` processes, ``tests/cluster.py``) and, where it applies, on the local cluster;
each checks what a fault must never do: lose an input, run one twice to a different result, leave
a partial file, or hang. The moments are events: the batch's test-only gate
(``omaps.batch.task.TEST_GATE``) holds each input at its start, says which process holds it, and
kills the process that runs an input the test names."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time

import pytest

from cluster import LoopbackCluster, kill_pid
from interrupts import gate_env, held, release, wait_for
from omaps.cli.main import main
from test_batch import _summary, _textures

SCHEMES = "sq16,tri2"
LIMIT = 300  # seconds: a hang guard only (a batch that never ends fails instead of hanging)
UNTIMED = ("seconds", "inputs_per_second", "retried")  # the totals that differ from run to run


def _library(tmp_path, n=6):
    src = tmp_path / "tex"
    _textures(src, n=n, seed=11)
    return src


def _serial(src, tmp_path):
    """The reference: the same batch serially, in this process."""
    ref = tmp_path / "ref"
    assert main(["batch", "eval", str(src), "-o", str(ref), "--scheduler", "none", "--schemes", SCHEMES,
                 "--quiet"]) == 0
    return ref


def _outputs(out):
    """Every output file of a batch (its markers and summary aside), name -> bytes."""
    return {f: (out / f).read_bytes() for f in sorted(os.listdir(out))
            if f.endswith(".json") and not f.startswith("summary")}


def _untimed(rec):
    return {k: v for k, v in rec.items() if k not in ("seconds", "resumed")}


def _same_summary(out, ref, resumed=0):
    """The summary of ``out`` is the serial run's: each input once, the same statuses and
    figures, the same totals (times aside)."""
    s, rows = _summary(out)
    r, ref_rows = _summary(ref)
    assert [_untimed(x) for x in s["inputs"]] == [_untimed(x) for x in r["inputs"]]
    want = {k: v for k, v in r["totals"].items() if k not in UNTIMED}
    assert {k: v for k, v in s["totals"].items() if k not in UNTIMED} == {**want, "resumed": resumed}
    assert [x["input"] for x in rows] == [x["input"] for x in ref_rows]
    return s


def _batch(src, out, scheduler, env=None, *more):
    """``omaps batch eval`` as a user runs it, in a process of its own; its stderr in a file
    (beside the inputs: OUTDIR's disk may be full)."""
    err = open(src.parent / f"{out.name}.stderr", "w+")
    cmd = [sys.executable, "-m", "omaps", "batch", "eval", str(src), "-o", str(out), "--scheduler", scheduler,
           "--schemes", SCHEMES, *more]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=env or os.environ,
                         start_new_session=True)
    p.err = err
    return p


def _finish(p, limit=LIMIT):
    """Wait for the batch (hang guard ``limit``): its exit code and stderr."""
    try:
        p.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()
        raise AssertionError(f"the batch did not end in {limit} s (hang guard)") from None
    p.err.seek(0)
    text = p.err.read()
    p.err.close()
    return p.returncode, text


def _markers(out):
    m = out / ".batch"
    return sorted(f[:-5] for f in os.listdir(m) if f.endswith(".json") and not f.startswith(".")) if m.is_dir() \
        else []


def _holder(gate, what):
    """The id of the process the gate holds ``what`` in."""
    return int((gate / f"held-{what}").read_text())


@pytest.mark.parametrize("where", ["loopback", "loopback-nanny", "local"])
def test_a_worker_killed_mid_job_loses_no_input(tmp_path, where):
    """One of two workers SIGKILLed while it runs an input, another input finished: the batch
    completes, every output byte-identical to a serial run, each input once in an exact summary,
    the lost worker reported in one line (no traceback) and its input counted as run again.
    Without a nanny the worker stays dead (a pre-empted node); with one (and on the local
    cluster), Dask starts it again (a worker killed by the kernel's OOM killer)."""
    src = _library(tmp_path)
    ref = _serial(src, tmp_path)
    gate, out = tmp_path / "gate", tmp_path / "out"
    with contextlib.ExitStack() as stack:
        if where == "local":
            p = _batch(src, out, "local", gate_env(os.environ, gate))
        else:
            cluster = stack.enter_context(LoopbackCluster(tmp_path / "cluster", nanny=where.endswith("nanny"),
                                                          env=gate_env({}, gate)))
            p = _batch(src, out, cluster.address)
        try:
            wait_for(lambda: len(held(gate, "input-")) == 2, "two inputs held", p)
            first, second = held(gate, "input-")
            release(gate, first)
            wait_for(lambda: first[len("input-"):] in _markers(out), f"{first} finished", p)
            kill_pid(_holder(gate, second))  # the worker running the second input
            release(gate)
            rc, err = _finish(p)
        finally:
            if p.poll() is None:
                p.kill()
    assert rc == 0, err
    assert _outputs(out) == _outputs(ref)
    s = _same_summary(out, ref)
    assert s["totals"]["retried"] >= 1
    lost = [line for line in err.splitlines() if "left the cluster" in line]
    assert len(lost) == 1 and "in flight to run again" in lost[0], err
    assert "Traceback" not in err, err
    assert not [f for f in os.listdir(out) if f.startswith(".omaps-")]


def test_the_scheduler_killed_mid_job_stops_the_batch_and_a_rerun_finishes_it(tmp_path):
    """The scheduler SIGKILLed while an input runs, another finished: omaps ends (no hang) with
    exit 3 and one error line naming the scheduler, the finished input keeps its marker and
    output, the others none; the same command on a fresh cluster then completes with outputs
    identical to a serial run and runs only the unfinished inputs again."""
    src = _library(tmp_path)
    ref = _serial(src, tmp_path)
    gate, out = tmp_path / "gate", tmp_path / "out"
    with LoopbackCluster(tmp_path / "cluster", env=gate_env({}, gate)) as cluster:
        p = _batch(src, out, cluster.address)
        try:
            wait_for(lambda: len(held(gate, "input-")) == 2, "two inputs held", p)
            first = held(gate, "input-")[0]
            release(gate, first)
            wait_for(lambda: first[len("input-"):] in _markers(out), f"{first} finished", p)
            cluster.kill("scheduler")
            rc, err = _finish(p)
        finally:
            if p.poll() is None:
                p.kill()
        done = _markers(out)  # (before the workers go: a held input is never let go)
    assert rc == 3, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("omaps: error: the batch stopped: lost the Dask scheduler "
                                                   + cluster.address), err
    assert done == [first[len("input-"):]], done
    assert sorted(f[:-5] for f in _outputs(out)) == done  # an output for each marker, none other
    s, _ = _summary(out)
    assert s["totals"]["unfinished"] == 6 - len(done) and s["stopped"].startswith("lost the Dask scheduler")
    with LoopbackCluster(tmp_path / "cluster2") as cluster:
        rc, err = _finish(_batch(src, out, cluster.address))
    assert rc == 0, err
    assert _outputs(out) == _outputs(ref)
    _same_summary(out, ref, resumed=len(done))


POISON = "t03"  # the input whose task kills the worker process it runs in (the gate's kill-input-t03)
ALLOWED = 1  # the test scheduler's allowed-failures (Dask's default is 3): fewer restarts to wait for


def _poisoned(gate):
    os.makedirs(gate, exist_ok=True)
    (gate / f"kill-input-{POISON}").write_text("")
    release(gate)  # (no input is held: the other inputs run at once)


@pytest.mark.parametrize("where", ["loopback", "local"])
def test_an_input_that_kills_every_worker_is_one_recorded_error(tmp_path, where):
    """An input whose task kills (SIGKILL) every worker process it runs in, as one that needs more
    memory than a worker has: Dask gives up on it after the scheduler's allowed-failures, omaps
    runs it once more alone (so that no input that only ran beside it is blamed), then records it
    as failed with the reason; every other input completes, identical to a serial run. The
    workers have nannies (Dask starts a killed worker process again)."""
    src = _library(tmp_path)
    ref = _serial(src, tmp_path)
    gate, out = tmp_path / "gate", tmp_path / "out"
    _poisoned(gate)
    allowed = {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(ALLOWED)}
    if where == "local":
        rc, err = _finish(_batch(src, out, "local", gate_env({**os.environ, **allowed}, gate)))
    else:
        with LoopbackCluster(tmp_path / "cluster", nanny=True, env=gate_env({}, gate),
                             scheduler_env=allowed) as cluster:
            rc, err = _finish(_batch(src, out, cluster.address))
    assert rc == 1, err
    s, _ = _summary(out)
    r, _ = _summary(ref)
    poison = [x for x in s["inputs"] if x["input"].endswith(f"{POISON}.png")]
    assert len(poison) == 1 and poison[0]["status"] == "error", s["inputs"]
    why = poison[0]["error"]
    assert "worker died each time it ran it" in why and f"allowed-failures, {ALLOWED}" in why and "alone" in why, why
    others = [_untimed(x) for x in s["inputs"] if x is not poison[0]]
    assert others == [_untimed(x) for x in r["inputs"] if not x["input"].endswith(f"{POISON}.png")]
    assert s["totals"]["ok"] == 5 and s["totals"]["error"] == 1 and s["totals"]["retried"] >= 1
    want = _outputs(ref)
    want.pop(f"{POISON}.json")
    assert _outputs(out) == want
    assert sum(f"omaps: error: {poison[0]['input']}" in line for line in err.splitlines()) == 1, err
    assert "Traceback" not in err, err


# --- a full output disk ------------------------------------------------------------------------

def _mount_small_disk(folder, size):
    """A tmpfs of ``size`` bytes at ``folder``, else skip (mounting needs root)."""
    os.makedirs(folder, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], capture_output=True,
                       text=True)
    if r.returncode != 0:
        pytest.skip(f"a small disk for the test needs mounting a tmpfs, which failed here: {r.stderr.strip()}")


def _unmount(folder):
    subprocess.run(["umount", "-l", str(folder)], capture_output=True)


@pytest.mark.parametrize("where", ["loopback", "local", "none"])
def test_a_full_output_disk_stops_the_batch_and_leaves_no_partial_file(tmp_path, where):
    """OUTDIR on a disk (a tmpfs) that fills up after a few inputs: the input being written is
    recorded as failed with the system's words, no partial or temporary file is left (an output
    is there with its marker or not at all), no new input starts and omaps says why (exit 3);
    after space is freed, the same command completes with outputs identical to a serial run and
    runs only the inputs not finished before."""
    src = _library(tmp_path, n=8)
    ref = _serial(src, tmp_path)
    disk = tmp_path / "disk"
    out = disk / "out"
    _mount_small_disk(disk, 24 * 1024)
    try:
        def run():
            if where != "loopback":
                return _finish(_batch(src, out, where, None, "--window", "2"))
            with LoopbackCluster(tmp_path / "cluster") as cluster:
                return _finish(_batch(src, out, cluster.address))

        rc, err = run()
        assert rc == 3, err
        assert "No space left on device" in err and "the batch stopped: the output disk is full" in err, err
        assert "Traceback" not in err, err
        left = [os.path.join(r, f) for r, ds, fs in os.walk(out) for f in fs + ds if f.startswith(".omaps-")]
        assert not left, left
        done = _markers(out)
        assert 0 < len(done) < 8, done
        outs = _outputs(out)
        assert sorted(f[:-5] for f in outs) == done  # an output with its marker, or neither
        assert outs == {f: b for f, b in _outputs(ref).items() if f in outs}
        if (out / "summary.json").exists():  # (written if the disk had room for it again)
            s, _ = _summary(out)
            assert s["stopped"].startswith("the output disk is full") and s["totals"]["error"] >= 1
        else:
            assert "omaps: error: the summary could not be written: " in err, err
        subprocess.run(["mount", "-o", "remount,size=4m", str(disk)], check=True)
        rc, err = run()
        assert rc == 0, err
        assert _outputs(out) == _outputs(ref)
        _same_summary(out, ref, resumed=len(done))
    finally:
        _unmount(disk)


def test_a_cluster_left_without_workers_stops_the_batch(tmp_path, monkeypatch):
    """Both workers (no nanny) killed by an input that kills every worker it runs on, before
    Dask's allowed-failures (3) gives up on it: the cluster has no worker left, and the batch
    stops after ``NO_WORKERS_SECONDS`` (here 1 s) with the reason and its unfinished inputs
    recorded, instead of waiting for ever (through the library call, as a Python user runs it)."""
    import omaps
    from omaps.batch import engine

    monkeypatch.setattr(engine, "NO_WORKERS_SECONDS", 1)
    src = _library(tmp_path)
    gate = tmp_path / "gate"
    _poisoned(gate)
    with LoopbackCluster(tmp_path / "cluster", env=gate_env({}, gate)) as cluster:
        with pytest.warns(omaps.batch.BatchWarning, match="left the cluster"):
            res = omaps.run_batch("eval", [src], tmp_path / "out", {"schemes": SCHEMES}, scheduler=cluster.address)
        assert cluster.workers() == 0
    assert res.stopped is not None and "has had no workers for 1 s" in res.stopped, res.stopped
    assert not res.complete and not res.ok
    t = res.totals
    poison = [r for r in res.records if r["input"].endswith(f"{POISON}.png")]
    assert poison[0]["status"] == "unfinished" and t["unfinished"] >= 1 and t["ok"] + t["unfinished"] == 6, \
        [(r["input"][-7:], r["status"], r.get("error")) for r in res.records]
    assert [r["status"] for r in res.records if r["status"] == "ok"] == ["ok"] * len(_markers(tmp_path / "out"))


def test_the_progress_bar_counts_failed_and_retried_inputs():
    from omaps.batch.engine import Progress

    bar = Progress("eval", 4, show=True)
    bar.done({"status": "ok"})
    bar.done({"status": "error"})
    bar.again(2)
    bar.done({"status": "skipped"})
    assert (bar.bar.n, bar.failed, bar.retried) == (3, 1, 2)
    assert bar.bar.postfix == "1 failed, 2 retried"
    bar.close()


def test_the_scheduler_killed_while_a_split_scene_bakes_stops_the_batch(tmp_path):
    """``omaps batch omm --split``: the scheduler SIGKILLed while a piece of the first of two
    scenes runs: omaps ends with exit 3 and one line (the lost pieces stop the batch, not the
    scene as an error), no output and no marker; a rerun on a fresh cluster writes the serial
    bake's files byte for byte."""
    from test_batch_split import _files, _grid_scene

    scenes = [_grid_scene(tmp_path / "a.gltf"), _grid_scene(tmp_path / "b.gltf", k=12, seed=4)]
    opts = ["--quiet", "--level", "5"]
    assert main(["batch", "omm", *scenes, "-o", str(tmp_path / "whole"), "--scheduler", "none", *opts]) == 0
    gate, out = tmp_path / "gate", tmp_path / "out"
    err = open(tmp_path / "split.stderr", "w+")
    cmd = [sys.executable, "-m", "omaps", "batch", "omm", *scenes, "-o", str(out), "--split", *opts]
    with LoopbackCluster(tmp_path / "cluster", env=gate_env({}, gate)) as cluster:
        p = subprocess.Popen([*cmd, "--scheduler", cluster.address], stdout=subprocess.DEVNULL, stderr=err,
                             start_new_session=True)
        p.err = err
        try:
            wait_for(lambda: held(gate, "piece-"), "a piece held", p)
            cluster.kill("scheduler")
            rc, text = _finish(p)
        finally:
            if p.poll() is None:
                p.kill()
    assert rc == 3, text
    lines = text.strip().splitlines()
    assert len(lines) == 1 and "the batch stopped: lost the Dask scheduler" in lines[0], text
    assert _markers(out) == [] and not (out / "a").exists()
    with LoopbackCluster(tmp_path / "cluster2") as cluster:
        r = subprocess.run([*cmd, "--scheduler", cluster.address], capture_output=True, text=True, timeout=LIMIT)
    assert r.returncode == 0, r.stderr
    for name in ("a", "b"):
        assert _files(out / name) == _files(tmp_path / "whole" / name)
