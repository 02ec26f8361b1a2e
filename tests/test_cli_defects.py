"""What a new user runs into on the command line: options that only apply in one texel-state mode,
inputs and outputs of the wrong kind, misspelt options and commands, counts in messages, and the
wait for the kernels a first use compiles."""

import json
import os
import re
import sys
import time as real_time

import numpy as np
import pytest
from PIL import Image

from gltf_files import write_quad_gltf
from omaps.atomic import check_folder
from omaps.cli import main, precompile
from omaps.errors import InputError


def _alpha(n=32):
    yy, xx = np.mgrid[0:n, 0:n]
    a = np.zeros((n, n), np.uint8)
    d2 = (xx - n / 2) ** 2 + (yy - n / 2) ** 2
    a[d2 < (0.4 * n) ** 2] = 60  # alpha 60: O under --cutoff 0.2, T under the default cutoff 0.5
    a[d2 < (0.2 * n) ** 2] = 255
    return a


@pytest.fixture
def leaf(tmp_path):
    p = tmp_path / "leaf.png"
    Image.fromarray(_alpha()).save(p)
    return p


def _listing(folder):
    return sorted(os.listdir(folder))


# ---- --cutoff, --t-max and --o-min belong to one mode each ------------------------------------

def test_cutoff_alone_selects_cutoff_mode(tmp_path, leaf, capsys):
    j = tmp_path / "e.json"
    assert main(["eval", str(leaf), "--quiet", "--jobs", "1", "--schemes", "sq4", "--cutoff", "0.2",
                 "--json", str(j)]) == 0
    settings = json.loads(j.read_text())["settings"]
    assert settings["mode"] == "cutoff" and settings["cutoff"] == 0.2
    assert "mode cutoff" in capsys.readouterr().out
    # bake: the same map as with --mode cutoff spelt out
    implied, spelt = tmp_path / "a.npy", tmp_path / "b.npy"
    assert main(["bake", str(leaf), "--scheme", "sq8", "--cutoff", "0.2", "-o", str(implied)]) == 0
    assert main(["bake", str(leaf), "--scheme", "sq8", "--mode", "cutoff", "--cutoff", "0.2", "-o", str(spelt)]) == 0
    levels = tmp_path / "c.npy"
    assert main(["bake", str(leaf), "--scheme", "sq8", "-o", str(levels)]) == 0
    assert np.array_equal(np.load(implied), np.load(spelt))
    assert not np.array_equal(np.load(implied), np.load(levels))


@pytest.mark.parametrize("extra, named", [
    (["--mode", "levels", "--cutoff", "0.25"], "--cutoff"),
    (["--mode", "cutoff", "--t-max", "10"], "--t-max"),
    (["--mode", "cutoff", "--o-min", "200"], "--o-min"),
    (["--cutoff", "0.25", "--t-max", "10"], "--t-max"),
    (["--cutoff", "0.25", "--o-min", "200"], "--o-min"),
])
def test_option_of_the_other_mode_is_an_error(tmp_path, leaf, capsys, extra, named):
    for argv in (["eval", str(leaf), "--quiet", "--jobs", "1", "--schemes", "sq4", "--json", str(tmp_path / "e.json")],
                 ["bake", str(leaf), "--scheme", "sq8", "-o", str(tmp_path / "b.npy")]):
        assert main(argv + extra) == 2
        err = capsys.readouterr().err
        assert named in err and "mode" in err, err
    assert _listing(tmp_path) == ["leaf.png"]


# ---- a folder where decode reads a block file --------------------------------------------------

def test_decode_a_folder_is_bad_input(tmp_path, capsys):
    folder = tmp_path / "blocks"
    folder.mkdir()
    assert main(["decode", str(folder), "--codec", "vq2"]) == 2
    err = capsys.readouterr().err
    assert str(folder) in err and "folder" in err, err


# ---- outputs with a suffix of another kind ----------------------------------------------------

