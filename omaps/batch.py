"""``run_batch`` (``omaps batch omm|eval|trace``): one command's library call over many inputs, on
Dask.

Each input runs through exactly the single command's library call (``bake_omms``,
``evaluate_corpus``, ``trace_scene``) with the batch's options (that call's keyword arguments),
its output at one path under OUTDIR (the same layout as the single command: an ``omm`` folder, the
``eval`` / ``trace`` JSON), so its outputs are those of ``omaps CMD INPUT -o/--json PATH`` byte
for byte (a ``trace`` JSON differs only in its timings). Around it:

* inputs: files, folders (searched recursively: images for ``eval``, ``.gltf`` / ``.glb`` for
  ``omm`` and ``trace``) and globs; output names are paths relative to the folder given (a file
  or a glob's match: its file name, but a ``scene.gltf`` / ``scene.glb`` takes its folder's name:
  ``smallpine/scene.gltf`` is ``smallpine``), extension dropped; the extension kept (``NAME_EXT``) where
  two inputs would share a name; two inputs still sharing one (or an omm folder inside another's)
  are an error naming both, before any work;
* robust: a bad input is a recorded error (its message, exit code 2 of the single command), never
  a failed batch; outputs are written by the command's own atomic ``Outputs``;
* resume: after an input's outputs are in place, a completion marker
  ``OUTDIR/.batch/NAME.json`` (the input's size and mtime, the options, its figures) is written,
  atomically, last; a re-run skips an input whose marker matches and whose output exists;
* scheduling: ``none`` (serial, in this process), ``local`` (a ``LocalCluster``: one worker
  process per core, one thread each) or ``tcp://HOST:PORT`` (an existing Dask cluster); at most
  ``window`` inputs are in flight (default: twice the workers' threads), so memory stays bounded;
* the summary: ``OUTDIR/summary.json`` and ``OUTDIR/summary.csv`` (per input its status and
  figures or its error; totals).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import glob
import io
import json
import os
import sys
import time
import traceback
import warnings

from . import atomic
from .errors import InputError, check_count
from .text import plural as count  # "1 input", "2 inputs"

__all__ = ["run_batch", "plan_batch", "run_plan", "BatchPlan", "BatchResult", "COMMANDS", "library_call", "run_one",
           "find_inputs", "output_names", "check_scheduler", "dask_client"]

COMMANDS = ("omm", "eval", "trace")
MARKERS = ".batch"
SUMMARY = "summary"
GLTF_EXTENSIONS = (".gltf", ".glb")


def library_call(command: str):
    """The one library call a batch runs per input: ``bake_omms``, ``evaluate_corpus`` or
    ``trace_scene``."""
    if command == "omm":
        from .jobs import bake_omms

        return bake_omms
    if command == "eval":
        from .corpus import evaluate_corpus

        return evaluate_corpus
    from .trace import trace_scene

    return trace_scene


# ---------------------------------------------------------------------------------------------
# inputs and their outputs

def _has_magic(p: str) -> bool:
    return glob.has_magic(p)


def _wanted(command: str, path: str) -> bool:
    from .texture import IMAGE_EXTENSIONS

    low = path.lower()
    return low.endswith(IMAGE_EXTENSIONS) if command == "eval" else low.endswith(GLTF_EXTENSIONS)


def find_inputs(command: str, given, outdir: str) -> list[tuple[str, str]]:
    """(input path, name relative to the folder or glob it came from, extension kept) per input,
    in the order given, folders and globs sorted; a path that does not exist is kept (its error
    is recorded when it runs). The output folder is never searched."""
    out_abs = os.path.abspath(outdir)
    found: list[tuple[str, str]] = []
    seen = set()

    def add(path, name):
        a = os.path.abspath(path)
        if a in seen or a == out_abs or a.startswith(out_abs + os.sep):
            return
        seen.add(a)
        found.append((path, name))

    for g in given:
        g = os.fspath(g)
        if os.path.isdir(g):
            for root, dirs, files in os.walk(g):
                dirs.sort()
                if os.path.abspath(root) == out_abs or os.path.abspath(root).startswith(out_abs + os.sep):
                    dirs[:] = []
                    continue
                for f in sorted(files):
                    full = os.path.join(root, f)
                    if _wanted(command, full):
                        add(full, os.path.relpath(full, g))
        elif not os.path.lexists(g) and _has_magic(g):
            matches = sorted(glob.glob(g, recursive=True))
            if not matches:
                raise InputError("no file matches this pattern", g)
            for m in matches:
                if os.path.isfile(m) and _wanted(command, m):
                    add(m, os.path.basename(m))
        else:
            add(g, os.path.basename(g))
    if not found:
        raise InputError("no input found (" + ("images" if command == "eval" else ".gltf / .glb scenes") + ")",
                         ", ".join(map(os.fspath, given)))
    return found


GENERIC_SCENE = "scene"  # what many exporters call every scene: such a file is named by its folder


def _base_name(command: str, path: str, rel: str) -> str:
    """An input's output name before collisions: ``rel`` (its path relative to the folder given,
    or its file name) without the extension; a glTF scene called scene.gltf / scene.glb named by
    its file name alone takes its folder's name instead (found in a folder given, its relative
    path already names its folder: ``smallpine/scene``)."""
    stem = os.path.splitext(rel)[0]
    if command != "eval" and path.lower().endswith(GLTF_EXTENSIONS) and stem.lower() == GENERIC_SCENE:
        return os.path.basename(os.path.dirname(os.path.abspath(path))) or stem
    return stem


def output_names(command: str, found, folders: bool | None = None) -> list[str]:
    """The output name of each input (``_base_name``), with its extension (``NAME_EXT``) where two
    inputs would share one; two inputs still sharing a name, or (``folders``: omm folders) one
    input's output folder inside another's, are an error naming both."""
    if folders is None:
        folders = command == "omm"
    reserved = {SUMMARY, MARKERS}
    stems = [_base_name(command, path, n) for path, n in found]
    counts: dict[str, int] = {}
    for s in stems:
        counts[s.lower()] = counts.get(s.lower(), 0) + 1
    names = []
    for (path, _), s in zip(found, stems):
        if counts[s.lower()] > 1 or s.lower() in reserved:
            s = s + "_" + os.path.splitext(path)[1].lstrip(".")
        names.append(s)
    taken: dict[str, str] = {}
    for (path, _), s in zip(found, names):
        if s.lower() in taken:
            raise InputError(f"has the same output name ({s}) as {taken[s.lower()]}; run them in separate batches",
                             path)
        taken[s.lower()] = path
    if folders:  # an output folder inside another input's, which replaces its folder whole
        for (path, _), s in zip(found, names):
            parts = s.lower().split(os.sep)
            for k in range(1, len(parts)):
                outer = os.sep.join(parts[:k])
                if outer in taken:
                    raise InputError(f"its output folder ({s}) would lie inside the output folder of "
                                     f"{taken[outer]}; run them in separate batches", path)
    return names


def output_path(command: str, outdir: str, name: str, options: dict | None = None) -> str:
    if command == "omm":
        return os.path.join(outdir, name + ".glb") if (options or {}).get("glb") else os.path.join(outdir, name)
    return os.path.join(outdir, name + ".json")


def marker_path(outdir: str, name: str) -> str:
    return os.path.join(outdir, MARKERS, name + ".json")


def with_root(command: str, options: dict, path: str, rel: str) -> dict:
    """An input's options with the root of its scene's URI policy (``omaps.load_scene``) where
    none is given: the folder given that it was found in (``rel``: its path from there), its own
    folder for a file named or a glob's match."""
    if command == "eval" or options.get("root") is not None or options.get("allow_outside"):
        return options
    given = path[:len(path) - len(rel)] if rel and path.endswith(rel) else os.path.dirname(path)
    return {**options, "root": given or "."}


