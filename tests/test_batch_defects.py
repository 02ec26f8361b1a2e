"""``omaps batch``: output names (a glTF called scene.gltf is named by its folder; two inputs
sharing a name are an error naming both), the help (only what batch accepts), an unreachable
scheduler (a quick exit 2), Ctrl-C during the Dask start-up (one line, exit 130) and the counts
in its messages (singular and plural)."""

from __future__ import annotations

import os
import re
import select
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from gltf_files import write_quad_gltf
from interrupts import LIMIT, check_interrupted, children, gate_env, wait_for
from omaps import batch as engine
from omaps.batch import engine as batch_engine
from omaps.batch.engine import CONNECT_SECONDS, check_scheduler
from omaps.text import plural as count
from omaps.cli.main import main
from omaps.errors import InputError
from test_batch import _summary, _textures


def _alpha(seed=0):
    a = (np.random.default_rng(seed).random((4, 4)) > 0.5).astype(np.uint8) * 255
    return np.kron(a, np.ones((8, 8), np.uint8))


def _scene(folder, name="scene.gltf", seed=0):
    os.makedirs(folder, exist_ok=True)
    write_quad_gltf(os.path.join(folder, name), _alpha(seed))
    return os.path.join(folder, name)


# --- output names ------------------------------------------------------------------------------

def _names(command, given, outdir="/nonexistent-out"):
    return engine.output_names(command, engine.find_inputs(command, given, outdir))


def test_scene_gltf_is_named_by_its_folder(tmp_path):
    pine = _scene(tmp_path / "pine")
    oak = _scene(tmp_path / "oak", "scene.glb")  # (not a valid .glb: only names are made here)
    assert _names("omm", [pine]) == ["pine"]
    assert _names("omm", [pine, oak]) == ["pine", "oak"]
    assert _names("omm", [str(tmp_path / "*" / "scene.gl*")]) == ["oak", "pine"]
    # found in a folder given: the path relative to it (which names the scene's folder)
    assert _names("omm", [str(tmp_path)]) == ["oak/scene", "pine/scene"]
    assert _names("omm", [str(tmp_path / "pine")]) == ["pine"]
    other = _scene(tmp_path / "pine", "bark.gltf")
    assert _names("omm", [str(tmp_path)]) == ["oak/scene", "pine/bark", "pine/scene"]
    assert _names("trace", [other, pine]) == ["bark", "pine"]


