"""omaps/report/assets/three.min.js is what its recipe builds: tools/build_three.mjs (esbuild and
three.js at the exact versions of tools/package.json) rebuilds it, byte for byte, from
omaps/report/assets/three-entry.js. The rebuild needs node and ``npm ci --prefix tools`` (skipped
otherwise, naming the reason); the pins and the build script's refusal of other installed
versions are checked with node alone or with nothing."""

import json
import os
import re
import shutil
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOLS = os.path.join(ROOT, "tools")
ASSETS = os.path.join(ROOT, "omaps", "report", "assets")
BUNDLE = os.path.join(ASSETS, "three.min.js")
SCRIPT = os.path.join(TOOLS, "build_three.mjs")
NODE = shutil.which("node")
REBUILD = "npm ci --prefix tools && node tools/build_three.mjs"

needs_node = pytest.mark.skipif(NODE is None, reason="node is not on PATH: the three.js bundle checks are skipped")


def _installed(name):
    """The version of ``name`` in tools/node_modules, or None."""
    try:
        with open(os.path.join(TOOLS, "node_modules", name, "package.json")) as f:
            return json.load(f)["version"]
    except (OSError, ValueError, KeyError):
        return None


def _pins():
    with open(os.path.join(TOOLS, "package.json")) as f:
        return json.load(f)["dependencies"]


def test_three_and_esbuild_are_pinned_exactly_and_locked():
    pins = _pins()
    with open(os.path.join(TOOLS, "package-lock.json")) as f:
        lock = json.load(f)["packages"]
    for name in ("three", "esbuild"):
        assert re.fullmatch(r"\d+\.\d+\.\d+", pins.get(name, "")), \
            f"tools/package.json must pin {name} to one exact version, not {pins.get(name)!r}"
        assert lock[""]["dependencies"][name] == pins[name], "tools/package-lock.json is stale: npm install --prefix tools"
        assert lock[f"node_modules/{name}"]["version"] == pins[name]
    assert pins["three"] == "0.187.0"
    # esbuild's per-platform binaries are the only other packages the recipe adds to the lock
    extra = {k for k in lock if k.startswith("node_modules/")} - {
        "node_modules/three", "node_modules/esbuild", "node_modules/gltf-validator"}
    for key in extra:
        assert key.startswith("node_modules/@esbuild/") and lock[key].get("optional"), key
        assert lock[key]["version"] == pins["esbuild"], key


@needs_node
@pytest.mark.skipif(_installed("three") is None or _installed("esbuild") is None,
                    reason="three and esbuild are not installed in tools/node_modules (run `npm ci --prefix tools`): "
                           "the three.js bundle is not rebuilt")
def test_committed_bundle_is_what_the_recipe_builds(tmp_path):
    out = tmp_path / "three.min.js"
    run = subprocess.run([NODE, SCRIPT, str(out)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"tools/build_three.mjs failed:\n{run.stderr}"
    built = out.read_bytes()
    with open(BUNDLE, "rb") as f:
        committed = f.read()
    if built != committed:
        at = next((i for i, (a, b) in enumerate(zip(built, committed)) if a != b), min(len(built), len(committed)))
        pytest.fail(f"omaps/report/assets/three.min.js ({len(committed)} bytes) is not what tools/build_three.mjs "
                    f"builds ({len(built)} bytes; first difference at byte {at}); rebuild it with `{REBUILD}` "
                    f"and commit it")


@needs_node
def test_committed_bundle_defines_the_entry_names_as_global_three():
    """The committed file, run as a classic script, defines THREE with every name three-entry.js exports."""
    with open(os.path.join(ASSETS, "three-entry.js")) as f:
        entry = f.read()
    names = sorted({n for block in re.findall(r"export\s*\{([^}]*)\}", entry) for n in re.split(r"[\s,]+", block) if n})
    assert "WebGLRenderer" in names and "OrbitControls" in names
    probe = ("const vm = require('node:vm'); const fs = require('node:fs');"
             "const ctx = {}; vm.createContext(ctx);"
             "vm.runInContext(fs.readFileSync(process.argv[1], 'utf8') + '\\n;this.THREE = THREE;', ctx);"
             "console.log(JSON.stringify(Object.keys(ctx.THREE).filter(k => ctx.THREE[k] !== undefined)));")
    run = subprocess.run([NODE, "-e", probe, BUNDLE], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert sorted(json.loads(run.stdout)) == names


@needs_node
def test_build_refuses_other_installed_versions(tmp_path):
    """A tools/node_modules left from other pins is refused (exit 2, naming the package), nothing written."""
    tools = tmp_path / "tools"
    tools.mkdir()
    shutil.copy(SCRIPT, tools / "build_three.mjs")
    pins = _pins()
    (tools / "package.json").write_text(json.dumps({"dependencies": pins}))
    for name, version in (("three", pins["three"]), ("esbuild", "0.0.1")):
        (tools / "node_modules" / name).mkdir(parents=True)
        (tools / "node_modules" / name / "package.json").write_text(json.dumps({"name": name, "version": version}))
    out = tmp_path / "three.min.js"
    run = subprocess.run([NODE, str(tools / "build_three.mjs"), str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert "esbuild 0.0.1" in run.stderr and pins["esbuild"] in run.stderr and "npm ci --prefix tools" in run.stderr
    assert not out.exists()