def plain(value):
    """Options as JSON (what a marker and the summary record): a settings object (``MaterialRules``,
    ``EvalConfig``) as its fields, tuples as lists."""
    import dataclasses

    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def fingerprint(command: str, path: str, options: dict) -> dict:
    try:
        st = os.stat(path)
        stat = [st.st_size, st.st_mtime_ns]
    except OSError:
        stat = None
    return {"command": command, "input": os.path.abspath(path), "stat": stat, "options": plain(options)}


def remove_stale_temporaries(outdir: str) -> None:
    """Remove what a killed batch left under OUTDIR: only omaps' own hidden temporary names
    (``.omaps-…``, never a finished output); one batch per OUTDIR at a time."""
    for root, dirs, files in os.walk(outdir):
        for n in list(dirs) + files:
            if n.startswith(atomic.TEMP_PREFIX):
                atomic._remove(os.path.join(root, n))
        dirs[:] = [d for d in dirs if not d.startswith(atomic.TEMP_PREFIX)]


def finished(command: str, out: str, marker: str, fp: dict) -> dict | None:
    """The recorded result of an input done before with the same options (its marker matches
    and its output is in place), else None."""
    try:
        with open(marker, encoding="utf-8") as f:
            m = json.load(f)
    except (OSError, ValueError):
        return None
    if not isinstance(m, dict) or m.get("fingerprint") != json.loads(json.dumps(fp)):
        return None
    rec = m.get("record")
    if not isinstance(rec, dict):
        return None
    if rec.get("status") == "skipped":
        return rec
    done = (os.path.isfile(os.path.join(out, "omm.json")) if command == "omm" and not out.endswith(".glb")
            else os.path.isfile(out))
    return rec if done else None


