"""``omaps batch eval`` on a real loopback Dask cluster (``dask scheduler`` and two ``dask worker
--nthreads 1 --no-nanny`` processes on 127.0.0.1) with one of the two workers SIGKILLed after a
third of the inputs, against the same cluster left alone and a serial run, side by side in one
run: whether the batch completes, whether every output is identical to the serial run's, and the
wall time with the kill against without it.

    python bench/bench_batch_faults.py                  # the 368 textures: 46 real ones x 8 orientations
    python bench/bench_batch_faults.py --repeat 2 --schemes sq16,vq4

The library is built at run time in a temporary folder from the shared textures
(``bench_batch.texture_library``: each texture of at least 64 px in its 8 flips and quarter
turns, longer side at most 384 px). Each round runs serial, the cluster without a fault and the
cluster with the kill (a fresh cluster for each cluster run; the order turns each round). The
kill comes when a third of the inputs have their completion markers (a bench, not a test: the
moment is the markers' count, whatever the machine's speed); the killed worker stays dead, as a
pre-empted node, so the remaining two thirds run on one worker. No assertion on times.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' loopback cluster

from bench_batch import SCHEMES, compare, loadavg, texture_library  # noqa: E402
from cluster import LoopbackCluster  # noqa: E402


def markers(out: str) -> int:
    try:
        return sum(f.endswith(".json") and not f.startswith(".") for f in os.listdir(os.path.join(out, ".batch")))
    except OSError:
        return 0


def batch(lib: str, out: str, scheduler: str, schemes: str, kill=None, after: int = 0) -> tuple[float, int, str]:
    """``omaps batch eval`` as a user runs it: (seconds, exit code, stderr). ``kill``: called once
    ``after`` inputs have their markers."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "omaps", "batch", "eval", lib, "-o", out, "--scheduler", scheduler,
                          "--schemes", schemes, "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True)
    if kill is not None:
        while p.poll() is None and markers(out) < after:
            time.sleep(0.05)
        kill()
    err = p.communicate()[1]
    return time.perf_counter() - t0, p.returncode, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1, help="rounds (the order of the three runs turns each round)")
    ap.add_argument("--schemes", default=SCHEMES, help="the schemes evaluated")
    ap.add_argument("--max-side", type=int, default=384, help="the textures' longer side, at most")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="omaps-bench-faults-"))
    try:
        lib = texture_library(tmp / "lib", 8, [a.max_side])[0]
        n = sum(len(fs) for _, _, fs in os.walk(lib))
        print(f"omaps batch eval: {n} inputs, {len(a.schemes.split(','))} schemes; {os.cpu_count()} cores; "
              f"kill one of two workers after {n // 3} inputs")
        times: dict[str, list[float]] = {"serial": [], "cluster": [], "cluster, one worker killed": []}
        same = []
        for r in range(a.repeat):
            order = list(times) if r % 2 == 0 else list(times)[::-1]
            outs = {}
            for key in order:
                out = str(tmp / f"out_{r}_{len(outs)}")
                before = loadavg()
                if key == "serial":
                    dt, rc, err = batch(lib, out, "none", a.schemes)
                    left = ""
                else:
                    with LoopbackCluster(tmp / f"cluster_{r}_{len(outs)}") as c:
                        kill = (lambda c=c: c.kill("worker1")) if key.endswith("killed") else None
                        dt, rc, err = batch(lib, out, c.address, a.schemes, kill, n // 3)
                        left = f", workers at the end: {c.workers()}"
                lost = sum("left the cluster" in line for line in err.splitlines())
                times[key].append(dt)
                outs[key] = out
                print(f"  round {r + 1} {key:27s}: {dt:7.2f} s, exit {rc}, {lost} lost-worker line{left} "
                      f"(loadavg {before} -> {loadavg()})", flush=True)
                if rc != 0:
                    print(err)
            for key in outs:
                if key != "serial":
                    ok, text = compare(outs["serial"], outs[key])
                    same.append(ok)
                    print(f"  round {r + 1} {key} vs serial: {text}", flush=True)
            for out in outs.values():
                shutil.rmtree(out, ignore_errors=True)
        best = {k: min(v) for k, v in times.items()}
        print(f"best times: serial {best['serial']:.2f} s, cluster {best['cluster']:.2f} s, with the kill "
              f"{best['cluster, one worker killed']:.2f} s ({best['cluster, one worker killed'] / best['cluster']:.2f}x "
              f"the cluster left alone)")
        print("outputs identical to serial in every run" if all(same) else "OUTPUTS DIFFER")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
