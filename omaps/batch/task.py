"""One input's run, as a task on a worker: the command's library call, its output written
atomically, then its marker; a failure is the input's record, never the batch's."""

from __future__ import annotations

import contextlib
import json
import os
import time
import traceback
import warnings

from .. import atomic
from ..errors import InputError
from .inputs import library_call, output_path
from .markers import marker_path


class BatchStopped(Exception):
    """The batch stopped before its end (the scheduler lost, the output disk full, no workers
    left): ``reason`` says why, in a sentence; the inputs finished before it are kept."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


# Test-only: when this environment variable names a folder, each input's task (``run_one``, not
# split) and each piece's task (``bake_piece_task``) stops at ``_test_gate`` until the test lets it
# go, so that a test interrupts or kills a batch at a moment it chooses, whatever the machine's
# speed. Never set outside the tests; unset, the gate is one dictionary lookup.
TEST_GATE = "OMAPS_TEST_GATE"


def _test_gate(what: str) -> None:
    """Test-only (``TEST_GATE``): with the variable unset, nothing. Set to a folder: if a file
    ``kill-WHAT`` is there, kill this process at once (SIGKILL: a task that kills every worker it
    runs on). Else wait until a file ``release`` or ``release-WHAT`` appears there, or the folder
    is removed (or the process is interrupted or killed), writing ``held-WHAT`` there once waiting
    (this process's id in it: the test acts on it); then write ``passed-WHAT`` (a test checks that
    no task it held went on)."""
    folder = os.environ.get(TEST_GATE)
    if not folder:
        return
    what = "".join(c if c.isalnum() or c in "-_." else "_" for c in what)
    if os.path.exists(os.path.join(folder, f"kill-{what}")):
        import signal

        os.kill(os.getpid(), signal.SIGKILL)
    go = (os.path.join(folder, "release"), os.path.join(folder, f"release-{what}"))
    held = False
    while os.path.isdir(folder) and not any(os.path.exists(g) for g in go):
        if not held:  # written from inside the wait: a gate that does not wait never says it holds
            with open(os.path.join(folder, f"held-{what}"), "w") as f:
                f.write(str(os.getpid()))
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
    from ..jobs import bake_omms
    from ..omm.split import build_split

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
    except BatchStopped:  # (a split bake's pieces: the cluster lost) the batch's, not the input's
        raise
    except InputError as exc:
        if command == "eval" and exc.problem.startswith("no texture is at least"):
            rec["status"], rec["reason"] = "skipped", f"smaller than min_size {options.get('min_size')} px"
        else:
            rec["status"], rec["error"] = "error", str(exc) if exc.path else f"{path}: {exc.problem}"
    except OSError as exc:
        _os_error(rec, exc, path, out)
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
        try:
            atomic.write_text(marker_path(outdir, name), json.dumps({"fingerprint": fp, "record": rec}, indent=1)
                              + "\n")
        except OSError as exc:  # (a full disk): not done after all; its output goes too (error: no output)
            if rec["output"] is not None:
                atomic._remove(out)
            _os_error(rec, exc, path, marker_path(outdir, name))
            rec["output"] = None
            rec.pop("figures", None)
    return rec


def _os_error(rec: dict, exc: OSError, path: str, writing: str) -> None:
    """An input's record of an ``OSError``: the file and the system's words (an error that names
    no file, as a full disk's, names the input and the output being written), and its errno's
    name (``ENOSPC``: the engine stops on a full disk)."""
    import errno

    where = exc.filename or f"{path} (writing {writing})"
    rec["status"], rec["error"] = "error", f"{where}: {exc.strerror or exc}"
    if exc.errno in errno.errorcode:
        rec["errno"] = errno.errorcode[exc.errno]


def bake_piece_task(test, piece, *rest):
    """``omaps.omm.split.bake_piece`` as a Dask task."""
    from ..omm.split import bake_piece

    _test_gate(f"piece-{piece.geometry}-{piece.a}")
    return bake_piece(test, piece, *rest)