# ---------------------------------------------------------------------------------------------
# one input

# Test-only: when this environment variable names a folder, each input's task (``run_one``, not
# split) and each piece's task (``bake_piece_task``) stops at ``_test_gate`` until the test lets it
# go, so that a test interrupts or kills a batch at a moment it chooses, whatever the machine's
# speed. Never set outside the tests; unset, the gate is one dictionary lookup.
TEST_GATE = "OMAPS_TEST_GATE"


def _test_gate(what: str) -> None:
    """Test-only (``TEST_GATE``): with the variable unset, nothing. Set to a folder: wait until
    a file ``release`` or ``release-WHAT`` appears there, or the folder is removed (or the process
    is interrupted or killed), writing ``held-WHAT`` there once waiting (the test acts on it);
    then write ``passed-WHAT`` (a test checks that no task it held went on)."""
    folder = os.environ.get(TEST_GATE)
    if not folder:
        return
    what = "".join(c if c.isalnum() or c in "-_." else "_" for c in what)
    go = (os.path.join(folder, "release"), os.path.join(folder, f"release-{what}"))
    held = False
    while os.path.isdir(folder) and not any(os.path.exists(g) for g in go):
        if not held:  # written from inside the wait: a gate that does not wait never says it holds
            with open(os.path.join(folder, f"held-{what}"), "w"):
                held = True
        time.sleep(0.01)
    with contextlib.suppress(OSError), open(os.path.join(folder, f"passed-{what}"), "w"):
        pass


SETTINGS = ("level", "dynamic", "max_level", "budget", "format", "promote", "seed", "special", "dedup", "source",
            "encoder", "effort", "jobs")  # bake_omms' options that make its OmmSettings (omm_settings)


def bake_split(path: str, output: str, run=None, pieces: int = 8, **options):
    """``bake_omms([path], output, **options)`` for a glTF scene, its bake and resolve split into
    pieces run by ``run`` (``omaps.omm.split.build_split``; default: here, one after the other),
    packed and written here: the same files, byte for byte. Options that do not split (a budget,
    a square source) are an ``InputError``."""
    from .jobs import bake_omms
    from .omm.split import build_split

    return bake_omms([path], output, build_stage=lambda geoms, settings, progress=None: build_split(
        geoms, settings, run, pieces), **options)


