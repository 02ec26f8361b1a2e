"""Worker processes, one way for every command: spawned (numba's threads do not survive a
fork), deaf to Ctrl-C (the main process alone handles it), and stopped at once when the main
process stops early, so an interrupted run prints ``omaps: interrupted`` and no worker tracebacks.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
import threading
from concurrent.futures import ProcessPoolExecutor


_SIGINT = {signal.SIGINT}
_MASKS = hasattr(signal, "pthread_sigmask")


def _worker_start() -> None:
    """In each worker: ignore SIGINT, then let signals through again (they were blocked from
    the worker's start, see ``process_pool``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if _MASKS:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGINT)


def _noop() -> None:
    return None


@contextlib.contextmanager
def process_pool(jobs: int):
    """A ``ProcessPoolExecutor`` of ``jobs`` spawned workers that ignore SIGINT. The workers
    start here with SIGINT blocked (a child inherits the signal mask, so a Ctrl-C while it is
    still starting cannot print its traceback; this process receives it once they are started),
    and they are terminated if the block raises (an error, KeyboardInterrupt) instead of
    draining the queued work."""
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_start)
    try:
        block = _MASKS and threading.current_thread() is threading.main_thread()
        if block:
            signal.pthread_sigmask(signal.SIG_BLOCK, _SIGINT)
        try:
            pool.submit(_noop)  # launches every worker (spawn starts them all at the first submit)
        finally:
            if block:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGINT)  # a pending Ctrl-C arrives here
        yield pool
    except BaseException:
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            with contextlib.suppress(Exception):
                p.terminate()
        for p in processes:
            with contextlib.suppress(Exception):
                p.join()
        raise
    else:
        pool.shutdown(wait=True)
