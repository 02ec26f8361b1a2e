"""Outputs, the same in every command (``omaps.atomic``): modes from the umask, every output path
checked before any work (exit 2, nothing written, no temporary name shown), one overwrite rule,
Ctrl-C leaves nothing; settings in every JSON; --per-texture; progress bars; trace's epilog."""

import json
import os
import re
import signal
import stat
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf
from omaps.cli import main

# every command and its output options: (option, name in the output folder, file or folder)
OUTPUTS = {
    "eval": [("--json", "e.json", "file"), ("--csv", "e.csv", "file"), ("--plot", "e.svg", "file"),
             ("--show", "show", "folder")],
    "bake": [("-o", "b.npy", "file")],
    "encode": [("-o", "e.vq2", "file")],
    "decode": [("--show", "d.png", "file")],
    "omm": [("-o", "omm", "folder")],
    "trace": [("--json", "t.json", "file"), ("--heatmap", "h.png", "file"), ("--render", "r.png", "file")],
}
MANIFEST = {("eval", "--show"): "show.json", ("omm", "-o"): "omm.json"}


def _disc(n=64, r=0.35):
    yy, xx = np.mgrid[0:n, 0:n]
    a = np.zeros((n, n), np.uint8)
    d2 = (xx - n / 2) ** 2 + (yy - n / 2) ** 2
    a[d2 < (r * n) ** 2] = 255
    a[d2 < (r * n / 2) ** 2] = 120
    return a


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    Image.fromarray(_disc()).save(d / "leaf.png")
    rng = np.random.default_rng(1)
    np.save(d / "uvs.npy", rng.random((8, 3, 2)))
    write_quad_gltf(d / "quad.gltf", _disc())
    assert main(["encode", str(d / "leaf.png"), "--codec", "vq2", "--effort", "fast", "-o", str(d / "leaf.vq2")]) == 0
    return d


def argv(cmd, inputs, out, **override):
    """The command line of ``cmd`` with its outputs in folder ``out`` (``override``: option -> path)."""
    leaf, uvs, block, scene = (str(inputs / n) for n in ("leaf.png", "uvs.npy", "leaf.vq2", "quad.gltf"))
    base = {"eval": ["eval", leaf, "--quiet", "--schemes", "sq4,tri1", "--jobs", "1"],
            "bake": ["bake", leaf, "--scheme", "sq8"],
            "encode": ["encode", leaf, "--codec", "vq2", "--effort", "fast"],
            "decode": ["decode", block, "--codec", "vq2"],
            "omm": ["omm", leaf, uvs, "--level", "2", "--quiet"],
            "trace": ["trace", scene, "--schemes", "none,sq4", "--size", "8", "--quiet"]}[cmd]
    for opt, name, _ in OUTPUTS[cmd]:
        base += [opt, str(override.get(opt, out / name))]
    return base


def listing(folder):
    return sorted(os.path.relpath(os.path.join(r, f), folder) for r, ds, fs in os.walk(folder) for f in fs + ds)


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_modes_follow_the_umask(tmp_path, inputs, capsys, umask):
    out = tmp_path / "new" / "deeper"  # parents created too
    old = os.umask(umask)
    try:
        for cmd in OUTPUTS:
            assert main(argv(cmd, inputs, out)) == 0, capsys.readouterr().err
    finally:
        os.umask(old)
    paths = [tmp_path / "new"] + [tmp_path / "new" / p for p in listing(tmp_path / "new")]
    assert len(paths) > 15
    for p in paths:
        mode = stat.S_IMODE(p.stat().st_mode)
        want = (0o777 if p.is_dir() else 0o666) & ~umask
        assert mode == want, (str(p), oct(mode), oct(want))
    assert not [p for p in paths if p.name.startswith(".omaps")]


def _bad_cases(tmp_path):
    """(command, option, bad path, problem) for every command."""
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "keep.txt").write_text("mine")
    (tmp_path / "a_folder").mkdir()
    f, fo, d = tmp_path / "a_file", tmp_path / "foreign", tmp_path / "a_folder"
    return [
        ("eval", "--plot", tmp_path / "o" / "chart.xyz", "--plot must end in"),
        ("eval", "--json", f / "r.json", "is not a folder"),
        ("eval", "--csv", d, "is a folder"),
        ("eval", "--show", fo, "holds no show.json"),
        ("eval", "--show", f, "is not a folder"),
        ("eval", "--json", "/proc/omaps-test/r.json", "cannot create files in /proc"),
        ("bake", "-o", d, "is a folder"),
        ("bake", "-o", "LEAF", "is also an input"),
        ("encode", "-o", f / "x" / "e.vq2", "is not a folder"),
        ("encode", "-o", "LEAF", "is also an input"),
        ("decode", "--show", tmp_path / "o" / "d.jpg", "--show must end in .png"),
        ("decode", "--show", "BLOCK", "is also an input"),
        ("omm", "-o", f, "is not a folder"),
        ("omm", "-o", fo, "holds no omm.json"),
        ("trace", "--render", tmp_path / "o" / "r.tga", "--render must end in .png"),
        ("trace", "--json", d, "is a folder"),
    ]


