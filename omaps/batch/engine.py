"""The Dask engine: the scheduler's check, the client and local cluster (started and stopped
quietly), and the loop that keeps inputs in flight and yields their records."""

from __future__ import annotations

import contextlib
import os
import sys
import time

from ..errors import InputError
from .task import bake_piece_task, run_one

# ---------------------------------------------------------------------------------------------
# scheduling

DEFAULT_PORT = 8786  # a Dask scheduler's port when the address names none
CONNECT_SECONDS = 2  # an unreachable scheduler: the error within this (a refused connection: at once)
HANDSHAKE_BYTES = 16  # a Dask scheduler speaks first: its handshake's length and frame count (8 bytes each)


def check_scheduler(address: str) -> None:
    """A ``tcp://`` scheduler address that takes a TCP connection and answers as a Dask scheduler
    does (it sends its handshake first: a message length, then a frame count), checked in
    ``CONNECT_SECONDS`` at most before any work (Dask's client would retry for its whole timeout,
    and a server that is not Dask's can make it fail with a traceback). A ``tls://`` address is
    checked for the connection only."""
    import socket
    import struct
    from urllib.parse import urlsplit

    if not address.startswith(("tcp://", "tls://")):
        return
    try:
        u = urlsplit(address)
        host, port = u.hostname, u.port or DEFAULT_PORT
    except ValueError as exc:
        raise InputError(f"not a scheduler address tcp://HOST:PORT ({exc})", address) from None
    if not host:
        raise InputError("not a scheduler address tcp://HOST:PORT (no host)", address)
    deadline = time.monotonic() + CONNECT_SECONDS
    got, connected = b"", False
    try:
        with socket.create_connection((host, port), timeout=CONNECT_SECONDS) as s:
            connected = True
            while address.startswith("tcp://") and len(got) < HANDSHAKE_BYTES:
                s.settimeout(max(deadline - time.monotonic(), 0.01))
                more = s.recv(HANDSHAKE_BYTES - len(got))
                if not more:
                    raise InputError("not a Dask scheduler (it closed the connection without a handshake)",
                                     address)
                got += more
    except TimeoutError:
        what = "it took the connection but sent no Dask handshake" if connected else "no answer"
        raise InputError(f"cannot connect to the Dask scheduler ({what} in {CONNECT_SECONDS} s)", address) from None
    except OSError as exc:
        raise InputError(f"cannot connect to the Dask scheduler ({exc.strerror or exc})", address) from None
    if got:
        length, frames = struct.unpack("<QQ", got)
        if not (0 < length < 1 << 24 and 0 < frames < 64):
            raise InputError("not a Dask scheduler (its first bytes are not a Dask handshake)", address)


def _children() -> set:
    import psutil

    with contextlib.suppress(psutil.Error):
        return {c.pid for c in psutil.Process().children(recursive=True)}
    return set()


def _stop_quietly(stack: contextlib.ExitStack, before: set, clusters: set) -> None:
    """Tear the Dask client and cluster down after Ctrl-C (or any early stop), whatever state
    their start-up is in, printing nothing: their processes (this batch's own: those started since
    ``before``) are killed, then the client, the cluster (``clusters``: those begun since, even
    half started) and the event loop are closed with this process's stderr on /dev/null, and Dask's,
    asyncio's and tornado's logs are turned off (for good: the batch is over, and their tasks may
    still log as they are collected). A second Ctrl-C meanwhile is ignored."""
    import gc
    import logging

    import psutil

    from ..workers import sigint_ignored

    with sigint_ignored():
        for name in ("distributed", "asyncio", "tornado", "dask"):  # for good: their tasks may log later
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        sys.stderr.flush()
        saved = os.dup(2)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        try:
            procs = []
            for pid in _children() - before:
                with contextlib.suppress(psutil.Error):
                    p = psutil.Process(pid)
                    p.kill()
                    procs.append(p)
            psutil.wait_procs(procs, timeout=5)
            for c in clusters:
                with contextlib.suppress(BaseException):
                    c.close(timeout=2)
                if "_cluster_info" not in vars(c):  # interrupted inside its constructor: no name, which
                    c._cluster_info = {"name": f"interrupted-{id(c)}"}  # Dask's equality (and so discard) reads
                type(c)._instances.discard(c)  # (else Dask's exit handler closes it again, for 10 s)
            with contextlib.suppress(BaseException):
                stack.close()
            gc.collect()
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            os.close(devnull)


CLOSE_SECONDS = 5  # closing the client or the cluster (a cluster whose workers were killed can wait for ever)


def _close(thing) -> None:
    """Close a Dask client or cluster within ``CLOSE_SECONDS``; the batch's work is done (or
    interrupted) by then, so a slow or failed close is not its error."""
    with contextlib.suppress(Exception):
        thing.close(timeout=CLOSE_SECONDS)


# a local worker computes on one core: its numba kernels use one thread (else each worker's parallel
# kernels would take every core, and two workers oversubscribe them)
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
# the local cluster's Dask settings: workers may start processes (not daemons); no statistical
# profiler (it samples every thread every 10 ms), GIL monitor (every 1 ms) or disk counters, and the
# event loops' tick (every 20 ms), system monitor (500 ms) and memory monitor (100 ms) slowed: an idle
# cluster cost a tenth of a core on a loaded 2-core machine (a fifth of a short job's CPU time), a
# fiftieth with these; nobody reads the dashboard here. Dask's default worker environment sets
# MALLOC_TRIM_THRESHOLD_, and any such setting turns off glibc's adaptive mmap threshold: every array
# over 128 KiB is then mapped fresh and unmapped when freed, its pages faulted in again each time (on
# the eval library the workers' system time was 5 times the serial run's, and the median input took
# 1.27 times its serial time, 1.09 without): the workers keep glibc's defaults, as a serial run does
# (None unsets it; Dask's thread limits stay)
LOCAL_CONFIG = {"distributed.worker.daemon": False, "distributed.worker.profile.enabled": False,
                "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                "distributed.admin.system-monitor.gil.enabled": False,
                "distributed.admin.system-monitor.disk": False, "distributed.admin.tick.interval": "1s",
                "distributed.admin.system-monitor.interval": "5s",
                "distributed.worker.memory.monitor-interval": "1s"}


