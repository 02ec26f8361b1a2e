"""OMM baking speed on the issue's oak leaf: the whole ``omaps omm`` process, the in-process bake
rate, ``omaps omm --help`` and the time to the first triangle baked, in one run.

The case (issue 14): shared/data/textures/q009-vegetation__oak_oak_leaf.png (512², bilinear,
clamp, opaque iff alpha > 0.5), 100,000 random UV triangles drawn as bench_bilinear.py draws them
(centres uniform in [0.05, 0.95], corners within +-0.05: 200 texels on average, median 150),
level 4, 4-state, nearest promotion: 25.6 M micro-triangles.

meshoptimizer side by side: no package on the registries this project reaches exposes
meshoptimizer's opacity-map baker (npm ``meshoptimizer`` 1.3.0 ships the encoder, decoder,
simplifier, clusterizer and tangents only; PyPI ``meshoptimizer`` 0.2.30a0 wraps meshoptimizer
0.22, ``meshopt`` and ``almeshopt`` its codecs and optimisers). So its time is the issue's own
measured figure on this machine (0.72 s, one thread, not conservative), printed as such and not
as a side-by-side measurement.

    python bench/bench_omm_oak.py [--triangles 100000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from bench_bilinear import CUTOFF, LEAF, issue_triangles  # the oak case's triangles, one place

from omaps.alpha_test import StateRule
from omaps.bake.micromap import GROW_TEXEL, bake_micromaps, flag_table
from omaps import omm_format
from omaps.omm.pipeline import Geometry, OmmSettings, build
from omaps.omm.resolve import resolve_counted
from omaps.texture import load_alpha

ISSUE_MESHOPT_S = 0.72  # the issue's measurement of meshoptimizer's one-thread baker, whole process
ISSUE_OMAPS_S = 1.94  # the issue's measurement of omaps on the same case (before exact bilinear)
LEVEL = 4


def _child_cpu():
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


def best_run(cmd, repeat, env=None):
    """Fastest wall time of ``repeat`` runs of a command (it must succeed), and the least CPU
    time (user + system, every thread) of one run: on a shared machine the wall time depends on
    the other jobs, the CPU time much less (on an idle machine a one-thread run takes about its
    CPU time)."""
    best = cpu = np.inf
    for _ in range(repeat):
        c0 = _child_cpu()
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        dt = time.perf_counter() - t0
        if r.returncode:
            raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stdout}{r.stderr}")
        best = min(best, dt)
        cpu = min(cpu, _child_cpu() - c0)
    return best, cpu


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--triangles", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    if not LEAF.is_file():
        print(f"{LEAF} is absent: nothing to measure", file=sys.stderr)
        return 0
    tris = issue_triangles(a.triangles)
    n_micro = len(tris) * 4 ** LEVEL
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(threads)
    print(f"{LEAF.name}, {len(tris)} triangles, level {LEVEL} ({n_micro / 1e6:.1f} M micro-triangles), bilinear, "
          f"clamp, opaque iff alpha > {CUTOFF}; {threads} threads")

    # in process: the bake alone and the whole build (bake, promotion, reuse, packing)
    test = StateRule("cutoff", cutoff=CUTOFF).alpha_test(load_alpha(LEAF), "linear", "clamp")
    grid = test.grid()
    sat = flag_table(grid)
    build([Geometry("warm", test, tris[:8])], OmmSettings(level=LEVEL))  # load (or compile) the kernels
    t_bake = t_resolve = t_build = np.inf
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        states3, starts = bake_micromaps(grid, tris, LEVEL, GROW_TEXEL, sat)
        t_bake = min(t_bake, time.perf_counter() - t0)
        t0 = time.perf_counter()
        resolve_counted(states3, starts, LEVEL, test, tris, omm_format.FORMAT_4_STATE)
        t_resolve = min(t_resolve, time.perf_counter() - t0)
        t0 = time.perf_counter()
        build([Geometry("oak", test, tris)], OmmSettings(level=LEVEL))
        t_build = min(t_build, time.perf_counter() - t0)
    n_unknown = int(np.count_nonzero(states3 == 2))
    print(f"in process: bake {n_micro / t_bake / 1e6:.1f} M micro-triangles/s ({t_bake:.2f} s); 4-state resolve of "
          f"its {n_unknown / 1e6:.2f} M unknown micro-triangles {t_resolve:.2f} s; whole build "
          f"{n_micro / t_build / 1e6:.1f} M/s ({t_build:.2f} s)")

    # whole processes (warm numba cache: one run first)
    with tempfile.TemporaryDirectory() as d:
        uvs = Path(d) / "uvs.npy"
        one = Path(d) / "one.npy"
        np.save(uvs, tris)
        np.save(one, tris[:1])
        omm = [sys.executable, "-m", "omaps", "omm"]
        args = ["--level", str(LEVEL), "--filter", "linear", "--wrap", "clamp", "--cutoff", str(CUTOFF), "--quiet"]
        env = dict(os.environ, OMAPS_PROGRESS="0")
        best_run(omm + [str(LEAF), str(one), "-o", str(Path(d) / "o1")] + args, 1, env)
        t_whole, c_whole = best_run(omm + [str(LEAF), str(uvs), "-o", str(Path(d) / "o")] + args, a.repeat, env)
        t_first, c_first = best_run(omm + [str(LEAF), str(one), "-o", str(Path(d) / "o1")] + args, a.repeat, env)
        t_help, _ = best_run(omm + ["--help"], a.repeat, env)
        t_python, _ = best_run([sys.executable, "-c", "pass"], a.repeat, env)
        imp = subprocess.run([sys.executable, "-X", "importtime", "-m", "omaps", "omm", "--help"], capture_output=True,
                             text=True, env=env)
        help_numba = any(line.split("|")[-1].strip() == "numba" for line in imp.stderr.splitlines())

    load = os.getloadavg()[0]
    print(f"\nwhole process `omaps omm OAK UVS --level {LEVEL}`: {t_whole:.2f} s "
          f"({n_micro / t_whole / 1e6:.1f} M micro-triangles/s end to end); {c_whole:.2f} CPU-s "
          f"(load average {load:.1f} on {os.cpu_count()} cores)")
    print(f"  meshoptimizer's one-thread baker: {ISSUE_MESHOPT_S:.2f} s -- the issue's figure, NOT measured here "
          "(no registry package exposes its opacity-map baker)")
    print(f"  omaps / meshoptimizer (issue figure): {t_whole / ISSUE_MESHOPT_S:.2f}x the time; omaps at issue time: "
          f"{ISSUE_OMAPS_S:.2f} s (issue figure)")
    print(f"start to first triangle baked (whole process on 1 triangle, output written): {t_first:.2f} s, "
          f"{c_first:.2f} CPU-s (bare python start {t_python:.2f} s)")
    print(f"`omaps omm --help`: {t_help:.2f} s; imports numba: {'yes' if help_numba else 'no'}")
    goals = [("whole process <= meshoptimizer's 0.72 s (issue figure)", t_whole <= ISSUE_MESHOPT_S),
             ("--help <= 0.3 s", t_help <= 0.3), ("--help without numba", not help_numba),
             ("first triangle <= 0.5 s", t_first <= 0.5),
             ("first triangle <= 0.5 CPU-s (about its time on an idle machine)", c_first <= 0.5)]
    print("goals: " + "; ".join(f"{name}: {'met' if ok else 'MISSED'}" for name, ok in goals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
