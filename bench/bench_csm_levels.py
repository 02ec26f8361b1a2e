"""Merged-subtree micromaps (``csmL``) of the shared forest at fine levels, baked straight into
the DAG (``trace.maps.merged_subtree_maps``): seconds, peak memory (each level in a process of its
own), runs, distinct nodes and bytes per level, and the time ratio of each level to the one two
below (a tree bake grows with the mixed nodes, about 2x a level; the states 4x).

    python bench/bench_csm_levels.py                # levels 6, 8, 10
    python bench/bench_csm_levels.py --levels 6,8,10,12
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "scenes",
                     "forest.glb")

CHILD = r"""
import json, sys, time
from omaps.scene import load_scene
from omaps import trace
from omaps.schemes import parse_schemes
from omaps.trace.maps import merged_subtree_maps
scene = load_scene(sys.argv[1])
prep = trace.prepare(scene, parse_schemes(["none"]))
s = parse_schemes([f"csm{sys.argv[2]}"])[0]
t = time.perf_counter()
m = merged_subtree_maps(prep.alpha, prep.tests, s)
print(json.dumps({"seconds": time.perf_counter() - t, "bytes": m.map_bytes, "nodes": m.info["csm_nodes"],
                  "distinct": m.distinct_maps, "triangles": int(len(m.rows))}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="6,8,10")
    a = ap.parse_args()
    if not os.path.isfile(SCENE):
        print(f"{SCENE} is absent: nothing to measure", file=sys.stderr)
        return 0
    # compile once first, so no level pays numba's compile
    subprocess.run([sys.executable, "-c", CHILD, SCENE, "2"], check=True, capture_output=True)
    rows = []
    for level in [int(v) for v in a.levels.split(",")]:
        t0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-c", CHILD, SCENE, str(level)], stdout=subprocess.PIPE, text=True)
        out = p.stdout.read()
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode:
            print(f"level {level}: exit {p.returncode}", file=sys.stderr)
            return 1
        r = json.loads(out)
        r.update(level=level, peak_mb=usage.ru_maxrss / 1024, wall=time.perf_counter() - t0)
        rows.append(r)
    print(f"forest.glb: {rows[0]['triangles']:,} alpha triangles; csmL baked into its DAG (load and pairing not "
          "counted in 'bake s'; peak of the whole process)")
    print(f"{'level':>5} {'bake s':>8} {'x two below':>11} {'peak MB':>8} {'nodes':>10} {'KiB':>9}")
    for i, r in enumerate(rows):
        prev = next((q for q in rows[:i] if q["level"] == r["level"] - 2), None)
        ratio = f"{r['seconds'] / prev['seconds']:.2f}" if prev else "-"
        print(f"{r['level']:>5} {r['seconds']:>8.1f} {ratio:>11} {r['peak_mb']:>8.0f} {r['nodes']:>10,} "
              f"{r['bytes'] / 1024:>9,.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
