"""One scene's OMM bake split into pieces that run anywhere (``omaps batch omm --split``): the
same buffers as ``build``, byte for byte.

``build`` runs its stages geometry by geometry, chunk by chunk: plan (``plan_geometry``), bake
(``bake_states``), resolve (``resolve.resolve_counted``), pack (``Packer``). The bake and the
resolve of a triangle depend on that triangle alone (its UVs, level, unknown flag and the
geometry's alpha test), so they split into pieces of triangles (``Piece``) that a pool of
workers runs in any order (``bake_piece``); the plan stays here, and ``build`` itself packs
the pieces' micromaps, joined into its own chunks in its order (its ``plans`` and ``chunks``), so
every buffer and figure (floating-point sums included) is the same.

What splits: the texture source at one level or ``--dynamic`` levels. What does not: a
``--budget`` (its levels are chosen over the whole scene at once) and a square ``--from``
source (its pair maps are encoded by the codec's own worker processes); ``splittable`` says why.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.omm import Geometry, OmmSettings, build
    >>> from omaps.omm.split import build_split
    >>> from omaps.texture import load_alpha
    >>> test = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8)), "linear", "wrap")
    >>> g = Geometry("leaf", test, np.random.default_rng(0).random((40, 3, 2)))
    >>> a, b = build([g], OmmSettings(level=3)), build_split([g], OmmSettings(level=3), pieces=4)
    >>> a.data.tobytes() == b.data.tobytes() and a.summary == b.summary
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bake.micromap import flag_table
from ..errors import InputError
from .pipeline import Geometry, OmmResult, OmmSettings, bake_states, build, chunk_ranges, plan_geometry
from .resolve import resolve_counted

__all__ = ["Piece", "bake_piece", "plan_pieces", "build_split", "splittable"]

MIN_PIECE_MICRO_TRIANGLES = 1 << 16  # a piece smaller than this costs more to send than to bake


def splittable(settings: OmmSettings) -> str | None:
    """None when a bake with these settings splits into pieces, else why not (the parameter it
    names as ``{budget}`` or ``{source}``, as ``InputError`` templates do)."""
    if settings.budget is not None:
        return "a {budget} bake chooses every triangle's level over the whole scene at once"
    if settings.merged_level is not None:
        return "a {source} bake merges every triangle's micromap into one DAG in one process"
    if settings.source != "texture":
        return "a {source} bake encodes its pair maps with the codec's own worker processes"
    return None


@dataclass
class Piece:
    """Triangles ``a:b`` of geometry ``geometry``'s plan: what a worker bakes and resolves."""

    geometry: int
    a: int
    b: int
    tris: np.ndarray
    levels: np.ndarray
    unknown: np.ndarray | None

    @property
    def micro_triangles(self) -> int:
        return int(np.sum(np.left_shift(np.int64(1), 2 * self.levels)))


def bake_piece(test, piece: Piece, fmt: int, promotion: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A piece's OMM states (flat) and per-triangle counts (``resolve_counted``), as ``build``
    computes them for those triangles. ``test``: the geometry's ``AlphaTest`` (its grid is made
    once per test object: a worker that keeps the test keeps its grid)."""
    grid = test.grid()
    sat = test.__dict__.get("_flag_table")
    if sat is None:
        sat = flag_table(grid)
        object.__setattr__(test, "_flag_table", sat)
    s3, starts = bake_states(grid, piece.tris, piece.levels, sat, piece.unknown)
    return resolve_counted(s3, starts, piece.levels, test, piece.tris, fmt, promotion, seed, out=s3)


def plan_pieces(geometries: list[Geometry], settings: OmmSettings, pieces: int) -> tuple[list, list[Piece]]:
    """The plans (``plan_geometry``) of every geometry and the pieces to bake: each of ``build``'s
    chunks cut into runs of about 1/``pieces`` of the scene's micro-triangles (at least
    ``MIN_PIECE_MICRO_TRIANGLES``, whole triangles), in ``build``'s order."""
    why = splittable(settings)
    if why is not None:
        raise InputError(f"this bake does not split into pieces: {why}", param=("budget", "source"))
    plans = [plan_geometry(g, settings) for g in geometries]
    total = sum(int(np.sum(np.left_shift(np.int64(1), 2 * p.levels))) for p in plans)
    target = max(total // max(int(pieces), 1), MIN_PIECE_MICRO_TRIANGLES)
    out = []
    for gi, p in enumerate(plans):
        for a, b in chunk_ranges(p.levels):
            sizes = np.cumsum(np.left_shift(np.int64(1), 2 * p.levels[a:b]))
            cuts = [a] + [a + int(np.searchsorted(sizes, k * target, side="right")) for k in
                          range(1, int(sizes[-1] // target) + 1)] + [b]
            for x, y in zip(cuts, cuts[1:]):
                if y > x:
                    out.append(Piece(gi, x, y, p.tris[x:y], p.levels[x:y],
                                     None if p.unknown is None else p.unknown[x:y]))
    return plans, out


def _serial(jobs):
    for test, piece, *rest in jobs:
        yield bake_piece(test, piece, *rest)


def build_split(geometries: list[Geometry], settings: OmmSettings = OmmSettings(), run=None,
                pieces: int = 8) -> OmmResult:
    """``build`` with the bake and resolve of its triangles in pieces run by ``run``: a function
    taking the list of ``(test, piece, fmt, promotion, seed)`` (``bake_piece``'s arguments) and
    yielding their results in that order (default: one after the other, here). The result is
    ``build``'s, byte for byte."""
    fmt = settings.format_code
    plans, work = plan_pieces(geometries, settings, pieces)
    jobs = [(geometries[p.geometry].test, p, fmt, settings.promotion, settings.seed) for p in work]
    results = (run or _serial)(jobs)
    try:
        return build(geometries, settings, plans=plans, chunks=_per_chunk(plans, work, results))
    finally:
        close = getattr(results, "close", None)
        if close is not None:  # (a generator left early: its own clean-up, now)
            close()


def _per_chunk(plans, work: list[Piece], results):
    """The pieces' results joined into ``build``'s chunks, in its order."""
    k = 0  # the next piece
    for gi, gp in enumerate(plans):
        for _, b in chunk_ranges(gp.levels):
            parts = []
            while k < len(work) and work[k].geometry == gi and work[k].b <= b:
                parts.append(next(results))
                k += 1
            yield np.concatenate([o for o, _ in parts]), np.concatenate([c for _, c in parts])
