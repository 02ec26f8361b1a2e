"""The ``omaps`` command line: a thin layer over the Python API, one module per command family."""

from __future__ import annotations

import argparse
import atexit
import difflib
import gc
import os
import re
import sys
import threading
import warnings
from typing import NoReturn

from .. import __version__, interrupt
from ..errors import InputError
from .common import show_warning


class Parser(argparse.ArgumentParser):
    """argparse's parser, and its errors: an unknown option is reported by the (sub)command that
    got it, with that command's usage and the closest of its options (``--sheme``: did you mean
    --schemes?); an unknown command or choice with the closest choice. Exit 2. Its help names the
    registry's codecs when it is shown (``common.CODECS``)."""

    def parse_known_args(self, args=None, namespace=None):
        ns, extras = super().parse_known_args(args, namespace)
        if extras:  # (argparse would hand them back up to ``omaps``, and its usage)
            self.error(f"unrecognized arguments: {' '.join(extras)}" + self._suggest(extras))
        return ns, extras

    def _suggest(self, extras) -> str:
        options = [o for o in self._option_string_actions if o.startswith("--")]
        for word in extras:
            if word.startswith("-") and word != "--":
                close = difflib.get_close_matches(word.split("=", 1)[0], options, n=1, cutoff=0.6)
                if close:
                    return f" (did you mean {close[0]}?)"
        return ""

    def format_help(self):
        from .common import codec_help

        for action in self._actions:  # the registry's codecs in the help texts (``common.CODECS``)
            action.help = codec_help(action.help)
        return super().format_help()

    def _check_value(self, action, value):
        if action.choices is not None and value not in action.choices:
            choices = [str(c) for c in action.choices]
            close = difflib.get_close_matches(str(value), choices, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise argparse.ArgumentError(action, f"invalid choice: {value!r} (choose from {', '.join(choices)}){hint}")


def parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; with ``command="omm"`` only that command's (a command line
    that names it needs no other, and ``omaps omm`` then imports no other command's modules)."""
    p = Parser(prog="omaps", description="Bake, compress and evaluate opacity maps "
               "for ray tracing alpha-tested geometry.")
    p.add_argument("--version", action="version", version=f"omaps {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    if command == "omm":
        from . import omm

        omm.add_parser(sub)
        return p
    from . import batch, maps, omm, report, trace

    maps.add_parsers(sub)
    trace.add_parser(sub)
    omm.add_parser(sub)
    batch.add_parser(sub)
    report.add_parser(sub)
    return p


def main(argv=None) -> int:
    """Exit codes: 0 done; 1 done, but with problems it lists (eval: unreadable files skipped;
    trace: a scheme changed the visible result; omm --verify: a check failed) or a system error
    while writing (nothing written); 2 bad input or options (nothing written); 130 interrupted
    (nothing written)."""
    from . import precompile

    argv = list(sys.argv[1:] if argv is None else argv)
    ahead = None
    options: dict[str, str] = {}
    try:
        if argv[:1] == ["omm"]:
            p = parser("omm")
            args = p.parse_args(argv)
        else:
            from .trace import bind_camera_value

            p = parser()
            args = p.parse_args(bind_camera_value(argv))
        options = option_names(p, args)
        from ..workers import start_resource_tracker

        start_resource_tracker()  # before a progress bar's lock or a worker pool starts one that prints
        ahead = precompile.compile_first(args)  # the command's uncached kernels, on every core, announced
        precompile.finish_ahead(ahead)
        ahead = None
        _resume_gc()
        with warnings.catch_warnings(), interrupt.remembered(quiet_after=True):
            warnings.showwarning = show_warning
            warnings.simplefilter("always", UserWarning)
            return args.func(args)
    except InputError as exc:
        print(f"omaps: error: {error_text(exc, options)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"omaps: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("omaps: interrupted", file=sys.stderr)
        return 130
    finally:
        precompile.stop_ahead(ahead)


def option_names(p: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """The options of the command line's (sub)command, by their destination (the library's
    parameter name, as in ``--from`` for ``source``): ``{"level": "--level", ...}``."""
    out: dict[str, str] = {}
    current: argparse.ArgumentParser | None = p
    while current is not None:
        following = None
        for action in current._actions:  # noqa: SLF001 - argparse keeps no public list
            if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                following = action.choices.get(str(getattr(args, action.dest, "")))
            elif action.option_strings and action.dest not in ("help", "version"):
                names = [o for o in action.option_strings if o.startswith("--")] or action.option_strings
                out[action.dest] = max(names, key=len)
        current = following
    return out


_CLASS_NAME = re.compile(r"\b[A-Z][A-Za-z0-9_]*(?:Error|Exception|Warning): ")


def error_text(exc: InputError, options: dict[str, str]) -> str:
    """An ``InputError`` as the command line prints it: ``path: problem``, the parameters it
    names replaced by the command's options (``level must ...`` -> ``--level must ...``),
    without exception class names or the path repeated inside the problem."""
    names = {p: options[p.replace("-", "_")] for p in exc.params if p.replace("-", "_") in options}
    problem = _CLASS_NAME.sub("", exc.named(names))
    if exc.path:
        problem = problem.replace(f"{exc.path}: ", "")
    return f"{exc.path}: {problem}" if exc.path else problem


_gc_paused = False  # ``run`` paused the cyclic garbage collector for the start-up


def _resume_gc() -> None:
    """The command starts: what start-up made (numpy, numba, the command's modules: about 110,000
    objects that live to the end) is set aside for good (``gc.freeze``) and collection resumes."""
    global _gc_paused
    if _gc_paused:
        _gc_paused = False
        gc.freeze()
        gc.enable()


def run(argv=None) -> NoReturn:
    """The ``omaps`` program: ``main``, then exit without tearing the interpreter down.

    Freeing numba's and LLVM's objects at interpreter shutdown took 0.12 s after every command
    (a quarter of ``omaps omm`` on one triangle). Everything a command writes is complete when
    ``main`` returns (outputs are renamed into place, worker processes joined), so the exit
    handlers registered with ``atexit`` run, the standard streams are flushed, and the process
    ends there with ``main``'s exit code. Under a profiler, tracer or debugger (``python -m
    cProfile -m omaps ...``, coverage), which reports after the program returns, it exits as usual.

    Start-up (parsing, numpy and numba loading) runs with the cyclic garbage collector paused:
    collecting its long-lived objects as they came took 0.06-0.09 s of every command."""
    global _gc_paused
    if gc.isenabled():
        gc.disable()
        _gc_paused = True
    try:
        rc = main(argv)
    finally:
        _resume_gc()
    # ... and as usual while a non-daemon thread still runs: the interpreter's exit joins it first
    # (an interrupted worker pool's manager thread unlinks its semaphores; cut short between unlink
    # and unregister, multiprocessing's resource tracker printed "leaked semaphore" warnings after
    # "omaps: interrupted")
    others = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon]
    if sys.getprofile() is not None or sys.gettrace() is not None or others:
        sys.exit(rc)
    atexit._run_exitfuncs()  # noqa: SLF001 - what the interpreter's own exit would run first
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: the interpreter's own exit would report 120
            rc = rc or 120
    os._exit(rc)


if __name__ == "__main__":
    run()
