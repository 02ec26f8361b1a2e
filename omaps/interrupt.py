"""A Ctrl-C that is never lost on its way.

Python raises ``KeyboardInterrupt`` wherever the main thread happens to be when SIGINT is
handled. Inside a finaliser (``__del__``: llvmlite disposing of a compiled function while numba
compiles, a Dask future released) or a garbage-collector callback the exception cannot
propagate: Python drops it, prints "Exception ignored in …" with a traceback, and the work goes
on as if no Ctrl-C had come, to the end, and writes its outputs.

``remembered()`` (around a whole command, and around a batch's wait on its cluster) makes a
Ctrl-C stick:

* the SIGINT handler records the interrupt and raises it as before;
* an interrupt that Python drops after that is not printed, and is raised again in the main
  thread moments later (``_thread.interrupt_main`` from a short timer), out of the finaliser;
* ``check()`` raises ``KeyboardInterrupt`` whenever one came: ``atomic`` calls it before any
  output is renamed into place, so a command that was interrupted writes nothing, whatever
  swallowed the exception.

In a thread other than the main thread, or where SIGINT is ignored or left to the system,
``remembered()`` changes nothing.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

_SEEN: list[int] = []  # a Ctrl-C came while ``remembered()`` was active
_ACTIVE: list[bool] = []
_TIMERS: list[threading.Timer] = []
_LOCK = threading.Lock()
RAISE_AGAIN_SECONDS = 0.02  # a dropped interrupt is raised again this long after (out of the finaliser)


def requested() -> bool:
    """Whether a Ctrl-C came while ``remembered()`` is active."""
    return bool(_SEEN)


def check() -> None:
    """``KeyboardInterrupt`` if a Ctrl-C came (``requested()``), even one that was dropped."""
    if _SEEN:
        raise KeyboardInterrupt


def _raise_again() -> None:
    import _thread

    with _LOCK:
        if _ACTIVE:
            _thread.interrupt_main(signal.SIGINT)


def _handle_pending() -> None:
    """Nothing; calling a Python function lets the main thread handle a pending signal."""


def _drop(u) -> None:
    """An unraisable-exception hook that reports nothing."""


@contextlib.contextmanager
def remembered(quiet_after: bool = False):
    """Remember a Ctrl-C for the block (see the module's docstring); nested: the outer one.
    ``quiet_after``: when a Ctrl-C came, leave the process's finalisers unreported after the
    block (a program that ends on the interrupt: objects it cut short while they were torn down,
    such as llvmlite's, may fail again in their finalisers at exit; the program's one line is
    its word)."""
    previous = signal.getsignal(signal.SIGINT)
    if _ACTIVE or threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield
        return

    def handler(signum, frame):
        _SEEN.append(signum)
        previous(signum, frame)

    previous_hook = sys.unraisablehook

    def unraisable(u):
        if not (_SEEN and u.exc_type is not None and issubclass(u.exc_type, KeyboardInterrupt)):
            previous_hook(u)
            return
        try:  # (not at interpreter shutdown: no thread can start then)
            t = threading.Timer(RAISE_AGAIN_SECONDS, _raise_again)
            t.daemon = True
            t.start()
            _TIMERS.append(t)
        except RuntimeError:
            pass

    _SEEN.clear()
    _ACTIVE.append(True)
    signal.signal(signal.SIGINT, handler)
    sys.unraisablehook = unraisable
    finished = False
    try:
        yield
        finished = True
    finally:
        with _LOCK:
            _ACTIVE.clear()
            for t in _TIMERS:
                t.cancel()
            _TIMERS.clear()
        try:  # an interrupt raised again just before is handled here, by this block's handler
            _handle_pending()
        except KeyboardInterrupt:
            pass
        came = bool(_SEEN)
        sys.unraisablehook = _drop if came and quiet_after else previous_hook
        signal.signal(signal.SIGINT, previous)
        _SEEN.clear()
    if finished and came:  # the block went on after a Ctrl-C that was dropped: it was interrupted
        raise KeyboardInterrupt
