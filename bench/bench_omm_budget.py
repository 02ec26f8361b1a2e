"""``omaps omm --budget``: the budgeted bake's time against the uniform level-4 bake it is
compared with, side by side, and its plan's quality before and after the pricing that bakes
each item once (coarser levels from the finest's meets, finer ones only where the greedy's
certificate asks).

For each scene: the uniform ``--level 4`` bake's data + record bytes are the budget B; then
``omaps omm SCENE --level 4`` and ``omaps omm SCENE --budget B`` run as separate processes in
turns (best of N each, so that load from other work hits them alike), and the ratio is printed.
The plan: expected alpha tests saved (omm.json's "budget" value, a fraction of the candidate
hits) and bytes stored, for the current pricing and for the reference one that bakes every
level up to --max-level for every item (``tests/reference_budget.py``, the pricing before the certificate, in-process, one run); the
two plans are compared triangle by triangle. With ``--trace``: alpha tests per ray of both bakes
(``omaps trace OUT.glb --schemes none,omm --size 128``).

    python bench/bench_omm_budget.py [--repeats 3] [--forest] [--no-reference] [--trace]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT.parent / "shared" / "data" / "scenes"
OMAPS = [sys.executable, "-m", "omaps"]
OMM = OMAPS + ["omm"]


def run(args) -> float:
    t = time.perf_counter()
    subprocess.run(OMM + [str(a) for a in args], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def summary(out: Path) -> dict:
    if out.suffix == ".glb":
        from omaps.omm.gltf_io import read_gltf

        return read_gltf(out).summary
    return json.loads((out / "omm.json").read_text())


def trace(out: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        js = Path(tmp) / "t.json"
        subprocess.run(OMAPS + ["trace", str(out), "--schemes", "none,omm", "--size", "128", "--json", str(js)],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        data = json.loads(js.read_text())
    return {name: round(r["alpha_tests_per_primary_ray"], 4) for name, r in data["schemes"].items()} | \
        {"differing_pixels": sum(r["differing_pixels"] for r in data["schemes"].values())}


def reference_plan(scene: Path, budget: int):
    """The reference pricing's plan (every level baked), and its time (in-process, one run)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import reference_budget as ref
    from omaps.omm import budget as cur
    from omaps.omm.inputs import scene_spec, load_geometries
    from omaps.omm.pipeline import OmmSettings

    geoms, _, _ = load_geometries(scene_spec(str(scene)))
    s = OmmSettings(budget=budget)
    t = time.perf_counter()
    plan_ref, rep_ref = ref.budget_levels(geoms, s, budget)
    t_ref = time.perf_counter() - t
    t = time.perf_counter()
    plan_cur, rep_cur = cur.budget_levels(geoms, s, budget)
    t_cur = time.perf_counter() - t
    same = all(np.array_equal(a[0], b[0]) and a[1].keys() == b[1].keys()
               and all(np.array_equal(a[1][k][0], b[1][k][0]) and np.array_equal(a[1][k][1], b[1][k][1]) for k in a[1])
               for a, b in zip(plan_cur, plan_ref))
    return rep_ref, rep_cur, t_ref, t_cur, same


def bench(scene: Path, repeats: int, reference: bool, do_trace: bool) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        uni, bud = Path(tmp) / "u4.glb", Path(tmp) / "budget.glb"
        run([scene, "--level", "4", "-o", uni, "--quiet"])  # warm-up, and the budget
        budget = int(summary(uni)["statistics"]["data_and_record_bytes"])
        run([scene, "--budget", budget, "-o", bud, "--quiet"])  # warm-up (numba caches)
        t_uni, t_bud = [], []
        for _ in range(repeats):
            t_uni.append(run([scene, "--level", "4", "-o", uni, "--quiet"]))
            t_bud.append(run([scene, "--budget", budget, "-o", bud, "--quiet"]))
        su, sb = summary(uni), summary(bud)
        print(f"{scene.name}: B = {budget} bytes (level-4 data + records)")
        print(f"  uniform level 4   best {min(t_uni):6.2f} s   (runs {', '.join(f'{t:.2f}' for t in t_uni)})")
        print(f"  budget B          best {min(t_bud):6.2f} s   (runs {', '.join(f'{t:.2f}' for t in t_bud)})")
        print(f"  ratio budget / uniform: {min(t_bud) / min(t_uni):.2f}x (best of {repeats}, interleaved)")
        b = sb["budget"]
        print(f"  plan (after):  expected tests saved {b['expected_tests_saved_fraction']:.6f}, "
              f"stored {b['stored_bytes']} bytes, levels {sb['statistics']['levels']}")
        print(f"  uniform level 4: known area {su['statistics']['known_area_fraction']:.4f}, "
              f"{su['statistics']['data_and_record_bytes']} bytes")
        if reference:
            rep_ref, rep_cur, t_ref, t_cur, same = reference_plan(scene, budget)
            print(f"  plan (before, every level priced): expected tests saved "
                  f"{rep_ref['expected_tests_saved_fraction']:.6f}, stored {rep_ref['stored_bytes']} bytes")
            print(f"  pricing in-process, one run each: before {t_ref:.2f} s, after {t_cur:.2f} s "
                  f"({t_ref / t_cur:.1f}x); plans identical triangle by triangle: {same}")
        if do_trace:
            print(f"  alpha tests per ray (trace --size 128): uniform {trace(uni)}, budget {trace(bud)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--forest", action="store_true", help="also the forest scene")
    ap.add_argument("--no-reference", action="store_true", help="skip the reference pricing (slow)")
    ap.add_argument("--trace", action="store_true", help="alpha tests per ray of both bakes")
    a = ap.parse_args()
    scenes = [SCENES / "palm.glb"] + ([SCENES / "forest.glb"] if a.forest else [])
    for s in scenes:
        bench(s, a.repeats, not a.no_reference, a.trace)


if __name__ == "__main__":
    main()
