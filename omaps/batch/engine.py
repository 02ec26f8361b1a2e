"""The Dask engine: the scheduler's check, the client and local cluster (started and stopped
quietly), and the loop that keeps inputs in flight and yields their records."""

from __future__ import annotations

import contextlib
import os
import sys
import time

from .. import interrupt
from ..errors import InputError
from .task import BatchStopped, bake_piece_task, run_one

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
def _dask_logs_quiet():
    """Dask's client logs nothing while the batch runs (a lost scheduler would print its
    reconnection's tracebacks): the batch says what happened itself, in one line."""
    import logging

    names = ["distributed"] + [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for n, level in levels.items():
            log = logging.getLogger(n)
            if log.level <= logging.CRITICAL + 1:  # (unless turned off for good meanwhile: _stop_quietly)
                log.setLevel(level)


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
    stack.enter_context(_dask_logs_quiet())
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


def dask_pieces(client, window: int, watch):
    """A ``build_split`` runner on a Dask client: the pieces submitted (at most ``window`` in
    flight), each distinct alpha test sent to the cluster once, the results yielded in order
    (awaited by ``watch``, a ``ClusterWatch``: the batch stops if the cluster is lost)."""
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
                res = watch.result(fut, [f.key for f in flight])
                fut.release()
                yield res
        finally:
            for f in list(flight) + list(sent.values()):
                f.release()

    return run


PIECES_PER_THREAD = 4  # a split scene: its bake in this many pieces per worker thread (they differ in cost)


# errors that mean the output disk is full: every input after it would fail alike, so the batch
# stops taking new ones (those in flight finish or fail on their own)
DISK_FULL = ("ENOSPC", "EDQUOT")
POLL_SECONDS = 0.5  # the loop's wait for a finished input between its checks of the cluster
RPC_SECONDS = 5  # a question to the scheduler (its workers, what they run): no answer in this = not now
NO_WORKERS_SECONDS = 120  # inputs waiting and no worker in the cluster this long: the batch stops


class Progress:
    """The progress bar: inputs done, and how many of them failed; inputs run again because
    their worker was lost; one warning line per lost worker."""

    def __init__(self, command: str, total: int, show: bool):
        from tqdm import tqdm

        self.bar = tqdm(total=total, desc=f"batch {command}", unit="input", disable=not show, leave=False)
        self.failed = self.retried = 0

    def done(self, rec: dict) -> None:
        self.failed += rec["status"] == "error"
        self._postfix()
        self.bar.update()

    def again(self, n: int) -> None:
        self.retried += n
        self._postfix()

    def _postfix(self) -> None:
        self.bar.set_postfix_str(f"{self.failed} failed, {self.retried} retried", refresh=False)

    def warn(self, text: str) -> None:
        import warnings

        from tqdm import tqdm

        from .summary import BatchWarning

        with tqdm.external_write_mode(file=sys.stderr):
            warnings.warn(text, BatchWarning, stacklevel=3)

    def close(self) -> None:
        self.bar.close()


def disk_full(rec: dict) -> bool:
    """An input's record whose error is a full output disk (``DISK_FULL``)."""
    return rec.get("errno") in DISK_FULL


def _stop_for_disk(rec: dict) -> str:
    return (f"the output disk is full ({rec['error']}); free space and run the same command again "
            "to finish the rest")


class ClusterWatch:
    """What the batch's loop checks on a Dask cluster between finished inputs: the scheduler
    still there (else ``BatchStopped``, never a wait without end), each worker that leaves
    (reported once, with the inputs it was running: Dask runs them again), and a cluster left
    with no workers for ``NO_WORKERS_SECONDS``."""

    def __init__(self, client, scheduler: str, progress: Progress):
        self.client, self.scheduler, self.progress = client, scheduler, progress
        self.workers: dict[str, set] = {}  # worker address -> the batch's keys it ran at the last look
        self.empty_since: float | None = None
        self.last = 0.0
        self.look()

    def check(self) -> None:
        """``BatchStopped`` if the client has lost its scheduler (Dask closes it when it cannot
        reconnect in the client's timeout); ``KeyboardInterrupt`` again if a Ctrl-C came
        and was lost on its way (``interrupt``)."""
        interrupt.check()
        if self.client.status in ("closing", "closed"):
            raise BatchStopped(self.cancelled(None))

    def cancelled(self, exc) -> str:
        """Why the batch stops when Dask cancelled its tasks (``exc``; None: the client closed):
        the scheduler lost, or Dask's reason."""
        from concurrent.futures import CancelledError

        if exc is None or not isinstance(exc, CancelledError) or "connection" in str(exc) or \
                self.client.status != "running":
            return (f"lost the Dask scheduler {self.scheduler}; start the cluster again and run the same "
                    "command to finish the rest")
        return f"the Dask scheduler {self.scheduler} cancelled the batch's tasks ({str(exc).splitlines()[0]})"

    def result(self, fut, keys=()):
        """A future's result, looking at the cluster while it comes (``keys``: the batch's other
        tasks in flight). Its data lives on a worker: one lost meanwhile makes Dask compute it
        again, which needs a worker. Its result lost with the scheduler: ``BatchStopped``."""
        from concurrent.futures import CancelledError

        from distributed.comm import CommClosedError

        while True:
            try:
                return fut.result(timeout=POLL_SECONDS)
            except TimeoutError:
                self.look([*keys, fut.key], every=POLL_SECONDS)
            except (CancelledError, CommClosedError, OSError) as exc:
                raise BatchStopped(self.cancelled(exc)) from None

    def look(self, keys=(), every: float = 0) -> None:
        """Compare the cluster's workers with the last look (``every``: not again within that
        many seconds): a worker gone is reported, and the batch's inputs it was running
        (``keys``: those in flight) counted as run again."""
        self.check()
        if time.monotonic() - self.last < every:
            return
        self.last = time.monotonic()
        try:
            now = self.client.sync(self.client.scheduler.processing, callback_timeout=RPC_SECONDS)
        except Exception:  # (no answer now: the scheduler lost, or busy; the next look tells)
            return
        keys = set(keys)
        now = {w: set(ks) & keys for w, ks in now.items()}
        for w in sorted(set(self.workers) - set(now)):
            n = len(self.workers[w])
            self.progress.again(n)
            again = ("it was running no input" if not n else
                     f"its {'input' if n == 1 else f'{n} inputs'} in flight to run again")
            self.progress.warn(f"Dask worker {w} left the cluster ({again})")
        self.workers = now
        if now:
            self.empty_since = None
        elif keys:
            t = time.monotonic()
            self.empty_since = self.empty_since or t
            if t - self.empty_since > NO_WORKERS_SECONDS:
                raise BatchStopped(f"the Dask cluster {self.scheduler} has had no workers for "
                                   f"{NO_WORKERS_SECONDS} s; start workers and run the same command to "
                                   "finish the rest")


def _killed(exc: BaseException) -> bool:
    from distributed.scheduler import KilledWorker

    return isinstance(exc, KilledWorker)


def _one_after_another(jobs, bar: Progress, split=None):
    """The inputs one after the other in this process (``split``: ``run_one``'s, each omm bake
    in pieces run by ``split[0]``); a full output disk stops them."""
    for j in jobs:
        rec = run_one(*j, split=split)
        bar.done(rec)
        yield rec
        if disk_full(rec):
            raise BatchStopped(_stop_for_disk(rec))


def run_all(command, jobs, scheduler: str, window: int | None, bar: Progress, split: bool = False):
    """Run ``jobs`` (lists of ``run_one``'s arguments) and yield their records as they finish.
    ``split``: one input after the other, each omm bake in pieces (``PIECES_PER_THREAD`` per
    worker thread) run on the scheduler's workers, packed and written here (``bake_split``).
    ``bar``: the progress (``Progress``), counting inputs done, failed and run again.

    Faults: a worker lost mid-task is reported once, and Dask runs its tasks again; an input
    whose workers die each time it runs (Dask's ``allowed-failures``, then once more alone, so
    that no other input is blamed) is recorded as an error; a full output disk, a lost scheduler
    or a cluster left without workers raise ``BatchStopped`` after the records finished so far
    (no new input is started; those in flight on a full disk finish first)."""
    if scheduler == "none":
        yield from _one_after_another(jobs, bar, (None, PIECES_PER_THREAD) if split else None)
        return
    with interrupt.remembered(), dask_client(scheduler) as client:
        threads = sum(client.nthreads().values()) or 1
        limit = window or 2 * threads
        if split:  # one input at a time, its pieces on every worker
            run = dask_pieces(client, limit, ClusterWatch(client, scheduler, bar))
            yield from _one_after_another(jobs, bar, (run, PIECES_PER_THREAD * threads))
        else:
            yield from _on_cluster(client, command, jobs, bar, limit, scheduler)


def _on_cluster(client, command, jobs, bar: Progress, limit: int, scheduler: str):
    """One task per input, at most ``limit`` in flight, checked between finished inputs
    (``ClusterWatch``); inputs whose workers were killed each time run again alone at the end."""
    from concurrent.futures import CancelledError

    from distributed import wait

    watch = ClusterWatch(client, scheduler, bar)
    todo = list(jobs)
    todo.reverse()
    alone: list = []  # inputs to run again alone (KilledWorker while others ran beside them)
    flight: dict = {}  # future -> (job, run alone?)
    stop = None

    def submit(j, solo=False):
        fut = client.submit(run_one, *j, pure=False, key=f"omaps-batch-{command}-{os.urandom(8).hex()}")
        flight[fut] = (j, solo)

    while todo or flight or (alone and stop is None):
        if stop is None:
            while todo and len(flight) < limit:
                submit(todo.pop())
            if not todo and not flight and alone:
                submit(alone.pop(0), solo=True)
        try:
            done, _ = wait(list(flight), timeout=POLL_SECONDS, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = ()
        except CancelledError as exc:  # Dask cancels every future when the client loses its scheduler
            raise BatchStopped(watch.cancelled(exc)) from None
        watch.look([f.key for f in flight], every=POLL_SECONDS)  # (the scheduler checked first)
        for fut in done:
            j, solo = flight.pop(fut)
            try:
                rec = watch.result(fut, [f.key for f in flight])
            except BatchStopped:
                raise
            except Exception as exc:  # the worker died under it, or the task could not run there (``run_one``
                # itself returns every failure of its input as a record)
                if _killed(exc) and not solo:
                    alone.append(j)
                    bar.again(1)
                    fut.release()
                    continue
                watch.check()  # (a future cancelled because the client lost its scheduler)
                path = j[2]
                why = (f"its worker died each time it ran it: on {exc.allowed_failures + 1} workers (the "
                       f"scheduler's allowed-failures, {exc.allowed_failures}), and again when run alone "
                       "(out of memory, or a crash in native code)" if _killed(exc)
                       else f"{type(exc).__name__}: {exc}")
                rec = {"input": path, "status": "error", "error": f"{path}: worker failed: {why}"}
            fut.release()
            bar.done(rec)
            yield rec
            if disk_full(rec) and stop is None:
                stop = _stop_for_disk(rec)
                todo.clear()
                alone.clear()
    watch.look(())  # (a worker lost since the last look, with the batch's last inputs)
    if stop is not None:
        raise BatchStopped(stop)

