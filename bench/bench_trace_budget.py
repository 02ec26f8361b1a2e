"""A ``budget:BYTES`` scheme's maps with the run's cache (the pair squares and encoded maps of its
uniform schemes, ``Prepared.cache``) against the same maps built alone, side by side in one run.

    python bench/bench_trace_budget.py [--scene ../shared/data/scenes/palm.glb] [--schemes ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from omaps.budget import triangle_weights
from omaps.scene import load_scene
from omaps.schemes import parse_schemes
from omaps.trace import prepare
from omaps.trace.budget import budget_maps
from omaps.trace.maps import default_jobs

SCENES = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(SCENES / "palm.glb"))
    p.add_argument("--schemes", default="none,sq16,vq2,vq4,vq4x64,budget:120KiB")
    a = p.parse_args()
    if not Path(a.scene).exists():
        sys.exit(f"bench_trace_budget: {a.scene} is absent (the shared data set)")
    scene = load_scene(a.scene)
    schemes = parse_schemes(a.schemes)
    budget = next(s for s in schemes if s.kind == "budget")
    jobs = default_jobs(None)
    t = time.perf_counter()
    prep = prepare(scene, schemes, jobs=jobs)
    print(f"prepare (uniform schemes baked and encoded): {time.perf_counter() - t:.1f} s")
    w = triangle_weights(scene, prep.alpha)
    t = time.perf_counter()
    shared = budget_maps(prep.alpha, prep.tests, budget, w, jobs, cache=prep.cache)
    t_shared = time.perf_counter() - t
    t = time.perf_counter()
    alone = budget_maps(prep.alpha, prep.tests, budget, w, jobs)
    t_alone = time.perf_counter() - t
    same = np.array_equal(shared.data, alone.data) and np.array_equal(shared.rows, alone.rows)
    print(f"{budget.name}: with the run's cache {t_shared:.1f} s, alone {t_alone:.1f} s: "
          f"{t_alone / max(t_shared, 1e-9):.1f}x faster; the same maps: {same}")


if __name__ == "__main__":
    main()