def test_two_inputs_with_one_name_are_an_error_naming_both(tmp_path, capsys):
    a = _scene(tmp_path / "a" / "pine")
    b = _scene(tmp_path / "b" / "pine")
    with pytest.raises(InputError) as e:
        _names("omm", [a, b])
    assert a in str(e.value) and b in str(e.value)
    out = tmp_path / "out"
    assert main(["batch", "omm", a, b, "-o", str(out), "--scheduler", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert a in err and b in err and "pine" in err
    assert not out.exists()
    # an omm folder inside another input's omm folder: also one output in the other's way
    c = _scene(tmp_path / "c" / "pine" / "cone")
    for given in ([a, str(tmp_path / "c")], [str(tmp_path / "c"), a]):
        with pytest.raises(InputError) as e:
            _names("omm", given)
        assert a in str(e.value) and c in str(e.value)
    assert _names("trace", [a, str(tmp_path / "c")]) == ["pine", "pine/cone/scene"]
    assert _names("omm", [str(tmp_path / "c")]) == ["pine/cone/scene"]
    assert _names("omm", [c]) == ["cone"]


def test_two_scene_gltf_run_side_by_side(tmp_path, capsys):
    pine, oak = _scene(tmp_path / "pine", seed=1), _scene(tmp_path / "oak", seed=2)
    out = tmp_path / "out"
    assert main(["batch", "omm", pine, oak, "-o", str(out), "--scheduler", "none", "--quiet", "--level", "2"]) == 0
    assert (out / "pine" / "omm.json").is_file() and (out / "oak" / "omm.json").is_file()
    s, _ = _summary(out)
    assert [r["output"] for r in s["inputs"]] == ["pine", "oak"]


def test_help_states_the_naming():
    r = subprocess.run([sys.executable, "-m", "omaps", "batch", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "scene.gltf" in r.stdout and "same output name" in " ".join(r.stdout.split())


# --- help ---------------------------------------------------------------------------------------

def _help(*argv):
    r = subprocess.run([sys.executable, "-m", "omaps", *argv, "--help"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout


def _options(text):
    return set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", text))


@pytest.mark.parametrize("command, single", [("eval", "eval"), ("omm", "omm"), ("trace", "trace")])
def test_batch_help_lists_only_what_batch_accepts(command, single):
    batch, alone = _help("batch", command), _help(single)
    refused = {"eval": {"--json", "--csv", "--plot", "--show", "--per-texture"},
               "omm": {"--verify", "--expand"},
               "trace": {"--json", "--heatmap", "--render", "--plot-budget", "--plot-frontier"}}[command]
    assert not _options(batch) & refused, _options(batch) & refused
    # every other option of the single command is there, with the same help (one definition)
    shared = _options(alone) - refused - {"--help", "--output", "--quiet"}
    assert shared <= _options(batch), shared - _options(batch)
    assert {"--scheduler", "--window", "--output"} <= _options(batch)
    assert "With no PATH" not in batch and "embedded" not in batch
    # the same definitions: each shared option has the single command's help, word for word
    from omaps.cli.main import parser

    sub = next(a for a in parser()._actions if a.dest == "command").choices
    batch_sub = next(a for a in sub["batch"]._actions if a.dest == "batch_command").choices[command]
    by_option = {o: a for a in batch_sub._actions for o in a.option_strings}
    for a in sub[single]._actions:
        opts = set(a.option_strings)
        if opts & (shared | {"--quiet"}):
            b = by_option[a.option_strings[-1]]
            assert b.help == a.help or a.dest == "quiet", a.option_strings
            assert (b.default, b.choices, b.type) == (a.default, a.choices, a.type), a.option_strings
    # the refused options are still refused with a clear message, not as unknown words
    for opt in sorted(refused):
        value = [] if opt in ("--per-texture", "--expand") else ["x.png" if opt != "--verify" else "d"]
        r = subprocess.run([sys.executable, "-m", "omaps", "batch", command, "in.png", "-o", "/tmp/never-made",
                            opt, *value], capture_output=True, text=True)
        assert r.returncode == 2 and opt in r.stderr and ("not available" in r.stderr or "drop" in r.stderr), \
            r.stderr


# --- an unreachable scheduler ------------------------------------------------------------------

# How the address check failed shows in its message (a refused connection, or the check's own
# CONNECT_SECONDS deadline); the time taken is only bounded against a hang (the kernel's own
# connection attempt gives up after about 2 minutes, a silent server never), never to decide a result
HANG_GUARD = CONNECT_SECONDS + 60


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_fails_quickly_naming_it(tmp_path, capsys):
    src = tmp_path / "tex"
    _textures(src, n=2)
    address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.monotonic()
    rc = main(["batch", "eval", str(src), "-o", str(tmp_path / "out"), "--scheduler", address, "--quiet"])
    dt = time.monotonic() - t0
    assert rc == 2 and dt < HANG_GUARD, dt
    err = capsys.readouterr().err
    assert address in err and "scheduler" in err and len(err.strip().splitlines()) == 1, err
    assert "refused" in err.lower(), err
    assert not (tmp_path / "out").exists()


class _Server:
    """A local TCP server that takes connections and then says nothing (``reply`` None) or
    sends ``reply`` at once: not a Dask scheduler, which speaks first with its handshake."""

    def __init__(self, reply=None):
        import threading

        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.reply, self.conns = reply, []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(c)
            if self.reply:
                c.sendall(self.reply)

    def close(self):
        for c in self.conns:
            c.close()
        self.sock.close()


class _Unanswered:
    """A loopback port whose queue of connections is full (a backlog of 0, taken by one
    connection never accepted): the kernel drops a new connection's first packet, so the connection
    is never answered, as at an address no route leads to, without leaving this machine."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(0)
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.filler = socket.create_connection(self.sock.getsockname(), timeout=LIMIT)
        assert select.select([self.sock], [], [], LIMIT)[0], "the filler connection was not queued"

    def close(self):
        self.filler.close()
        self.sock.close()


def test_a_dask_scheduler_passes_the_check():
    """The check reads a real scheduler's handshake (``dask scheduler``, as on a cluster)."""
    port = _free_port()
    p = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port",
                          str(port), "--dashboard-address", ":0"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert p.poll() is None, "the scheduler did not start"
            time.sleep(0.2)
        check_scheduler(f"tcp://127.0.0.1:{port}")  # no error
    finally:
        p.terminate()
        p.wait(30)


@pytest.mark.parametrize("kind", ["silent", "http", "unanswered"])
def test_a_scheduler_address_that_is_not_a_dask_scheduler_fails_quickly_naming_it(tmp_path, capsys, monkeypatch,
                                                                                    kind):
    """A server that takes the connection but is silent or speaks another protocol (Dask's own
    client failed there with a traceback, or waited its whole timeout), and an address whose
    connection is never answered (``_Unanswered``, on loopback): exit 2 after the connection
    check's own deadline (``CONNECT_SECONDS``, which its message names) at most, one line naming
    the address and what happened, nothing written."""
    src = tmp_path / "tex"
    _textures(src, n=1)
    if kind == "unanswered":
        server = _Unanswered()
    else:
        server = _Server(b"HTTP/1.1 400 Bad Request\r\n\r\n" if kind == "http" else None)
    if kind == "http":  # its reply is read whenever the server's thread sends it (never a race with the deadline)
        monkeypatch.setattr(batch_engine, "CONNECT_SECONDS", HANG_GUARD)
    address = server.address
    try:
        t0 = time.monotonic()
        rc = main(["batch", "eval", str(src), "-o", str(tmp_path / "out"), "--scheduler", address, "--quiet"])
        dt = time.monotonic() - t0
    finally:
        server.close()
    err = capsys.readouterr().err
    assert rc == 2, err
    assert address in err and "scheduler" in err and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    said = {"silent": f"sent no Dask handshake in {CONNECT_SECONDS} s", "http": "not a Dask scheduler",
            "unanswered": f"no answer in {CONNECT_SECONDS} s"}[kind]
    assert said in err, err
    assert dt < HANG_GUARD, dt
    assert not (tmp_path / "out").exists()


# --- Ctrl-C during the Dask start-up -----------------------------------------------------------

@pytest.mark.parametrize("group, kids", [(True, 1), (True, 2), (False, 2)])
def test_ctrl_c_during_cluster_start_up(tmp_path, group, kids):
    """SIGINT once the batch has ``kids`` child processes (its resource tracker first, then the
    LocalCluster's first worker or a compile started before it): to the whole process group as a
    terminal's Ctrl-C, or to omaps alone. One line, exit 130, no output. The batch's inputs are
    held at the test-only gate (``omaps.batch.task.TEST_GATE``): however fast the machine, the batch
    cannot finish before the signal."""
    src = tmp_path / "tex"
    _textures(src, n=4)
    out, gate = tmp_path / "out", tmp_path / "gate"
    env = gate_env(dict(os.environ, PYTHONUNBUFFERED="1", OMAPS_PROGRESS="0"), gate)
    p = subprocess.Popen([sys.executable, "-m", "omaps", "batch", "eval", str(src), "-o", str(out),
                          "--scheduler", "local", "--schemes", "sq16"], env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, start_new_session=group)

    def moment():
        wait_for(lambda: len(children(p.pid)) >= kids, f"{kids} child processes", p)

    check_interrupted(p, out, moment, group=group, gate=gate)


def test_a_busy_dashboard_port_is_not_a_warning(tmp_path):
    """Two local clusters at once (two batches, or two test workers) must not print Dask's "Port
    8787 is already in use" warning: the cluster's HTTP server takes a free port."""
    src = tmp_path / "tex"
    _textures(src, n=1)
    held = socket.socket()
    try:
        held.bind(("127.0.0.1", 8787))  # (if the port is busy already, the case is there anyway)
        held.listen(1)
    except OSError:
        pass
    try:
        r = subprocess.run([sys.executable, "-m", "omaps", "batch", "eval", str(src), "-o", str(tmp_path / "out"),
                            "--scheduler", "local", "--schemes", "sq16", "--quiet"], capture_output=True, text=True,
                           timeout=300)
    finally:
        held.close()
    assert r.returncode == 0, r.stderr
    assert "8787" not in r.stderr and "already in use" not in r.stderr, r.stderr


# --- counts in messages -------------------------------------------------------------------------

def test_counts_are_singular_for_one(tmp_path, capsys):
    src = tmp_path / "tex"
    _textures(src, n=1)
    (src / "broken.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    assert main(["batch", "eval", str(src / "t00.png"), "-o", str(out), "--scheduler", "none", "--quiet",
                 "--schemes", "sq16"]) == 0
    text = capsys.readouterr()
    text = text.out + text.err
    assert "1 input," in text and "1 inputs" not in text, text
    assert main(["batch", "eval", str(src), "-o", str(out), "--scheduler", "none", "--quiet",
                 "--schemes", "sq16"]) == 1
    text = capsys.readouterr()
    text = text.out + text.err
    assert "2 inputs" in text and "1 error" in text and "1 errors" not in text, text
    assert "1 done before" in text
    _, rows = _summary(out)
    assert "1 error" in rows[-1]["status"] and "1 errors" not in rows[-1]["status"]
    assert "0 problems" in rows[-1]["status"] or "problem" not in rows[-1]["status"]
    assert count(1, "error") == "1 error" and count(2, "error") == "2 errors"
    assert count(0, "input") == "0 inputs"


# --- what the first line counts, and warnings on the terminal -------------------------------------

def test_the_plan_line_tells_done_from_refused(tmp_path):
    done, refused, todo = (_scene(tmp_path / n, seed=k) for k, n in enumerate(("done", "refused", "todo")))
    out = tmp_path / "out"
    options = {"level": 2, "jobs": 1}
    engine.run_batch("omm", [done], out, options, scheduler="none")
    (out / "refused").mkdir()
    (out / "refused" / "notes.txt").write_text("someone else's file")
    line = engine.plan_batch("omm", [done, refused, todo], out, options, scheduler="none").line()
    assert "3 inputs, 1 already done with these options" in line, line
    assert "1 refused (its output folder holds files omaps did not write" in line, line
    assert "1 to run" in line and "or refused" not in line, line


def test_an_inputs_warnings_reach_the_terminal_once(tmp_path, capsys):
    warned = tmp_path / "warned" / "scene.gltf"
    warned.parent.mkdir()
    write_quad_gltf(str(warned), _alpha(), extra_images=["nothere.png", "gone.png"])  # two missing, unused
    quiet = _scene(tmp_path / "quiet", seed=1)
    out = tmp_path / "out"
    assert main(["batch", "omm", str(warned), quiet, "-o", str(out), "--scheduler", "none", "--level", "2",
                 "--quiet"]) == 0
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if "warning" in x]
    assert len(lines) == 1, err  # one line for the input, however many warnings it had
    assert str(warned) in lines[0] and "nothere.png" in lines[0] and "1 more warning" in lines[0], lines
    assert lines[0].count(str(warned)) == 1, lines  # the input named once
    assert "quiet" not in err
    rec = {r["input"]: r for r in _summary(out)[0]["inputs"]}[str(warned)]
    assert len(rec["messages"]) == 2  # every warning in the summary
