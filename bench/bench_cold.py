"""First use: the README's first command and a trace with an empty numba cache, against warm, in one run.

    python bench/bench_cold.py [SCENE] [--skip-install]

1. The README's first command, ``omaps eval`` (the embedded corpus), with an empty private numba
   cache (NUMBA_CACHE_DIR; the shared cache is never touched), as a user sees it (OMAPS_PROGRESS=1):
   its time, and the longest gap between two outputs on its stdout or stderr (progress bars and
   the compile's status lines count), then the same command warm;
2. ``omaps trace SCENE --schemes none,vq4 --size 128 --quiet`` (default SCENE: palm.glb from
   ../shared) with another empty cache, then warm;
3. with ``--skip-install`` only step 2.

Prints each time and the ratios to the warm time. Timings depend on the machine's load (the
1-minute load average before and after is printed): the ratios are measured side by side in one run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PALM = ROOT.parent / "shared" / "data" / "scenes" / "palm.glb"


def run(argv, cache: str, progress: bool = False) -> tuple[float, float]:
    """Run a command with the numba cache ``cache``: its time, and the longest gap between two
    outputs (stdout or stderr, a progress bar's redraw included) from its start to its end."""
    import selectors

    env = dict(os.environ, NUMBA_CACHE_DIR=cache, OMAPS_PROGRESS="1" if progress else "0")
    t0 = time.perf_counter()
    p = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    sel = selectors.DefaultSelector()
    sel.register(p.stdout, selectors.EVENT_READ)
    sel.register(p.stderr, selectors.EVENT_READ)
    last, gap, err, open_ = t0, 0.0, b"", 2
    while open_:
        for key, _ in sel.select():
            chunk = os.read(key.fileobj.fileno(), 65536)
            now = time.perf_counter()
            if not chunk:
                sel.unregister(key.fileobj)
                open_ -= 1
                continue
            gap, last = max(gap, now - last), now
            if key.fileobj is p.stderr:
                err += chunk
    p.wait()
    end = time.perf_counter()
    gap = max(gap, end - last)
    if p.returncode != 0:
        sys.exit(f"bench_cold: {' '.join(map(str, argv))} exited {p.returncode}:\n{err.decode(errors='replace')}")
    return end - t0, gap


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default=str(PALM))
    ap.add_argument("--skip-install", action="store_true", help="only the cold and warm runs")
    a = ap.parse_args()
    if not Path(a.scene).is_file():
        print(f"bench_cold: {a.scene} not found (../shared is absent): nothing to measure", file=sys.stderr)
        return 0
    omaps = [sys.executable, "-m", "omaps"]
    cmd = omaps + ["trace", a.scene, "--schemes", "none,vq4", "--size", "128", "--quiet"]
    print(f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="omaps-cold-") as tmp:
        if not a.skip_install:
            first, gap = run(omaps + ["eval"], f"{tmp}/b", progress=True)
            again, _ = run(omaps + ["eval"], f"{tmp}/b", progress=True)
            print("omaps eval (the README's first command)")
            print(f"  empty cache                  {first:7.1f} s  (longest silent gap {gap:.1f} s)")
            print(f"  warm                         {again:7.1f} s")
            print(f"  first / warm                 {first / again:7.1f} x")
        cold, _ = run(cmd, f"{tmp}/a")
        warm, _ = run(cmd, f"{tmp}/a")
        print(f"omaps {' '.join(cmd[3:])}")
        print(f"  empty cache (cold)           {cold:7.1f} s")
        print(f"  warm                         {warm:7.1f} s")
        print(f"  cold / warm                  {cold / warm:7.1f} x")
    print(f"load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