def _run_call(command: str, options: dict, path: str, out: str, split=None) -> tuple[str, dict, list[str]]:
    """The command's library call on one input, its output written at ``out``: (status, the
    figures the summary keeps, the messages the single command would print on stderr).
    ``split``: (run, pieces) of an omm bake split into pieces (``bake_split``)."""
    call = library_call(command)
    if command == "omm":
        bake = call([path], out, **options) if split is None else bake_split(path, out, *split, **options)
        st = bake.statistics
        figs = {k: st[k] for k in ("triangles", "micro_triangles", "transparent", "opaque", "unknown",
                                   "known_area_fraction", "micromaps", "data_bytes") if k in st}
        return "ok", figs, bake.messages()
    outputs = atomic.Outputs(inputs=[path])
    outputs.file(out, "--json")
    if command == "eval":
        res = call([path], **options)
        with outputs.writing():
            res.write_json(outputs.path(out))
        t = res.results[0]
        return "ok", {"width": t.width, "height": t.height, "savings": {s: t.savings[s] for s in res.names},
                      "bits": {s: t.bits[s] for s in res.names}}, []
    res = call(path, **options)
    with outputs.writing():
        res.write_json(outputs.path(out))
    r = res.report
    figs = {"passed": r["passed"], "triangles": r["scene"].get("triangles"),
            "alpha_tests_per_primary_ray": {s: v["alpha_tests_per_primary_ray"] for s, v in r["schemes"].items()}}
    return ("ok" if res.passed else "problems"), figs, res.messages()


def run_one(command: str, options: dict, path: str, name: str, outdir: str, fp: dict, split=None) -> dict:
    """Run the command's library call on one input, its output at ``output_path``; then write
    the marker. Returns the input's record: status ok / problems (a scheme changed a visible
    result) / skipped / error. ``split``: (run, pieces), an omm bake split into pieces run by
    ``run`` (``bake_split``)."""
    out = output_path(command, outdir, name, {"glb": options.get("glb")})
    options = {k: v for k, v in options.items() if k != "glb"}
    rec = {"input": path, "output": os.path.relpath(out, outdir), "status": None}
    if split is None:
        _test_gate(f"input-{name}")
    t0 = time.perf_counter()
    messages: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            try:
                rec["status"], rec["figures"], messages = _run_call(command, options, path, out, split)
            finally:
                messages = [f"omaps: warning: {w.message}" for w in caught] + messages
    except InputError as exc:
        if command == "eval" and exc.problem.startswith("no texture is at least"):
            rec["status"], rec["reason"] = "skipped", f"smaller than min_size {options.get('min_size')} px"
        else:
            rec["status"], rec["error"] = "error", str(exc) if exc.path else f"{path}: {exc.problem}"
    except OSError as exc:
        rec["status"], rec["error"] = "error", f"{exc.filename or path}: {exc.strerror or exc}"
    except Exception as exc:  # a bug on one input must not stop the others: recorded with where it came from
        tb = traceback.extract_tb(exc.__traceback__)[-1]
        rec["status"] = "error"
        rec["error"] = f"{path}: {type(exc).__name__}: {exc} ({os.path.basename(tb.filename)}:{tb.lineno})"
    rec["seconds"] = round(time.perf_counter() - t0, 3)
    if messages:
        rec["messages"] = messages
    if rec["status"] in ("error", "skipped"):  # no output
        rec["output"] = None
    if rec["status"] != "error":  # last, atomically: the input is done (an error is tried again next time)
        atomic.write_text(marker_path(outdir, name), json.dumps({"fingerprint": fp, "record": rec}, indent=1) + "\n")
    return rec


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
    except socket.timeout:
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

    from .workers import sigint_ignored

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

    from .workers import sigint_blocked, start_resource_tracker

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


