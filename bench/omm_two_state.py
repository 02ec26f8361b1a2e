"""2-state OMMs from three states: per-pixel coverage error of each C promotion against the
alpha-tested reference image.

Every texture covers the corpus pair (two triangles, omaps.pair). The reference image is the
alpha test itself (cutoff 0.5, the chosen filter, clamp) at a 1024 x 1024 grid of sample points
over the square; a 2-state OMM instead says opaque where the micro-triangle holding the point is
opaque. Per pixel (a block of samples), coverage = the opaque share of its samples; the error is
|OMM coverage - reference coverage|. Pixel sizes are set against the micro-triangles: ``close``
(each cell of 2 micro-triangles spans 4 x 4 pixels), ``matched`` (1 pixel per cell) and ``far``
(4 x 4 cells per pixel), as a surface seen nearer or further away. Promotions: nearest (majority),
opaque, transparent, hashed (omaps.promotion). Means over textures, then over pixels.

    python bench/omm_two_state.py [--levels 3,5] [--filter linear]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from numba import njit, prange

from omaps import birdcurve, pair
from omaps.alpha_test import StateRule, sample_passes
from omaps.bake import bake_micromaps
from omaps import omm_format
from omaps.omm import resolve
from omaps.promotion import PROMOTIONS
from omaps.texture import load_alpha

ROOT = Path(__file__).resolve().parents[1]
TEXTURES = ROOT.parent / "shared" / "data" / "textures"
GRID = 1024  # sample points per side of the pair's square


@njit(cache=True, parallel=True)
def _sample(value, thr, inclusive, filt, mu, mv, w, h, level, n, ref, micro):
    """Reference alpha test and (triangle, micro-triangle) of every sample point."""
    for j in prange(n):
        for i in range(n):
            u = (i + 0.5) / n
            v = (j + 0.5) / n
            ref[j, i] = sample_passes(value, thr, inclusive, filt, mu, mv, u * w, v * h)
            t, b1, b2 = pair.uv_to_hit(u, v)
            micro[j, i] = t * (1 << (2 * level)) + birdcurve.bary_to_index(b1, b2, level)


def _coverage(samples: np.ndarray, px: int) -> np.ndarray:
    b = samples.shape[0] // px
    return samples.reshape(px, b, px, b).mean(axis=(1, 3))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", default="3,5")
    ap.add_argument("--filter", default="linear", choices=["nearest", "linear"])
    ap.add_argument("--cutoff", type=float, default=0.5)
    a = ap.parse_args()
    if TEXTURES.is_dir():
        texs = [t for t in (load_alpha(p) for p in sorted(TEXTURES.glob("*.png"))) if min(t.width, t.height) >= 64]
        label = "shared corpus"
    else:
        from omaps.corpus import default_corpus

        texs, label = default_corpus(), "procedural corpus"
    levels = [int(x) for x in a.levels.split(",")]
    print(f"{len(texs)} textures ({label}), cutoff {a.cutoff}, {a.filter}, clamp; {GRID}² samples over the pair")
    for level in levels:
        n_cells = 1 << level
        views = {"close": 4 * n_cells, "matched": n_cells, "far": max(n_cells // 4, 1)}
        err = {m: {v: [] for v in views} for m in PROMOTIONS}
        bias = {m: {v: [] for v in views} for m in PROMOTIONS}
        sample_err = {m: [] for m in PROMOTIONS}
        c_frac = []
        for tex in texs:
            test = StateRule("cutoff", cutoff=a.cutoff).alpha_test(tex, a.filter, "clamp")
            s3, starts = bake_micromaps(test.grid(), pair.PAIR, level)
            c_frac.append(np.mean(s3 == 2))
            ref = np.empty((GRID, GRID), dtype=np.bool_)
            micro = np.empty((GRID, GRID), dtype=np.int64)
            filt, mu, mv = test.codes()
            _sample(test.value, test.threshold, test.inclusive, filt, mu, mv, float(tex.width), float(tex.height),
                    level, GRID, ref, micro)
            ref_f = ref.astype(np.float64)
            for m in PROMOTIONS:
                omm = resolve.resolve(s3, starts, level, test, pair.PAIR, omm_format.FORMAT_2_STATE, m)
                got = omm[micro].astype(np.float64)
                sample_err[m].append(np.mean(got != ref_f))
                for v, px in views.items():
                    d = _coverage(got, px) - _coverage(ref_f, px)
                    err[m][v].append(np.mean(np.abs(d)))
                    bias[m][v].append(np.mean(d))
        print(f"\nlevel {level} ({2 * 4 ** level} micro-triangles per pair; {np.mean(c_frac):.1%} of them C on average)")
        print(f"{'promotion':12} {'wrong samples':>13}  " + "  ".join(f"{v + f' ({px}²)':>22}" for v, px in views.items()))
        print(f"{'':12} {'':>13}  " + "  ".join(f"{'|error|':>11}{'bias':>11}" for _ in views))
        for m in PROMOTIONS:
            cells = "  ".join(f"{np.mean(err[m][v]):11.4f}{np.mean(bias[m][v]):+11.4f}" for v in views)
            print(f"{m:12} {np.mean(sample_err[m]):13.4f}  {cells}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
