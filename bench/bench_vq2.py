"""VQ2 speed: blocks/s per encoder, and random-access lookups against a raw 2-bit map, side by side.

Maps: the sq16 map of every 64x64-texel tile of the shared textures (or of the procedural
corpus when ../shared is absent), so the encoders see thousands of real blocks.

    python bench/bench_vq2.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from numba import njit

from omaps import maps, states
from omaps.codecs import vq2_block, vq2_encode
from omaps.procedural import default_corpus
from omaps.sampling import footprint_grid
from omaps.texel_states import StateRule
from omaps.texture import load_alpha

TEXTURES = Path(__file__).resolve().parents[2] / "shared" / "data" / "textures"


def tile_maps(tile=64):
    texs = [load_alpha(p) for p in sorted(TEXTURES.glob("*.png"))] if TEXTURES.is_dir() else default_corpus()
    out = []
    rule = StateRule()
    for t in texs:
        s = rule.classify(t)
        for y in range(0, t.height - tile + 1, tile):
            for x in range(0, t.width - tile + 1, tile):
                out.append(maps.bake_square(footprint_grid(s[y:y + tile, x:x + tile]), 16))
    m = np.stack(out)
    # drop all-T / all-O tiles: trivial blocks would flatter the rate
    keep = np.array([len(np.unique(a)) > 1 for a in m])
    return m[keep]


@njit(cache=True)
def raw_lookup_batch(raw, block_ids, xs, ys):
    """The uncompressed baseline: 2 bits per cell, cell i at bits 2(i mod 4) of byte i div 4."""
    out = np.empty(xs.shape[0], dtype=np.uint8)
    for i in range(xs.shape[0]):
        c = ys[i] * 16 + xs[i]
        out[i] = (raw[block_ids[i], c >> 2] >> ((c & 3) * 2)) & 3
    return out


def pack_raw(m):
    flat = m.reshape(len(m), -1).astype(np.uint8)
    q = flat.reshape(len(m), -1, 4)
    return (q[..., 0] | (q[..., 1] << 2) | (q[..., 2] << 4) | (q[..., 3] << 6)).astype(np.uint8)


def main():
    m = tile_maps()
    print(f"{len(m)} non-uniform 16x16 maps from 64x64 tiles; one core")
    sq = np.mean([maps.known_fraction(a) for a in m])
    for enc, eff in [("paper", "medium"), ("best", "fast"), ("best", "medium"), ("best", "thorough")]:
        vq2_encode.encode_many(m[:4], enc, eff)  # compile / load cache
        t0 = time.perf_counter()
        blocks = vq2_encode.encode_many(m, enc, eff)
        dt = time.perf_counter() - t0
        dec = [b.decode() for b in blocks]
        assert all(states.is_conservative(a, d) for a, d in zip(m, dec))
        sav = np.mean([maps.known_fraction(d) for d in dec])
        print(f"  {enc:5} {eff:8} {len(m) / dt:9.0f} blocks/s   savings {sav:.4f} = {sav / sq:.4f} x sq16")
    blocks = np.stack([np.frombuffer(b.pack(), np.uint8) for b in vq2_encode.encode_many(m, "best", "fast")])
    raw = pack_raw(m)
    rng = np.random.default_rng(0)
    n = 2_000_000
    ids = rng.integers(0, len(m), n)
    xs, ys = rng.integers(0, 16, n), rng.integers(0, 16, n)
    vq2_block.lookup_batch(blocks, ids[:10], xs[:10], ys[:10])
    raw_lookup_batch(raw, ids[:10], xs[:10], ys[:10])
    rates = {}
    for name, fn, data in [("raw 2-bit", raw_lookup_batch, raw), ("vq2", vq2_block.lookup_batch, blocks)]:
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            fn(data, ids, xs, ys)
            best = min(best, time.perf_counter() - t0)
        rates[name] = n / best
        print(f"  lookup {name:9} {rates[name] / 1e6:7.1f} M lookups/s")
    print(f"  vq2 / raw lookup rate: {rates['vq2'] / rates['raw 2-bit']:.2f}")


if __name__ == "__main__":
    main()
