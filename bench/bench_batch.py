"""``omaps batch``: serial (``--scheduler none``) against a Dask LocalCluster (``--scheduler local``,
one worker process per core) on a library-sized job, side by side in one run, and whether their
outputs are identical.

    python bench/bench_batch.py                 # eval: the library of textures, every scheme family
    python bench/bench_batch.py omm             # omm: dozens of scenes (the palm with transformed UVs)
    python bench/bench_batch.py split           # one large scene (the forest): split into tasks or not
    python bench/bench_batch.py eval --repeat 3 --variants 8 --max-side 384,192

The library is built at run time in a temporary folder from the shared data (never kept):

* ``eval``: each real texture of at least 64 px, in ``--variants`` of its 8 flips and rotations,
  rescaled so that its longer side is at most ``--max-side`` px, at each size given (by default 384
  and 192 px, as two mips; one of the 46 textures is too small for the second: 91 x 8 = 728 inputs),
  evaluated with ``SCHEMES`` (square maps, micromaps, their lossless trees, the texel map, every
  codec with its default and its -paper encoder: 27 schemes);
* ``omm``: ``--scenes`` copies of ``palm.glb`` whose UVs are mirrored, rotated by quarter turns
  and shrunk into one of the texture's quadrants (``omm --level 5``);
* ``split``: ``forest.glb`` alone (``omm --level 4``): serial, the local cluster with the scene as
  one task, and the local cluster with ``--split`` (its bake in pieces on both workers).

Each round runs serial then local (alternating which goes first), each as a user runs it (a
process of its own: interpreter, import and cluster start-up are part of both timings); it prints
each run's seconds and CPU-seconds (its processes', workers included), the local / serial
speed-up (each round's, their median, and that of the best times), /proc/loadavg before and
after, and whether every output file is identical (eval JSONs
byte for byte; omm folders byte for byte; the summaries' figures, leaving out timings). No
assertion on times (the machine may be shared).

The serial run's numba kernels (the micromap and pair-square bakers, the resolve) already run on
every core, so a local cluster on the same cores wins only the rest; ``--one-thread`` adds a
serial run with numba on one thread (one core, as each local worker), against which the cluster's
own scaling shows.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SHARED = Path(os.environ.get("OMAPS_SHARED", Path(__file__).resolve().parents[2] / "shared")) / "data"
# every scheme family; each vector-quantisation codec with its default and its -paper encoder
SCHEMES = ("sq1,sq2,sq4,sq8,sq16,sq32,sq64,sq128,tri0,tri1,tri2,tri3,tri4,tri5,tri6,succinct4,csm4,texel,"
           "vq2,vq2-paper,vq4,vq4-paper,vq4x64,vq4x64-paper,vq4-synth,vq4-synth-paper,wavelet3")


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def texture_library(folder: Path, variants: int, max_sides: list[int]) -> list[str]:
    """The real textures of at least 64 px, each in ``variants`` of its 8 flips and rotations, at
    each of ``max_sides`` (rescaled, bilinear as an engine's mips, so that the longer side is at
    most that; a size that leaves the texture as the larger one did is not repeated)."""
    import numpy as np
    from PIL import Image

    src = sorted(p for p in (SHARED / "textures").glob("*.png") if min(Image.open(p).size) >= 64)
    if not src:
        raise SystemExit(f"no shared textures under {SHARED / 'textures'}")
    folder.mkdir(parents=True)
    for p in src:
        full = np.asarray(Image.open(p).convert("L"))
        shape = None  # the texture's at the previous (larger) size
        for side in sorted(set(max_sides), reverse=True):
            a, s = full, max(full.shape)
            if s > side:
                h, w = (max(1, round(x * side / s)) for x in a.shape)
                a = np.asarray(Image.fromarray(a).resize((w, h), Image.BILINEAR))
            if a.shape == shape:
                continue  # not smaller than at the larger size: the same texture
            shape = a.shape
            for k in range(variants):  # the dihedral group: k % 4 quarter turns, then a mirror for k >= 4
                v = np.rot90(a, k % 4)
                v = v[:, ::-1] if k >= 4 else v
                Image.fromarray(np.ascontiguousarray(v)).save(folder / f"{p.stem}__s{side}__d{k}.png")
    return [str(folder)]


def scene_library(folder: Path, n: int) -> list[str]:
    """``n`` copies of palm.glb, each with its UVs mirrored / turned (about the centre of the
    texture) and scaled into a quadrant: different micromaps, the same real texture."""
    import numpy as np
    import pygltflib

    src = SHARED / "scenes" / "palm.glb"
    folder.mkdir(parents=True)
    for i in range(n):
        g = pygltflib.GLTF2().load(str(src))
        blob = bytearray(g.binary_blob())
        done = set()
        for mesh in g.meshes:
            for prim in mesh.primitives:
                acc = prim.attributes.TEXCOORD_0
                if acc is None or acc in done:
                    continue
                done.add(acc)
                a = g.accessors[acc]
                bv = g.bufferViews[a.bufferView]
                off = (bv.byteOffset or 0) + (a.byteOffset or 0)
                stride = bv.byteStride or 8
                assert a.componentType == 5126, "float UVs expected"
                uv = np.ndarray((a.count, 2), np.float32, blob, off, (stride, 4)).copy()
                c = uv - 0.5
                for _ in range(i % 4):
                    c = np.stack([-c[:, 1], c[:, 0]], axis=1)
                if (i // 4) % 2:
                    c[:, 0] = -c[:, 0]
                scale = 1.0 if i < 8 else 0.5
                quad = np.array([(i // 8) % 2, (i // 16) % 2], np.float32) * 0.5 if scale < 1 else 0.0
                uv2 = ((c + 0.5) * scale + quad).astype(np.float32)
                view = np.ndarray((a.count, 2), np.float32, blob, off, (stride, 4))
                view[:] = uv2
                a.min, a.max = uv2.min(axis=0).tolist(), uv2.max(axis=0).tolist()
        g.set_binary_blob(bytes(blob))
        g.save(str(folder / f"palm_{i:02d}.glb"))
    return [str(folder)]


def run(command: str, paths, opts, scheduler: str, out: str, env=None) -> tuple[float, float, dict]:
    """The command as a user runs it: (seconds, CPU seconds of it and its processes, the
    summary's totals)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "omaps", "batch", command, *paths, "-o", out, "--scheduler", scheduler,
                        "--quiet", *opts], capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if r.returncode not in (0, 1):
        raise SystemExit(f"omaps batch {command} --scheduler {scheduler} exited {r.returncode}:\n{r.stderr}")
    with open(os.path.join(out, "summary.json")) as f:
        tot = json.load(f)["totals"]
    return dt, cpu, tot


