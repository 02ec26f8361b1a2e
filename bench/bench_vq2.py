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
from omaps.codecs import get_codec, vq2_block, vq2_encode

DEFAULT = get_codec("vq2").default_effort
GOAL_RATE = 20000  # issue 14: the default encoder per core, at no less than medium's savings


def main():
    m = tile_maps(16)
    print(f"{len(m)} non-uniform 16x16 maps from 64x64 tiles; one core")
    sq = np.mean([known_fraction(a) for a in m])
    rate, saved = {}, {}
    for enc, eff in [("paper", "medium"), ("best", "fast"), ("best", "medium"), ("best", "thorough")]:
        vq2_encode.encode_many(m[:4], enc, eff)  # compile / load cache
        t0 = time.perf_counter()
        blocks = vq2_encode.encode_many(m, enc, eff)
        dt = time.perf_counter() - t0
        dec = [b.decode() for b in blocks]
        assert all(states.is_conservative(a, d) for a, d in zip(m, dec))
        sav = np.mean([known_fraction(d) for d in dec])
        rate[enc, eff], saved[enc, eff] = len(m) / dt, sav
        print(f"  {enc:5} {eff:8} {len(m) / dt:9.0f} blocks/s   savings {sav:.4f} = {sav / sq:.4f} x sq16")
    d = ("best", DEFAULT)
    gap = saved[d] - saved["best", "medium"]
    print(f"  goal: default ({DEFAULT}) {rate[d]:.0f} blocks/s (>= {GOAL_RATE}: "
          f"{'met' if rate[d] >= GOAL_RATE else 'missed'}); savings {gap:+.4f} against medium "
          f"(>= 0: {'met' if gap >= 0 else 'missed'}), fast {rate['best', 'fast']:.0f} blocks/s at "
          f"{saved['best', 'fast'] - saved['best', 'medium']:+.4f}")
    blocks = np.stack([np.frombuffer(b.pack(), np.uint8) for b in vq2_encode.encode_many(m, "best", "fast")])
    rates = lookup_rates(16, [("raw 2-bit", raw_lookup_batch, pack_raw(m)), ("vq2", vq2_block.lookup_batch, blocks)])
    print(f"  vq2 / raw lookup rate: {rates['vq2'] / rates['raw 2-bit']:.2f}")


if __name__ == "__main__":
    main()
