"""Tracer speed: rays/s of every scheme against an opaque-only traversal of the same scene, in one run.

Prepares the scene once (pair, bake, encode, Embree BVH), then traces each scheme's primary and
shadow rays ``--repeat`` times round-robin (so load on the machine hits every scheme alike) and
reports the median. "opaque" traces the same BVH with no filter at all: every alpha-tested
triangle is taken as opaque (a wrong picture, the speed limit of the traversal). The ratio
scheme / opaque is the cost of the any-hit path with that scheme's maps.

    python bench/bench_trace.py [--scene ../shared/data/scenes/forest.glb] [--size 512] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from omaps import trace
from omaps.scene import load_scene
from omaps.schemes import TRACE_KINDS, parse_schemes
from omaps.trace.maps import default_jobs

DEFAULT_SCHEMES = "none,tri3,sq16,vq2,vq4,vq4x64"

SCENES = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(SCENES / "forest.glb"))
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--schemes", default=None)
    a = p.parse_args()
    if not Path(a.scene).is_file():
        print(f"bench_trace: {a.scene} not found (../shared is absent): nothing to measure")
        return
    schemes = parse_schemes("none," + (a.schemes or DEFAULT_SCHEMES), TRACE_KINDS)
    names = [s.name for s in schemes]
    scene = load_scene(a.scene)
    t0 = time.perf_counter()
    prep = trace.prepare(scene, schemes, jobs=default_jobs(None))
    t_prep = time.perf_counter() - t0
    w = h = a.size
    bounds = scene.bounds()
    cam = trace.choose_default_camera(prep, w, h)[0].basis(w, h)  # omaps trace's default view
    light = trace.light_direction()
    tnear = trace.SHADOW_TNEAR * float(np.linalg.norm(bounds[1] - bounds[0]))
    runs = {n: [] for n in ["opaque"] + names}
    for n in runs:  # warm-up: compile filters and loops
        trace.trace_scheme(prep, None if n == "opaque" else n, cam, 8, 8, light, tnear)
    for _ in range(a.repeat):
        for n in runs:
            r = trace.trace_scheme(prep, None if n == "opaque" else n, cam, w, h, light, tnear)
            runs[n].append(r)
    print(f"bench_trace: {Path(a.scene).name}, {w}x{h} primary rays + shadow rays from their hits, "
          f"median of {a.repeat} (prepare {t_prep:.1f} s, Embree {prep.device.version_text})")
    print(f"{'scheme':8} {'tests/ray':>9} {'primary Mrays/s':>15} {'shadow Mrays/s':>14} {'all Mrays/s':>11} "
          f"{'x opaque':>8}")
    base = None
    for n, rs in runs.items():
        prim = np.median([r.primary.seconds for r in rs])
        shad = np.median([r.shadow.seconds for r in rs])
        n_shadow = rs[0].shadow.rays
        rate = (w * h + n_shadow) / (prim + shad)
        base = rate if base is None else base
        tests = (rs[0].primary.tests.sum() + rs[0].shadow.tests.sum()) / (w * h + n_shadow)
        print(f"{n:8} {tests:9.3f} {w * h / prim / 1e6:15.2f} {n_shadow / shad / 1e6:14.2f} {rate / 1e6:11.2f} "
              f"{rate / base:8.2f}")


if __name__ == "__main__":
    main()