def test_bad_output_paths(tmp_path, inputs, capsys):
    """Every command checks every output before the work: exit 2, ``omaps: error: PATH:
    problem``, no temporary name, and nothing written (not even the other, good outputs)."""
    cases = _bad_cases(tmp_path)
    assert {c[0] for c in cases} == set(OUTPUTS)
    before = listing(tmp_path)
    before_inputs = {p: (inputs / p).read_bytes() for p in listing(inputs) if (inputs / p).is_file()}
    for cmd, opt, bad, problem in cases:
        bad = {"LEAF": inputs / "leaf.png", "BLOCK": inputs / "leaf.vq2"}.get(str(bad), bad)
        args = argv(cmd, inputs, tmp_path / "o", **{opt: bad})
        assert main(args) == 2, (cmd, opt, bad)
        err = capsys.readouterr().err
        assert err.startswith(f"omaps: error: {bad}: "), err
        assert problem in err, err
        assert ".omaps" not in err and "Traceback" not in err
        assert listing(tmp_path) == before, (cmd, opt)
    assert {p: (inputs / p).read_bytes() for p in before_inputs} == before_inputs
    assert (tmp_path / "foreign" / "keep.txt").read_text() == "mine"


def test_same_output_twice(tmp_path, inputs, capsys):
    h = tmp_path / "h.png"
    assert main(argv("trace", inputs, tmp_path, **{"--heatmap": h, "--render": h})) == 2
    assert "given to both --heatmap and --render" in capsys.readouterr().err
    j = tmp_path / "r.json"  # (--json and --csv cannot share a path: each has its suffix)
    assert main(argv("eval", inputs, tmp_path, **{"--csv": j, "--json": j})) == 2
    assert f"{j}: --csv must end in .csv, not .json" in capsys.readouterr().err
    assert main(argv("eval", inputs, tmp_path, **{"--json": tmp_path / "show" / "r.json"})) == 2
    assert "inside the output folder of --show" in capsys.readouterr().err
    assert listing(tmp_path) == []


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root may write read-only files")
def test_read_only_output_is_kept(tmp_path, inputs, capsys):
    out = tmp_path / "b.npy"
    out.write_bytes(b"keep")
    out.chmod(0o444)
    assert main(argv("bake", inputs, tmp_path, **{"-o": out})) == 2
    assert "read-only" in capsys.readouterr().err and out.read_bytes() == b"keep"


@pytest.mark.parametrize("cmd", list(OUTPUTS))
def test_overwrite_rule(tmp_path, inputs, capsys, cmd):
    """Files are replaced; a folder is replaced whole when it holds the same command's manifest
    or is empty; any other folder is refused (exit 2) and left as it was."""
    assert main(argv(cmd, inputs, tmp_path)) == 0
    for opt, name, kind in OUTPUTS[cmd]:
        p = tmp_path / name
        if kind == "file":
            p.write_bytes(b"stale")
        else:
            assert (p / MANIFEST[cmd, opt]).is_file()
            (p / "stale.txt").write_text("stale")
    assert main(argv(cmd, inputs, tmp_path)) == 0, capsys.readouterr().err
    for opt, name, kind in OUTPUTS[cmd]:
        p = tmp_path / name
        if kind == "file":
            assert p.read_bytes() != b"stale" and p.stat().st_size > 0
        else:
            assert not (p / "stale.txt").exists() and (p / MANIFEST[cmd, opt]).is_file()
    for opt, name, kind in OUTPUTS[cmd]:
        if kind != "folder":
            continue
        other = tmp_path / "other"
        other.mkdir()
        (other / "notes.txt").write_text("mine")
        capsys.readouterr()
        assert main(argv(cmd, inputs, tmp_path, **{opt: other})) == 2
        assert f"{other}: folder is not empty and holds no {MANIFEST[cmd, opt]}" in capsys.readouterr().err
        assert listing(other) == ["notes.txt"]
        (other / "notes.txt").unlink()
        assert main(argv(cmd, inputs, tmp_path, **{opt: other})) == 0  # empty: taken
        assert (other / MANIFEST[cmd, opt]).is_file()
        other.rename(tmp_path / "other_done")
    assert not [p for p in listing(tmp_path) if os.path.basename(p).startswith(".omaps")]