@pytest.mark.parametrize("make_argv, option, name, allowed", [
    (lambda d, leaf: ["bake", leaf, "--scheme", "sq8", "-o", f"{d}/m.txt"], "-o", "m.txt", ".npy"),
    (lambda d, leaf: ["eval", leaf, "--quiet", "--schemes", "sq4", "--json", f"{d}/e.txt"], "--json", "e.txt", ".json"),
    (lambda d, leaf: ["eval", leaf, "--quiet", "--schemes", "sq4", "--csv", f"{d}/e.json"], "--csv", "e.json", ".csv"),
    (lambda d, leaf: ["eval", leaf, "--quiet", "--schemes", "sq4", "--show", f"{d}/s.png"], "--show", "s.png", None),
    (lambda d, leaf: ["encode", leaf, "--codec", "sq4", "-o", f"{d}/b.png"], "-o", "b.png", None),
    (lambda d, leaf: ["omm", leaf, f"{d}/uvs.npy", "-o", f"{d}/x.txt"], "-o", "x.txt", ".glb"),
    (lambda d, leaf: ["omm", f"{d}/quad.gltf", "-o", f"{d}/x.json"], "-o", "x.json", ".gltf"),
    (lambda d, leaf: ["trace", f"{d}/quad.gltf", "--size", "8", "--json", f"{d}/t.txt"], "--json", "t.txt", ".json"),
])
def test_output_with_a_wrong_suffix_is_refused(tmp_path, leaf, capsys, make_argv, option, name, allowed):
    np.save(tmp_path / "uvs.npy", np.array([[[0, 0], [1, 0], [0, 1]]], float))
    write_quad_gltf(tmp_path / "quad.gltf", _alpha())
    before = _listing(tmp_path)
    assert main(make_argv(str(tmp_path), str(leaf))) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path}/{name}" in err and option in err, err
    if allowed:
        assert allowed in err, err
    assert _listing(tmp_path) == before


def test_folder_names_with_a_file_suffix(tmp_path):
    for name in ("x.txt", "x.PNG", "x.json", "x.npy", "x.csv"):
        with pytest.raises(InputError, match=r"--show"):
            check_folder(tmp_path / name, "show.json", "--show")
    for name in ("out", "out.v2", "run.2024-05"):  # a dot in a folder's name is no file suffix
        check_folder(tmp_path / name, "show.json", "--show")


# ---- misspelt options and commands -------------------------------------------------------------

