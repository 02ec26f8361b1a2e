"""What each representation costs to build (seconds per million alpha triangles) and to look up
(nanoseconds per lookup), measured side by side on a real scene.

Build: the scheme's maps from the scene's alpha triangles as the tracer builds them
(``trace.maps.build_scheme_maps``: bake, keep the distinct maps, store), one scheme at a time in
one process, after a warm-up that compiles every kernel; the best of the rounds. Per million alpha
triangles of the scene (prototypes: an instance shares its prototype's maps).

Lookup: every lookup of the primary pass from the scene's default camera (the frontier page's
view, 256 x 256 pixels, in ray order) replayed through the tracer's state function
(``trace.lookups.state_function``: the hit's micro-triangle or cell, then the stored data) in a
compiled loop; the rounds go through the schemes in turn and each scheme's best round counts, so
the ratios to triL's raw rows come from the same stretch of time on a shared machine.

    python bench/bench_lookup_cost.py                          # palm and forest: tri6, succinct6, csm6, vq4
    python bench/bench_lookup_cost.py --scene S.glb --schemes tri8,csm8 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
from numba import njit

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "scenes")
SCHEMES = "tri6,succinct6,csm6,vq4"


@njit
def _replay(state, table, tri, b1, b2):
    s = 0
    for j in range(tri.shape[0]):
        s += state(table, tri[j], b1[j], b2[j])
    return s


def measure(path: str, schemes: str, size: int = 256, rounds: int = 5) -> dict:
    """Build seconds and lookup nanoseconds of each of ``schemes`` (the first is the reference of
    the ratios) on the glTF scene ``path``."""
    import omaps
    from omaps.schemes import parse_schemes
    from omaps.trace.lookups import state_function
    from omaps.trace.maps import build_scheme_maps
    from omaps.trace.memory import record_lookups
    from omaps.trace.tables import scheme_tables

    names = [n.strip() for n in schemes.split(",") if n.strip()]
    res = omaps.trace_scene(path, ",".join(names), size=size)
    prep = res.prep
    at = prep.alpha
    parsed = parse_schemes(names)
    build = {n: float("inf") for n in names}
    for _ in range(rounds):
        for s in parsed:
            t0 = time.perf_counter()
            build_scheme_maps(at, prep.tests, [s])
            build[s.name] = min(build[s.name], time.perf_counter() - t0)
    replay = {}
    for n in names:
        lk, _ = record_lookups(prep, n, res.basis, size, size, res.runs[n].primary.calls)
        tables = scheme_tables(prep.base, prep.maps[n])
        args = (state_function(prep.maps[n]), tables.table, lk.tri, lk.b1, lk.b2)
        got = _replay(*args)  # compiles; and the states must be the traced ones
        if got != int(lk.state.astype(np.int64).sum()):
            raise RuntimeError(f"{n}: the replayed lookups read other states than the trace")
        replay[n] = (args, tables, lk.count)
    best = {n: float("inf") for n in names}
    for _ in range(rounds):
        for n in names:
            args, _, _ = replay[n]
            t0 = time.perf_counter()
            _replay(*args)
            best[n] = min(best[n], time.perf_counter() - t0)
    ref = names[0]
    rows = []
    for n in names:
        count = replay[n][2]
        ns = 1e9 * best[n] / max(count, 1)
        rows.append({"scheme": n, "map_bytes": int(prep.maps[n].map_bytes), "build_s": build[n],
                     "build_s_per_million": build[n] / (at.count / 1e6), "lookups": count, "lookup_ns": ns})
    ref_ns = rows[0]["lookup_ns"]
    for r in rows:
        r["lookup_over_first"] = r["lookup_ns"] / ref_ns if ref_ns else None
    return {"scene": os.path.basename(path), "alpha_triangles": int(at.count), "size": size, "rounds": rounds,
            "reference": ref, "rows": rows}


def format_result(m: dict) -> str:
    out = [f"{m['scene']}: {m['alpha_triangles']:,} alpha triangles; lookups of a {m['size']}x{m['size']} primary "
           f"pass, best of {m['rounds']} rounds",
           "scheme        map KiB   build s   s per M triangles   ns per lookup   x " + m["reference"]]
    for r in m["rows"]:
        out.append(f"{r['scheme']:12} {r['map_bytes'] / 1024:9.1f} {r['build_s']:9.2f} {r['build_s_per_million']:19.1f}"
                   f" {r['lookup_ns']:15.1f} {r['lookup_over_first']:8.2f}")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", help="a glTF scene (default: the shared palm and forest)")
    ap.add_argument("--schemes", default=SCHEMES, help=f"schemes, the first the reference (default {SCHEMES})")
    ap.add_argument("--size", type=int, default=256, help="pixels per side of the traced view (default 256)")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of each measurement, best kept (default 5)")
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()
    paths = [a.scene] if a.scene else [os.path.join(SCENES, f"{n}.glb") for n in ("palm", "forest")]
    missing = [p for p in paths if not os.path.isfile(p)]
    if missing:
        print(f"{missing[0]} is absent: nothing to measure", file=sys.stderr)
        return 0 if not a.scene else 2
    results = []
    for p in paths:
        m = measure(p, a.schemes, a.size, a.rounds)
        print(format_result(m), flush=True)
        results.append(m)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
