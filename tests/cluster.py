"""A real multi-process Dask cluster on loopback for the batch's fault tests: ``dask scheduler``
and ``dask worker`` processes (one thread each) that the test starts on 127.0.0.1, kills when it
decides, and always tears down."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

LIMIT = 120  # seconds: a hang guard for the cluster's start only (never a result)


class LoopbackCluster:
    """``dask scheduler`` and ``workers`` ``dask worker --nthreads 1`` processes on 127.0.0.1,
    each in its own session (its nanny's worker process with it): ``nanny`` False runs the
    workers without a nanny (a killed worker stays dead, as a pre-empted node), True with one (a
    killed worker process is started again, as a worker killed by the kernel's OOM killer).
    ``env``: the workers' extra environment (the batch's test gate); ``scheduler_env``: the
    scheduler's (Dask settings such as ``DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES``). The logs
    are in ``folder``."""

    def __init__(self, folder, workers: int = 2, nanny: bool = False, env: dict | None = None,
                 scheduler_env: dict | None = None):
        self.folder = os.fspath(folder)
        os.makedirs(self.folder, exist_ok=True)
        self.n, self.nanny = workers, nanny
        self.env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                    "DASK_DISTRIBUTED__WORKER__DAEMON": "False", **(env or {})}
        self.scheduler_env = {**os.environ, **(scheduler_env or {})}
        self.procs: dict[str, subprocess.Popen] = {}
        self.file = os.path.join(self.folder, "scheduler.json")
        self.address = None

    def _start(self, name, args, env):
        log = open(os.path.join(self.folder, f"{name}.log"), "wb")
        self.procs[name] = subprocess.Popen([sys.executable, "-m", "dask", *args], env=env, stdout=log,
                                            stderr=subprocess.STDOUT, start_new_session=True)
        log.close()

    def __enter__(self):
        if os.path.exists(self.file):  # (a cluster started before in the same folder)
            os.remove(self.file)
        try:
            self._start("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                      "--scheduler-file", self.file], self.scheduler_env)
            deadline = time.monotonic() + LIMIT
            while not os.path.exists(self.file):
                assert self.procs["scheduler"].poll() is None, self.log("scheduler")
                assert time.monotonic() < deadline, "the scheduler did not start (hang guard)"
                time.sleep(0.05)
            time.sleep(0.05)  # (written whole: Dask writes the file in one call)
            with open(self.file) as f:
                self.address = json.load(f)["address"]
            assert self.address.startswith("tcp://127.0.0.1:"), self.address
            for i in range(self.n):
                self._start(f"worker{i}", ["worker", "--scheduler-file", self.file, "--nthreads", "1",
                                           "--host", "127.0.0.1", "--no-dashboard", "--name", f"w{i}",
                                           "--nanny" if self.nanny else "--no-nanny"], self.env)
            self.wait_for_workers(self.n)
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()

    def workers(self) -> int:
        """The scheduler's count of workers now (asked through a Dask client)."""
        from distributed import Client

        with Client(self.address, timeout="10s") as c:
            return len(c.scheduler_info(n_workers=-1)["workers"])

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout="10s") as c:
            c.wait_for_workers(n, timeout=LIMIT)

    def kill(self, name: str) -> None:
        """SIGKILL a process of the cluster (``scheduler``, ``worker0``…) and its session."""
        p = self.procs[name]
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait()

    def log(self, name: str) -> str:
        with open(os.path.join(self.folder, f"{name}.log"), errors="replace") as f:
            return f.read()

    def stop(self) -> None:
        for name in list(self.procs):
            self.kill(name)


def kill_pid(pid: int) -> None:
    """SIGKILL one process (a worker process whose id the batch's test gate wrote)."""
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