def test_misspelt_option_suggests_the_command_s_option(capsys):
    for argv in (["eval", "--sheme", "vq2"], ["eval", "--sheme=vq2"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert "usage: omaps eval" in err and "did you mean --schemes?" in err, err
    with pytest.raises(SystemExit) as e:
        main(["batch", "eval", "x.png", "-o", "out", "--jobz", "2"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "usage: omaps batch eval" in err and "did you mean --jobs?" in err, err


def test_misspelt_command_suggests_the_command(capsys):
    with pytest.raises(SystemExit) as e:
        main(["evl"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "did you mean eval?" in err, err
    with pytest.raises(SystemExit) as e:
        main(["eval", "--mode", "cutof"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "usage: omaps eval" in err and "did you mean cutoff?" in err, err


# ---- counts ------------------------------------------------------------------------------------

def test_plural():
    from omaps.cli.common import plural

    assert plural(1, "texture") == "1 texture"
    assert plural(0, "texture") == "0 textures"
    assert plural(3, "file") == "3 files"
    assert plural(2, "family", "families") == "2 families"


def test_eval_counts_read_in_the_singular(tmp_path, leaf, capsys):
    assert main(["eval", str(leaf), "--quiet", "--jobs", "1", "--schemes", "sq4"]) == 0
    assert "1 texture from 1 file," in capsys.readouterr().out
    d = tmp_path / "tex"
    d.mkdir()
    Image.fromarray(_alpha()).save(d / "a.png")
    (d / "broken.png").write_bytes(b"junk")
    (d / "notes.txt").write_text("x")
    assert main(["eval", str(d), "--quiet", "--jobs", "1", "--schemes", "sq4"]) == 1
    err = capsys.readouterr().err
    assert "1 file without an image extension" in err and "1 file could not be read" in err, err


# ---- the wait for the kernels compiled before a command runs ---------------------------------

STUB = """
import os, sys, time
for f in sys.argv[1:]:
    while not os.path.exists(os.path.join({gate!r}, "go-" + f)):  # the test's clock says when
        time.sleep(0.001)
    print(f, flush=True)
"""
HANG_GUARD = 300  # seconds: a stub that never reports fails the test instead of hanging it


class _Clock:
    """The waiting loop's clock, virtual: ``sleep`` advances it by what was asked, ``perf_counter``
    reads it. The compile processes (stubs) are driven by it: once the clock has passed the time a
    family takes (``delays``, one after the other in its process), the stub is told to report it
    (a file ``go-FAMILY`` in ``gate``) and the clock waits until it has (and, for its last family,
    until the process has ended). What the loop sees at each virtual time is then the same on any
    machine, however loaded."""

    def __init__(self, gate, delays):
        self.t = 0.0
        self.gate, self.delays = gate, dict(a.split("=") for a in delays.split(","))
        self.started, self.released = None, set()

    def perf_counter(self):
        return self.t

    def sleep(self, s):
        self.t += max(s, 0.001)  # a real sleep always takes some time
        for g, p, _, _ in self.started.procs if self.started else []:
            at = 0.0
            for i, f in enumerate(g):
                at += float(self.delays[f])
                if at > self.t or f in self.released:
                    continue
                (self.gate / f"go-{f}").touch()
                self.released.add(f)
                deadline = real_time.monotonic() + HANG_GUARD
                while f not in self.started.done():
                    assert real_time.monotonic() < deadline and p.poll() is None, f"the stub never reported {f}"
                    real_time.sleep(0.001)
                if i == len(g) - 1:
                    p.wait(HANG_GUARD)


def _stub(gate, delays):
    return lambda group, evaluation=False: [sys.executable, "-c", STUB.format(gate=str(gate)), *group]


class _Stamped:
    """A stderr that records each line with the virtual clock's time."""

    def __init__(self, clock):
        self.clock = clock
        self.lines = []

    def write(self, s):
        for ln in s.splitlines():
            if ln.strip():
                self.lines.append((self.clock.t, ln))
        return len(s)

    def flush(self):
        pass

    def isatty(self):
        return False


def test_waiting_for_the_compile_shows_progress(monkeypatch, tmp_path):
    """Slow compile processes (stubs that report each family when the virtual clock has passed
    its time): while the command waits for them, a line at least every PROGRESS_EVERY seconds
    says which families are done, which still compile, and the time so far (no timing of this
    machine is asserted)."""
    delays = "vq4=0.3,synth=1.6,wavelet=1.2,trace=0.2,vq2=0.2,omm=0.2,budget=0.2"
    clock = _Clock(tmp_path, delays)
    monkeypatch.setattr(precompile, "time", clock)
    monkeypatch.setattr(precompile, "PROGRESS_EVERY", 0.4)
    monkeypatch.setattr(precompile, "uncached", lambda families: list(families))
    monkeypatch.setattr(precompile, "_command", _stub(tmp_path, delays))
    monkeypatch.delenv("OMAPS_PRECOMPILE", raising=False)
    monkeypatch.setenv("OMAPS_PROGRESS", "1")
    monkeypatch.setattr(precompile, "_cores", lambda: 2)
    monkeypatch.setattr(precompile, "families_for", lambda args: ["vq4", "synth", "wavelet", "trace", "vq2", "omm",
                                                                  "budget"])
    err = _Stamped(clock)
    monkeypatch.setattr(sys, "stderr", err)
    args = type("A", (), {"command": "eval", "schemes": "vq4-synth"})()
    started = precompile.compile_first(args)
    assert started is not None
    clock.started = started
    assert "about" in err.lines[0][1]
    t0 = clock.t
    precompile.finish_ahead(started)
    stamps = [t0] + [t for t, _ in err.lines[1:]]
    gaps = np.diff(stamps)
    assert gaps.max() <= 0.4 + 0.002, (gaps, err.lines)  # PROGRESS_EVERY between lines (+ the clock's step)
    waiting = [ln for _, ln in err.lines[1:-1]]
    assert len(waiting) >= 4, err.lines
    assert len(started.procs) == 2  # one process per core
    assert any("done" in ln and "compiling" in ln for ln in waiting), waiting
    assert all(re.search(r"\d+ s", ln) for ln in waiting), waiting
    assert not any(re.search(r"compiling +\(", ln) for ln in waiting), waiting  # never an empty list
    assert "kernels compiled in" in err.lines[-1][1]


def test_compile_estimate_and_split(monkeypatch):
    """The families are spread over the cores, longest first, so the processes take about as long;
    the estimate is the slowest process's, from the measured factor, and grows with the load of
    other work."""
    monkeypatch.setattr(precompile, "_cores", lambda: 2)
    fam = precompile.FAMILIES
    groups = precompile._groups(["square", "micromap", "trace", "omm"], 2)
    assert sorted(f for g in groups for f in g) == ["micromap", "omm", "square", "trace"] and len(groups) == 2
    per = sorted(sum(fam[f][1] for f in g) for g in groups)
    assert per[1] - per[0] <= max(fam[f][1] for f in ["square", "micromap", "trace", "omm"])
    assert precompile._groups(["square"], 2) == [["square"]]
    low, high = precompile._ahead_seconds([["square"], ["micromap"]])
    assert abs(low - fam["square"][1] * precompile.AHEAD_RANGE[0]) <= 5
    assert abs(high - fam["square"][1] * precompile.AHEAD_RANGE[1]) <= 5
    busy_low, _ = precompile._ahead_seconds([["square"], ["micromap"]], load=7.0)
    assert busy_low >= 4 * low - 10


def test_compile_first_off_or_cached(monkeypatch, capsys):
    """OMAPS_PRECOMPILE=0: nothing starts, one line announces the compile; nothing uncached:
    nothing starts and nothing is said."""
    monkeypatch.setenv("OMAPS_PROGRESS", "1")
    monkeypatch.setattr(precompile, "uncached", lambda families: list(families))
    args = type("A", (), {"command": "eval", "paths": [], "schemes": "sq16,tri3"})()
    monkeypatch.setenv("OMAPS_PRECOMPILE", "0")
    assert precompile.compile_first(args) is None
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "compiling numba kernels for first use: square, micromap" in err[0], err
    monkeypatch.delenv("OMAPS_PRECOMPILE")
    monkeypatch.setattr(precompile, "uncached", lambda families: [])
    assert precompile.compile_first(args) is None
    assert capsys.readouterr().err == ""


def test_status_when_every_family_is_done_but_the_processes_run_on(tmp_path):
    """Between a process's last family and its exit the line says so; it never ends in an empty
    'compiling' list."""

    class Running:
        def poll(self):
            return None

    out = open(tmp_path / "out", "w+b")  # as the process's stdout: a real file, written at its offset
    out.write(b"vq4\nsynth\n")
    out.flush()
    ahead = object.__new__(precompile._Ahead)
    ahead.procs = [(["vq4", "synth"], Running(), out, None)]
    ahead.t0 = precompile.time.perf_counter()
    ahead.estimate = (110, 220)
    line = ahead.status()
    assert "done vq4, synth" in line and "writing the cache" in line, line
    assert not re.search(r"compiling +\(", line), line
    out.close()


def test_a_silent_compile_is_waited_for(monkeypatch, capsys, tmp_path):
    """Off a terminal (no OMAPS_PROGRESS) the compile still runs first and is waited for, silently,
    over several turns of the wait loop (the wait loop once read the time of a line it had not
    printed: TypeError)."""
    delays = "square=0.3,micromap=0.2"
    clock = _Clock(tmp_path, delays)
    monkeypatch.setattr(precompile, "time", clock)
    monkeypatch.setenv("OMAPS_PROGRESS", "0")
    monkeypatch.delenv("OMAPS_PRECOMPILE", raising=False)
    monkeypatch.setattr(precompile, "uncached", lambda families: list(families))
    monkeypatch.setattr(precompile, "_command", _stub(tmp_path, delays))
    args = type("A", (), {"command": "eval", "paths": [], "schemes": "sq16,tri3"})()
    started = precompile.compile_first(args)
    assert started is not None
    clock.started = started
    precompile.finish_ahead(started)
    assert clock.t >= 0.3 and clock.released == {"square", "micromap"}
    assert all(p.poll() is not None for _, p, _, _ in started.procs)
    assert capsys.readouterr().err == ""
