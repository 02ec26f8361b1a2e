"""A batch's inputs: finding them (files, folders, globs), naming their outputs, and the library
call each one runs."""

from __future__ import annotations

import glob
import os

from ..errors import InputError

COMMANDS = ("omm", "eval", "trace")
MARKERS = ".batch"  # OUTDIR/.batch/NAME.json: the completion markers
SUMMARY = "summary"  # OUTDIR/summary.json and .csv
from ..scene.files import SCENE_SUFFIXES as GLTF_EXTENSIONS  # every scene file: glTF and OpenUSD


def library_call(command: str):
    """The one library call a batch runs per input: ``bake_omms``, ``evaluate_corpus`` or
    ``trace_scene``."""
    if command == "omm":
        from ..jobs import bake_omms

        return bake_omms
    if command == "eval":
        from ..corpus import evaluate_corpus

        return evaluate_corpus
    from ..trace import trace_scene

    return trace_scene


def _has_magic(p: str) -> bool:
    return glob.has_magic(p)


def _wanted(command: str, path: str) -> bool:
    from ..texture import IMAGE_EXTENSIONS

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
        raise InputError("no input found (" + ("images" if command == "eval" else ".gltf / .glb / .usd / .usda / .usdc / .usdz scenes") + ")",
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


def with_root(command: str, options: dict, path: str, rel: str) -> dict:
    """An input's options with the root of its scene's URI policy (``omaps.load_scene``) where
    none is given: the folder given that it was found in (``rel``: its path from there), its own
    folder for a file named or a glob's match."""
    if command == "eval" or options.get("root") is not None or options.get("allow_outside"):
        return options
    given = path[:len(path) - len(rel)] if rel and path.endswith(rel) else os.path.dirname(path)
    return {**options, "root": given or "."}


def found_without_alpha(command: str, given, found, options: dict) -> dict[str, str]:
    """The eval inputs found in a folder or by a pattern (not named one by one) that are images
    without an alpha channel, with why (``texture.without_alpha``; none when a channel is
    given): skipped, as ``omaps eval`` skips them in a folder, not run into an error each."""
    if command != "eval" or getattr(options.get("config"), "channel", None) is not None:
        return {}
    from ..texture import without_alpha

    named = {os.path.abspath(os.fspath(g)) for g in given if os.path.isfile(os.fspath(g))}
    out = {}
    for path, _ in found:
        if os.path.abspath(path) not in named:
            why = without_alpha(path)
            if why is not None:
                out[path] = why
    return out
