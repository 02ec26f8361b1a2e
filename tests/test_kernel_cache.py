"""numba's on-disk cache keyed on what a kernel imports (``omaps.kernel_cache``): a kernel that
inlines another module's function or constant is recompiled when that module changes, in a
fresh process, and a kernel whose imports did not change is loaded from the cache."""

import os
import subprocess
import sys
import textwrap

import pytest

from omaps import kernel_cache

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# the probe: the package's kernel, with omaps's key or numba's own; prints the kernel's result and
# whether numba compiled it in this process
PROBE = """
import os, sys
sys.path.insert(0, sys.argv[1])
if sys.argv[2] == "keyed":
    from omaps import kernel_cache
    kernel_cache.watch(os.path.join(sys.argv[1], "pkgx"))
    kernel_cache.watch_numba()
from pkgx.kern import total
print(total(), len(total.stats.cache_misses))
"""


def _package(tmp_path, code=1, lazy_value=10):
    pkg = tmp_path / "pkgx"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text(textwrap.dedent("""
        def __getattr__(name):  # a lazily exported name, as omaps's packages export theirs
            if name == "scale":
                from .helpers import scale
                return scale
            raise AttributeError(name)
    """))
    (pkg / "consts.py").write_text(f"CODE = {code}\n")
    (pkg / "helpers.py").write_text(textwrap.dedent(f"""
        from numba import njit

        @njit(cache=True, inline="always")
        def scale(x):
            return x * {lazy_value}
    """))
    (pkg / "kern.py").write_text(textwrap.dedent("""
        from numba import njit

        from . import consts
        from pkgx import scale

        @njit(cache=True)
        def total():
            return consts.CODE + scale(1)
    """))
    return tmp_path


