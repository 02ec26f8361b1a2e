"""The ``omaps`` program ends without tearing the interpreter down (``omaps.cli.run``): its exit
code is ``main``'s, its output reaches a file or a pipe whole, and exit handlers still run."""

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

ENV = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # buffered streams, as by default
SCRIPT = """
import atexit, sys
atexit.register(lambda: open(sys.argv[1], "w").write("ran"))
from omaps.cli import run
run(sys.argv[2:])
"""


def _leaf(tmp_path):
    img = np.zeros((8, 8, 4), np.uint8)
    img[2:6, 2:6, 3] = 255
    Image.fromarray(img).save(tmp_path / "leaf.png")
    np.save(tmp_path / "uvs.npy", np.array([[[0, 0], [1, 0], [0, 1]]], float))


def test_run_flushes_output_and_runs_exit_handlers(tmp_path):
    _leaf(tmp_path)
    out = tmp_path / "stdout.txt"
    with open(out, "w") as f:  # a file: stdout is block-buffered, so an unflushed line would be lost
        r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "mark"), "omm", str(tmp_path / "leaf.png"),
                            str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "omm"), "--quiet"], stdout=f,
                           stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=ENV)
    assert r.returncode == 0, r.stderr
    assert re.search(r"1 triangles?, 256 micro-triangles", out.read_text())
    assert (tmp_path / "mark").read_text() == "ran"
    assert (tmp_path / "omm" / "omm.json").is_file()


def test_run_keeps_the_exit_code_of_bad_input(tmp_path):
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "mark"), "omm", str(tmp_path / "absent.png"),
                        str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "omm")], capture_output=True, text=True, env=ENV)
    assert r.returncode == 2
    assert "absent.png" in r.stderr
    assert (tmp_path / "mark").read_text() == "ran"
    assert not (tmp_path / "omm").exists()


