"""Codecs from other packages: the entry point group ``omaps.codecs``.

A distribution that declares, in its ``pyproject.toml``::

    [project.entry-points."omaps.codecs"]
    rle16 = "omaps_rle16:entries"

adds the codecs that ``omaps_rle16.entries()`` returns (an iterable of
``omaps.codecs.CodecEntry``) to the registry when omaps starts: every command, the tracer, the
byte budgets (those that opt in), the compile-ahead and the docs' codec tables then know them. The
registry checks each entry as it checks its own, gives it a format code after omaps' own codecs
(in the order of the distributions' and entry points' names) and names the plug-in in any error.
A plug-in's package is keyed in numba's cache by its content (``omaps.kernel_cache.watch``), and
omaps' kernels that inline the codecs' lookups are keyed on every installed plug-in's code, so a
plug-in added, removed or changed never leaves a stale kernel behind.

``OMAPS_CODEC_PLUGINS=0`` starts omaps without plug-ins (for a broken one: its error says so).
An entry point is code its distribution runs in omaps' process: install only plug-ins you trust,
as any Python package.

Example::

    >>> from omaps.plugins import codec_entry_points
    >>> [ep.name for ep in codec_entry_points()]          # none installed here
    []
"""

from __future__ import annotations

import os

__all__ = ["GROUP", "codec_entry_points", "codec_entries", "package_folder", "enabled"]

GROUP = "omaps.codecs"
_OFF = "OMAPS_CODEC_PLUGINS"
HINT = f" (set {_OFF}=0 to start omaps without plug-ins)"  # the end of every plug-in's error


def enabled() -> bool:
    """Whether plug-ins load (``OMAPS_CODEC_PLUGINS`` is not ``0``)."""
    return os.environ.get(_OFF, "").strip() != "0"


def _distribution(ep) -> str:
    dist = getattr(ep, "dist", None)
    return getattr(dist, "name", None) or "?"


def codec_entry_points() -> list:
    """The installed entry points of the group ``omaps.codecs``, in the order their codecs get
    format codes: by distribution name, then entry point name (none when plug-ins are off)."""
    if not enabled():
        return []
    from importlib.metadata import entry_points

    found = {(_distribution(ep), ep.name, ep.value): ep for ep in entry_points(group=GROUP)}
    return [found[k] for k in sorted(found)]


def describe(ep) -> str:
    """How messages name a plug-in: ``codec plug-in 'rle16' (omaps_rle16:entries, from omaps-rle16)``."""
    return f"codec plug-in {ep.name!r} ({ep.value}, from {_distribution(ep)})"


def package_folder(ep) -> tuple[str, str] | None:
    """(top-level package name, its folder) of an entry point's module, found without running it;
    None for a module that is no package."""
    import importlib.util

    top = ep.value.split(":")[0].strip().split(".")[0]
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return None
    locations = list(getattr(spec, "submodule_search_locations", None) or []) if spec else []
    return (top, locations[0]) if locations else None


def codec_entries(prepare=None) -> list[tuple[str, list]]:
    """Each plug-in's entries: (how messages name it, what its entry point returned, as a list).
    ``prepare(folder, name)`` is called with its package before its code runs (the registry
    passes ``kernel_cache.watch``). A plug-in that cannot be loaded, or whose callable fails or
    returns no iterable, is an ``InputError`` naming it."""
    from .errors import InputError

    out = []
    for ep in codec_entry_points():
        where = describe(ep)
        pkg = package_folder(ep)
        if pkg is None:
            raise InputError(f"{where}: its module must be part of a package (omaps keys its kernels on the "
                             f"package's files){HINT}")
        if prepare is not None:
            prepare(pkg[1], pkg[0])
        try:
            fn = ep.load()
            if not callable(fn):
                raise TypeError(f"{ep.value} is a {type(fn).__name__}, not a callable returning CodecEntry objects")
            entries = list(fn())
        except Exception as exc:  # noqa: BLE001 - a stranger's code: any failure is reported as theirs
            raise InputError(f"{where}: loading its codecs failed: {type(exc).__name__}: {exc}{HINT}") from exc
        out.append((where, entries))
    return out
