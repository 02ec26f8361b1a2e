"""The example codec plug-in (examples/omaps-rle16) installed as an external package.

pip installs a copy of the example, offline (``--no-index --no-build-isolation``: its build
backend, setuptools, comes from this environment: the ``test`` extra), into a folder of its own;
omaps then runs in subprocesses with that folder on ``PYTHONPATH``, so the plug-in's entry point
is found as any installed distribution's. Checked: the codec passes the conformance tests every
codec gets; ``omaps eval`` and ``omaps trace`` use it (lossy but conservative: no better than
sq16, no differing pixel) and a byte budget chooses it when a scheme names it, while the default
budgets are the same with and without it (it does not opt in); the command line's help lists it;
a broken plug-in stops omaps with exit 2 and one line naming it, and ``OMAPS_CODEC_PLUGINS=0``
starts omaps without it.

The trace compiles the tracer's kernels once for an environment with the plug-in (its own cache
entries, keyed on the plug-in's code: ``omaps.kernel_cache``); later runs load them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT

EXAMPLE = ROOT / "examples" / "omaps-rle16"
TIMING = ("second", "timing", "per_second", "over_opaque")  # figures that vary run to run


def _env(*paths: Path, plugins: bool = True) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(map(str, paths)), OMAPS_PROGRESS="0", OMAPS_PRECOMPILE="0")
    env.pop("OMAPS_CODEC_PLUGINS", None)
    if not plugins:
        env["OMAPS_CODEC_PLUGINS"] = "0"
    return env


def _omaps(args, env, cwd, timeout=900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "omaps", *map(str, args)], env=env, cwd=str(cwd),
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def plugin(tmp_path_factory) -> Path:
    """The folder pip installed omaps-rle16 into (from a copy: the build writes beside the sources)."""
    tmp = tmp_path_factory.mktemp("plugin")
    src = tmp / "src"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("__pycache__", "build", "*.egg-info"))
    target = tmp / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index",
                        "--disable-pip-version-check", "--quiet", "--target", str(target), str(src)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"pip could not install the example (setuptools>=70.1 is in the test extra):\n{r.stderr}"
    assert (target / "omaps_rle16" / "block.py").is_file()
    assert list(target.glob("omaps_rle16-*.dist-info/entry_points.txt"))
    return target


@pytest.fixture(scope="module")
def textures(tmp_path_factory) -> tuple[Path, Path]:
    """Two 64x64 alpha textures: a disc (few runs: rle16 keeps every cell of its 16x16 map) and a
    checkerboard of 4-texel squares with a disc (too many runs: rle16 turns some into C)."""
    from PIL import Image

    d = tmp_path_factory.mktemp("textures")
    y, x = np.mgrid[:64, :64] + 0.5
    disc = np.where(np.hypot(x - 30, y - 34) < 22, 255, 0).astype(np.uint8)
    checker = np.where(((x // 4 + y // 4) % 2 == 0) | (np.hypot(x - 30, y - 34) < 12), 255, 0).astype(np.uint8)
    Image.fromarray(disc).save(d / "disc.png")
    Image.fromarray(checker).save(d / "checker.png")
    return d / "disc.png", d / "checker.png"


# (not marked long: run late, it loads what the suite compiled before it instead of compiling it again)
def test_the_plugin_passes_the_conformance_tests(plugin):
    r = subprocess.run([sys.executable, "-m", "pytest", "tests/test_codec_conformance.py", "-k", "rle16", "-q", "-n", "0",
                        "-p", "no:cacheprovider"], env=_env(plugin), cwd=str(ROOT), capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "3 passed" in r.stdout, r.stdout[-2000:]  # its three conformance tests, none deselected or skipped


def test_eval_scores_the_plugin_no_better_than_the_raw_map(plugin, textures, tmp_path):
    out = tmp_path / "eval.json"
    r = _omaps(["eval", *textures, "--schemes", "sq16,rle16", "--json", out, "--jobs", "1", "--quiet"],
               _env(plugin), tmp_path)
    assert r.returncode == 0, r.stderr
    rows = {t["name"]: t["schemes"] for t in json.loads(out.read_text())["textures"]}
    for name, s in rows.items():
        assert s["rle16"]["bits"] == s["sq16"]["bits"] == 512
        assert 0 < s["rle16"]["savings"] <= s["sq16"]["savings"], (name, s)
    assert rows["disc.png"]["rle16"]["savings"] == rows["disc.png"]["sq16"]["savings"]  # few runs: lossless
    assert rows["checker.png"]["rle16"]["savings"] < rows["checker.png"]["sq16"]["savings"]  # runs turned into C


def _scene(path: Path) -> Path:
    from gltf_files import grid_scene

    rng = np.random.default_rng(3)
    alpha = np.kron((rng.random((16, 16)) > 0.5).astype(np.uint8) * 255, np.ones((4, 4), np.uint8))
    return Path(grid_scene(path, alpha, 12, seed=2))


def _figures(report: dict, name: str) -> dict:
    return {k: v for k, v in report["schemes"][name].items() if not any(w in k for w in TIMING)}


# (not marked long: run late, it loads what the suite compiled before it instead of compiling it again)
def test_trace_with_the_plugin(plugin, tmp_path):
    """One trace with the plug-in (its codec, a budget that may choose it among the defaults,
    one that has only it, and a default budget), one without: the default budget's figures and
    options are the same (rle16 does not opt in to the default budgets)."""
    scene = _scene(tmp_path / "grid.gltf")
    schemes = "none,sq16,rle16,budget:2KiB:default+rle16,budget:2KiB:none+rle16,budget:1KiB"
    r = _omaps(["trace", scene, "--schemes", schemes, "--size", 48, "--encoder", "paper", "--json",
                tmp_path / "with.json", "--quiet"], _env(plugin), tmp_path)
    assert r.returncode == 0, r.stderr  # exit 1: a scheme changed a visible pixel
    report = json.loads((tmp_path / "with.json").read_text())
    s = report["schemes"]
    assert report["passed"] is True
    for name, fig in s.items():
        assert fig["differing_pixels"] == 0, name
    assert s["rle16"]["alpha_tests_per_primary_ray"] < s["none"]["alpha_tests_per_primary_ray"]
    assert s["rle16"]["alpha_tests_per_primary_ray"] >= s["sq16"]["alpha_tests_per_primary_ray"]
    assert s["rle16"]["map_bytes"] == 64 * report["scene"]["pairs"]
    for name in ("budget:2048:default+rle16", "budget:2048:none+rle16"):
        assert s[name]["map_bytes"] <= 2048, name
        assert "rle16" in report["settings"]["schemes"][name]["options"], name
    assert s["budget:2048:none+rle16"]["choices"].get("rle16", 0) > 0  # the budget chose it for some pairs
    assert "rle16" not in s["budget:1024"]["choices"]

    r = _omaps(["trace", scene, "--schemes", "none,sq16,budget:1KiB", "--size", 48, "--encoder", "paper", "--json",
                tmp_path / "without.json", "--quiet"], _env(plugin, plugins=False), tmp_path)
    assert r.returncode == 0, r.stderr
    without = json.loads((tmp_path / "without.json").read_text())
    for name in ("none", "sq16", "budget:1024"):
        assert _figures(report, name) == _figures(without, name), name
    assert report["settings"]["schemes"]["budget:1024"] == without["settings"]["schemes"]["budget:1024"]


def test_help_lists_the_plugin(plugin, tmp_path):
    """The command line's codec lists come from the registry: rle16 is there with the plug-in
    and not without it."""
    on = _omaps(["eval", "--help"], _env(plugin), tmp_path)
    off = _omaps(["eval", "--help"], _env(plugin, plugins=False), tmp_path)
    assert on.returncode == off.returncode == 0, on.stderr + off.stderr
    assert "rle16" in on.stdout
    assert "rle16" not in off.stdout


# a broken plug-in: its package's __init__ defines entries(); the distribution's metadata written by hand
BROKEN = {
    "raises": "def entries():\n    raise RuntimeError('no codecs today')\n",
    "not-an-entry": "def entries():\n    return ['rle16']\n",
    "name-clash": ("from omaps.codecs import CodecEntry\n\n\ndef entries():\n"
                   "    return [CodecEntry('vq4', 32, 64, lambda: None, lambda: None, description='a second vq4')]\n"),
}
BROKEN_SAYS = {"raises": "no codecs today", "not-an-entry": "CodecEntry", "name-clash": "'vq4'"}


def _broken_plugin(target: Path, body: str) -> None:
    pkg = target / "omaps_broken"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(body)
    info = target / "omaps_broken-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: omaps-broken\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[omaps.codecs]\nbroken = omaps_broken:entries\n")


@pytest.mark.parametrize("kind", list(BROKEN))
def test_a_broken_plugin_stops_omaps_naming_it(kind, textures, tmp_path):
    target = tmp_path / "site"
    _broken_plugin(target, BROKEN[kind])
    args = ["eval", textures[0], "--schemes", "sq4", "--jobs", "1", "--quiet"]
    r = _omaps(args, _env(target), tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "codec plug-in 'broken'" in lines[0] and "omaps-broken" in lines[0], lines[0]
    assert BROKEN_SAYS[kind] in lines[0], lines[0]
    assert "OMAPS_CODEC_PLUGINS=0" in lines[0] or kind != "raises", lines[0]
    r = _omaps(args, _env(target, plugins=False), tmp_path)
    assert r.returncode == 0, r.stderr