def test_failed_write_leaves_nothing(tmp_path, inputs, capsys, monkeypatch):
    """A failure while writing (here the plot) leaves none of the outputs and names no temporary."""
    from omaps.corpus import report

    def broken(path, *a, **k):
        raise OSError(28, "No space left on device", path)

    monkeypatch.setattr(report, "plot_savings", broken)
    assert main(argv("eval", inputs, tmp_path)) == 1
    err = capsys.readouterr().err
    assert err.strip() == f"omaps: error: {tmp_path / 'e.svg'}: No space left on device"
    assert listing(tmp_path) == []
    out = tmp_path / "new" / "sub"  # folders made for the outputs go again too
    assert main(argv("eval", inputs, out)) == 1
    assert listing(tmp_path) == []


def _settings_of(cmd, tmp_path, inputs, capsys):
    if cmd == "decode":
        assert main(["decode", str(inputs / "leaf.vq2"), "--codec", "vq2", "--json"]) == 0
        return json.loads(capsys.readouterr().out)
    assert main(argv(cmd, inputs, tmp_path)) == 0
    return {"eval": lambda: json.loads((tmp_path / "e.json").read_text()),
            "trace": lambda: json.loads((tmp_path / "t.json").read_text()),
            "omm": lambda: json.loads((tmp_path / "omm" / "omm.json").read_text())}[cmd]()


@pytest.mark.parametrize("cmd, keys", [
    ("eval", ["mode", "t_max", "o_min", "filter", "wrap", "channel", "encoder", "effort", "min_size", "schemes"]),
    ("trace", ["materials", "schemes", "two_state", "shadows", "encoder", "effort"]),
    ("omm", ["source", "level", "dynamic_scale", "max_level", "promotion", "special", "dedup", "encoder", "effort"]),
    ("decode", ["codec"]),
])
def test_every_json_records_its_settings(tmp_path, inputs, capsys, cmd, keys):
    doc = _settings_of(cmd, tmp_path, inputs, capsys)
    missing = [k for k in keys if k not in doc["settings"]]
    assert not missing, missing
    if cmd == "eval":
        assert doc["settings"]["schemes"]["sq4"]["kind"] == "square"
        show = json.loads((tmp_path / "show" / "show.json").read_text())
        assert show["settings"] == doc["settings"]
    if cmd == "omm":  # the texture input's alpha test: cut-off, filter, wrap
        assert doc["format"] == "4state"
        assert {"cutoff", "filter", "wrap", "channel"} <= set(doc["input"])
    if cmd == "trace":
        assert {"cutoff", "filter", "wrap", "blend"} <= set(doc["settings"]["materials"])