def bake_piece_task(test, piece, *rest):
    """``omaps.omm.split.bake_piece`` as a Dask task."""
    from .omm.split import bake_piece

    _test_gate(f"piece-{piece.geometry}-{piece.a}")
    return bake_piece(test, piece, *rest)


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


# ---------------------------------------------------------------------------------------------
# the summary

def totals(command: str, records: list[dict]) -> dict:
    t = {"inputs": len(records)}
    for s in ("ok", "problems", "skipped", "error"):
        t[s] = sum(r["status"] == s for r in records)
    t["resumed"] = sum(bool(r.get("resumed")) for r in records)
    done = [r["figures"] for r in records if r.get("figures")]
    if command == "eval" and done:
        schemes = list(done[0]["savings"])
        t["mean_savings"] = {s: sum(f["savings"][s] for f in done) / len(done) for s in schemes}
    elif command == "omm":
        for k in ("triangles", "micro_triangles", "micromaps", "data_bytes"):
            t[k] = sum(f.get(k, 0) for f in done)
    elif command == "trace":
        t["passed"] = sum(bool(f.get("passed")) for f in done)
    return t


def _flat(f: dict) -> dict:
    out = {}
    for k, v in (f or {}).items():
        if isinstance(v, dict):
            out.update({f"{k}:{s}": x for s, x in v.items()})
        else:
            out[k] = v
    return out


def summary_csv(records: list[dict], tot: dict) -> str:
    rows = [{"input": r["input"], "output": r.get("output") or "", "status": r["status"],
             "error": r.get("error") or r.get("reason") or "", **_flat(r.get("figures"))} for r in records]
    total = {"input": "(total)", "output": "", "status": f"{tot['ok']} ok, {count(tot['problems'], 'problem')}, "
             f"{tot['skipped']} skipped, {count(tot['error'], 'error')}", "error": ""}
    kept = {("savings" if k == "mean_savings" else k): v for k, v in tot.items()
            if k in ("mean_savings", "triangles", "micro_triangles", "micromaps", "data_bytes", "passed")}
    total.update(_flat(kept))  # the eval row's savings columns hold the means
    cols = []
    for r in rows + [total]:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, cols, lineterminator="\n")
    w.writeheader()
    w.writerows(rows + [total])
    return buf.getvalue()


def precheck(command: str, options: dict) -> None:
    """The library call's own option checks, once before any work (else every input would fail
    alike)."""
    from .schemes import EVAL_KINDS, TRACE_KINDS, parse_schemes

    jobs = options.get("jobs")
    check_count(jobs)
    if command == "eval":
        from .corpus import EvalConfig

        config = options.get("config") or EvalConfig()
        if options.get("schemes") is not None:
            parse_schemes(options["schemes"], EVAL_KINDS, config.encoder, config.effort, "omaps eval")
        if options.get("min_size", 0) < 0:
            raise InputError(f"min_size must be >= 0, got {options['min_size']}", param="min_size")
    elif command == "trace":
        from .trace import parse_camera, parse_light
        from .trace.two_state import parse_modes

        parse_schemes(options.get("schemes", "none"), TRACE_KINDS, options.get("encoder"), options.get("effort"),
                      "omaps trace")
        parse_modes(options.get("two_state"))
        if options.get("shadows") and isinstance(options.get("light"), (str, type(None))):
            parse_light(options.get("light"))
        if isinstance(options.get("camera"), str):
            parse_camera(options["camera"])
    else:
        from .jobs import omm_settings

        omm_settings(**{k: v for k, v in options.items() if k in (
            "level", "dynamic", "max_level", "budget", "format", "promote", "seed", "special", "dedup", "source",
            "encoder", "effort", "jobs")})


