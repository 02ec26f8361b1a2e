"""``omaps omm`` against meshoptimizer's opacity-map baker, side by side: whole processes, wall time
and CPU-seconds, and the two bakers' per-micro-triangle states compared.

The case (the meshoptimizer issue): shared/data/textures/q009-vegetation__oak_oak_leaf.png (512²),
random UV triangles (centres uniform in [0.05, 0.95]², each vertex within +-0.02 of its centre,
seeded; about 32 texels of area on average, median 24), bilinear, clamp, cut-off 0.5, 4-state,
N = 100,000 and 1,000,000 triangles, levels 4, 6 and 8. Both read the same float32 UVs (omaps from a
float32 .npy, meshoptimizer from the raw file).

meshoptimizer is shared/anchors/meshoptimizer (its README: a one-thread driver around
``meshopt_opacityMapMeasure`` / ``Rasterize`` / ``Compact``), compiled into a temporary folder
with its build.sh. Contenders, each the whole process, taking turns within every repeat (the
order rotates) so that load from other work hits them alike; each keeps its least wall time and
its least CPU-seconds (user + system of the child, every thread) over ``--repeat`` runs:

- ``omaps omm LEAF UVS.npy -o DIR --level L --format 4state --filter linear --wrap clamp
  --cutoff 0.5 --quiet`` on its default threads (all cores), with ``--threads 1``, and with
  ``--threads 2`` where the default is not 2;
- ``mo_omm_driver --tex LEAF --tris TRIS.f32 --level L --format 4 --filter linear --address clamp
  --cutoff 0.5`` (one thread; it writes nothing, omaps writes its OMM folder).

The issue's targets: omaps' CPU-seconds <= meshoptimizer's (ratio <= 1.0), and omaps' wall time
on 2 threads <= 0.6 x meshoptimizer's.

States (``--check-states``, by default at the smallest N): meshoptimizer's ``--dump`` (an extra,
untimed run; per input triangle 4^L bytes, 0 T, 1 O, 2 unknown-transparent, 3 unknown-opaque,
bird-curve order) against the states of omaps' OMM folder from the timed runs (omm_data.bin,
omm_triangles.bin, omm_index.bin, docs/FORMAT.md), special indices expanded, as a 4 x 4 count
matrix (meshoptimizer's state x omaps'): micro-triangles meshoptimizer marks known (T/O) where
omaps says unknown and the reverse, and O<->T disagreements (omaps is exact and grows regions by
GROW_TEXEL, so an O<->T disagreement is meshoptimizer being non-conservative). At most
``--check-max-micro`` micro-triangles per case are compared (the first triangles).

Every case records the SHA-256 of omaps' states (per input triangle, in input order, its 4-state
micromap packed as in omm_data.bin -- 2 bits per micro-triangle, bird-curve order -- with special
indices expanded: independent of reuse and record order) for every thread count, so a speed change
can be checked "identical omaps states before and after"; a thread count whose states differ is
reported.

Cases above ``--max-micro`` micro-triangles (N x 4^L; by default 100k at level 8 and 1M at levels
6 and 8, each tens of minutes of meshoptimizer and many GB) are skipped with a note; raise it to
run them.

    python bench/bench_omm_meshopt.py [--triangles 100000,1000000] [--levels 4,6,8] [--repeat 3]
        [--max-micro 5e8] [--check-states smallest|all|none] [--check-max-micro 5.2e8]
        [--seed 12] [--spread 0.02] [--json FILE] [--quick]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from common import TEXTURES  # ../shared/data/textures, one place

from omaps import birdcurve
from omaps.omm import files as omm_files
from omaps import omm_format
from omaps.texture import load_alpha

ROOT = Path(__file__).resolve().parents[1]
ANCHOR = ROOT.parent / "shared" / "anchors" / "meshoptimizer"
LEAF = TEXTURES / "q009-vegetation__oak_oak_leaf.png"
CUTOFF = 0.5
STATE_NAMES = ("T", "O", "UT", "UO")
CPU_TARGET = 1.0  # omaps CPU-s / meshoptimizer CPU-s
WALL2_TARGET = 0.6  # omaps 2-thread wall / meshoptimizer wall
CHUNK_MICRO = 1 << 24  # micro-triangles per chunk when expanding, hashing and comparing states
MAX_DISAGREEMENTS = 2_000_000  # judged by the exact bilinear extremes, per case


def oak_triangles(n, seed=12, spread=0.02):
    """n UV triangles: centres uniform in [0.05, 0.95]², vertices uniform within +-spread of them
    (bench_bilinear.issue_triangles' draws with another spread), rounded to float32 (what both
    bakers read)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.05, 0.95, (n, 1, 2)) + rng.uniform(-spread, spread, (n, 3, 2))
    return t.astype(np.float32)


