"""Generate the frontier page (docs/frontier.md, docs/img/frontier_*.png) from traces of the shared
test scenes with every representation and ``memory=True``.

    python docs/scripts/frontier.py                 # trace palm and forest (tens of minutes), then render
    python docs/scripts/frontier.py --render-only   # re-render the page from docs/scripts/frontier.json
    python docs/scripts/frontier.py --scenes palm   # trace only these of the page's scenes, keep the others' runs
    python docs/scripts/frontier.py --scene S.glb --level 8 --json out.json   # any scene: its gap table

Each scene is traced once by ``omaps.trace_scene`` (the default camera, SIZE x SIZE pixels) with
every scheme of ``SCHEMES``, ``memory=True`` and a ``CACHE_KIB`` tile cache; the reports are kept
in ``docs/scripts/frontier.json`` (committed with the page) and the page is a pure function of
that file (tests/test_frontier.py checks it is what this script renders).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
DATA_JSON = DOCS / "scripts" / "frontier.json"
PAGE = DOCS / "frontier.md"
SIZE = 256
CACHE_KIB = 16
SCHEMES = {
    "palm": "none,tri4,tri6,tri8,succinct4,succinct6,succinct8,csm4,csm6,csm8,vq2,vq4,vq4x64,sq16,sq32,sq64",
    "forest": "none,tri4,tri6,succinct4,succinct6,csm4,csm6,vq2,vq4,vq4x64,sq16,sq32",
}
LEVEL = {"palm": 8, "forest": 6}  # the must-show level of each scene
# the papers' own words (docs/FORMAT.md "Hierarchical micromaps" gives the references)
CLAIMS = {"succinct": "up to 110x smaller than standard OMMs (Waldemarson & Doggett 2024)",
          "csm": "up to two orders of magnitude smaller than standard OMMs; a 1.2 M triangle forest at level 10 "
                 "in under 6 MiB (Chernaik, Modisett & Billeter 2026)"}


TESTS_SLACK = 1.05  # the gap table: points with at most this many times triL's alpha tests


def scheme_set(level: int) -> str:
    """The page's full scheme set up to ``level``: every micromap representation at the even
    levels 4 to ``level`` (and ``level`` itself), and the palm's blocks and raw squares."""
    levels = sorted({lv for lv in range(4, level + 1, 2)} | {level})
    squares = [n for n in SCHEMES["palm"].split(",") if not n.startswith(("none", "tri", "succinct", "csm"))]
    return ",".join(["none"] + [f"{k}{lv}" for k in ("tri", "succinct", "csm") for lv in levels] + squares)


def shared_root() -> Path:
    return Path(os.environ.get("OMAPS_SHARED", ROOT.parent / "shared"))


COST_SCHEMES = "tri6,succinct6,csm6,vq4"  # what building and looking up cost (bench/bench_lookup_cost.py)
COST_ROUNDS = 3


