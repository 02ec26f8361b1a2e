"""``omaps batch omm|eval|trace INPUTS... -o OUTDIR``: the single command over many inputs, on Dask
(``omaps.batch``). Each subcommand takes the single command's own options (its parser, reused)."""

from __future__ import annotations

import argparse
import sys

from .. import batch as engine
from ..batch.engine import CONNECT_SECONDS
from ..errors import InputError
from .common import show_progress

STOPPED = 3  # the exit code of a batch that stopped before its end (run the same command again)

# the single command's positional input (namespace attribute), and its options a batch refuses (it
# writes one output per input itself); hidden from the batch's help, as is eval's and trace's --json
INPUT_DEST = {"omm": "inputs", "eval": "paths", "trace": "scene"}
REFUSED = {"eval": ("csv", "plot", "show", "per_texture"), "omm": ("verify", "expand"),
           "trace": ("heatmap", "render", "plot_budget", "plot_frontier")}


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
        hidden = set(REFUSED[name]) | ({"json"} if name != "omm" else set())
        for act in p._actions:  # the single command's input becomes many inputs
            if act.dest == INPUT_DEST[name]:
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
            g.add_argument("--split", action="store_true",
                           help="one scene after the other, each one's bake split into pieces of triangles that "
                                "run on every worker, then packed and written here: the same outputs (for a few "
                                "large scenes; not with --budget or --from)")
        g.add_argument("--scheduler", default="local", metavar="local|none|tcp://HOST:PORT",
                       help="local: a Dask LocalCluster sized to this machine (default); none: serial, in this "
                            "process; tcp://HOST:PORT: an existing Dask scheduler (an address that does not answer as "
                            f"one within {CONNECT_SECONDS} s is an error)")
        g.add_argument("--window", type=int, default=None, metavar="N",
                       help="at most N inputs (or pieces of a split scene) in flight (default: twice the "
                            "workers' threads)")
        p.set_defaults(func=cmd_batch)


def cmd_batch(a: argparse.Namespace) -> int:
    """``omaps batch``: the single command's options as its library call's keyword arguments,
    then ``omaps.batch.plan_batch`` and ``run_plan``. Exit 0 when every input is ok or skipped, 1
    when one has an error or problems (all listed in the summary), 2 bad batch options, 3
    (``STOPPED``) when the batch stopped before its end or could not write its summary."""
    from . import maps, omm, trace

    command, outdir = a.batch_command, a.batch_output
    if command == "omm":
        a.output = None  # moved to batch_output; the per-input output is set by the batch
    if not outdir:
        raise InputError(f"give the output folder with -o OUTDIR (omaps batch {command} INPUTS... -o OUTDIR)")
    for opt in REFUSED[command]:
        if getattr(a, opt, None):
            raise InputError(f"omaps batch {command} writes one output per input under OUTDIR; "
                             f"--{opt.replace('_', '-')} is not available here")
    if command != "omm" and getattr(a, "json", None):
        raise InputError(f"omaps batch {command} writes each input's JSON under OUTDIR; drop --json")
    options = {"omm": omm.bake_options, "eval": maps.eval_options, "trace": trace.trace_options}[command](a)
    plan = engine.plan_batch(command, getattr(a, INPUT_DEST[command]), outdir, options, scheduler=a.scheduler,
                             window=a.window, glb=getattr(a, "glb", False), split=getattr(a, "split", False))
    print(plan.line(), flush=True)
    res = engine.run_plan(plan, show_progress(a.quiet))
    for m in res.messages():
        print(m, file=sys.stderr)
    if res.stopped:
        print(f"omaps: error: the batch stopped: {res.stopped}", file=sys.stderr)
    if res.summary_error:
        print(f"omaps: error: the summary could not be written: {res.summary_error}", file=sys.stderr)
    print(res.line())
    return 0 if res.ok else 1 if res.complete else STOPPED