def test_run_under_a_profiler_exits_as_usual(tmp_path):
    """``python -m cProfile -o FILE -m omaps ...`` writes its profile after the program returns."""
    r = subprocess.run([sys.executable, "-m", "cProfile", "-o", str(tmp_path / "p.prof"), "-m", "omaps", "omm",
                        str(tmp_path / "absent.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "omm")],
                       capture_output=True, text=True, env=ENV)
    assert "absent.png" in r.stderr  # (cProfile itself ends with 0 whatever the program's code)
    assert (tmp_path / "p.prof").stat().st_size > 0


def test_run_waits_for_a_running_thread(tmp_path):
    """A non-daemon thread still running when ``main`` returns (an interrupted worker pool's
    manager, unlinking its semaphores) finishes before the process ends. The thread writes its
    mark only once the interpreter's exit has begun (the main thread is over), so a process that
    ends without waiting for it never writes it, however fast or slow the machine."""
    script = """
import sys, threading, time
import importlib
m = importlib.import_module("omaps.cli.main")
def main(argv):
    def late():
        while threading.main_thread().is_alive():  # until the interpreter's exit has begun
            time.sleep(0.01)
        open(sys.argv[1], "w").write("done")
    threading.Thread(target=late).start()
    return 3
m.main = main
m.run([])
"""
    r = subprocess.run([sys.executable, "-c", script, str(tmp_path / "mark")], capture_output=True, text=True, env=ENV,
                       timeout=300)
    assert r.returncode == 3, r.stderr
    assert (tmp_path / "mark").read_text() == "done"


LEAK = """
import sys
from multiprocessing import resource_tracker
if sys.argv[1] == "omaps":
    from omaps.workers import start_resource_tracker
    start_resource_tracker()
else:
    resource_tracker.ensure_running()
resource_tracker.register("/omaps-test-leak", "semaphore")  # as a worker stopped by Ctrl-C leaves one
print("exit", flush=True)
"""


@pytest.mark.parametrize("start", ["plain", "omaps"])
def test_resource_tracker_notes_stay_off_the_terminal(start):
    """A semaphore left registered by a worker that Ctrl-C stopped makes multiprocessing's
    resource tracker print 'leaked semaphore objects' after ``omaps: interrupted`` (seen about
    one Ctrl-C during a Dask start-up in 30). The tracker omaps starts cleans up without a word;
    the plain one shows what the test would catch."""
    r = subprocess.run([sys.executable, "-c", LEAK, start], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout == "exit\n", r.stderr
    if start == "plain":
        assert "leaked semaphore" in r.stderr, r.stderr
    else:
        assert r.stderr == "", r.stderr


def test_a_command_starts_the_quiet_tracker_first(tmp_path):
    """A command starts the quiet tracker before anything else can start a loud one (a progress
    bar's multiprocessing lock did, before the worker pool: an interrupted ``omaps eval`` then
    printed 'leaked semaphore objects' after ``omaps: interrupted``)."""
    Image.fromarray(np.full((8, 8), 255, np.uint8)).save(tmp_path / "t.png")
    code = f"""
from omaps.cli.main import main
from multiprocessing import resource_tracker
assert main(["eval", {str(tmp_path / "t.png")!r}, "--schemes", "sq4", "--jobs", "1"]) == 0
resource_tracker.register("/omaps-test-leak", "semaphore")  # as a worker stopped by Ctrl-C leaves one
"""
    env = dict(os.environ, OMAPS_PROGRESS="1", OMAPS_PRECOMPILE="0")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert "leaked semaphore" not in r.stderr and "resource_tracker" not in r.stderr, r.stderr


def test_a_cluster_interrupted_in_its_constructor_is_dropped_quietly():
    """Ctrl-C inside ``LocalCluster.__init__`` leaves a registered cluster without its name
    (``_cluster_info``), which Dask's equality reads: the batch's quiet stop must still drop it
    (it once raised AttributeError, and the batch exited 1 instead of 130)."""
    import contextlib

    from distributed import LocalCluster
    from distributed.deploy.spec import SpecCluster

    from omaps.batch.engine import _children, _stop_quietly

    c = object.__new__(LocalCluster)  # as the interrupt leaves it: registered, never named
    SpecCluster._instances.add(c)
    try:
        _stop_quietly(contextlib.ExitStack(), _children(), {c})
        assert all(r() is not c for r in list(SpecCluster._instances.data))
    finally:
        for r in list(SpecCluster._instances.data):
            if r() is c:
                SpecCluster._instances.data.discard(r)


# --- Ctrl-C while a local-cluster batch runs ---------------------------------------------------

def _grid_scene(path, k=24):
    from gltf_files import grid_scene

    rng = np.random.default_rng(0)
    return grid_scene(path, np.kron((rng.random((16, 16)) > 0.5).astype(np.uint8) * 255, np.ones((4, 4), np.uint8)),
                      k, seed=1)


class _Dropping:
    """An object whose finaliser raises ``exc``: Python drops it (``sys.unraisablehook``)."""

    def __init__(self, exc):
        self.exc = exc

    def __del__(self):
        raise self.exc


def _ctrl_c():
    """SIGINT to this process, handled (as a terminal's Ctrl-C) before this returns."""
    with pytest.raises(KeyboardInterrupt):
        signal.raise_signal(signal.SIGINT)
        _until(lambda: False)


def _until(done, limit=60.0):
    """Run Python code (where the main thread handles signals) until ``done()``; an interrupt
    that should come and never does fails the test after ``limit`` seconds instead of hanging."""
    end = time.monotonic() + limit
    while not done():
        assert time.monotonic() < end, "no KeyboardInterrupt came"
        time.sleep(0.001)


def test_a_ctrl_c_dropped_in_a_finaliser_is_raised_again_and_not_printed(monkeypatch):
    """A KeyboardInterrupt raised inside a finaliser (llvmlite's while numba compiles, a Dask
    future released) is dropped there by Python and handed to ``sys.unraisablehook``, which
    prints "Exception ignored in"; once a Ctrl-C has come (``interrupt.remembered``) the report
    goes nowhere and the interrupt is raised again in the main thread, out of the finaliser. Any
    other dropped exception still reaches the hook that was there, and so does an interrupt that
    came before any Ctrl-C; after the block that hook and the SIGINT handler are back, unless the
    block is a program that ends on the interrupt (``quiet_after``): then nothing is reported."""
    from omaps import interrupt

    reported = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: reported.append(u.exc_type.__name__))
    hook, handler = sys.unraisablehook, signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt), interrupt.remembered():
        _Dropping(KeyboardInterrupt())  # no Ctrl-C has come: reported
        assert reported == ["KeyboardInterrupt"] and not interrupt.requested()
        _ctrl_c()
        assert interrupt.requested()
        _Dropping(ValueError("a real problem"))
        assert reported == ["KeyboardInterrupt", "ValueError"]
        _Dropping(KeyboardInterrupt())  # dropped: not printed, raised again moments later
        assert reported == ["KeyboardInterrupt", "ValueError"]
        _until(lambda: False)
    assert sys.unraisablehook is hook and signal.getsignal(signal.SIGINT) is handler
    assert not interrupt.requested()
    with pytest.raises(KeyboardInterrupt), interrupt.remembered(quiet_after=True):  # a program ending on it
        _ctrl_c()
    _Dropping(AttributeError("a half torn-down object"))  # after the block: not reported
    assert reported == ["KeyboardInterrupt", "ValueError"] and sys.unraisablehook is not hook


def test_a_block_that_went_on_after_a_ctrl_c_ends_interrupted(tmp_path):
    """Whatever swallowed a Ctrl-C, the block ends in KeyboardInterrupt
    and a command's outputs are not renamed into place: nothing is written."""
    from omaps import interrupt
    from omaps.atomic import Outputs, write_text

    out = Outputs()
    out.file(tmp_path / "a.json", "--json")
    with pytest.raises(KeyboardInterrupt), interrupt.remembered():
        _ctrl_c()  # (swallowed: by pytest.raises here)
        with out.writing():
            with open(out.path(tmp_path / "a.json"), "w") as f:
                f.write("{}")
    with pytest.raises(KeyboardInterrupt), interrupt.remembered():
        _ctrl_c()
        write_text(tmp_path / "b.txt", "b")
    with pytest.raises(KeyboardInterrupt), interrupt.remembered():
        _ctrl_c()  # a block that writes nothing ends interrupted too
    assert sorted(os.listdir(tmp_path)) == []
    with interrupt.remembered():  # no Ctrl-C: the block ends as it ends
        write_text(tmp_path / "b.txt", "b")
    assert sorted(os.listdir(tmp_path)) == ["b.txt"]


@pytest.mark.long
@pytest.mark.parametrize("phase", ["inputs", "pieces"])
def test_ctrl_c_while_a_local_cluster_batch_runs(tmp_path, phase):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) once the batch is under way:
    ``inputs``, after one input of many finished on the workers while others run there;
    ``pieces``, while a split scene's pieces run on the workers and this process waits for them
    (``omaps batch omm --split``). One line, exit 130, no summary, no process left.

    The moment is an event, not a time: the batch's test-only gate (``omaps.batch.task.TEST_GATE``)
    holds every task at its start until the test releases it, so the batch cannot finish (or
    not yet start its work) before the signal, however fast the machine."""
    from interrupts import check_interrupted, gate_env, held, release, wait_for

    out, gate = tmp_path / "out", tmp_path / "gate"
    if phase == "inputs":
        src = tmp_path / "tex"
        src.mkdir()
        rng = np.random.default_rng(0)
        for i in range(12):  # (the gate, not the work's length, keeps the batch from finishing first)
            a = np.kron((rng.random((32, 32)) > 0.5).astype(np.uint8) * 255, np.ones((8, 8), np.uint8))
            Image.fromarray(a).save(src / f"t{i:02d}.png")
        cmd = ["eval", str(src), "--schemes", "sq16"]
    else:
        cmd = ["omm", _grid_scene(tmp_path / "grid.gltf", k=24), "--level", "6", "--split"]
    env = gate_env(dict(ENV, OMAPS_PROGRESS="0"), gate)
    p = subprocess.Popen([sys.executable, "-m", "omaps", "batch", *cmd, "-o", str(out), "--scheduler", "local"],
                         env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)

    markers = []  # the released input's

    def finished():
        return [f.name for f in (out / ".batch").iterdir() if not f.name.startswith(".")]

    def moment():
        if phase == "inputs":  # one input let through and finished (its marker written); the rest held
            wait_for(lambda: held(gate, "input-"), "an input held on a worker", p)
            first = held(gate, "input-")[0]
            release(gate, first)
            markers.append(first[len("input-"):] + ".json")
            wait_for(lambda: (out / ".batch" / markers[0]).is_file(), f"the marker of {first}", p)
            assert finished() == markers
        else:  # a piece has started on a worker: this process waits for the pieces
            wait_for(lambda: held(gate, "piece-"), "a piece held on a worker", p)

    check_interrupted(p, out, moment, gate=gate)
    if phase == "inputs":  # the released input finished, no other
        assert finished() == markers


GC_SCRIPT = """
import atexit, gc, sys
from omaps.cli import omm, run
seen = []
def command(a):  # the command itself: collection back on, start-up's objects set aside
    seen.append((gc.isenabled(), gc.get_freeze_count() > 0))
    return 0
omm.cmd_omm = command
atexit.register(lambda: print(gc.isenabled(), seen))
run(sys.argv[1:])
"""


def test_run_pauses_garbage_collection_for_start_up_only(tmp_path):
    r = subprocess.run([sys.executable, "-c", GC_SCRIPT, "omm", "leaf.png", "uvs.npy", "-o", "out"],
                       capture_output=True, text=True, cwd=tmp_path, env=dict(ENV, OMAPS_PRECOMPILE="0"))
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[0] == "True [(True, True)]"
