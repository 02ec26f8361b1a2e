"""``omaps batch omm|eval|trace INPUTS... -o OUTDIR``: the single command over many inputs, on Dask
(``omaps.batch``). Each subcommand takes the single command's own options (its parser, reused)."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time

from .. import atomic
from .. import batch as engine
from ..errors import InputError
from .common import show_progress


NAMING = ("Output names: an input's path relative to the folder given, extension dropped; a file named (or "
          "matched by a glob): its file name, but a scene.gltf or scene.glb takes its folder's name "
          "(smallpine/scene.gltf: smallpine). Where two inputs would share a name, each keeps its extension "
          "(NAME_EXT); two inputs still with the same output name, or an omm folder inside another's, are an "
          "error naming both (exit 2) before any work.")


def add_parser(sub) -> None:
    """``omaps batch omm|eval|trace``: each subcommand is the single command's own parser (its
    options, defaults and help, defined once), less what a batch sets itself or refuses: the
    single command's output options and those are hidden from the help (and refused with a
    message naming them), its input takes many, and the batch's options are added."""
    from . import maps, omm, trace

    b = sub.add_parser("batch", help="run omm, eval or trace over many inputs on Dask (resumable, one summary)",
                       description="Run omaps omm, eval or trace on every input (files, folders, globs), one "
                                   "output per input under OUTDIR (the single command's layout: OUTDIR/NAME/ for "
                                   "omm, OUTDIR/NAME.json for eval and trace), and write OUTDIR/summary.json and "
                                   "summary.csv. A bad input is a recorded error; a re-run skips finished inputs. "
                                   + NAMING)
    bsub = b.add_subparsers(dest="batch_command", required=True, metavar="omm|eval|trace")
    makers = {"omm": omm.add_parser, "eval": maps.add_eval_parser, "trace": trace.add_parser}
    for name in engine.COMMANDS:
        makers[name](bsub)
        p = bsub.choices[name]
        what = bsub._choices_actions[-1].help  # the single command's one-line help
        p.prog = f"omaps batch {name}"
        p.description = (f"omaps {name} ({what}) on every input, its output under OUTDIR "
                         + ("(OUTDIR/NAME/, or OUTDIR/NAME.glb with --glb)" if name == "omm" else "(OUTDIR/NAME.json)")
                         + ", then OUTDIR/summary.json and summary.csv. " + NAMING)
        p.epilog = None  # (trace's: its printed table, which a batch does not print)
        p.formatter_class = argparse.HelpFormatter
        hidden = set(engine.REFUSED[name]) | ({"json"} if name != "omm" else set())
        for act in p._actions:  # the single command's input becomes many inputs
            if act.dest == engine.INPUT_DEST[name]:
                act.nargs, act.metavar = "+", "INPUT"
                act.help = "files, folders (searched recursively) or globs"
            elif act.dest in hidden:
                act.help = argparse.SUPPRESS
            elif act.dest == "quiet":
                act.help = "no progress bar"
            if name == "omm" and act.dest == "output":
                act.help = "OUTDIR: one omm folder per input (OUTDIR/NAME/), summary.json, summary.csv"
                act.metavar = "OUTDIR"
                act.dest = "batch_output"
        if name != "omm":
            p.add_argument("-o", "--output", dest="batch_output", metavar="OUTDIR",
                           help="one JSON per input (OUTDIR/NAME.json), summary.json, summary.csv")
        g = p.add_argument_group("batch")
        if name == "omm":
            g.add_argument("--glb", action="store_true",
                           help="write OUTDIR/NAME.glb (each glTF scene with EXT_mesh_opacity_micromap, as "
                                "omaps omm SCENE -o NAME.glb) instead of an OMM folder")
        g.add_argument("--scheduler", default="local", metavar="local|none|tcp://HOST:PORT",
                       help="local: a Dask LocalCluster sized to this machine (default); none: serial, in this "
                            "process; tcp://HOST:PORT: an existing Dask scheduler (an address that takes no "
                            f"connection in {engine.CONNECT_SECONDS} s is an error)")
        g.add_argument("--window", type=int, default=None, metavar="N",
                       help="at most N inputs in flight (default: twice the workers' threads)")
        p.set_defaults(func=cmd_batch)


def cmd_batch(a: argparse.Namespace) -> int:
    if a.batch_command == "omm":
        a.output = None  # moved to batch_output; the per-input output is set by the batch
    return run_batch(a)


