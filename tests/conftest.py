import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# numba compiles (or loads its cache) on a kernel's first call, which can take longer than
# Hypothesis' per-example deadline: timing is not what these tests check
settings.register_profile("omaps", deadline=None)
settings.load_profile("omaps")

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("OMAPS_SHARED", ROOT.parent / "shared"))
TEXTURES = SHARED / "data" / "textures"
SCENES = SHARED / "data" / "scenes"


def real_textures(min_size=0):
    """Paths of the real alpha textures in ../shared (empty when absent)."""
    if not TEXTURES.is_dir():
        return []
    from PIL import Image

    out = []
    for p in sorted(TEXTURES.glob("*.png")):
        with Image.open(p) as im:
            if min(im.size) >= min_size:
                out.append(p)
    return out


def tile_maps(paths, size, tile=64, limit=300):
    """The size x size map of every tile x tile texel tile of some real textures (bench/common.py's
    maps), without all-T / all-O ones: at most ``limit``, spread over them."""
    from omaps.alpha_test import StateRule
    from omaps.bake import bake_square
    from omaps.sampling import footprint_grid
    from omaps.texture import load_alpha

    rule = StateRule()
    out = []
    for p in paths:
        s = rule.classify(load_alpha(p))
        for y in range(0, s.shape[0] - tile + 1, tile):
            for x in range(0, s.shape[1] - tile + 1, tile):
                m = bake_square(footprint_grid(s[y:y + tile, x:x + tile]), size)
                if len(np.unique(m)) > 1:
                    out.append(m)
    return np.stack(out[:: max(1, len(out) // limit)][:limit])


needs_shared = pytest.mark.skipif(not TEXTURES.is_dir(),
                                  reason=f"real textures not found at {TEXTURES} (../shared is absent)")


needs_scenes = pytest.mark.skipif(not (SCENES / "palm.glb").is_file(),
                                  reason=f"scenes not found at {SCENES} (../shared is absent)")


def untimed(d):
    """A trace report without what depends on the machine's speed (timings, rates, seconds) or
    on the file's name: two runs of the same scene compare equal."""
    if isinstance(d, dict):
        return {k: untimed(v) for k, v in d.items()
                if k not in ("timings", "timing", "file") and "per_second" not in k and "seconds" not in k}
    if isinstance(d, list):
        return [untimed(v) for v in d]
    return d


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def tex_and_uvs(tmp_path, rng):
    """A 32x24 8-bit mask (a transparent band, an opaque band, noise) as mask.png and 9 UV
    triangles as uvs.npy: (png path, npy path, alpha, triangles)."""
    from PIL import Image

    a = rng.integers(0, 256, size=(24, 32)).astype(np.uint8)
    a[:, :10] = 0
    a[:8] = 255
    Image.fromarray(a).save(tmp_path / "mask.png")
    tris = rng.uniform(0.1, 0.9, size=(9, 1, 2)) + rng.uniform(-0.1, 0.1, size=(9, 3, 2))
    np.save(tmp_path / "uvs.npy", tris)
    return tmp_path / "mask.png", tmp_path / "uvs.npy", a, tris


def pytest_sessionstart(session):
    """With an empty numba cache, compile every command's kernels first, in two processes
    (``omaps.cli.precompile``), so that the test workers load them instead of each compiling the
    same kernels at once. Only for the whole suite (``python -m pytest``); skipped in xdist
    workers, when everything is cached, or with OMAPS_PRECOMPILE=0."""
    if hasattr(session.config, "workerinput") or os.environ.get("OMAPS_PRECOMPILE") == "0":
        return
    if [Path(a).resolve() for a in session.config.args] != [ROOT / "tests"]:
        return
    import subprocess
    import sys
    import time

    from omaps.cli.precompile import FAMILIES, uncached

    missing = uncached(list(FAMILIES))
    if not missing:
        return
    groups = [g for g in ([f for f in missing if f == "vq4"], [f for f in missing if f != "vq4"]) if g]
    tr = session.config.pluginmanager.get_plugin("terminalreporter")
    if tr is not None:
        tr.write_line(f"compiling numba kernels first (empty cache): {', '.join(missing)}")
    t0 = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-m", "omaps.cli.precompile", *g], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) for g in groups]
    for p in procs:
        p.wait()  # a failure only means the tests compile what they need themselves
    if tr is not None:
        tr.write_line(f"kernels compiled in {time.perf_counter() - t0:.0f} s")


def pytest_xdist_make_scheduler(config, log):
    """With ``--dist load`` (pyproject.toml), the xdist workers are given one test at a time
    (each keeps at most three queued), but a test module with a module- or class-scoped fixture
    as one unit, to one worker, so that the fixture is computed once; the units go out largest
    first, then the single tests in the collection's order (pytest_collection_modifyitems).
    (pytest-xdist's own ``loadgroup`` cannot group: it renames node ids, which pytest 9 ignores.)"""
    if config.getoption("dist") != "load":
        return None
    import re

    from xdist.scheduler import LoadScopeScheduling

    here = Path(__file__).resolve().parent
    grouped = {p.relative_to(config.rootpath).as_posix() for p in here.glob("test_*.py")
               if re.search(r"@pytest\.fixture\(scope=\"(module|class)\"", p.read_text(encoding="utf-8"))}

    class ModuleFixtureScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            module = nodeid.split("::", 1)[0]
            return module if module in grouped else nodeid

    return ModuleFixtureScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    """The tests marked ``long`` (the longest, e.g. the README part tracing the forest) first,
    so that the workers start them early and short ones fill in at the end: the workers finish
    together. Depends on the collection only, so every worker computes the same order."""
    items.sort(key=lambda it: it.get_closest_marker("long") is None)  # stable: else as collected
