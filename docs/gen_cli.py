"""Generate the command-line reference (``reference/cli.md``) from the argparse parser of
``omaps.cli.main.parser()``: every subcommand's usage, description and options, as ``--help``
prints them. Run by the mkdocs-gen-files plugin during ``mkdocs build``; also runnable alone:
``python docs/gen_cli.py`` prints the page."""

from __future__ import annotations

import argparse
import os

PAGE = "reference/cli.md"


def _subparsers(p: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in p._actions:  # argparse keeps no public list of them
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help(p: argparse.ArgumentParser) -> str:
    os.environ["COLUMNS"] = "100"  # a fixed width: the same page on every terminal
    return p.format_help().rstrip()


def render() -> str:
    from omaps.cli.main import parser

    root = parser()
    out = ["# Command-line reference", "",
           "Generated from `omaps.cli.main.parser()` when the site is built (`docs/gen_cli.py`): "
           "exactly what `omaps COMMAND --help` prints. The [user guide](../guide/eval.md) explains "
           "each command with examples.", "",
           "## omaps", "", "```text", _help(root), "```", ""]

    def walk(p, name):
        for sub, sp in _subparsers(p).items():
            full = f"{name} {sub}"
            out.extend([f"## {full}", "", "```text", _help(sp), "```", ""])
            walk(sp, full)

    walk(root, "omaps")
    return "\n".join(out)


try:
    import mkdocs_gen_files
except ImportError:  # run alone
    mkdocs_gen_files = None

if mkdocs_gen_files is not None and __name__ != "__main__":
    with mkdocs_gen_files.open(PAGE, "w") as f:
        f.write(render())
    mkdocs_gen_files.set_edit_path(PAGE, "gen_cli.py")

if __name__ == "__main__":
    print(render())