def run_batch(a) -> int:
    """``omaps batch``: see the module docstring. Exit 0 when every input is ok or skipped, 1 when
    one has an error or problems (all listed in the summary), 2 bad batch options."""
    command, outdir = a.batch_command, a.batch_output
    if not outdir:
        raise InputError(f"give the output folder with -o OUTDIR (omaps batch {command} INPUTS... -o OUTDIR)")
    for opt in engine.REFUSED[command]:
        if getattr(a, opt, None):
            raise InputError(f"omaps batch {command} writes one output per input under OUTDIR; "
                             f"--{opt.replace('_', '-')} is not available here")
    if command != "omm" and getattr(a, "json", None):
        raise InputError(f"omaps batch {command} writes each input's JSON under OUTDIR; drop --json")
    if a.scheduler not in ("none", "local") and not a.scheduler.startswith(("tcp://", "tls://", "inproc://")):
        raise InputError(f"--scheduler must be local, none or tcp://HOST:PORT, got {a.scheduler!r}")
    engine.check_scheduler(a.scheduler)
    engine.precheck(command, a)
    if a.window is not None and a.window < 1:
        raise InputError(f"--window must be >= 1, got {a.window}")
    if os.path.lexists(outdir) and not os.path.isdir(outdir):
        raise InputError("exists and is not a folder; -o is the batch's output folder", outdir)
    atomic.check_file(os.path.join(outdir, engine.SUMMARY + ".json"), "-o")  # OUTDIR can be created and written
    found = engine.find_inputs(command, getattr(a, engine.INPUT_DEST[command]) or [], outdir)
    names = engine.output_names(command, found, command == "omm" and not getattr(a, "glb", False))
    engine.remove_stale_temporaries(outdir)
    options = engine.command_options(a)
    engine.single_function(command)  # importable before any work
    records: dict[str, dict] = {}
    jobs = []
    for (path, _), name in zip(found, names):
        fp = engine.fingerprint(command, path, options)
        out = engine.output_path(command, outdir, name, options)
        done = engine.finished(command, out, engine.marker_path(outdir, name), fp)
        if done is not None:
            records[name] = {**done, "resumed": True}
            continue
        if command == "omm" and os.path.isdir(out) and os.listdir(out) and "omm.json" not in os.listdir(out):
            records[name] = {"input": path, "output": os.path.relpath(out, outdir), "status": "error",
                             "error": f"{out}: folder is not empty and holds no omm.json (not written by omaps): "
                                      "not replacing it"}
            continue
        jobs.append((command, options, path, name, outdir, fp))
    t0 = time.perf_counter()
    print(f"omaps batch {command}: {engine.count(len(found), 'input')}, {len(found) - len(jobs)} already done "
          f"or refused, {len(jobs)} to run (scheduler {a.scheduler})", flush=True)
    by_input = {j[2]: j[3] for j in jobs}
    for rec in engine.run_all(command, jobs, a.scheduler, a.window, show_progress(a.quiet)):
        records[by_input.get(rec["input"], rec["input"])] = rec
    dt = time.perf_counter() - t0
    ordered = [records[n] for n in names if n in records]
    ordered += [r for n, r in records.items() if n not in names]
    tot = engine.totals(command, ordered)
    tot["seconds"] = round(dt, 3)
    tot["inputs_per_second"] = round(len(jobs) / dt, 4) if jobs and dt > 0 else None
    settings = {"command": command, "scheduler": a.scheduler, "options": options}
    with contextlib.suppress(OSError):
        os.rmdir(os.path.join(outdir, engine.MARKERS))  # only if empty (nothing done)
    atomic.write_text(os.path.join(outdir, engine.SUMMARY + ".json"),
                      json.dumps({"settings": settings, "inputs": ordered, "totals": tot}, indent=1) + "\n")
    atomic.write_text(os.path.join(outdir, engine.SUMMARY + ".csv"), engine.summary_csv(ordered, tot))
    for r in ordered:
        if r["status"] == "error":
            print(f"omaps: error: {r['error']}", file=sys.stderr)
        elif r["status"] == "problems":
            print(f"omaps: {r['input']}: done with problems: " + "; ".join(r.get("messages", [])), file=sys.stderr)
    print(f"omaps batch {command}: {tot['ok']} ok, {tot['problems']} with problems, {tot['skipped']} skipped, "
          f"{engine.count(tot['error'], 'error')} ({tot['resumed']} done before); {dt:.2f} s; summary in "
          f"{os.path.join(outdir, engine.SUMMARY + '.json')} and .csv")
    if command == "eval" and "mean_savings" in tot:
        print("mean savings: " + ", ".join(f"{s} {v:.3f}" for s, v in tot["mean_savings"].items()))
    return 1 if tot["error"] or tot["problems"] else 0