@contextlib.contextmanager
def dask_client(scheduler: str):
    """A distributed Client: ``local`` starts a LocalCluster (one single-threaded worker process
    per core, its numba kernels on one thread: ``WORKER_ENV``; workers may start the command's own
    worker processes), else connects to the address.

    Dask's event loop thread is started with SIGINT blocked, so the cluster's processes (spawned
    from it) never see Ctrl-C; this thread does, at any moment (start-up included), and the
    client and cluster are then stopped without a word (``_stop_quietly``)."""
    import logging

    import dask
    from distributed import Client, LocalCluster
    from distributed.deploy.spec import SpecCluster
    from distributed.utils import LoopRunner

    from ..workers import sigint_blocked, start_resource_tracker

    start_resource_tracker()  # (before the list of processes that are not the batch's own)
    before, known = _children(), set(SpecCluster._instances)
    stack = contextlib.ExitStack()
    try:
        with sigint_blocked():
            runner = LoopRunner()
            runner.start()
        stack.callback(runner.stop)
        if scheduler == "local":
            n = max(1, os.cpu_count() or 1)
            with dask.config.set(LOCAL_CONFIG):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address="127.0.0.1:0",  # (loopback only, as the scheduler)
                                       silence_logs=logging.CRITICAL, loop=runner.loop, env=WORKER_ENV)
            stack.callback(_close, cluster)
            client = Client(cluster, loop=runner.loop)
            stack.callback(_close, client)
        else:
            try:
                client = Client(scheduler, timeout="5s", loop=runner.loop)
            except Exception as exc:  # (a server that is not Dask's can fail its handshake any way)
                raise InputError(f"cannot connect to the Dask scheduler ({type(exc).__name__}: {exc})",
                                 scheduler) from None
            stack.callback(_close, client)
    except BaseException:  # Ctrl-C during the start-up, or no connection
        _stop_quietly(stack, before, set(SpecCluster._instances) - known)
        raise
    try:
        yield client
    except BaseException as exc:
        if isinstance(exc, Exception):
            stack.close()
        else:  # Ctrl-C (or the batch's loop stopped early): the workers may be mid-task
            _stop_quietly(stack, before, set(SpecCluster._instances) - known)
        raise
    else:
        stack.close()


def dask_pieces(client, window: int):
    """A ``build_split`` runner on a Dask client: the pieces submitted (at most ``window`` in
    flight), each distinct alpha test sent to the cluster once, the results yielded in order."""
    import collections

    def run(jobs):
        sent: dict[int, object] = {}  # id(test) -> its future on the cluster
        todo = collections.deque(jobs)
        flight: collections.deque = collections.deque()
        try:
            while todo or flight:
                while todo and len(flight) < window:
                    test, *rest = todo.popleft()
                    if id(test) not in sent:
                        sent[id(test)] = client.scatter(test, hash=False, broadcast=True)  # (no worker favoured)
                    flight.append(client.submit(bake_piece_task, sent[id(test)], *rest, pure=False,
                                                key=f"omaps-piece-{os.urandom(8).hex()}"))
                fut = flight.popleft()
                res = fut.result()
                fut.release()
                yield res
        finally:
            for f in list(flight) + list(sent.values()):
                f.release()

    return run


PIECES_PER_THREAD = 4  # a split scene: its bake in this many pieces per worker thread (they differ in cost)


def run_all(command, jobs, scheduler: str, window: int | None, progress: bool, split: bool = False):
    """Run ``jobs`` (lists of ``run_one``'s arguments) and yield their records as they finish.
    ``split``: one input after the other, each omm bake in pieces (``PIECES_PER_THREAD`` per
    worker thread) run on the scheduler's workers, packed and written here (``bake_split``)."""
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), desc=f"batch {command}", unit="input", disable=not progress, leave=False)
    try:
        if scheduler == "none":
            for j in jobs:
                rec = run_one(*j, split=(None, PIECES_PER_THREAD) if split else None)
                bar.update()
                yield rec
            return
        from distributed import as_completed

        with dask_client(scheduler) as client:
            threads = sum(client.nthreads().values()) or 1
            limit = window or 2 * threads
            if split:  # one input at a time, its pieces on every worker
                for j in jobs:
                    rec = run_one(*j, split=(dask_pieces(client, limit), PIECES_PER_THREAD * threads))
                    bar.update()
                    yield rec
                return
            todo = list(jobs)
            todo.reverse()
            pending = as_completed()
            inputs = {}

            def submit():
                j = todo.pop()
                fut = client.submit(run_one, *j, pure=False, key=f"omaps-batch-{command}-{os.urandom(8).hex()}")
                inputs[fut.key] = j[2]
                pending.add(fut)

            while todo and pending.count() < limit:
                submit()
            for fut in pending:
                try:
                    rec = fut.result()
                except Exception as exc:  # a worker that died (killed, out of memory): recorded, the rest go on
                    rec = {"input": inputs[fut.key], "status": "error",
                           "error": f"{inputs[fut.key]}: worker failed: {type(exc).__name__}: {exc}"}
                inputs.pop(fut.key, None)
                fut.release()
                bar.update()
                yield rec
                if todo:
                    submit()
    finally:
        bar.close()
