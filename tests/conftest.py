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


needs_shared = pytest.mark.skipif(not TEXTURES.is_dir(),
                                  reason=f"real textures not found at {TEXTURES} (../shared is absent)")


needs_scenes = pytest.mark.skipif(not (SCENES / "palm.glb").is_file(),
                                  reason=f"scenes not found at {SCENES} (../shared is absent)")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


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