def _run(root, mode, cache):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=ROOT)
    r = subprocess.run([sys.executable, "-c", PROBE, str(root), mode], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    value, misses = r.stdout.split()
    return int(value), int(misses)


def test_a_kernel_recompiles_when_what_it_imports_changes(tmp_path):
    root = _package(tmp_path)
    keyed, plain = tmp_path / "keyed_cache", tmp_path / "plain_cache"
    assert _run(root, "keyed", keyed) == (11, 1)  # compiled
    assert _run(root, "keyed", keyed) == (11, 0)  # loaded from the cache
    (root / "pkgx" / "unrelated.py").write_text("X = 1\n")
    os.utime(root / "pkgx" / "kern.py")  # touched, same content
    assert _run(root, "keyed", keyed) == (11, 0)  # nothing it imports changed
    assert _run(root, "plain", plain) == (11, 1)
    _package(tmp_path, code=2)  # a constant the kernel inlines, in another module
    # numba's own key (the kernel's file alone): the stale kernel, without an error -- the hazard
    assert _run(root, "plain", plain) == (11, 0)
    # keyed on the imports: recompiled once
    assert _run(root, "keyed", keyed) == (12, 1)
    _package(tmp_path, code=2, lazy_value=20)  # a function it takes through a lazy export
    assert _run(root, "keyed", keyed) == (22, 1)


def test_omaps_kernels_are_keyed_on_the_registry_and_every_lookup():
    """The tracer's filters inline every codec's block lookup and the registry's format codes:
    their key covers each codec's modules; the command line and the batch are in no kernel's key."""
    from omaps.codecs.registry import ENTRIES

    pkg = os.path.join(ROOT, "omaps")
    deps = {os.path.relpath(p, pkg) for p in kernel_cache.dependencies(os.path.join(pkg, "trace", "filter.py"))}
    for need in ["codecs/registry.py", "codecs/dispatch.py", "trace/lookups.py", "codecs/csm.py", "codecs/succinct.py"]:
        assert need in deps
    for e in ENTRIES:
        lookup = e.lookup()
        mod = getattr(getattr(lookup, "py_func", lookup), "__module__", None)
        if mod and mod.startswith("omaps."):
            assert mod[len("omaps."):].replace(".", "/") + ".py" in deps, (e.name, mod)
    for kernel_file in ["trace/filter.py", "raster.py", "bake/square.py", "omm/resolve.py"]:
        deps = {os.path.relpath(p, pkg) for p in kernel_cache.dependencies(os.path.join(pkg, kernel_file))}
        assert not any(d.startswith(("cli/", "batch/")) for d in deps), (kernel_file, sorted(deps))
    # and a codec's change leaves the bakers' kernels cached
    for kernel_file in ["raster.py", "bake/square.py", "bake/micromap.py"]:
        deps = {os.path.relpath(p, pkg) for p in kernel_cache.dependencies(os.path.join(pkg, kernel_file))}
        assert "codecs/registry.py" not in deps and "codecs/vq4_block.py" not in deps, (kernel_file, sorted(deps))


def test_the_key_follows_content_not_location(tmp_path):
    import shutil

    a = _package(tmp_path / "a")
    b = tmp_path / "b"
    shutil.copytree(a, b)
    keys = []
    for root in (a, b):
        kernel_cache.watch(str(root / "pkgx"))
        try:
            keys.append(kernel_cache.source_key(str(root / "pkgx" / "kern.py")))
        finally:
            kernel_cache._ROOTS.pop("pkgx", None)
    assert keys[0] == keys[1]


# --- the codec registry changed under a warm cache ---------------------------------------------

# the registry gives format codes in declaration order: declaring sq32 before sq16 swaps their codes
SWAP = ("_RAW_SIZES = tuple(1 << k for k in range(8))", "_RAW_SIZES = (1, 2, 4, 8, 32, 16, 64, 128)")


# a codec added to omaps' own: the raw 16x16 map again, under another name (so its figures must be sq16's)
ADD = ("PLUGIN_GROUP = ", "_BUILTIN += (CodecEntry(\"copy16\", 16, 64, _raw_lookup(16), "
       "lambda: replace(_raw(16), name=\"copy16\"), (\"square\",), description=\"sq16 again\"),)\n\nPLUGIN_GROUP = ")


def _trace(pkg_root, cache, scene, out, schemes="none,sq16,sq32"):
    """``omaps trace`` from the copy of omaps in ``pkg_root`` with its own kernel cache: rc,
    stderr and each scheme's figures (timings left out)."""
    import json

    env = dict(os.environ, PYTHONPATH=str(pkg_root), OMAPS_PROGRESS="0")
    env.pop("NUMBA_CACHE_DIR", None)
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    r = subprocess.run([sys.executable, "-m", "omaps", "trace", scene, "--schemes", schemes, "--size",
                        "48", "--json", str(out), "--quiet"], capture_output=True, text=True, env=env,
                       cwd=str(pkg_root), timeout=1800)
    if r.returncode:
        return r.returncode, r.stderr, None
    report = json.loads(out.read_text())
    figures = {name: {k: v for k, v in s.items() if "second" not in k and "timing" not in k}
               for name, s in report["schemes"].items()}
    return r.returncode, r.stderr, figures


# (not marked long: run late, it loads what the suite compiled before it instead of compiling it again)
def test_swapped_format_codes_under_a_warm_cache_trace_as_a_cold_run(tmp_path):
    """Swap two codecs' format codes in the registry of a copy of omaps whose kernel cache is
    warm: the next trace, in a fresh process, gives the figures of the trace before the edit
    (format codes change no figure: what a cold run gives) and 0 differing pixels (with numba's
    own key, the tracer's kernels kept the old codes: each pair's block was read by the other
    codec's lookup, and pixels changed). Then add a codec (sq16's map under another name, its
    figures known: sq16's): traced at once, under the same warm cache, as sq16."""
    import shutil

    import numpy as np
    from gltf_files import grid_scene

    pkg = tmp_path / "pkg"
    # the copy takes the checkout's kernel cache along (numba's __pycache__ files: the key is the
    # content, wherever it lies), so only what the edits below change compiles
    shutil.copytree(os.path.join(ROOT, "omaps"), pkg / "omaps")
    rng = np.random.default_rng(3)
    scene = grid_scene(tmp_path / "grid.gltf", np.kron((rng.random((16, 16)) > 0.5).astype(np.uint8) * 255,
                                                       np.ones((4, 4), np.uint8)), 12, seed=2)
    cache = None  # the copy's own __pycache__ folders
    rc, err, cold = _trace(pkg, cache, scene, tmp_path / "cold.json")
    assert rc == 0, err
    registry = pkg / "omaps" / "codecs" / "registry.py"
    text = registry.read_text()
    assert SWAP[0] in text, "the test's edit no longer matches the registry's raw entries"
    registry.write_text(text.replace(SWAP[0], SWAP[1]))
    rc, err, warm = _trace(pkg, cache, scene, tmp_path / "warm.json")
    assert rc == 0, err  # the tracer exits 1 when a scheme changes a visible pixel
    assert warm == cold
    text = registry.read_text()
    assert ADD[0] in text, "the test's edit no longer matches the registry"
    registry.write_text(text.replace(ADD[0], ADD[1], 1))
    rc, err, added = _trace(pkg, cache, scene, tmp_path / "added.json", "none,sq16,sq32,copy16")
    assert rc == 0, err
    copy16 = added.pop("copy16")
    assert added == cold
    same = ("alpha_tests_per_primary_ray", "map_bytes", "differing_pixels")
    assert {k: copy16.get(k) for k in same} == {k: cold["sq16"].get(k) for k in same}
    assert cold["sq16"]["alpha_tests_per_primary_ray"] < cold["none"]["alpha_tests_per_primary_ray"]
