"""OMM baking speed: micro-triangles per second at levels 3-6 for 10,000 random triangles of
about 128 texels each on a 1024 x 1024 texture, the fast baker (1 and 2 threads) against
``maps.bake_triangles`` (the per-region raster, one thread) side by side, with the states
checked identical on the reference's subset.

Textures: a real 1024² leaf mask from ../shared when present (else the procedural leaves drawn at
1024²), and white noise (half the texels opaque: the worst case, nothing uniform to skip).
Alpha test: cutoff 0.5, bilinear, wrap (what engines use for foliage).

    python bench/bench_omm.py [--triangles 10000] [--reference 300]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numba
import numpy as np

from omaps import birdcurve, raster
from omaps.alpha_test import StateRule
from omaps.bake import micromap as bake
from omaps.omm.pipeline import Geometry, OmmSettings, build
from omaps.texture import AlphaTexture, load_alpha

ROOT = Path(__file__).resolve().parents[1]
LEAVES = ROOT.parent / "shared" / "data" / "textures" / "proton-scatter__t_leaves_1.png"
SIZE = 1024


def textures():
    if LEAVES.is_file():
        leaves = load_alpha(LEAVES)
    else:
        from omaps.corpus.procedural import leaves as draw_leaves

        leaves = draw_leaves(np.random.default_rng(1), SIZE, SIZE)
    noise = AlphaTexture("noise", (np.random.default_rng(2).random((SIZE, SIZE)) < 0.5).astype(np.uint8) * 255, 255)
    return [leaves, noise]


def random_triangles(n, texels=128.0, seed=0):
    """Random shapes (no slivers below 1/8 of the best aspect), each scaled to an area drawn
    uniformly from [0.75, 1.25] x ``texels`` texels, at random places."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, 3, 2))
    k = 0
    while k < n:
        t = rng.normal(size=(3, 2))
        e1, e2 = t[1] - t[0], t[2] - t[0]
        area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
        per = sum(np.hypot(*(t[i] - t[(i + 1) % 3])) for i in range(3))
        if area / per ** 2 < np.sqrt(3) / 36 / 8:
            continue
        t = (t - t.mean(axis=0)) * np.sqrt(texels * rng.uniform(0.75, 1.25) / area)
        out[k] = (t + rng.uniform(0, SIZE, size=2)) / SIZE
        k += 1
    return out


def best_time(fn, repeat=5, min_total=0.5):
    """Fastest of at least ``repeat`` runs, running on until ``min_total`` seconds have passed
    (short runs on a shared machine are noisy)."""
    best = np.inf
    start = time.perf_counter()
    k = 0
    while k < repeat or time.perf_counter() - start < min_total:
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        k += 1
    return best


def per_region_raster(grid, tris_uv, level):
    """The straightforward baker the tree walk is measured against: every micro-triangle
    rasterised on its own by ``raster.region_states`` (one thread)."""
    micro = np.stack([birdcurve.uv_micro_triangles(t, level) for t in tris_uv])
    texel = micro.reshape(-1, 3, 2) * np.array([grid.width, grid.height], dtype=np.float64)
    return raster.region_states(grid, texel).reshape(len(tris_uv), -1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--triangles", type=int, default=10000)
    ap.add_argument("--reference", type=int, default=300, help="triangles the reference bakes per level")
    a = ap.parse_args()
    tris = random_triangles(a.triangles)
    t = tris * SIZE
    area = 0.5 * np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
                        - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0]))
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    print(f"{a.triangles} triangles, mean texel area {area.mean():.1f}, {SIZE}² texture, cutoff 0.5, linear, wrap; "
          f"reference on {a.reference} of them; {numba.config.NUMBA_NUM_THREADS} cores available")
    ok = True
    for tex in textures():
        test = StateRule("cutoff", cutoff=0.5).alpha_test(tex, "linear", "wrap")
        grid = test.grid()
        sat = bake.flag_table(grid)
        bake.bake_micromaps(grid, tris[:4], 3, 0.0, sat)  # compile or load the cache
        per_region_raster(grid, tris[:2], 1)
        print(f"\n{tex.name}: {np.mean(test.texel_states() == 1):.1%} of texels opaque")
        print(f"{'level':>5} {'M micro/s 1 thr':>16} {f'{threads} thr':>8} {'reference M/s':>14} "
              f"{'1 thr / ref':>11} {'T':>6} {'O':>6} {'C':>6} identical")
        sub = tris[:a.reference]
        for level in (3, 4, 5, 6):
            n_micro = len(tris) * 4 ** level
            rates = []
            for th in (1, threads):
                numba.set_num_threads(th)
                rates.append(n_micro / best_time(lambda: bake.bake_micromaps(grid, tris, level, 0.0, sat)) / 1e6)
            s, _ = bake.bake_micromaps(grid, tris, level, 0.0, sat)
            frac = np.bincount(s, minlength=3) / len(s)
            t_ref = best_time(lambda: per_region_raster(grid, sub, level), repeat=1, min_total=0)
            ref_rate = len(sub) * 4 ** level / t_ref / 1e6
            same = np.array_equal(per_region_raster(grid, sub, level), bake.bake_micromap_rows(grid, sub, level))
            ok &= same
            print(f"{level:5d} {rates[0]:16.1f} {rates[1]:8.1f} {ref_rate:14.2f} {rates[0] / ref_rate:10.0f}x "
                  f"{frac[0]:6.3f} {frac[1]:6.3f} {frac[2]:6.3f} {'yes' if same else 'NO'}")
        # the whole pipeline: bake, promotion (nearest: sampled opaque fractions), special indices, reuse, packing
        numba.set_num_threads(threads)
        geo = [Geometry(tex.name, test, tris)]
        build([Geometry(tex.name, test, tris[:10])], OmmSettings(level=4))
        dt = best_time(lambda: build(geo, OmmSettings(level=4)), repeat=1, min_total=0)
        print(f"      omm build, level 4, {threads} threads (bake + nearest promotion + reuse + packing): "
              f"{len(tris) * 4 ** 4 / dt / 1e6:.1f} M micro-triangles/s")
    if not ok:
        print("STATES DIFFER from the per-region raster", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
