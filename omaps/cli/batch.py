"""``omaps batch omm|eval|trace INPUTS... -o OUTDIR``: the single command over many inputs, on Dask
(``omaps.batch``). Each subcommand takes the single command's own options (its parser, reused)."""

from __future__ import annotations

import argparse

from .. import batch as engine


def add_parser(sub) -> None:
    from . import maps, omm, trace

    b = sub.add_parser("batch", help="run omm, eval or trace over many inputs on Dask (resumable, one summary)",
                       description="Run omaps omm, eval or trace on every input (files, folders, globs), one "
                                   "output per input under OUTDIR (the single command's layout: OUTDIR/NAME/ for "
                                   "omm, OUTDIR/NAME.json for eval and trace), and write OUTDIR/summary.json and "
                                   "summary.csv. A bad input is a recorded error; a re-run skips finished inputs.")
    bsub = b.add_subparsers(dest="batch_command", required=True, metavar="omm|eval|trace")
    makers = {"omm": omm.add_parser, "eval": maps.add_eval_parser, "trace": trace.add_parser}
    for name in engine.COMMANDS:
        makers[name](bsub)
        p = bsub.choices[name]
        p.prog = f"omaps batch {name}"
        for act in p._actions:  # the single command's input becomes many inputs
            if act.dest == engine.INPUT_DEST[name]:
                act.nargs, act.metavar = "+", "INPUT"
                act.help = "files, folders (searched recursively) or globs"
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
                            "process; tcp://HOST:PORT: an existing Dask scheduler")
        g.add_argument("--window", type=int, default=None, metavar="N",
                       help="at most N inputs in flight (default: twice the workers' threads)")
        p.set_defaults(func=cmd_batch)


def cmd_batch(a: argparse.Namespace) -> int:
    if a.batch_command == "omm":
        a.output = None  # moved to batch_output; the per-input output is set by the batch
    return engine.batch(a)
