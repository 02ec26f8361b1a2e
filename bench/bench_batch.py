"""``omaps batch``: inputs per second, serial (``--scheduler none``) against a Dask LocalCluster
(``--scheduler local``, one worker process per core), on the same inputs, fresh output folders.

    python bench/bench_batch.py            # eval over the shared textures (>= 64 px)
    python bench/bench_batch.py omm        # omm over the shared scenes but forest

Prints each run's inputs/s and their ratio; no assertion on times (the machine is shared).
Without ../shared: eval over generated textures.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def inputs(command: str, tmp: str) -> tuple[list[str], list[str]]:
    if command == "omm":
        s = SHARED / "scenes"
        return [str(s / "palm.glb"), str(s / "smallpine" / "scene.gltf"),
                str(s / "khronos" / "AlphaBlendModeTest" / "AlphaBlendModeTest.glb")], []
    if (SHARED / "textures").is_dir():
        return [str(SHARED / "textures")], ["--min-size", "64"]
    import numpy as np
    from PIL import Image

    rng = np.random.default_rng(0)
    for i in range(48):
        a = np.kron((rng.random((32, 32)) > 0.5).astype(np.uint8) * 255, np.ones((8, 8), np.uint8))
        Image.fromarray(a, "L").save(os.path.join(tmp, f"t{i:02d}.png"))
    return [tmp], []


def run(command: str, paths, opts, scheduler: str, out: str) -> tuple[float, dict]:
    # the command as a user runs it (a process of its own: start-up is part of both timings)
    t0 = time.perf_counter()
    rc = subprocess.run([sys.executable, "-m", "omaps", "batch", command, *paths, "-o", out, "--scheduler", scheduler,
                         "--quiet", *opts], capture_output=True, text=True).returncode
    dt = time.perf_counter() - t0
    with open(os.path.join(out, "summary.json")) as f:
        tot = json.load(f)["totals"]
    assert rc in (0, 1), rc
    return dt, tot


if __name__ == "__main__":
    command = sys.argv[1] if len(sys.argv) > 1 else "eval"
    with tempfile.TemporaryDirectory() as tmp:
        paths, opts = inputs(command, tmp)
        print(f"omaps batch {command} on {os.cpu_count()} cores: {' '.join(paths)} {' '.join(opts)}")
        rates = {}
        for scheduler in ("none", "local"):
            dt, tot = run(command, paths, opts, scheduler, os.path.join(tmp, f"out_{scheduler}"))
            n = tot["ok"] + tot["problems"] + tot["skipped"] + tot["error"]
            rates[scheduler] = n / dt
            print(f"  --scheduler {scheduler:5s}: {n} inputs ({tot['ok']} ok, {tot['skipped']} skipped, "
                  f"{tot['error']} errors) in {dt:.2f} s (cluster start-up included): {rates[scheduler]:.2f} inputs/s")
        print(f"  local / serial: {rates['local'] / rates['none']:.2f}x")