def texel_areas(tris, w, h):
    t = tris.astype(np.float64) * [w, h]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _child_cpu():
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


def run_once(cmd, env=None):
    """Wall time, CPU-seconds (user + system, every thread) and stdout of one run of a command that
    must succeed."""
    c0 = _child_cpu()
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    cpu = _child_cpu() - c0
    if r.returncode:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed ({r.returncode}):\n{r.stdout}{r.stderr}")
    return dt, cpu, r.stdout


def build_driver(out_dir):
    """Compile mo_omm_driver into out_dir; its path, or None with the reason printed."""
    r = subprocess.run(["bash", str(ANCHOR / "build.sh"), str(out_dir)], capture_output=True, text=True)
    exe = Path(out_dir) / "mo_omm_driver"
    if r.returncode or not exe.is_file():
        raise SystemExit(f"building meshoptimizer's driver failed:\n{r.stdout}{r.stderr}")
    return exe


def omaps_rows(res, first, last, level):
    """(last - first, bytes) packed 4-state micromaps of input triangles first..last-1 of an OMM
    result, special indices expanded (2 bits per micro-triangle, bird-curve order: omm_data.bin's
    layout). Every micromap must be of this level and 4-state."""
    nb = omm_format.micromap_bytes(level, 2)
    idx = np.asarray(res.index[first:last])
    rows = np.empty((len(idx), nb), dtype=np.uint8)
    special = idx < 0
    s = (-1 - idx[special]).astype(np.uint8)
    rows[special] = (s if level == 0 else s * np.uint8(0x55))[:, None]  # level 0: one state, 6 padding bits
    rec = res.triangles[idx[~special]]
    off = rec["data_offset"].astype(np.int64)
    data = np.asarray(res.data)
    if len(data) % nb == 0 and not np.any(off % nb):
        rows[~special] = data.reshape(-1, nb)[off // nb]
    else:
        rows[~special] = data[off[:, None] + np.arange(nb)]
    return rows


def check_uniform(res, level):
    lv, fm = np.unique(res.triangles["level"]), np.unique(res.triangles["format"])
    if np.any(lv != level) or np.any(fm != 2):
        raise SystemExit(f"omaps' OMM holds levels {lv.tolist()} and formats {fm.tolist()}: level {level}, "
                         "4-state (2) expected")


def states_hash(res, level):
    """SHA-256 of omaps' per-triangle packed 4-state micromaps (specials expanded), in input order."""
    check_uniform(res, level)
    h = hashlib.sha256()
    n = len(res.index)
    step = max(1, CHUNK_MICRO // 4 ** level)
    for a in range(0, n, step):
        h.update(omaps_rows(res, a, min(n, a + step), level).tobytes())
    return h.hexdigest()


def compare_states(res, dump_path, n_tris, level, keep=MAX_DISAGREEMENTS):
    """4 x 4 counts [meshoptimizer state, omaps state] over the first n_tris triangles, and where
    they disagree on what is known (one known, the other unknown, or O against T): the first
    ``keep`` such micro-triangles' global indices (triangle x 4^L + micro-triangle) and both states."""
    check_uniform(res, level)
    per = 4 ** level
    mo = np.memmap(dump_path, dtype=np.uint8, mode="r")
    if len(mo) != n_tris * per:
        raise SystemExit(f"{dump_path}: {len(mo)} bytes, {n_tris} x {per} expected")
    m = np.zeros(16, dtype=np.int64)
    pos, mss, oms = [], [], []
    kept = 0
    step = max(1, CHUNK_MICRO // per)
    for a in range(0, n_tris, step):
        b = min(n_tris, a + step)
        om = omm_format.unpack(omaps_rows(res, a, b, level), level, 2).reshape(-1)
        ms = np.asarray(mo[a * per:b * per])
        if ms.max(initial=0) > 3:
            raise SystemExit(f"{dump_path}: state {ms.max()} (0..3 expected)")
        m += np.bincount((ms << 2) | om, minlength=16)
        if kept < keep:
            k_mo, k_om = ms < 2, om < 2
            at = np.flatnonzero((k_mo != k_om) | (k_mo & k_om & (ms != om)))[:keep - kept]
            pos.append(at.astype(np.int64) + a * per)
            mss.append(ms[at])
            oms.append(om[at])
            kept += len(at)
    cat = (lambda x, t: np.concatenate(x) if x else np.zeros(0, t))
    return m.reshape(4, 4), cat(pos, np.int64), cat(mss, np.uint8), cat(oms, np.uint8)


def exact_check(tris, level, alpha8, pos, ms, om):
    """Judge the disagreements by the exact bilinear extremes over each micro-triangle
    (tests/reference.py, independent of omaps' clipping; no growth): a known state is contradicted
    where the alpha reaches the other side of the cut-off (beyond 1e-9 of a level)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import reference as ref  # noqa: E402 (the exact reference, as bench_bilinear.py uses it)

    h, w = alpha8.shape
    per = 4 ** level
    bary = birdcurve.micro_triangles(level)[pos % per]  # (k, 3, 2) barycentric (u, v)
    p = tris[pos // per].astype(np.float64)  # (k, 3, 2) UV
    pts = ((1.0 - bary[..., 0] - bary[..., 1])[..., None] * p[:, None, 0] + bary[..., 0, None] * p[:, None, 1]
           + bary[..., 1, None] * p[:, None, 2]) * [w, h]
    ext = ref.bilinear_extremes_many(alpha8.astype(np.float64), 1, np.ascontiguousarray(pts))
    thr, eps = CUTOFF * 255, 1e-9 * 255

    def wrong(st):  # a known state the exact extremes contradict
        return ((st == 1) & (ext[:, 0] <= thr - eps)) | ((st == 0) & (ext[:, 1] > thr + eps))

    k_mo, k_om = ms < 2, om < 2
    mo_only, om_only, both = k_mo & ~k_om, k_om & ~k_mo, k_mo & k_om
    return {"judged": int(len(pos)),
            "meshopt_known_omaps_unknown_contradicted": int(np.sum(wrong(ms) & mo_only)),
            "meshopt_known_omaps_unknown_exact_agrees": int(np.sum(~wrong(ms) & mo_only)),
            "omaps_known_meshopt_unknown_contradicted": int(np.sum(wrong(om) & om_only)),
            "O_T_meshopt_contradicted": int(np.sum(wrong(ms) & both)),
            "O_T_omaps_contradicted": int(np.sum(wrong(om) & both))}


def summarize_matrix(m):
    known_mo, unk_mo = m[:2, :].sum(), m[2:, :].sum()
    d = {
        "micro_triangles": int(m.sum()),
        "matrix_meshopt_x_omaps": m.tolist(),  # rows: meshoptimizer T, O, UT, UO; columns: omaps
        "meshopt_known": int(known_mo), "meshopt_unknown": int(unk_mo),
        "omaps_known": int(m[:, :2].sum()), "omaps_unknown": int(m[:, 2:].sum()),
        "meshopt_known_omaps_unknown": int(m[:2, 2:].sum()),
        "omaps_known_meshopt_unknown": int(m[2:, :2].sum()),
        "meshopt_O_omaps_T": int(m[1, 0]), "meshopt_T_omaps_O": int(m[0, 1]),
        "both_unknown_other_hint": int(m[2, 3] + m[3, 2]),
        "identical": int(np.trace(m)),
    }
    return d


def ratio(a, b):
    return a / b if b > 0 else float("inf")


def parse_list(text, kind=int):
    return [kind(float(x)) for x in text.replace(" ", "").split(",") if x]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--triangles", default="100000,1000000", help="comma-separated triangle counts")
    ap.add_argument("--levels", default="4,6,8", help="comma-separated subdivision levels")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each contender per case (best kept)")
    ap.add_argument("--max-micro", type=float, default=5e8,
                    help="skip cases of more micro-triangles (N x 4^L) than this (default 5e8)")
    ap.add_argument("--check-states", choices=("smallest", "all", "none"), default="smallest",
                    help="compare states at the smallest N (default), at every N, or nowhere")
    ap.add_argument("--check-max-micro", type=float, default=5.2e8,
                    help="compare at most this many micro-triangles per case (the first triangles)")
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--spread", type=float, default=0.02, help="vertices within +-SPREAD of the centre (UV)")
    ap.add_argument("--json", metavar="FILE", help="also write the JSON line to FILE")
    ap.add_argument("--quick", action="store_true", help="smoke run: 100,000 triangles, level 4 only")
    a = ap.parse_args()
    if a.quick:
        a.triangles, a.levels = "100000", "4"
    counts, levels = sorted(set(parse_list(a.triangles))), sorted(set(parse_list(a.levels)))
    if a.repeat < 1 or not counts or not levels or min(counts) < 1 or min(levels) < 0 or max(levels) > 12:
        ap.error("--repeat >= 1, triangle counts >= 1 and levels 0..12 expected")

    # what the run needs: skip (exit 0) with the reason where it is absent
    missing = [why for ok, why in [
        (TEXTURES.parent.is_dir(), f"{TEXTURES.parent} is absent (../shared/data)"),
        (LEAF.is_file(), f"{LEAF} is absent"),
        ((ANCHOR / "build.sh").is_file(), f"{ANCHOR} (meshoptimizer's baker and driver) is absent"),
        (shutil.which("g++") is not None, "g++ is not installed (needed to build meshoptimizer's driver)"),
    ] if not ok]
    if missing:
        print("bench_omm_meshopt: skipped: " + "; ".join(missing))
        return 0

    default_threads = numba.config.NUMBA_NUM_THREADS
    omaps_cfgs = [("omaps", None), ("omaps-1t", 1)]  # (name, --threads)
    if default_threads != 2:
        omaps_cfgs.append(("omaps-2t", 2))
    name_2t = "omaps" if default_threads == 2 else "omaps-2t"
    env = dict(os.environ, OMAPS_PROGRESS="0")
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip()
    except OSError:
        commit = ""
    record = {"bench": "omm_meshopt", "texture": LEAF.name, "filter": "linear", "wrap": "clamp", "cutoff": CUTOFF,
              "format": "4state", "seed": a.seed, "spread": a.spread, "repeat": a.repeat, "omaps_commit": commit,
              "omaps_default_threads": default_threads, "cpu_count": os.cpu_count(),
              "load_average_start": os.getloadavg()[0], "cases": [], "skipped": []}

    with tempfile.TemporaryDirectory(prefix="bench_omm_meshopt_") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        driver = build_driver(tmp / "mo")
        print(f"meshoptimizer's driver built in {time.perf_counter() - t0:.1f} s ({ANCHOR})")
        alpha8 = load_alpha(LEAF).alpha8
        h, w = alpha8.shape
        print(f"{LEAF.name} {w}x{h}, bilinear, clamp, cut-off {CUTOFF}, 4-state; omaps on {default_threads} threads "
              f"(default) and 1{' and 2' if default_threads != 2 else ''}; meshoptimizer one thread; "
              f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; best of {a.repeat}, turns interleaved")

        rows = []
        for n in counts:
            tris = oak_triangles(n, a.seed, a.spread)
            area = texel_areas(tris, w, h)
            uvs, raw = tmp / f"uvs{n}.npy", tmp / f"tris{n}.f32"
            np.save(uvs, tris)
            tris.tofile(raw)
            print(f"\n{n:,} triangles: texel area mean {area.mean():.1f}, median {np.median(area):.1f}")
            one_uvs, one_raw = tmp / "one.npy", tmp / "one.f32"
            np.save(one_uvs, tris[:1])
            tris[:1].tofile(one_raw)
            for level in levels:
                micro = n * 4 ** level
                if micro > a.max_micro:
                    why = f"{micro:.3g} micro-triangles > --max-micro {a.max_micro:.3g}"
                    print(f"  level {level}: skipped ({why})")
                    record["skipped"].append({"triangles": n, "level": level, "reason": why})
                    continue
                omm_args = ["--level", str(level), "--format", "4state", "--filter", "linear", "--wrap", "clamp",
                            "--cutoff", str(CUTOFF), "--quiet"]
                mo_args = ["--level", str(level), "--format", "4", "--filter", "linear", "--address", "clamp",
                           "--cutoff", str(CUTOFF)]
                cmds = {}
                for name, th in omaps_cfgs:
                    extra = [] if th is None else ["--threads", str(th)]
                    cmds[name] = [sys.executable, "-m", "omaps", "omm", str(LEAF), str(uvs), "-o",
                                  str(tmp / f"out_{name}")] + omm_args + extra
                cmds["meshopt"] = [str(driver), "--tex", str(LEAF), "--tris", str(raw)] + mo_args
                # warm: numba's cache and the texture read once, one triangle each (untimed)
                for name, th in omaps_cfgs:
                    run_once([sys.executable, "-m", "omaps", "omm", str(LEAF), str(one_uvs), "-o", str(tmp / "warm")]
                             + omm_args + ([] if th is None else ["--threads", str(th)]), env)
                run_once([str(driver), "--tex", str(LEAF), "--tris", str(one_raw)] + mo_args)
                names = list(cmds)
                best = {k: [np.inf, np.inf] for k in names}
                mo_bake = np.inf
                for r in range(a.repeat):
                    for k in names[r % len(names):] + names[:r % len(names)]:
                        dt, cpu, out = run_once(cmds[k], env)
                        best[k][0], best[k][1] = min(best[k][0], dt), min(best[k][1], cpu)
                        if k == "meshopt" and " bake " in out:
                            mo_bake = min(mo_bake, float(out.split(" bake ")[1].split()[0]))
                case = {"triangles": n, "level": level, "micro_triangles": micro,
                        "wall_s": {k: v[0] for k, v in best.items()}, "cpu_s": {k: v[1] for k, v in best.items()},
                        "meshopt_bake_s": None if mo_bake == np.inf else mo_bake}
                mw, mc = best["meshopt"]
                case["cpu_ratio"] = {k: ratio(best[k][1], mc) for k in names if k != "meshopt"}
                case["wall_ratio"] = {k: ratio(best[k][0], mw) for k in names if k != "meshopt"}
                case["targets"] = {"cpu_ratio_le_1": case["cpu_ratio"]["omaps"] <= CPU_TARGET,
                                   "wall_2t_le_0.6": case["wall_ratio"][name_2t] <= WALL2_TARGET}

                # omaps' states: one hash per thread count (they must agree), then against meshoptimizer's
                res = {k: omm_files.read(tmp / f"out_{k}") for k, _ in omaps_cfgs}
                hashes = {k: states_hash(res[k], level) for k in res}
                case["omaps_states_sha256"] = hashes["omaps"]
                case["omaps_states_same_across_threads"] = len(set(hashes.values())) == 1
                if not case["omaps_states_same_across_threads"]:
                    case["omaps_states_sha256_by_threads"] = hashes
                st = res["omaps"].summary["statistics"]
                case["omaps_counts"] = {k: st[k] for k in ("transparent", "opaque", "unknown")}
                if a.check_states == "all" or (a.check_states == "smallest" and n == counts[0]):
                    k_tris = int(min(n, max(1, a.check_max_micro // 4 ** level)))
                    src = raw
                    if k_tris < n:
                        src = tmp / "check.f32"
                        tris[:k_tris].tofile(src)
                    dump = tmp / "mo_dump"
                    run_once([str(driver), "--tex", str(LEAF), "--tris", str(src)] + mo_args + ["--dump", str(dump)])
                    m, pos, ms, om = compare_states(res["omaps"], f"{dump}.states.u8", k_tris, level)
                    os.remove(f"{dump}.states.u8")
                    cmp_ = summarize_matrix(m)
                    cmp_["exact"] = exact_check(tris, level, alpha8, pos, ms, om)
                    cmp_["triangles"] = k_tris
                    if k_tris == n:  # the expansion agrees with omaps' own statistics
                        got = m.sum(axis=0)
                        want = [st["transparent"], st["opaque"], st["unknown_resolved"]["unknown_transparent"],
                                st["unknown_resolved"]["unknown_opaque"]]
                        if got.tolist() != want:
                            raise SystemExit(f"omaps' expanded states count {got.tolist()}, omm.json says {want}")
                    case["states"] = cmp_
                del res
                record["cases"].append(case)
                rows.append(case)
                c = case.get("states")
                print(f"  level {level}: omaps {best['omaps'][0]:.2f} s / {best['omaps'][1]:.2f} CPU-s, "
                      f"meshopt {mw:.2f} s / {mc:.2f} CPU-s"
                      + (f"; states: {c['micro_triangles']:,} compared" if c else ""))

    # the table
    others = [k for k, _ in omaps_cfgs]
    print(f"\nwhole processes, best of {a.repeat} (wall s / CPU-s); load average now {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores")
    head = (f"{'triangles':>10} {'L':>2} " + " ".join(f"{k + ' wall/CPU':>17}" for k in others)
            + f" {'meshopt wall/CPU':>17} " + " ".join(f"{k + ' CPU x':>12}" for k in others) + " "
            + " ".join(f"{k + ' wall x':>13}" for k in others) + "  targets")
    print(head)
    for c in rows:
        ws, cs = c["wall_s"], c["cpu_s"]
        t = c["targets"]
        print(f"{c['triangles']:>10,} {c['level']:>2} "
              + " ".join(f"{ws[k]:>8.2f}/{cs[k]:<8.2f}" for k in others)
              + f" {ws['meshopt']:>8.2f}/{cs['meshopt']:<8.2f} "
              + " ".join(f"{c['cpu_ratio'][k]:>12.2f}" for k in others) + " "
              + " ".join(f"{c['wall_ratio'][k]:>13.2f}" for k in others)
              + f"  CPU x<={CPU_TARGET}: {'met' if t['cpu_ratio_le_1'] else 'MISSED'}; "
              f"2-thread wall x<={WALL2_TARGET}: {'met' if t['wall_2t_le_0.6'] else 'MISSED'}")
    for s in record["skipped"]:
        print(f"{s['triangles']:>10,} {s['level']:>2}  skipped: {s['reason']}")
    print("(x: omaps / meshoptimizer; targets: omaps' CPU-s on its default threads <= 1.0 x meshoptimizer's; "
          f"omaps' wall on 2 threads ({name_2t}) <= {WALL2_TARGET} x meshoptimizer's)")

    checked = [c for c in rows if "states" in c]
    if checked:
        print("\nstates, meshoptimizer (mo) against omaps (micro-triangles; omaps exact with regions grown by "
              "GROW_TEXEL). 'wrong': a known state the exact bilinear extremes contradict (tests/reference.py)")
        print(f"{'triangles':>10} {'L':>2} {'compared':>13} {'mo known':>8} {'omaps known':>11} "
              f"{'mo known, omaps unk':>19} {'(mo wrong)':>10} {'omaps known, mo unk':>19} {'(omaps wrong)':>13} "
              f"{'mo O, omaps T':>13} {'mo T, omaps O':>13} {'UT<->UO':>9}")
        for c in checked:
            s = c["states"]
            x = s["exact"]
            tot = s["micro_triangles"]
            part = "" if x["judged"] == s["meshopt_known_omaps_unknown"] + s["omaps_known_meshopt_unknown"] + \
                s["meshopt_O_omaps_T"] + s["meshopt_T_omaps_O"] else f" (first {x['judged']:,} judged)"
            print(f"{s['triangles']:>10,} {c['level']:>2} {tot:>13,} {s['meshopt_known'] / tot:>8.2%} "
                  f"{s['omaps_known'] / tot:>11.2%} {s['meshopt_known_omaps_unknown']:>19,} "
                  f"{x['meshopt_known_omaps_unknown_contradicted']:>10,} {s['omaps_known_meshopt_unknown']:>19,} "
                  f"{x['omaps_known_meshopt_unknown_contradicted']:>13,} {s['meshopt_O_omaps_T']:>13,} "
                  f"{s['meshopt_T_omaps_O']:>13,} {s['both_unknown_other_hint']:>9,}{part}")
            if x["O_T_meshopt_contradicted"] or x["O_T_omaps_contradicted"]:
                print(f"{'':>13} O<->T: meshoptimizer wrong on {x['O_T_meshopt_contradicted']:,}, "
                      f"omaps wrong on {x['O_T_omaps_contradicted']:,}")
        if any(c["states"]["exact"]["omaps_known_meshopt_unknown_contradicted"]
               or c["states"]["exact"]["O_T_omaps_contradicted"] for c in checked):
            print("  OMAPS NOT CONSERVATIVE: some of its known micro-triangles are contradicted by the exact extremes")
    print("\nomaps states SHA-256 (per triangle, 4-state packed, specials expanded):")
    for c in rows:
        same = "same on every thread count" if c["omaps_states_same_across_threads"] else "DIFFER across thread counts"
        print(f"{c['triangles']:>10,} {c['level']:>2} {c['omaps_states_sha256']} ({same})")

    record["load_average_end"] = os.getloadavg()[0]
    line = json.dumps(record, separators=(",", ":"))
    print(line)
    if a.json:
        with open(a.json, "w") as f:
            f.write(line + "\n")
    bad = [c for c in rows if not c["omaps_states_same_across_threads"]]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
