"""Resuming: the completion marker written last for each finished input, the fingerprint it
holds, and what a killed batch left behind."""

from __future__ import annotations

import json
import os

from .. import atomic
from .inputs import MARKERS


def marker_path(outdir: str, name: str) -> str:
    return os.path.join(outdir, MARKERS, name + ".json")


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
