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
* faults: a worker lost mid-task is reported once and its inputs run again (by Dask); an input
  whose workers die each time it runs is run once more alone, then recorded as an error; a lost
  scheduler, a full output disk or a cluster left without workers stop the batch
  (``BatchResult.stopped``; its inputs not finished: ``unfinished``), never a wait without end;
* the summary: ``OUTDIR/summary.json`` and ``OUTDIR/summary.csv`` (per input its status and
  figures or its error; totals).

The package, one module per concern: ``inputs`` (finding and naming inputs), ``markers``
(markers and resume), ``task`` (one input's run on a worker), ``engine`` (the Dask client,
cluster and the loop over inputs, faults included), ``summary`` (totals, files, the result) and
``plan`` (the checks before any work).
"""

from __future__ import annotations

import contextlib
import json
import os
import time

from .. import atomic
from .engine import BatchStopped, Progress, check_scheduler, dask_client, run_all
from .inputs import COMMANDS, MARKERS, SUMMARY, find_inputs, library_call, output_names, output_path
from .markers import finished, marker_path, plain
from .plan import BatchPlan, plan_batch
from .summary import BatchResult, BatchWarning, summary_csv, totals, warn_input
from .task import run_one

__all__ = ["run_batch", "plan_batch", "run_plan", "BatchPlan", "BatchResult", "BatchWarning", "COMMANDS",
           "library_call", "run_one", "find_inputs", "output_names", "check_scheduler", "dask_client", "BatchStopped"]


def run_plan(plan: BatchPlan, progress: bool = False) -> BatchResult:
    """Run a ``plan_batch`` plan and write OUTDIR/summary.json and summary.csv. A batch that
    stops before its end (``BatchResult.stopped``: the scheduler lost, the output disk full, no
    workers left) records its unstarted and unfinished inputs as ``unfinished``; a summary that
    cannot be written is ``BatchResult.summary_error`` (the markers of finished inputs stay)."""
    t0 = time.perf_counter()
    records = dict(plan.records)
    by_input = {j[2]: j[3] for j in plan.jobs}
    bar = Progress(plan.command, len(plan.jobs), progress)
    stopped = None
    try:
        for rec in run_all(plan.command, plan.jobs, plan.scheduler, plan.window, bar, plan.split):
            records[by_input.get(rec["input"], rec["input"])] = rec
            warn_input(rec)
    except BatchStopped as exc:
        stopped = exc.reason
    finally:
        bar.close()
    for command, _, path, name, outdir, fp in plan.jobs:
        if name not in records:  # (finished on a worker, its record lost with the scheduler: its marker's)
            done = finished(command, output_path(command, outdir, name, plan.options), marker_path(outdir, name), fp)
            records[name] = done or {"input": path, "output": None, "status": "unfinished",
                                     "reason": "not run to its end: the batch stopped"}
    dt = time.perf_counter() - t0
    ordered = [records[n] for n in plan.names if n in records]
    ordered += [r for n, r in records.items() if n not in plan.names]
    tot = totals(plan.command, ordered)
    tot["retried"] = bar.retried
    tot["seconds"] = round(dt, 3)
    tot["inputs_per_second"] = round(len(plan.jobs) / dt, 4) if plan.jobs and dt > 0 else None
    settings = {"command": plan.command, "scheduler": plan.scheduler, "split": plan.split,
                "options": plain(plan.options)}
    with contextlib.suppress(OSError):
        os.rmdir(os.path.join(plan.outdir, MARKERS))  # only if empty (nothing done)
    js, cs = os.path.join(plan.outdir, SUMMARY + ".json"), os.path.join(plan.outdir, SUMMARY + ".csv")
    summary = {"settings": settings, "inputs": ordered, "totals": tot, **({"stopped": stopped} if stopped else {})}
    try:
        out = atomic.Outputs()
        for path in (js, cs):
            out.file(path, "-o")
        with out.writing():  # both or neither
            for path, text in ((js, json.dumps(summary, indent=1) + "\n"), (cs, summary_csv(ordered, tot))):
                with open(out.path(path), "w", encoding="utf-8", newline="") as f:
                    f.write(text)
    except OSError as exc:  # (the output disk full): said, never a traceback
        return BatchResult(plan.command, ordered, tot, None, None, dt, stopped,
                           f"{exc.filename or js}: {exc.strerror or exc}")
    return BatchResult(plan.command, ordered, tot, js, cs, dt, stopped)


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
        A lost scheduler, a full output disk or a cluster without workers end the batch early
        (``stopped`` says why; its other inputs are ``unfinished``), never a wait without end.

    Examples
    --------
    >>> import omaps                                                               # doctest: +SKIP
    >>> res = omaps.run_batch("eval", ["textures/"], "out", {"schemes": "sq16,vq4"}, scheduler="none")  # doctest: +SKIP
    >>> res.totals["ok"], res.totals["mean_savings"]["vq4"]                        # doctest: +SKIP
    """
    plan = plan_batch(command, inputs, outdir, options, scheduler=scheduler, window=window, glb=glb, split=split)
    return run_plan(plan, progress)