def test_per_texture(tmp_path, capsys):
    d = tmp_path / "many"
    d.mkdir()
    for i in range(23):
        Image.fromarray(_disc(16 + i)).save(d / f"t{i:02d}.png")
    j = tmp_path / "r.json"
    assert main(["eval", str(d), "--schemes", "sq4", "--jobs", "1", "--json", str(j)]) == 0
    out = capsys.readouterr().out
    assert "t00.png" not in out and "23 per-texture rows not shown: --per-texture prints them" in out
    assert len(json.loads(j.read_text())["textures"]) == 23
    assert main(["eval", str(d), "--schemes", "sq4", "--jobs", "1", "--per-texture", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert all(f"t{i:02d}.png" in out for i in range(23)) and "not shown" not in out


@pytest.mark.parametrize("cmd", ["eval", "omm", "trace"])
def test_progress_bars(tmp_path, inputs, capsys, monkeypatch, cmd):
    """Progress goes to stderr: on when forced (or on a terminal), off with --quiet and by default
    when stderr is not a terminal (as under pytest and in CI logs)."""
    args = [a for a in argv(cmd, inputs, tmp_path) if a != "--quiet"]
    monkeypatch.delenv("OMAPS_PROGRESS", raising=False)
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "%|" not in captured.err and "%|" not in captured.out
    monkeypatch.setenv("OMAPS_PROGRESS", "1")
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "%|" in captured.err and "%|" not in captured.out
    assert main(args + ["--quiet"]) == 0
    assert "%|" not in capsys.readouterr().err


def test_trace_help_explains_every_column(tmp_path, inputs, capsys):
    """Each column of the printed table (with --shadows, the widest) is explained in the epilog."""
    assert main(argv("trace", inputs, tmp_path) + ["--shadows"]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(ln for ln in lines if ln.startswith("scheme"))
    columns = re.split(r"\s{2,}", header.strip())
    assert len(columns) == 11
    r = subprocess.run([sys.executable, "-m", "omaps", "trace", "--help"], capture_output=True, text=True)
    assert r.returncode == 0
    epilog = r.stdout[r.stdout.index("the printed table"):]
    explained = [ln.strip()[:14].strip() for ln in epilog.splitlines()[1:] if ln.startswith("  ") and
                 not ln.startswith("    ")]
    assert explained == columns


# --- Ctrl-C -----------------------------------------------------------------------------------

def _interrupt(args, cwd, wait_for: bytes, group=False):
    """Run ``omaps ARGS`` with progress bars forced on, send SIGINT once the pattern ``wait_for``
    has appeared on its stderr (the work has started; no timing), and return (exit code, stderr).
    ``group``: to the whole process group, workers included, as a terminal's Ctrl-C does."""
    env = dict(os.environ, OMAPS_PROGRESS="1", PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "omaps", *map(str, args)], cwd=cwd, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=group)
    seen = b""
    while not re.search(wait_for, seen):
        chunk = p.stderr.read1(4096)
        if not chunk:
            break
        seen += chunk
    assert re.search(wait_for, seen), seen.decode(errors="replace")
    if group:
        os.killpg(p.pid, signal.SIGINT)
    else:
        p.send_signal(signal.SIGINT)
    rest = p.stderr.read()
    p.wait()
    return p.returncode, (seen + rest).decode(errors="replace")


def _many_textures(folder, n):
    folder.mkdir()
    for i in range(n):
        Image.fromarray(_disc(96, 0.2 + 0.25 * i / n)).save(folder / f"t{i:03d}.png")


@pytest.mark.parametrize("stage, wait_for, group", [("workers", rb"\| *[1-9]\d*/120 \[", False),
                                                    ("workers", rb"\| *[1-9]\d*/120 \[", True),
                                                    ("pictures", rb"pictures:", False)])
def test_ctrl_c_eval(tmp_path, stage, wait_for, group):
    """Interrupted while the worker pool computes, or while the --show pictures are drawn:
    'omaps: interrupted', exit 130, no traceback (workers included), and nothing written."""
    tex = tmp_path / "tex"
    _many_textures(tex, 120)
    out = tmp_path / "out"
    out.mkdir()
    schemes = "vq4x64-thorough" if stage == "workers" else "sq4"
    rc, err = _interrupt(["eval", tex, "--schemes", schemes, "--jobs", "2", "--json", out / "r.json",
                          "--csv", out / "r.csv", "--show", out / "maps"], tmp_path, wait_for, group)
    assert rc == 130, err
    assert err.rstrip().endswith("omaps: interrupted") and "Traceback" not in err, err
    assert listing(out) == []


def test_ctrl_c_omm(tmp_path, inputs):
    uvs = np.random.default_rng(2).random((4000, 3, 2))
    np.save(tmp_path / "many.npy", uvs)
    out = tmp_path / "out"
    out.mkdir()
    (out / "omm").mkdir()  # an earlier output stays as it was
    (out / "omm" / "omm.json").write_text("{}")
    rc, err = _interrupt(["omm", inputs / "leaf.png", tmp_path / "many.npy", "--level", "9", "-o", out / "omm"],
                         tmp_path, b"omm baking:")
    assert rc == 130, err
    assert err.rstrip().endswith("omaps: interrupted") and "Traceback" not in err, err
    assert listing(out) == ["omm", os.path.join("omm", "omm.json")]


@needs_scenes
def test_ctrl_c_trace(tmp_path):
    """Interrupted (the whole process group) while the encoder's worker pool runs."""
    out = tmp_path / "out"
    out.mkdir()
    rc, err = _interrupt(["trace", SCENES / "palm.glb", "--schemes", "none,vq4-thorough", "--size", "32", "--jobs", "2",
                          "--json", out / "t.json", "--heatmap", out / "h.png"], tmp_path, rb"encode vq4", group=True)
    assert rc == 130, err
    assert err.rstrip().endswith("omaps: interrupted") and "Traceback" not in err, err
    assert listing(out) == []
