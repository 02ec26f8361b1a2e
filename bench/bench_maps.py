"""Baking speed: omaps' kernels against the brute-force reference, measured side by side.

Prints maps/s and regions/s for sq32 and tri5 with both, and the ratio. Uses the real textures
in ../shared when present (the 46 of at least 64 px), else the embedded procedural corpus; the
reference is slow, so it runs on a subset and its rate is per map.

    python bench/bench_maps.py [--reference-maps 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import reference as ref  # noqa: E402

from omaps import bake as maps  # noqa: E402 (the corpus pair bakers)
from omaps.corpus import EvalConfig, evaluate_many  # noqa: E402
from omaps.pair import PAIR  # noqa: E402
from omaps.corpus import default_corpus  # noqa: E402
from omaps.sampling import footprint_grid  # noqa: E402
from omaps.schemes import DEFAULT_SCHEMES, parse_schemes  # noqa: E402
from omaps.alpha_test import StateRule  # noqa: E402
from omaps.texture import load_alpha  # noqa: E402

TEXTURES = ROOT.parent / "shared" / "data" / "textures"


def corpus():
    if TEXTURES.is_dir():
        paths = sorted(TEXTURES.glob("*.png"))
        texs = [load_alpha(p) for p in paths]
        return [t for t in texs if min(t.width, t.height) >= 64], "shared corpus"
    return default_corpus(), "procedural corpus"


def timed(fn, repeat=1):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--reference-maps", type=int, default=3, help="textures the reference bakes per scheme")
    a = ap.parse_args()
    texs, label = corpus()
    rule = StateRule()
    imgs = [rule.classify(t) for t in texs]
    grids = [footprint_grid(s) for s in imgs]
    maps.bake_square(grids[0], 32)  # JIT warm-up (or cache load)
    maps.bake_pair_triangles(grids[0], 5)
    # pick reference textures of median size, so the ratio is not driven by one huge texture
    order = np.argsort([s.size for s in imgs])
    mid = order[len(order) // 2 - a.reference_maps // 2:][:a.reference_maps]
    print(f"{len(texs)} textures ({label}); reference on {len(mid)} of them "
          f"({', '.join(texs[i].name[:28] for i in mid)})")
    print(f"{'scheme':8} {'omaps maps/s':>13} {'regions/s':>12} {'ref maps/s':>11} {'regions/s':>11} {'speed-up':>9}")
    for name, bake_fast, bake_ref, regions in [
        ("sq32", lambda g: maps.bake_square(g, 32), lambda s: ref.square_map(s, 32), 32 * 32),
        ("tri5", lambda g: maps.bake_pair_triangles(g, 5),
         lambda s: [ref.triangle_states(s, t, 5) for t in PAIR], 2 * 4 ** 5),
    ]:
        # same textures for both sides, then the whole corpus for the fast one
        t_fast_sub, _ = timed(lambda: [bake_fast(grids[i]) for i in mid], repeat=3)
        t_ref_sub, _ = timed(lambda: [bake_ref(imgs[i]) for i in mid])
        t_fast_all, _ = timed(lambda: [bake_fast(g) for g in grids], repeat=3)
        n = len(mid)
        print(f"{name:8} {len(grids) / t_fast_all:13.0f} {len(grids) * regions / t_fast_all:12.3g} "
              f"{n / t_ref_sub:11.2f} {n * regions / t_ref_sub:11.3g} {t_ref_sub / t_fast_sub:8.0f}x")
    # the target: all textures, all ten schemes, after warm-up, on 2 cores
    items = [str(p) for p in sorted(TEXTURES.glob("*.png"))] if TEXTURES.is_dir() else texs
    schemes = parse_schemes(DEFAULT_SCHEMES)
    evaluate_many(items[:2], schemes, EvalConfig(), jobs=1, progress=False)
    for jobs in (1, 2):
        t, (res, _) = timed(lambda: evaluate_many(items, schemes, EvalConfig(), jobs=jobs, min_size=64,
                                                   progress=False))
        print(f"omaps eval, {len(res)} textures x {len(schemes)} schemes incl. loading, jobs={jobs}: {t:.2f} s")


if __name__ == "__main__":
    main()