def summary_figures(out: str) -> list:
    """Each input's output, status and figures from summary.json (timings left out)."""
    with open(os.path.join(out, "summary.json")) as f:
        inputs = json.load(f)["inputs"]
    return [(r["output"], r["status"], r.get("figures"), r.get("error")) for r in inputs]


def different_files(a: str, b: str) -> list[str]:
    """Files under a and b (summaries and markers aside) that differ byte for byte or exist in one only."""
    def files(root):
        return {os.path.relpath(os.path.join(d, f), root) for d, ds, fs in os.walk(root) for f in fs
                if not f.startswith("summary.") and ".batch" not in Path(d).relative_to(root).parts}

    fa, fb = files(a), files(b)
    diff = sorted(fa ^ fb)
    diff += [f for f in sorted(fa & fb) if not filecmp.cmp(os.path.join(a, f), os.path.join(b, f), shallow=False)]
    return diff


def compare(a: str, b: str) -> tuple[bool, str]:
    files = different_files(a, b)
    same_summary = summary_figures(a) == summary_figures(b)
    n = sum(len(fs) for _, _, fs in os.walk(a))
    if not files and same_summary:
        return True, f"identical outputs ({n} files, summaries' figures equal)"
    return False, f"DIFFERENT: {len(files)} files differ ({files[:5]}), summaries' figures equal: {same_summary}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("job", nargs="?", default="eval", choices=("eval", "omm", "split"))
    ap.add_argument("--repeat", type=int, default=1, help="rounds of serial and local (alternating order)")
    ap.add_argument("--variants", type=int, default=8, help="eval: flips / rotations of each texture (1..8)")
    ap.add_argument("--max-side", default="384,192",
                    help="eval: longer side of each texture, at most; several (comma-separated): each texture at each")
    ap.add_argument("--scenes", type=int, default=32, help="omm: transformed copies of the palm")
    ap.add_argument("--schemes", default=SCHEMES, help="eval: the schemes")
    ap.add_argument("--level", type=int, default=None, help="omm and split: the subdivision level (5; split 4)")
    ap.add_argument("--one-thread", action="store_true",
                    help="also run serially with numba on one thread (NUMBA_NUM_THREADS=1): one core, as a worker")
    ap.add_argument("--keep", metavar="DIR", help="build the library and outputs here (kept) instead of a temp folder")
    a = ap.parse_args()
    tmp = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="omaps-bench-batch-"))
    try:
        if a.job == "eval":
            sides = [int(x) for x in a.max_side.split(",")]
            command, paths, opts = "eval", texture_library(tmp / "lib", a.variants, sides), ["--schemes", a.schemes]
        elif a.job == "omm":
            command, paths, opts = "omm", scene_library(tmp / "lib", a.scenes), ["--level", str(a.level or 5)]
        else:
            command, paths, opts = "omm", [str(SHARED / "scenes" / "forest.glb")], ["--level", str(a.level or 4)]
        n_in = sum(len(fs) for _, _, fs in os.walk(paths[0])) if os.path.isdir(paths[0]) else len(paths)
        print(f"omaps batch {command}: {n_in} inputs, {' '.join(opts)}; {os.cpu_count()} cores")
        runs = {"none": [], "local": []} if a.job != "split" else {"none": [], "local": [], "local --split": []}
        if a.one_thread:
            runs["none 1-thread"] = []
        cpus: dict[str, list[float]] = {k: [] for k in runs}
        verdicts = []
        for r in range(a.repeat):
            order = list(runs) if r % 2 == 0 else list(runs)[::-1]
            outs = {}
            for key in order:
                sched, *extra = key.split()
                env = None
                if extra == ["1-thread"]:  # numba's kernels on one thread: one core, as each local worker
                    extra, env = [], dict(os.environ, NUMBA_NUM_THREADS="1")
                out = str(tmp / f"out_{r}_{key.replace(' ', '').replace('-', '')}")
                shutil.rmtree(out, ignore_errors=True)
                before = loadavg()
                dt, cpu, tot = run(command, paths, opts + extra, sched, out, env)
                runs[key].append(dt)
                cpus[key].append(cpu)
                outs[key] = out
                print(f"  round {r + 1} --scheduler {key:14s}: {dt:7.2f} s, {cpu:7.1f} CPU-s, {tot['ok']} ok, "
                      f"{tot['error']} errors (loadavg {before} -> {loadavg()})", flush=True)
            ref = outs["none"]
            for key in outs:
                if key != "none":
                    same, text = compare(ref, outs[key])
                    verdicts.append(same)
                    print(f"  round {r + 1} {key} vs serial: {text}", flush=True)
            for out in outs.values():
                shutil.rmtree(out, ignore_errors=True)
        best = {k: min(v) for k, v in runs.items()}
        for k in runs:
            if k.startswith("local"):
                ratios = [s / t for s, t in zip(runs["none"], runs[k])]
                print(f"local/serial speed-up ({k}): rounds {', '.join(f'{x:.2f}x' for x in ratios)}, median "
                      f"{statistics.median(ratios):.2f}x; best times {best['none'] / best[k]:.2f}x (serial "
                      f"{best['none']:.2f} s, {k} {best[k]:.2f} s); CPU-s {statistics.median(cpus[k]):.1f} against "
                      f"{statistics.median(cpus['none']):.1f} (medians)")
                if "none 1-thread" in best:
                    print(f"  against the one-thread serial run: {best['none 1-thread'] / best[k]:.2f}x "
                          f"({best['none 1-thread']:.2f} s)")
        print("outputs identical in every round" if all(verdicts) else "OUTPUTS DIFFER")
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