def _bench(name: str):
    """A module of bench/ (the cost and reach measurements are the benches' own)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def reach_levels(level: int) -> list[int]:
    """The levels of the reach table: the even levels from 6 to ``level`` (``level`` alone below 6)."""
    return list(range(6, level + 1, 2)) or [level]


def run(scenes: dict | None = None) -> dict:
    """Trace each scene ({name: (path, schemes, finest level)}; default: the page's) with
    ``memory=True``; then what each representation costs (``bench_lookup_cost``) and how near a
    map stored with its triangle or pair can come (``bench_both_fronts_reach``)."""
    import omaps

    folder = shared_root() / "data" / "scenes"
    scenes = scenes or {name: (folder / f"{name}.glb", schemes, LEVEL[name]) for name, schemes in SCHEMES.items()}
    out = {"size": SIZE, "cache_kib": CACHE_KIB, "scenes": {}}
    cost, reach = _bench("bench_lookup_cost"), _bench("bench_both_fronts_reach")
    for name, (path, schemes, level) in scenes.items():
        t0 = time.perf_counter()
        res = omaps.trace_scene(path, schemes, size=SIZE, memory=True, cache_kib=CACHE_KIB,
                                progress=sys.stderr.isatty())
        print(res.table(), flush=True)
        seconds = time.perf_counter() - t0
        costs = cost.measure(str(path), COST_SCHEMES, SIZE, COST_ROUNDS)
        print(cost.format_result(costs), flush=True)
        out["scenes"][name] = {"names": res.names, "report": res.report, "seconds": seconds, "costs": costs,
                               "reach": reach.measure(str(path), reach_levels(level), SIZE)}
    return out


def _kind(report: dict, n: str) -> str:
    s = report["settings"]["schemes"][n]
    if s.get("kind") == "micromap":
        return s.get("representation", "raw")
    return "none" if n == "none" else "square"


def _points(report: dict) -> list[tuple]:
    """(family, label, bytes, tests per ray, lines per ray, reads per lookup, texture lines per
    ray, map + texture lines per ray) of every scheme and layout (the last two None in a run
    without texture lines); family: 'omaps' (the deck's blocks and raw squares), 'tri' (standard
    OMMs: triL in its shared layout), 'succinct', 'csm'."""
    pts = []
    for n, r in report["schemes"].items():
        k = _kind(report, n)
        mem = r.get("memory")
        if k == "none" or not mem:
            continue
        t = r["alpha_tests_per_primary_ray"]
        tex = mem.get("texture_lines_per_ray")
        for lay in ("own", "shared"):
            m = mem[lay]
            if k == "raw":
                # the published standard OMMs (shared); triL's own raw rows are omaps' layout
                fam, label = ("tri", f"{n} OMM") if lay == "shared" else ("omaps", f"{n} raw")
            elif k == "csm" and lay == "shared":
                continue  # the same layout
            else:
                fam, label = ("omaps" if k == "square" else k), (n if lay == "own" else f"{n} shared")
            pts.append((fam, label, m["map_bytes"], t, m["map_lines_per_ray"], m["map_reads_per_lookup"], tex,
                        m.get("total_lines_per_ray")))
    return pts


FAMILY_NAMES = {"omaps": "omaps", "tri": "standard OMM", "succinct": "succinct", "csm": "csm"}


def traffic(report: dict) -> dict | None:
    """Alpha tests against map + texture lines per primary ray: ``none``'s texture lines and
    tests, every point with its total (``_points``), sorted by total, the points read less in
    all than ``none``, each family's least total and the front of tests against totals
    (``none`` among the points). None for a run without texture lines."""
    from omaps.frontier import front_mask

    none = report["schemes"].get("none", {})
    pts = [p for p in _points(report) if p[7] is not None]
    if not pts or "texture_lines_per_ray" not in (none.get("memory") or {}):
        return None
    nt, ntests = none["memory"]["texture_lines_per_ray"], none["alpha_tests_per_primary_ray"]
    ranked = sorted(pts, key=lambda p: (p[7], p[3]))
    fams = {}
    for p in ranked:
        fams.setdefault(p[0], p)
    every = [("none", "none", 0, ntests, 0.0, 0.0, nt, nt)] + ranked
    mask = front_mask([p[7] for p in every], [p[3] for p in every])
    front = sorted((p for p, m in zip(every, mask) if m), key=lambda p: p[7])
    return {"none_lines": nt, "none_tests": ntests, "ranked": ranked, "below": [p for p in ranked if p[7] < nt],
            "families": fams, "front": front}


def traffic_text(scene: str, tr: dict) -> str:
    """The paragraph on a scene's total traffic, from its numbers alone (``traffic``)."""
    nt, best = tr["none_lines"], tr["ranked"][0]
    saved = nt - best[6]
    out = [f"`none` reads no map and alpha-tests every candidate: {nt:.3f} lines of texture per primary ray "
           f"({tr['none_tests']:.3f} alpha tests)."]
    if not tr["below"]:
        out.append(f"On {scene} no map lowers the total: the least any point reads, map and texture together, is "
                   f"{best[1]}'s {best[7]:.3f} lines ({best[7] / nt:.2f}x `none`'s), its {best[4]:.3f} lines of map "
                   f"more than the {saved:.3f} lines of texture its map saves. Here a map earns its place by the alpha "
                   "tests (shader calls) it saves, not by memory traffic.")
    else:
        fams = sorted({FAMILY_NAMES[p[0]] for p in tr["below"]})
        out.append(f"On {scene}, {len(tr['below'])} of {len(tr['ranked'])} points read fewer lines in all than "
                   f"`none` (families: {', '.join(fams)}); the least is {best[1]}: {best[7]:.3f} lines "
                   f"({best[7] / nt:.2f}x `none`'s: {best[4]:.3f} of map, {best[6]:.3f} of texture) at "
                   f"{best[3]:.3f} alpha tests per ray.")
    per = []
    for fam, p in tr["families"].items():
        verdict = "below" if p[7] < nt else "above"
        per.append(f"{FAMILY_NAMES[fam]} {p[1]} {p[7]:.3f} ({verdict} `none`)")
    out.append("Each family's least total: " + "; ".join(per) + ".")
    names = [p[1] for p in tr["front"]]
    if len(names) == 1:
        out.append(f"{names[0]} alone is on the front of alpha tests against total lines: nothing reads less "
                   "and tests less.")
    else:
        out.append("On the front of alpha tests against total lines, from the fewest lines to the fewest tests: "
                   + ", ".join(names) + "; for every other point one of them reads no more and tests no more.")
    return " ".join(out)


def gap_rows(report: dict) -> list[tuple]:
    """Per level L with a traced ``triL``: (L, triL's tests per ray, the point of the page's
    points with at most ``TESTS_SLACK`` times those tests whose both-fronts gap is least, its
    bytes gap, lines gap and both-fronts gap); the gaps against every point of the report
    (``omaps.frontier.gaps``)."""
    from omaps.frontier import gaps

    pts = _points(report)
    tests = [p[3] for p in pts]
    by_bytes, by_lines = gaps(tests, [p[2] for p in pts]), gaps(tests, [p[4] for p in pts])
    both = [None if b is None or li is None else max(b, li) for b, li in zip(by_bytes, by_lines)]
    rows = []
    levels = sorted(int(n[3:]) for n in report["schemes"] if n.startswith("tri") and n[3:].isdigit())
    for lv in levels:
        t = report["schemes"][f"tri{lv}"]["alpha_tests_per_primary_ray"]
        fit = [i for i, p in enumerate(pts) if p[3] <= TESTS_SLACK * t and both[i] is not None]
        if fit:
            i = min(fit, key=lambda k: (both[k], pts[k][2]))
            rows.append((lv, t, pts[i], by_bytes[i], by_lines[i], both[i]))
    return rows


def _best(pts, fam, budget):
    """The family's point with the fewest tests per ray within ``budget`` bytes (ties: fewer bytes)."""
    fit = [p for p in pts if p[0] == fam and p[2] <= budget]
    return min(fit, key=lambda p: (p[3], p[2])) if fit else None


def _kib(b: float) -> str:
    return f"{b / 1024:,.1f}"


def _cell(p) -> str:
    return "—" if p is None else f"{p[1]}: {p[3]:.3f} ({_kib(p[2])} KiB, {p[4]:.2f} lines)"


def render(data: dict) -> str:
    size, cache = data["size"], data["cache_kib"]
    lines = [
        "# The frontier: alpha tests against bytes and memory read",
        "",
        "<!-- generated by docs/scripts/frontier.py from docs/scripts/frontier.json: do not edit -->",
        "",
        "Every opacity-map representation omaps traces, on one chart per scene: the alpha tests per primary ray "
        "(any-hit shader calls) against the map bytes and against the 64-byte lines of map data each primary ray "
        "reads (`omaps trace --memory`, docs/FORMAT.md \"What a lookup reads\"). Each scheme appears in its own "
        "layout (a block stored with its pair, a raw micromap row per triangle, a succinct tree per triangle) and "
        "in its shared one (identical maps stored once behind a 32-bit index; for `triL` that is the standard "
        "OMM layout `omaps omm` writes, labelled OMM). The Pareto front (fewer bytes or lines and fewer tests) is "
        "the line; dominated points are lighter. A third chart adds the alpha texture each alpha test still reads: "
        "alpha tests against map + texture lines per primary ray, with `none` (no map, every candidate tested) "
        "as a point of its own.",
        "",
        f"The traces are {size}x{size} pixels (smaller than the guide's 512x512 so that the run fits this "
        f"machine), from each scene's default camera; the cache misses are those of a {cache:g} KiB LRU cache "
        "shared by each 8x8 tile of pixels. Families in the tables: *omaps* is the deck's blocks (`vq2`, `vq4`, "
        "`vq4x64`) and raw squares `sqN` (own or shared layout) and triL's raw rows; *standard OMM* is `triL` as "
        "`omaps omm` writes it; *succinct* and *csm* the two published hierarchical micromaps (own or shared).",
        "",
        "Regenerate with `python docs/scripts/frontier.py` (or `--render-only` to redraw from the JSON).",
    ]
    for scene, d in data["scenes"].items():
        rep = d["report"]
        s = rep["scene"]
        lines += ["", f"## {scene}", "",
                  f"{s['alpha_triangles']:,} alpha-tested triangles of {s['triangles']:,}, {s['pairs']:,} prototype "
                  f"pairs; traced in {d['seconds']:.0f} s. Every scheme: 0 differing pixels: "
                  f"{'yes' if rep['passed'] else 'NO'}.", "",
                  f"![{scene}: alpha tests per primary ray against map bytes, map lines and map + texture lines "
                  "read per ray]"
                  f"(img/frontier_{scene}.png)", "",
                  "| scheme | tests/ray | differ | texture lines/ray | own KiB | reads/lookup | lines/ray | "
                  "misses/ray | total lines/ray | shared KiB | reads/lookup | lines/ray | misses/ray | "
                  "total lines/ray |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for n in d["names"]:
            r = rep["schemes"][n]
            m = r.get("memory")
            tex = (m or {}).get("texture_lines_per_ray")
            row = [n, f"{r['alpha_tests_per_primary_ray']:.3f}", str(r["differing_pixels"]),
                   "—" if tex is None else f"{tex:.3f}"]
            for lay in ("own", "shared"):
                if m:
                    x = m[lay]
                    total = x.get("total_lines_per_ray")
                    row += [_kib(x["map_bytes"]), f"{x['map_reads_per_lookup']:.2f}", f"{x['map_lines_per_ray']:.3f}",
                            f"{x['cache_misses_per_ray']:.3f}", "—" if total is None else f"{total:.3f}"]
                else:
                    row += ["—"] * 5
            lines.append("| " + " | ".join(row) + " |")
        tr = traffic(rep)
        if tr is not None:
            lines += ["", f"### {scene}: alpha tests against map + texture lines", "",
                      "Every alpha test a map leaves still reads the alpha texture: the taps of the material's filter "
                      "(one texel nearest, 2x2 linear), on mip level 0, with the texture stored as RGBA8 texels in "
                      "4x4 tiles, one 64-byte line per tile (docs/FORMAT.md, \"What a lookup reads\"). A point's "
                      "total is its lines of map data plus the texture lines its alpha tests read, per primary ray "
                      "(the right-hand chart). Both count the distinct lines each ray touches, with no cache shared "
                      "between rays; the tile cache's misses (the table) are modelled for map data only.", "",
                      traffic_text(scene, tr), "",
                      "| point (the front of tests against total lines) | tests/ray | map lines/ray | "
                      "texture lines/ray | total lines/ray | total / none's |", "|---|---|---|---|---|---|"]
            for p in tr["front"]:
                lines.append(f"| {p[1]} | {p[3]:.3f} | {p[4]:.3f} | {p[6]:.3f} | {p[7]:.3f} | "
                             f"{p[7] / tr['none_lines']:.2f} |")
        pts = _points(rep)
        sch = rep["schemes"]
        budgets = [(f"vq4 ({_kib(sch['vq4']['map_bytes'])} KiB)", sch["vq4"]["map_bytes"]),
                   (f"vq4x64 ({_kib(sch['vq4x64']['map_bytes'])} KiB)", sch["vq4x64"]["map_bytes"])]
        for lv in (4, 6):
            t = sch.get(f"tri{lv}")
            if t and t.get("memory"):
                budgets.append((f"standard OMM, level {lv} ({_kib(t['memory']['shared']['map_bytes'])} KiB)",
                                t["memory"]["shared"]["map_bytes"]))
        lines += ["", f"### {scene}: the best of each family within a byte budget", "",
                  "Tests per primary ray of the family's best point within the bytes (its bytes and lines per ray "
                  "in brackets); — where none fits.", "",
                  "| budget | omaps | standard OMM | succinct | csm |", "|---|---|---|---|---|"]
        for label, b in budgets:
            lines.append("| " + " | ".join([label] + [_cell(_best(pts, f, b)) for f in ("omaps", "tri", "succinct",
                                                                                         "csm")]) + " |")
        lines += ["", f"### {scene}: the distance to both fronts", "",
                  "A point's *bytes gap* is its map bytes over the fewest of any point with no more alpha tests per "
                  "primary ray; its *lines gap* the same for lines of map data per primary ray; its *both-fronts "
                  "gap* the larger of the two (1: on both fronts; `omaps trace --memory --json` gives all three "
                  f"per scheme and layout). Per level L, the point with the least both-fronts gap among those with at "
                  f"most {TESTS_SLACK:g}x triL's alpha tests.", "",
                  "| level | triL tests/ray | point | tests/ray | KiB | lines/ray | bytes gap | lines gap | "
                  "both-fronts gap |", "|---|---|---|---|---|---|---|---|---|"]
        for lv, t, p, b, li, both in gap_rows(rep):
            lines.append(f"| {lv} | {t:.3f} | {p[1]} | {p[3]:.3f} | {_kib(p[2])} | {p[4]:.3f} | {b:.2f} | {li:.2f} | "
                         f"**{both:.2f}** |")
        lines += ["", f"### {scene}: how much smaller the hierarchical micromaps are", "",
                  "Bytes of raw `triL` (a 2-bit row per triangle) and of standard OMMs (special indices, reuse) over "
                  "those of `succinctL` (own: a tree per triangle; shared: the distinct trees) and `csmL`, at the "
                  "same level: the same micromaps, so the same alpha tests.", "",
                  "| level | raw triL KiB | standard OMM KiB | succinct own | succinct shared | csm | "
                  "tests/ray (tri = succinct = csm) |", "|---|---|---|---|---|---|---|"]
        for lv in (4, 6, 8):
            if f"tri{lv}" not in sch or f"csm{lv}" not in sch:
                continue
            tm = sch[f"tri{lv}"]["memory"]
            raw, omm = tm["own"]["map_bytes"], tm["shared"]["map_bytes"]
            so, ss = (sch[f"succinct{lv}"]["memory"][k]["map_bytes"] for k in ("own", "shared"))
            cs = sch[f"csm{lv}"]["map_bytes"]
            same = {round(sch[f"{p}{lv}"]["alpha_tests_per_primary_ray"], 12) for p in ("tri", "succinct", "csm")}
            tests = (f"{sch[f'tri{lv}']['alpha_tests_per_primary_ray']:.3f}" + ("" if len(same) == 1 else " (DIFFER)"))
            lines.append(f"| {lv} | {_kib(raw)} | {_kib(omm)} | {_kib(so)} KiB: {raw / so:.1f}x raw, {omm / so:.2f}x OMM | "
                         f"{_kib(ss)} KiB: {raw / ss:.1f}x, {omm / ss:.2f}x | {_kib(cs)} KiB: {raw / cs:.1f}x, "
                         f"{omm / cs:.2f}x | {tests} |")
        lines += cost_lines(scene, d.get("costs")) + reach_lines(scene, d.get("reach"))
    lines += ["", "## The papers' claims beside these figures", "",
              f"- succinct: {CLAIMS['succinct']}.", f"- csm: {CLAIMS['csm']}.", ""]
    for scene, d in data["scenes"].items():
        sch = d["report"]["schemes"]
        f = {}
        for lv in (4, 6, 8):
            if f"tri{lv}" not in sch or f"csm{lv}" not in sch:
                continue
            tm = sch[f"tri{lv}"]["memory"]
            for rep, b in (("succinct", sch[f"succinct{lv}"]["memory"]["shared"]["map_bytes"]),
                           ("csm", sch[f"csm{lv}"]["map_bytes"])):
                for base, key in (("raw", "own"), ("omm", "shared")):
                    r = tm[key]["map_bytes"] / b
                    if r > f.get((rep, base), (0, 0))[0]:
                        f[(rep, base)] = (r, lv)
        s = d["report"]["scene"]
        lines.append(f"- measured on {scene} ({s['alpha_triangles']:,} alpha-tested triangles in the scene, each "
                     "prototype's stored once): the largest factors are succinct (distinct trees) "
                     f"{f[('succinct', 'raw')][0]:.1f}x smaller than raw triL (level {f[('succinct', 'raw')][1]}) and "
                     f"{f[('succinct', 'omm')][0]:.2f}x than standard OMMs (level {f[('succinct', 'omm')][1]}); csm "
                     f"{f[('csm', 'raw')][0]:.1f}x than raw triL (level {f[('csm', 'raw')][1]}) and "
                     f"{f[('csm', 'omm')][0]:.2f}x than standard OMMs (level {f[('csm', 'omm')][1]}).")
    lines += ["",
              "The papers compare with standard OMMs of their own making; omaps' standard OMMs already use special "
              "indices for uniform micromaps and store identical micromaps once, which on these scenes (micromaps "
              "repeated across instances' shared prototypes and across similar triangles) takes most of the gain "
              "that a per-triangle tree gets from pruning; the merged DAG still gains several times over them. Here "
              "the standard OMMs store C as unknown-transparent everywhere; `omaps omm`'s default nearest promotion "
              "resolves C per micro-triangle, which can split identical micromaps, so its files can be larger. What the trees cost is reads: a lookup's dependent "
              "reads and the lines a ray touches (tables above) grow with the level, where a block stored with its "
              "pair is one read. Figures as measured, not tuned.", ""]
    return "\n".join(lines)


def cost_lines(scene: str, c: dict | None) -> list[str]:
    """The page's table of what building and looking up each representation cost (``bench_lookup_cost``)."""
    if not c:
        return []
    out = ["", f"### {scene}: what building and looking up cost", "",
           f"Measured by `python bench/bench_lookup_cost.py` on this machine (2 cores), best of {c['rounds']} rounds. "
           "Build: the scheme's maps from the scene's alpha triangles as the tracer builds them (bake, keep the "
           "distinct maps, store), per million alpha triangles (prototypes). Lookup: every lookup of the primary "
           "pass above replayed in ray order through the tracer's state function (the hit's micro-triangle or "
           f"cell, then the stored data); the rounds alternate between schemes, ratios to {c['reference']}'s.", "",
           f"| scheme | map KiB | build s | s per million triangles | ns per lookup | x {c['reference']} |",
           "|---|---|---|---|---|---|"]
    for r in c["rows"]:
        out.append(f"| {r['scheme']} | {_kib(r['map_bytes'])} | {r['build_s']:.2f} | {r['build_s_per_million']:.1f} | "
                   f"{r['lookup_ns']:.1f} | {r['lookup_over_first']:.2f} |")
    return out


def reach_lines(scene: str, rows: list | None) -> list[str]:
    """The page's table of how near a map whose top is stored with its triangle or pair can come
    (``bench_both_fronts_reach``): per level, its best case and its nearer ``fit`` case."""
    if not rows:
        return []
    out = ["", f"### {scene}: how near a map stored with its triangle or pair can come", "",
           "Where each lookup of the primary pass ends (the depth of the uniform subtree or leaf that decides it), "
           "and the best case of one family of designs (`python bench/bench_both_fronts_reach.py`): a fixed "
           "record of R bytes per alpha triangle or per prototype pair at an address computed from its index, "
           "holding the top of its maps (one byte per mixed node, whole levels, as deep as fit, no pointer), and "
           "shared storage for the rest. A lookup that ends within the record reads its line only. Every other "
           "lookup also reads one line of shared data: in the *best case* one line per map and ray (as if a whole "
           "map fit in a line); in the *fit* case one line per subtree that fits in a line (the first node of its "
           "descent with at most 64 mixed nodes below it, each distinct one stored once). Bytes: the records (fit: "
           "and those subtrees, and a byte per mixed node above them). Real designs also store pointers and read "
           "the nodes above a subtree, so they read and store more. The gaps are against triL's raw rows' lines "
           "and csmL's bytes from the same trace, each the least over records of 4 to 128 bytes: the best case's "
           "is the least any such design could reach; the fit case's is nearer to one that could be built.", "",
           "The last column is what the fit case reads for free: per triangle the *route* to its subtrees, the "
           "mixed nodes above them and how many subtrees hang from it (mean, 90th percentile in brackets). A real "
           "design stores a node and a pointer per subtree of it in the record, or reads it from a line of its "
           "own before the subtree's.", "",
           "| level | decided at depth 0, 1, ... L | best case: least gap (record) | fit: least gap (record) | "
           "fit: lines/ray, KiB | route: mixed nodes, subtrees |", "|---|---|---|---|---|---|"]
    for r in rows:
        best = min(r["cases"], key=lambda c: c["gap"])
        fit = min(r["cases"], key=lambda c: c["fit_gap"])
        share = ", ".join(f"{v:.2f}" for v in r["depth_share"])
        route = (f"{r['route_mean']:.1f} ({r['route_p90']:.0f}), {r['subtrees_mean']:.1f} ({r['subtrees_p90']:.0f})"
                 if "route_mean" in r else "—")
        out.append(f"| {r['level']} | {share} | {best['gap']:.2f} ({best['record']} B a {best['unit']}) | "
                   f"{fit['fit_gap']:.2f} ({fit['record']} B a {fit['unit']}) | {fit['fit_lines']:.3f}, "
                   f"{_kib(fit['fit_bytes'])} | {route} |")
    return out


def draw(data: dict) -> None:
    from omaps.trace.pictures import frontier_plot

    for scene, d in data["scenes"].items():
        frontier_plot(str(DOCS / "img" / f"frontier_{scene}.png"), d["report"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--render-only", action="store_true", help="re-render from docs/scripts/frontier.json")
    ap.add_argument("--scenes", help="trace only these of the page's scenes (comma-separated), keeping the "
                                     "others' runs from docs/scripts/frontier.json")
    ap.add_argument("--scene", help="trace this glTF scene instead of the page's (the page is left alone)")
    ap.add_argument("--level", type=int, default=8, help="with --scene: the finest level of the scheme set (8)")
    ap.add_argument("--json", help="with --scene: write the run (the page's JSON format) here")
    a = ap.parse_args()
    if a.scene:
        data = run({Path(a.scene).stem: (a.scene, scheme_set(a.level), a.level)})
        if a.json:
            Path(a.json).write_text(json.dumps(data, indent=1))
        for name, d in data["scenes"].items():
            for lv, t, p, b, li, both in gap_rows(d["report"]):
                print(f"{name} level {lv}: triL {t:.3f} tests/ray; least both-fronts gap within {TESTS_SLACK:g}x: "
                      f"{p[1]} ({p[3]:.3f} tests/ray, {_kib(p[2])} KiB, {p[4]:.3f} lines/ray): bytes gap {b:.2f}, "
                      f"lines gap {li:.2f}, both {both:.2f}")
        return 0
    if a.render_only:
        data = json.loads(DATA_JSON.read_text())
    elif a.scenes:
        names = a.scenes.split(",")
        unknown = [n for n in names if n not in SCHEMES]
        if unknown:
            ap.error(f"--scenes: unknown scene {', '.join(unknown)} (choose from {', '.join(SCHEMES)})")
        data = json.loads(DATA_JSON.read_text())
        folder = shared_root() / "data" / "scenes"
        new = run({n: (folder / f"{n}.glb", SCHEMES[n], LEVEL[n]) for n in names})
        data["scenes"] = {n: new["scenes"].get(n, d) for n, d in data["scenes"].items()} | {
            n: d for n, d in new["scenes"].items() if n not in data["scenes"]}
        DATA_JSON.write_text(json.dumps(data, indent=1))
    else:
        data = run()
        DATA_JSON.write_text(json.dumps(data, indent=1))
    draw(data)
    PAGE.write_text(render(data))
    print(f"wrote {PAGE} and {len(data['scenes'])} charts")
    return 0


if __name__ == "__main__":
    sys.exit(main())
