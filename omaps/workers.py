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

import numpy as np


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


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now (if it is not running yet), its stderr on
    the null device. It cleans up after worker processes that a Ctrl-C or a failure stopped
    early (named semaphores of a pool or a Dask cluster); its notes about them ("leaked
    semaphore objects to clean up", "No such file or directory" for one a stopped process had
    already unlinked) are for multiprocessing's developers, and an interrupted run must print
    ``omaps: interrupted`` alone."""
    import os
    import sys
    from multiprocessing import resource_tracker

    if getattr(resource_tracker._resource_tracker, "_pid", None) is not None:
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no real stderr: nothing to keep apart
        resource_tracker.ensure_running()
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)  # the tracker inherits fd 2 when it starts
        resource_tracker.ensure_running()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


@contextlib.contextmanager
def sigint_blocked():
    """SIGINT blocked in this thread while the block runs (the main thread only; elsewhere it
    does nothing). A thread started meanwhile keeps the mask for good, and so does every process
    spawned from it, at once or later: such processes never print a Ctrl-C traceback. A Ctrl-C
    meanwhile arrives in this thread when the block ends."""
    block = _MASKS and threading.current_thread() is threading.main_thread()
    if block:
        # multiprocessing's resource tracker, started by the first spawn, unblocks SIGINT in the
        # spawning thread after starting it: started now, before the mask, it leaves the mask alone
        start_resource_tracker()
        signal.pthread_sigmask(signal.SIG_BLOCK, _SIGINT)
    try:
        yield
    finally:
        if block:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGINT)


@contextlib.contextmanager
def sigint_ignored():
    """Ctrl-C ignored while the block runs (the main thread only): a tear-down that must not be
    cut short by a second Ctrl-C."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


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
        with sigint_blocked():  # a pending Ctrl-C arrives at its end
            pool.submit(_noop)  # launches every worker (spawn starts them all at the first submit)
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


def _encode_chunk(args):
    from .codecs import get_codec

    name, maps_, encoder, effort = args
    return get_codec(name).encode_many(maps_, encoder, effort)


def encode_maps(codec, maps_: np.ndarray, encoder, effort, jobs: int = 1, progress=None):
    """``codec.encode_many`` spread over ``jobs`` worker processes, in chunks (8 per worker, so
    that uneven maps balance): (blocks (P, bytes), decoded (P, N, N)), the same as one process
    gives. ``progress(n)``, if given, is called as each chunk finishes (``n`` chunks in all via
    ``progress(None, total)`` first). Every command that encodes many maps (trace, omm --from)
    encodes through here; eval spreads whole textures instead."""
    if len(maps_) == 0 or not codec.compressed or jobs <= 1 or len(maps_) < 16:
        return codec.encode_many(maps_, encoder, effort)
    first = codec.encode_many(maps_[:1], encoder, effort)  # compiled (and cached) before the workers start
    edges = np.linspace(1, len(maps_), 8 * jobs + 1).astype(int)
    args = [(codec.name, maps_[a:b], encoder, effort) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    if progress is not None:
        progress(None, len(args))
    out = [first]
    with process_pool(jobs) as pool:
        for r in pool.map(_encode_chunk, args):
            out.append(r)
            if progress is not None:
                progress(1)
    return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out])
