"""How near both fronts can a map come whose top is stored with its triangle (or pair)? The best
case of that design, measured on a real trace.

The both-fronts goal asks one representation for about csmL's bytes and about raw triL rows' lines
per primary ray (one line per lookup). This bench measures, per scene and level, where each
lookup of the primary pass ends (the depth of the uniform subtree or leaf that decides it: the
part of the map it must read), and then the best case of one family of designs: a fixed record of
R bytes per alpha triangle (or per prototype pair, R/2 for each of its triangles) at an address
computed from its index, holding the top of its map, and shared storage for the rest.

* The record holds the top of each of its triangles' maps, one byte (the 4 children's states) per
  mixed node, whole levels, as deep as they fit, and no pointer. A lookup that ends within it
  reads the record's line only.
* Every other lookup reads its record's line and one line of shared data, and that line is the
  same for every lookup of the same map in a ray, as if a whole map fit in one line.
* Lines per ray: the distinct lines each primary ray reads under these rules. Bytes: the records'
  alone.

A second, nearer case (``fit``) lets a lookup's shared line hold only a subtree that fits in one:
the first node of its descent whose tree is at most 64 mixed nodes (64 bytes at one byte a node),
one line per such distinct subtree in the scene (shared by every map that holds it). Its bytes add
those subtrees and one byte per distinct mixed node above them (still no pointer). Printed beside
it: each triangle's *route*, the mixed nodes above its subtrees, and how many subtrees hang from
it -- what a real design must store (a node and a pointer a subtree) or read before that line.

Real designs need pointers in the record and more than one line for the maps that do not fit in
one, so they read more lines and store more bytes than this. The ``gap`` column is the both-fronts
gap of that best case: the larger of its lines over triL's raw rows' and its bytes over csmL's
(from the same trace). The frontier page's gaps use the fewest bytes and lines of every scheme,
which can only be lower, so the real gap of any such design is at least this.

    python bench/bench_both_fronts_reach.py                      # palm (levels 6, 8), forest (6)
    python bench/bench_both_fronts_reach.py --scene S.glb --levels 4,6
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "scenes")
RECORD_BYTES = (4, 8, 16, 32, 64, 128)
DEFAULT = {"palm": "6,8", "forest": "6"}


def decision_depths(nodes: np.ndarray, roots: np.ndarray, level: int, k: np.ndarray) -> np.ndarray:
    """Per lookup (root reference, micro-triangle k) the depth where the descent reaches a state."""
    ref = roots.astype(np.int64).copy()
    depth = np.zeros(len(ref), np.int64)
    for d in range(level):
        live = ref >= 3
        if not live.any():
            break
        child = (k[live] >> (2 * (level - 1 - d))) & 3
        ref[live] = nodes[ref[live] - 3, child]
        depth[live] += 1
    return depth


def mixed_per_depth(nodes: np.ndarray, level: int) -> np.ndarray:
    """(3 + N, L + 1): for each reference, the mixed nodes of its tree at each depth below it
    (the tree, not the DAG: a shared subtree counts once per place it appears)."""
    n = len(nodes)
    out = np.zeros((3 + n, level + 1), np.int64)
    done = np.zeros(3 + n, bool)
    done[:3] = True
    for r in range(3, 3 + n):  # children first, by an explicit stack
        stack = [r]
        while stack:
            x = stack[-1]
            if done[x]:
                stack.pop()
                continue
            todo = [int(c) for c in nodes[x - 3] if not done[c]]
            if todo:
                stack.extend(todo)
                continue
            out[x, 0] = 1
            out[x, 1:] = out[nodes[x - 3]].sum(axis=0)[:-1]
            done[x] = True
            stack.pop()
    return out


LINE = 64  # bytes of a line: a subtree of at most this many mixed nodes fits in one


def region_of(nodes: np.ndarray, size: np.ndarray, roots: np.ndarray, level: int, k: np.ndarray) -> np.ndarray:
    """Per lookup the first reference of its descent whose tree fits in a line (``size`` <= LINE),
    or its state where the descent ends before one."""
    ref = roots.astype(np.int64).copy()
    for d in range(level):
        live = (ref >= 3) & (size[ref] > LINE)
        if not live.any():
            break
        ref[live] = nodes[ref[live] - 3, (k[live] >> (2 * (level - 1 - d))) & 3]
    return ref


def fit_bytes(nodes: np.ndarray, size: np.ndarray, roots: np.ndarray) -> int:
    """Bytes of every map's subtrees that fit in a line, each distinct one once, plus one byte per
    distinct mixed node above them."""
    seen = np.zeros(len(size), bool)
    stack = [int(r) for r in np.unique(roots) if r >= 3]
    total = 0
    while stack:
        x = stack.pop()
        if seen[x]:
            continue
        seen[x] = True
        if size[x] <= LINE:
            total += int(size[x])
            continue
        total += 1
        stack.extend(int(c) for c in nodes[x - 3] if c >= 3)
    return total


def routes(nodes: np.ndarray, tree: np.ndarray, roots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per map (root reference) its *route* -- the mixed nodes of its tree whose own tree does
    not fit in a line -- and the subtrees that fit hanging from it (what a lookup must find
    before it reads the line of its subtree): (route nodes, subtrees) per entry of ``roots``."""
    out = {}
    for r in np.unique(roots):
        r = int(r)
        route = sub = 0
        stack = [r] if r >= 3 else []
        while stack:
            x = stack.pop()
            if tree[x] <= LINE:
                sub += 1
                continue
            route += 1
            stack.extend(int(c) for c in nodes[x - 3] if c >= 3)
        out[r] = (route, sub)
    got = np.array([out[int(r)] for r in roots], np.int64).reshape(-1, 2)
    return got[:, 0], got[:, 1]


