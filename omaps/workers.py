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


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _noop() -> None:
    return None


@contextlib.contextmanager
def process_pool(jobs: int):
    """A ``ProcessPoolExecutor`` of ``jobs`` spawned workers that ignore SIGINT. Its processes
    start here, with SIGINT ignored in this process too (a spawned child keeps an ignored signal
    from its very start, before it could install the initializer), and are terminated if the
    block raises (an error, KeyboardInterrupt) instead of draining the queued work."""
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_ignore_sigint)
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        pool.submit(_noop)  # launches every worker (spawn starts them all at the first submit)
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)
    try:
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