@dataclasses.dataclass
class BatchPlan:
    """What ``plan_batch`` found: the inputs with their output names, the records of inputs done
    before (resumed) or refused, and the jobs to run (``run_one``'s arguments)."""

    command: str
    outdir: str
    options: dict
    scheduler: str
    window: int | None
    found: list
    names: list
    records: dict
    jobs: list
    split: bool = False

    def line(self) -> str:
        """The line ``omaps batch`` prints before it runs."""
        done = sum(bool(r.get("resumed")) for r in self.records.values())
        no_alpha = sum(bool(r.get("without_alpha")) and not r.get("resumed") for r in self.records.values())
        why: dict[str, int] = {}
        for r in self.records.values():
            if not r.get("resumed") and not r.get("without_alpha"):
                why[r.get("refused", "an error")] = why.get(r.get("refused", "an error"), 0) + 1
        parts = [f"{done} already done with these options (not run again)"] if done else []
        if no_alpha:
            parts.append(f"{no_alpha} skipped (images without an alpha channel; give --channel to read them)")
        parts += [f"{n} refused ({w}; each named after the run)" for w, n in why.items()]
        return (f"omaps batch {self.command}: {count(len(self.found), 'input')}, "
                + "".join(p + ", " for p in parts) + f"{len(self.jobs)} to run (scheduler {self.scheduler}"
                + ("; each scene split into pieces)" if self.split else ")"))


@dataclasses.dataclass
class BatchResult:
    """What ``run_batch`` did: per input its record (status ok / problems / skipped / error, its
    figures or error, seconds), the totals, and where the summary was written."""

    command: str
    records: list
    totals: dict
    summary_json: str
    summary_csv: str
    seconds: float

    @property
    def ok(self) -> bool:
        """No input had an error or problems."""
        return not (self.totals["error"] or self.totals["problems"])

    def messages(self) -> list[str]:
        """Each input's error or problems, one line each, as ``omaps batch`` prints them."""
        out = []
        for r in self.records:
            if r["status"] == "error":
                out.append(f"omaps: error: {r['error']}")
            elif r["status"] == "problems":
                out.append(f"omaps: {r['input']}: done with problems: " + "; ".join(r.get("messages", [])))
        return out

    def line(self) -> str:
        """The closing line ``omaps batch`` prints (and the mean savings of an eval batch)."""
        t = self.totals
        text = (f"omaps batch {self.command}: {t['ok']} ok, {t['problems']} with problems, {t['skipped']} skipped, "
                f"{count(t['error'], 'error')} ({t['resumed']} done before); {self.seconds:.2f} s; summary in "
                f"{self.summary_json} and .csv")
        if self.command == "eval" and "mean_savings" in t:
            text += "\nmean savings: " + ", ".join(f"{s} {v:.3f}" for s, v in t["mean_savings"].items())
        return text


def check_split(command: str, options: dict) -> None:
    """A batch that splits each input into pieces: omm, with options whose bake splits
    (``omaps.omm.split.splittable``), else an ``InputError`` saying why."""
    if command != "omm":
        raise InputError(f"{{split}} splits an omm bake; a batch of {command} runs one task per input",
                         param="split")
    from .jobs import omm_settings
    from .omm.split import splittable

    why = splittable(omm_settings(**{k: v for k, v in options.items() if k in SETTINGS}))
    if why is None and options.get("weights", "area") != "area":
        why = "{weights} view goes with {budget}"
    if why is not None:
        raise InputError(f"{{split}}: this bake does not split into pieces ({why}); leave {{split}} off",
                         param=("split", "weights", "budget", "source"))


