"""VQ2 speed: blocks/s per encoder, and random-access lookups against a raw 2-bit map, side by side.

Maps: the sq16 map of every 64x64-texel tile of the shared textures (or of the procedural
corpus when ../shared is absent), so the encoders see thousands of real blocks.

    python bench/bench_vq2.py
"""

from __future__ import annotations

import time

import numpy as np
from common import lookup_rates, pack_raw, raw_lookup_batch, tile_maps

from omaps import states
from omaps.bake import known_fraction
from omaps.codecs import vq2_block, vq2_encode


def main():
    m = tile_maps(16)
    print(f"{len(m)} non-uniform 16x16 maps from 64x64 tiles; one core")
    sq = np.mean([known_fraction(a) for a in m])
    for enc, eff in [("paper", "medium"), ("best", "fast"), ("best", "medium"), ("best", "thorough")]:
        vq2_encode.encode_many(m[:4], enc, eff)  # compile / load cache
        t0 = time.perf_counter()
        blocks = vq2_encode.encode_many(m, enc, eff)
        dt = time.perf_counter() - t0
        dec = [b.decode() for b in blocks]
        assert all(states.is_conservative(a, d) for a, d in zip(m, dec))
        sav = np.mean([known_fraction(d) for d in dec])
        print(f"  {enc:5} {eff:8} {len(m) / dt:9.0f} blocks/s   savings {sav:.4f} = {sav / sq:.4f} x sq16")
    blocks = np.stack([np.frombuffer(b.pack(), np.uint8) for b in vq2_encode.encode_many(m, "best", "fast")])
    rates = lookup_rates(16, [("raw 2-bit", raw_lookup_batch, pack_raw(m)), ("vq2", vq2_block.lookup_batch, blocks)])
    print(f"  vq2 / raw lookup rate: {rates['vq2'] / rates['raw 2-bit']:.2f}")


if __name__ == "__main__":
    main()
