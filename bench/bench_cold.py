"""First use: a command's time with an empty numba cache against the same command warm, in one run.

    python bench/bench_cold.py [SCENE] [--skip-install]

Runs ``omaps trace SCENE --schemes none,vq4 --size 128 --quiet`` (default SCENE: palm.glb from
../shared) as a process:

1. cold: with an empty private numba cache (NUMBA_CACHE_DIR; the shared cache is never touched);
2. warm: again, with the cache step 1 filled;
3. after install: with another empty cache, first the README's first command's ``omaps eval``
   (the embedded corpus, which compiles every command's kernels ahead, beside the evaluation),
   then the trace command: what a user's first real command costs after the README's two commands.

Prints each time and the ratios to the warm time. Timings depend on the machine's load: the
ratios are measured side by side in one run.
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


def run(argv, cache: str) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, OMAPS_PROGRESS="0")
    t0 = time.perf_counter()
    r = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"bench_cold: {' '.join(map(str, argv))} exited {r.returncode}:\n{r.stderr}")
    return dt


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
    print(f"omaps {' '.join(cmd[3:])}, {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory(prefix="omaps-cold-") as tmp:
        cold = run(cmd, f"{tmp}/a")
        warm = run(cmd, f"{tmp}/a")
        print(f"  empty cache (cold)           {cold:7.1f} s")
        print(f"  warm                         {warm:7.1f} s")
        print(f"  cold / warm                  {cold / warm:7.1f} x")
        if not a.skip_install:
            install = run(omaps + ["eval", "--quiet"], f"{tmp}/b")
            first = run(cmd, f"{tmp}/b")
            print(f"  omaps eval, empty cache      {install:7.1f} s  (the README's first command after pip: "
                  "its evaluation and every command's kernels compiled ahead)")
            print(f"  then this command (first)    {first:7.1f} s")
            print(f"  first / warm                 {first / warm:7.1f} x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