def plan_batch(command: str, inputs, outdir, options: dict | None = None, *, scheduler: str = "local",
               window: int | None = None, glb: bool = False, split: bool = False) -> BatchPlan:
    """Check a batch before any work and find what it runs: the options (``precheck``), the
    scheduler's address, OUTDIR, the inputs and their output names, and the inputs finished
    before with the same options (resumed, not run again). ``split``: each omm scene's bake in
    pieces on every worker (``bake_split``; the same outputs)."""
    if not isinstance(command, str) or command not in COMMANDS:
        raise InputError(f"unknown batch command {command!r} (choose from {', '.join(COMMANDS)})", param="command")
    options = {**(options or {}), **({"glb": True} if glb else {})}
    if scheduler not in ("none", "local") and not scheduler.startswith(("tcp://", "tls://", "inproc://")):
        raise InputError(f"scheduler must be local, none or tcp://HOST:PORT, got {scheduler!r}", param="scheduler")
    check_scheduler(scheduler)
    precheck(command, {k: v for k, v in options.items() if k != "glb"})
    if split:
        check_split(command, options)
    if window is not None and window < 1:
        raise InputError(f"window must be >= 1, got {window}", param="window")
    outdir = os.fspath(outdir)
    if os.path.lexists(outdir) and not os.path.isdir(outdir):
        raise InputError("exists and is not a folder; -o is the batch's output folder", outdir)
    atomic.check_file(os.path.join(outdir, SUMMARY + ".json"), "-o")  # OUTDIR can be created and written
    found = find_inputs(command, inputs or [], outdir)
    names = output_names(command, found, command == "omm" and not glb)
    remove_stale_temporaries(outdir)
    library_call(command)  # importable before any work
    records: dict[str, dict] = {}
    jobs = []
    no_alpha = _found_without_alpha(command, inputs or [], found, options)
    for (path, rel), name in zip(found, names):
        if path in no_alpha:  # as omaps eval on a folder: an image that is not an alpha mask
            records[name] = {"input": path, "output": os.path.relpath(output_path(command, outdir, name, options),
                                                                        outdir),
                             "status": "skipped", "reason": f"not an alpha mask: {no_alpha[path]} (give a channel "
                             "to read one of its channels)", "without_alpha": True}
            continue
        fp = fingerprint(command, path, options)
        out = output_path(command, outdir, name, options)
        done = finished(command, out, marker_path(outdir, name), fp)
        if done is not None:
            records[name] = {**done, "resumed": True}
            continue
        if command == "omm" and os.path.isdir(out) and os.listdir(out) and "omm.json" not in os.listdir(out):
            records[name] = {"input": path, "output": os.path.relpath(out, outdir), "status": "error",
                             "error": f"{out}: folder is not empty and holds no omm.json (not written by omaps): "
                                      "not replacing it",
                             "refused": "its output folder holds files omaps did not write"}
            continue
        jobs.append((command, with_root(command, options, path, rel), path, name, outdir, fp))
    return BatchPlan(command, outdir, options, scheduler, window, found, names, records, jobs, split)


def _found_without_alpha(command: str, given, found, options: dict) -> dict[str, str]:
    """The eval inputs found in a folder or by a pattern (not named one by one) that are images
    without an alpha channel, with why (``texture.without_alpha``; none when a channel is
    given): skipped, as ``omaps eval`` skips them in a folder, not run into an error each."""
    if command != "eval" or getattr(options.get("config"), "channel", None) is not None:
        return {}
    from .texture import without_alpha

    named = {os.path.abspath(os.fspath(g)) for g in given if os.path.isfile(os.fspath(g))}
    out = {}
    for path, _ in found:
        if os.path.abspath(path) not in named:
            why = without_alpha(path)
            if why is not None:
                out[path] = why
    return out


class BatchWarning(UserWarning):
    """An input's warnings (its record's messages), one per input as it finishes."""


def warn_input(rec: dict) -> None:
    """An input's warnings as one ``BatchWarning`` (the first, and how many more the summary
    holds): above a progress bar, which is drawn again below it. Its error, or the problems
    it was done with, are said after the run (``BatchResult.messages``)."""
    notes = [m for m in rec.get("messages", []) if not m.startswith("omaps: error:")]
    if not notes:
        return
    first = notes[0].removeprefix("omaps: warning: ").removeprefix("omaps: ")
    for named in (rec["input"], os.path.abspath(rec["input"])):  # (a scene's warnings name its file)
        first = first.removeprefix(f"{named}: ")
    more = f" (and {count(len(notes) - 1, 'more warning')} in the summary)" if len(notes) > 1 else ""
    from tqdm import tqdm

    with tqdm.external_write_mode(file=sys.stderr):
        warnings.warn(f"{rec['input']}: {first}{more}", BatchWarning, stacklevel=3)