def lines_per_ray(pixel: np.ndarray, ids: np.ndarray, pixels: int) -> float:
    key = pixel.astype(np.int64) * (1 << 42) + ids
    return len(np.unique(key)) / pixels


def measure(path: str, levels: list[int], size: int) -> list[dict]:
    import omaps
    from omaps import birdcurve
    from omaps.trace.maps import baked_tree
    from omaps.trace.memory import record_lookups

    names = ",".join(f"tri{lv},csm{lv}" for lv in levels)
    res = omaps.trace_scene(path, names, size=size, memory=True)
    prep = res.prep
    pixels = size * size
    out = []
    for lv in levels:
        tri_mem = res.report["schemes"][f"tri{lv}"]["memory"]["own"]
        csm_mem = res.report["schemes"][f"csm{lv}"]["memory"]["own"]
        lk, _ = record_lookups(prep, f"csm{lv}", res.basis, size, size, res.runs[f"csm{lv}"].primary.calls)
        nodes, distinct, rows, _ = baked_tree(prep.alpha, prep.tests, lv)
        root = distinct[rows].astype(np.int64)  # each alpha triangle's root reference
        k = np.array([birdcurve.bary_to_index(a, b, lv) for a, b in zip(lk.b1, lk.b2)], np.int64)
        tri = lk.tri.astype(np.int64)
        depth = decision_depths(nodes, root[tri], lv, k)
        per_depth = mixed_per_depth(nodes, lv)
        pixel = np.repeat(np.arange(pixels), np.diff(lk.start))
        pair = np.asarray(prep.alpha.pair, np.int64)
        n_pairs = len(prep.alpha.pair_first)
        row = {"scene": os.path.basename(path), "level": lv, "lookups_per_ray": len(tri) / pixels,
               "depth_share": (np.bincount(depth, minlength=lv + 1) / max(len(tri), 1)).tolist(),
               "tri_lines": tri_mem["map_lines_per_ray"], "csm_bytes": csm_mem["map_bytes"],
               "csm_lines": csm_mem["map_lines_per_ray"], "cases": []}
        cum = np.cumsum(per_depth[root], axis=1)  # mixed nodes above each depth, per triangle
        tree = per_depth.sum(axis=1)  # mixed nodes of each reference's tree
        region = region_of(nodes, tree, root[tri], lv, k)
        shared_fit = fit_bytes(nodes, tree, root)
        route, subtrees = routes(nodes, tree, root)
        row.update(route_mean=float(route.mean()), route_p90=float(np.percentile(route, 90)),
                   subtrees_mean=float(subtrees.mean()), subtrees_p90=float(np.percentile(subtrees, 90)))
        for unit in ("triangle", "pair"):
            owner = tri if unit == "triangle" else pair[tri]
            count = len(root) if unit == "triangle" else n_pairs
            for r in RECORD_BYTES:
                room = r if unit == "triangle" else r / 2
                top = (cum <= room).sum(axis=1)  # whole levels of mixed nodes that fit: decides depths <= top
                decided = depth <= top[tri]
                ids = np.concatenate([owner * r // 64, (1 << 40) + root[tri][~decided]])
                lines = lines_per_ray(np.concatenate([pixel, pixel[~decided]]), ids, pixels)
                nbytes = r * count
                fit_ids = np.concatenate([owner * r // 64, (1 << 40) + region[~decided]])
                fit_lines = lines_per_ray(np.concatenate([pixel, pixel[~decided]]), fit_ids, pixels)
                fit_total = nbytes + shared_fit
                row["cases"].append({"unit": unit, "record": r, "decided": float(decided.mean()),
                                     "lines": lines, "bytes": nbytes,
                                     "gap": max(lines / row["tri_lines"], nbytes / row["csm_bytes"]),
                                     "fit_lines": fit_lines, "fit_bytes": fit_total,
                                     "fit_gap": max(fit_lines / row["tri_lines"], fit_total / row["csm_bytes"])})
        out.append(row)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", help="a glTF scene (default: the shared palm and forest)")
    ap.add_argument("--levels", help="micromap levels (default: palm 6,8; forest 6)")
    ap.add_argument("--size", type=int, default=256, help="pixels per side (the frontier page's 256)")
    a = ap.parse_args()
    if a.scene:
        jobs = {a.scene: a.levels or "6"}
    else:
        jobs = {os.path.join(SCENES, f"{n}.glb"): a.levels or lv for n, lv in DEFAULT.items()}
        missing = [p for p in jobs if not os.path.isfile(p)]
        if missing:
            print(f"{missing[0]} is absent: nothing to measure", file=sys.stderr)
            return 0
    for path, levels in jobs.items():
        t0 = time.perf_counter()
        for row in measure(path, [int(v) for v in levels.split(",")], a.size):
            share = " ".join(f"{s:.2f}" for s in row["depth_share"])
            print(f"\n{row['scene']} level {row['level']}: {row['lookups_per_ray']:.3f} lookups per ray; "
                  f"triL raw rows {row['tri_lines']:.3f} lines/ray; csmL {row['csm_bytes'] / 1024:.1f} KiB, "
                  f"{row['csm_lines']:.3f} lines/ray")
            print(f"  share of lookups decided at depth 0..{row['level']}: {share}")
            print(f"  per triangle, the route to its subtrees that fit in a line (fit case): {row['route_mean']:.1f} "
                  f"mixed nodes (90th percentile {row['route_p90']:.0f}) above {row['subtrees_mean']:.1f} subtrees "
                  f"({row['subtrees_p90']:.0f})")
            print("                          best case (a map a line)            fit (a subtree a line)")
            print("  record per   bytes  decided  lines/ray  x triL  KiB    x csmL  gap   lines/ray  x triL  KiB    "
                  "x csmL  gap")
            for c in row["cases"]:
                print(f"  {c['unit']:9} {c['record']:6}  {c['decided']:7.2f}  {c['lines']:9.3f}  "
                      f"{c['lines'] / row['tri_lines']:6.2f}  {c['bytes'] / 1024:6.1f} {c['bytes'] / row['csm_bytes']:6.2f}  "
                      f"{c['gap']:4.2f}  {c['fit_lines']:9.3f}  {c['fit_lines'] / row['tri_lines']:6.2f}  "
                      f"{c['fit_bytes'] / 1024:6.1f} {c['fit_bytes'] / row['csm_bytes']:6.2f}  {c['fit_gap']:4.2f}")
            for key, what in (("gap", "best case"), ("fit_gap", "fit")):
                best = min(row["cases"], key=lambda c: c[key])
                print(f"  {what}: least gap {best[key]:.2f}, a {best['record']}-byte record per {best['unit']}")
        print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
