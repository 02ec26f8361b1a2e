"""VQ2 speed: blocks/s per encoder, and random-access lookups against a raw 2-bit map, side by side.

Maps: the sq16 map of every 64x64-texel tile of the shared textures (or of the procedural
corpus when ../shared is absent), so the encoders see thousands of real blocks. Rates are the
encoder kernels' (``vq2_encode.encode_many_arrays``: maps in, block fields out) on one core:
blocks per second of this process's CPU time, the best of ``REPEATS`` runs for the fast
searches (on a shared machine the wall clock also counts other processes' turns; it is printed
beside). Issue 14's baseline is ``medium`` as it was before: the greedy codebook for every
distinct transform combination (``vq2_encode.EXHAUSTIVE``).

    python bench/bench_vq2.py
"""

from __future__ import annotations

import time

import numpy as np
from common import lookup_rates, pack_raw, raw_lookup_batch, tile_maps

from omaps import states
from omaps.bake import known_fraction
from omaps.codecs import get_codec, vq2_block, vq2_encode
from omaps.codecs.options import EFFORTS, ENCODERS

DEFAULT = get_codec("vq2").default_effort
GOAL_RATE = 20000  # issue 14: the default encoder per core, at no less than medium's savings
REPEATS = 3


def run(m, encoder, effort, repeats):
    """(CPU rate, wall rate, savings) of one encoder, checking every block is conservative."""
    vq2_encode.encode_many_arrays(m[:4], encoder, effort)  # compile / load cache
    cpu = wall = np.inf
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        idx, cb, tr = vq2_encode.encode_many_arrays(m, encoder, effort)
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - w0)
    dec = [vq2_block.VQ2Block(idx[i], cb[i], tr[i]).decode() for i in range(len(m))]
    assert all(states.is_conservative(a, d) for a, d in zip(m, dec))
    return len(m) / cpu, len(m) / wall, float(np.mean([known_fraction(d) for d in dec]))


def end_to_end(m, effort, repeats):
    """(CPU rate, wall rate) of maps -> stored bytes as eval / trace / omm run it: the codec's
    ``encode_many`` (encoder, bulk pack, bulk decode, conservativeness check)."""
    codec = get_codec("vq2")
    codec.encode_many(m[:4], "best", effort)  # compile / load cache
    cpu = wall = np.inf
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        codec.encode_many(m, "best", effort)
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - w0)
    return len(m) / cpu, len(m) / wall


def main():
    m = tile_maps(16)
    print(f"{len(m)} non-uniform 16x16 maps from 64x64 tiles; one core, blocks per CPU second (wall)")
    sq = np.mean([known_fraction(a) for a in m])
    best = ENCODERS.index("best")
    rows = [("paper", ENCODERS.index("paper"), EFFORTS["medium"], 1),
            ("fast", best, EFFORTS["fast"], REPEATS), ("medium", best, EFFORTS["medium"], REPEATS),
            ("thorough", best, EFFORTS["thorough"], 1),
            ("medium before issue 14 (exhaustive)", best, vq2_encode.EXHAUSTIVE, 1)]
    rate, saved = {}, {}
    for name, enc, eff, reps in rows:
        cpu, wall, sav = run(m, enc, eff, reps)
        rate[name], saved[name] = cpu, sav
        print(f"  {name:36} {cpu:8.0f} blocks/s ({wall:6.0f} wall)   savings {sav:.4f} = {sav / sq:.4f} x sq16")
    base = "medium before issue 14 (exhaustive)"
    gap = saved[DEFAULT] - saved[base]
    print(f"  goal: default ({DEFAULT}) {rate[DEFAULT]:.0f} blocks/s (>= {GOAL_RATE}: "
          f"{'met' if rate[DEFAULT] >= GOAL_RATE else 'missed'}, {rate[DEFAULT] / rate[base]:.0f} x the old "
          f"medium); savings {saved[DEFAULT]:.4f} against the old medium's {saved[base]:.4f}: {gap:+.4f} "
          f"(>= 0: {'met' if gap >= 0 else 'missed'}); fast {rate['fast']:.0f} blocks/s at "
          f"{saved['fast'] - saved[base]:+.4f}")
    for eff in ("fast", DEFAULT):
        cpu, wall = end_to_end(m, eff, REPEATS)
        print(f"  maps -> stored bytes ({eff}, codec.encode_many: encode, pack, decode, check) {cpu:.0f} blocks/s "
              f"({wall:.0f} wall) = {cpu / rate[eff]:.2f} x the encoder's {rate[eff]:.0f}")
    blocks = np.stack([np.frombuffer(b.pack(), np.uint8) for b in vq2_encode.encode_many(m, "best", "fast")])
    rates = lookup_rates(16, [("raw 2-bit", raw_lookup_batch, pack_raw(m)), ("vq2", vq2_block.lookup_batch, blocks)])
    print(f"  vq2 / raw lookup rate: {rates['vq2'] / rates['raw 2-bit']:.2f}")


if __name__ == "__main__":
    main()
