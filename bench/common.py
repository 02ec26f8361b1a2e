"""What the codec benchmarks share: real tile maps, and the raw 2-bit lookup they race against."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from numba import njit

from omaps.alpha_test import StateRule
from omaps.bake import bake_square
from omaps.corpus import default_corpus
from omaps.sampling import footprint_grid
from omaps.texture import load_alpha

TEXTURES = Path(__file__).resolve().parents[2] / "shared" / "data" / "textures"


def tile_maps(size, tile=64):
    """The size x size map of every tile x tile texel tile of the shared textures (or of the
    procedural corpus when ../shared is absent), without all-T / all-O maps (trivial blocks
    would flatter the rate)."""
    texs = [load_alpha(p) for p in sorted(TEXTURES.glob("*.png"))] if TEXTURES.is_dir() else default_corpus()
    out = []
    rule = StateRule()
    for t in texs:
        s = rule.classify(t)
        for y in range(0, t.height - tile + 1, tile):
            for x in range(0, t.width - tile + 1, tile):
                out.append(bake_square(footprint_grid(s[y:y + tile, x:x + tile]), size))
    m = np.stack(out)
    keep = np.array([len(np.unique(a)) > 1 for a in m])
    return m[keep]


@njit(cache=True)
def raw_lookup_batch(raw, block_ids, xs, ys):
    """The uncompressed baseline: 2 bits per cell, cell i = y * size + x at bits 2(i mod 4) of
    byte i div 4 (size from the row length)."""
    size = int(np.sqrt(raw.shape[1] * 4))
    out = np.empty(xs.shape[0], dtype=np.uint8)
    for i in range(xs.shape[0]):
        c = ys[i] * size + xs[i]
        out[i] = (raw[block_ids[i], c >> 2] >> ((c & 3) * 2)) & 3
    return out


def pack_raw(m):
    flat = m.reshape(len(m), -1).astype(np.uint8)
    q = flat.reshape(len(m), -1, 4)
    return (q[..., 0] | (q[..., 1] << 2) | (q[..., 2] << 4) | (q[..., 3] << 6)).astype(np.uint8)


def lookup_rates(size, contenders, n=2_000_000, repeats=7):
    """Lookups/s of each (name, batch function, data) on the same random cells; data rows are
    maps. The contenders take turns, and each keeps its best of ``repeats`` runs, so that load
    from other work on the machine hits them alike."""
    rng = np.random.default_rng(0)
    n_maps = len(contenders[0][2])
    ids = rng.integers(0, n_maps, n)
    xs, ys = rng.integers(0, size, n), rng.integers(0, size, n)
    best = {name: np.inf for name, _, _ in contenders}
    for name, fn, data in contenders:
        fn(data, ids[:10], xs[:10], ys[:10])  # compile / load cache
    for _ in range(repeats):
        for name, fn, data in contenders:
            t0 = time.perf_counter()
            fn(data, ids, xs, ys)
            best[name] = min(best[name], time.perf_counter() - t0)
    rates = {name: n / t for name, t in best.items()}
    for name, r in rates.items():
        print(f"  lookup {name:9} {r / 1e6:7.1f} M lookups/s")
    return rates
