"""Planning a batch before any work: its options checked once, the scheduler's address, OUTDIR,
the inputs found and named, and those finished before (resumed)."""

from __future__ import annotations

import dataclasses
import os

from .. import atomic
from ..errors import InputError, check_count
from ..text import plural as count
from .engine import check_scheduler
from .inputs import (COMMANDS, SUMMARY, find_inputs, found_without_alpha, library_call, output_names, output_path,
                     with_root)
from .markers import fingerprint, finished, marker_path, remove_stale_temporaries
from .task import SETTINGS


def precheck(command: str, options: dict) -> None:
    """The library call's own option checks, once before any work (else every input would fail
    alike)."""
    from ..schemes import EVAL_KINDS, TRACE_KINDS, parse_schemes

    jobs = options.get("jobs")
    check_count(jobs)
    if command == "eval":
        from ..corpus import EvalConfig

        config = options.get("config") or EvalConfig()
        if options.get("schemes") is not None:
            parse_schemes(options["schemes"], EVAL_KINDS, config.encoder, config.effort, "omaps eval")
        if options.get("min_size", 0) < 0:
            raise InputError(f"min_size must be >= 0, got {options['min_size']}", param="min_size")
    elif command == "trace":
        from ..trace import parse_camera, parse_light
        from ..trace.two_state import parse_modes

        parse_schemes(options.get("schemes", "none"), TRACE_KINDS, options.get("encoder"), options.get("effort"),
                      "omaps trace")
        parse_modes(options.get("two_state"))
        if options.get("shadows") and isinstance(options.get("light"), (str, type(None))):
            parse_light(options.get("light"))
        if isinstance(options.get("camera"), str):
            parse_camera(options["camera"])
    else:
        from ..jobs import omm_settings

        omm_settings(**{k: v for k, v in options.items() if k in SETTINGS})


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


def check_split(command: str, options: dict) -> None:
    """A batch that splits each input into pieces: omm, with options whose bake splits
    (``omaps.omm.split.splittable``), else an ``InputError`` saying why."""
    if command != "omm":
        raise InputError(f"{{split}} splits an omm bake; a batch of {command} runs one task per input",
                         param="split")
    from ..jobs import omm_settings
    from ..omm.split import splittable

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
    no_alpha = found_without_alpha(command, inputs or [], found, options)
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