def run_plan(plan: BatchPlan, progress: bool = False) -> BatchResult:
    """Run a ``plan_batch`` plan and write OUTDIR/summary.json and summary.csv."""
    t0 = time.perf_counter()
    records = dict(plan.records)
    by_input = {j[2]: j[3] for j in plan.jobs}
    for rec in run_all(plan.command, plan.jobs, plan.scheduler, plan.window, progress, plan.split):
        records[by_input.get(rec["input"], rec["input"])] = rec
        warn_input(rec)
    dt = time.perf_counter() - t0
    ordered = [records[n] for n in plan.names if n in records]
    ordered += [r for n, r in records.items() if n not in plan.names]
    tot = totals(plan.command, ordered)
    tot["seconds"] = round(dt, 3)
    tot["inputs_per_second"] = round(len(plan.jobs) / dt, 4) if plan.jobs and dt > 0 else None
    settings = {"command": plan.command, "scheduler": plan.scheduler, "split": plan.split,
                "options": plain(plan.options)}
    with contextlib.suppress(OSError):
        os.rmdir(os.path.join(plan.outdir, MARKERS))  # only if empty (nothing done)
    js, cs = os.path.join(plan.outdir, SUMMARY + ".json"), os.path.join(plan.outdir, SUMMARY + ".csv")
    atomic.write_text(js, json.dumps({"settings": settings, "inputs": ordered, "totals": tot}, indent=1) + "\n")
    atomic.write_text(cs, summary_csv(ordered, tot))
    return BatchResult(plan.command, ordered, tot, js, cs, dt)


def run_batch(command: str, inputs, outdir, options: dict | None = None, *, scheduler: str = "local",
              window: int | None = None, glb: bool = False, split: bool = False,
              progress: bool = False) -> BatchResult:
    """Run one command's library call over many inputs, one output per input under ``outdir``.

    Parameters
    ----------
    command : {"omm", "eval", "trace"}
        ``bake_omms``, ``evaluate_corpus`` or ``trace_scene`` per input.
    inputs : list of str
        Files, folders (searched recursively: images for eval, .gltf / .glb for omm and trace)
        and globs.
    outdir : str
        OUTDIR/NAME/ (omm; OUTDIR/NAME.glb with ``glb``) or OUTDIR/NAME.json per input, and
        OUTDIR/summary.json and summary.csv.
    options : dict, optional
        The library call's keyword arguments, the same for every input.
    scheduler : str
        ``none`` (serial, in this process), ``local`` (a Dask LocalCluster, one worker process per
        core) or ``tcp://HOST:PORT`` (an existing Dask scheduler).
    window : int, optional
        At most this many inputs (or pieces of a split scene) in flight (default: twice the
        workers' threads).
    glb : bool
        omm: write OUTDIR/NAME.glb instead of an OMM folder.
    split : bool
        omm: one scene after the other, each one's bake split into pieces that run on every
        worker, packed and written here: the same outputs, byte for byte. Not with a budget or a
        square source.
    progress : bool
        A progress bar on stderr.

    Returns
    -------
    BatchResult
        A bad input is a recorded error, never a failed batch; a re-run skips finished inputs.

    Examples
    --------
    >>> import omaps                                                               # doctest: +SKIP
    >>> res = omaps.run_batch("eval", ["textures/"], "out", {"schemes": "sq16,vq4"}, scheduler="none")  # doctest: +SKIP
    >>> res.totals["ok"], res.totals["mean_savings"]["vq4"]                        # doctest: +SKIP
    """
    plan = plan_batch(command, inputs, outdir, options, scheduler=scheduler, window=window, glb=glb, split=split)
    return run_plan(plan, progress)
