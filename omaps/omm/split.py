"""One scene's OMM bake split into pieces that run anywhere (``omaps batch omm --split``): the
same buffers as ``build``, byte for byte.

``build`` runs its stages geometry by geometry, chunk by chunk: plan (``plan_geometry``), bake
(``bake_states``), resolve (``resolve.resolve_counted``), pack (``Packer``). The bake and the
resolve of a triangle depend on that triangle alone (its UVs, level, unknown flag and the
geometry's alpha test), so they split into pieces of triangles (``Piece``) that a pool of
workers runs in any order (``bake_piece``); the plan and the pack stay here, in order: the
pack sees the pieces' micromaps in ``build``'s order and accumulates the statistics over
``build``'s own chunks, so every buffer and figure (floating-point sums included) is the same.

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

from .. import __version__, states
from ..bake.micromap import flag_table
from ..errors import InputError
from . import format as omm_format
from .pipeline import Geometry, OmmResult, OmmSettings, Packer, _chunks, bake_states, plan_geometry
from .resolve import resolve_counted

__all__ = ["Piece", "bake_piece", "plan_pieces", "build_split", "splittable"]

MIN_PIECE_MICRO_TRIANGLES = 1 << 16  # a piece smaller than this costs more to send than to bake


def splittable(settings: OmmSettings) -> str | None:
    """None when a bake with these settings splits into pieces, else why not."""
    if settings.budget is not None:
        return "a --budget bake chooses every triangle's level over the whole scene at once"
    if settings.source != "texture":
        return "a --from bake encodes its pair maps with the codec's own worker processes"
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
    return resolve_counted(s3, starts, piece.levels, test, piece.tris, fmt, promotion, seed)


def plan_pieces(geometries: list[Geometry], settings: OmmSettings, pieces: int) -> tuple[list, list[Piece]]:
    """The plans (``plan_geometry``) of every geometry and the pieces to bake: each of ``build``'s
    chunks cut into runs of about 1/``pieces`` of the scene's micro-triangles (at least
    ``MIN_PIECE_MICRO_TRIANGLES``, whole triangles), in ``build``'s order."""
    why = splittable(settings)
    if why is not None:
        raise InputError(f"this bake does not split into pieces: {why}")
    plans = [plan_geometry(g, settings) for g in geometries]
    total = sum(int(np.sum(np.left_shift(np.int64(1), 2 * p.levels))) for p in plans)
    target = max(total // max(int(pieces), 1), MIN_PIECE_MICRO_TRIANGLES)
    out = []
    for gi, p in enumerate(plans):
        for a, b in _chunks(p.levels):
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
        return _pack(geometries, settings, plans, work, results)
    finally:
        close = getattr(results, "close", None)
        if close is not None:  # (a generator left early: its own clean-up, now)
            close()


def _pack(geometries, settings, plans, work, results) -> OmmResult:
    """``build``'s pack stage and statistics over the pieces' results, in ``build``'s chunks."""
    fmt = settings.format_code
    packer = Packer(settings)
    index_parts, geo_info = [], []
    counts3 = np.zeros(3, dtype=np.int64)
    promoted = np.zeros(4, dtype=np.int64)
    known_area = total_area = 0.0
    micro_total = 0
    level_hist: dict[int, int] = {}
    bytes_no_reuse = 0
    first = 0
    k = 0  # the next piece
    for gi, (g, gp) in enumerate(zip(geometries, plans)):
        levels, weight, area = gp.levels, gp.weight, gp.area
        idx = np.empty(len(gp.tris), dtype=np.int32)
        for a, b in _chunks(levels):
            parts = []
            while k < len(work) and work[k].geometry == gi and work[k].b <= b:
                parts.append(next(results))
                k += 1
            omm = np.concatenate([o for o, _ in parts])
            tri_counts = np.concatenate([c for _, c in parts])
            lv = levels[a:b]
            starts = np.concatenate([[0], np.cumsum(np.left_shift(np.int64(1), 2 * lv))])
            w = weight[a:b]
            counts3 += (tri_counts[:, :3] * w[:, None]).sum(axis=0)
            promoted += (tri_counts[:, 3:] * w[:, None]).sum(axis=0)
            micro_total += int(np.sum(w << (2 * lv)))
            per_tri_known = tri_counts[:, 0] + tri_counts[:, 1]
            known_area += float(np.sum(area[a:b] * per_tri_known / np.left_shift(1, 2 * lv)))
            total_area += float(np.sum(area[a:b]))
            for lvl in np.unique(lv):
                sel = np.flatnonzero(lv == lvl)
                if len(sel) == len(lv):
                    rows = omm.reshape(len(lv), -1)
                else:
                    rows = omm[starts[sel][:, None] + np.arange(1 << (2 * int(lvl)))]
                idx[a + sel] = packer.add(rows, int(lvl), weights=w[sel])
                bytes_no_reuse += int(w[sel].sum()) * omm_format.micromap_bytes(int(lvl), fmt)
                level_hist[int(lvl)] = level_hist.get(int(lvl), 0) + int(w[sel].sum())
        index_parts.append(idx if gp.inverse is None else idx[gp.inverse])
        geo_info.append({"name": g.name, "first_triangle": first, "triangles": gp.n_input, "texture": g.test.name,
                         "width": g.test.width, "height": g.test.height, "filter": g.test.filter,
                         "wrap_u": g.test.wrap_u, "wrap_v": g.test.wrap_v, "threshold": g.test.threshold,
                         "inclusive": g.test.inclusive, "state_rule": g.test.rule, **g.info})
        first += gp.n_input
    index = np.concatenate(index_parts) if index_parts else np.zeros(0, dtype=np.int32)
    triangles = packer.record_array()
    data = packer.data()
    usage = omm_format.usage_histograms(triangles["level"], triangles["format"], index)
    special = {str(int(v)): int(np.count_nonzero(index == v)) for v in omm_format.SPECIAL_INDEX}
    summary = {
        "omaps": __version__,
        "format": settings.format, "format_code": fmt,
        "settings": {"source": settings.source, "level": None if settings.dynamic_scale else settings.level,
                     "dynamic_scale": settings.dynamic_scale, "max_level": settings.max_level,
                     "promotion": settings.promotion, "special": settings.special, "dedup": settings.dedup,
                     "seed": settings.seed, "encoder": settings.encoder, "effort": settings.effort,
                     "budget": settings.budget},
        "geometries": geo_info,
        "statistics": {
            "triangles": int(len(index)), "micro_triangles": int(micro_total),
            "levels": {str(k): v for k, v in sorted(level_hist.items())},
            "transparent": int(counts3[states.T]), "opaque": int(counts3[states.O]),
            "unknown": int(counts3[states.C]),
            "known_fraction": float((counts3[0] + counts3[1]) / micro_total) if micro_total else 0.0,
            "known_area_fraction": known_area / total_area if total_area > 0 else 0.0,
            "unknown_resolved": {"transparent": int(promoted[0]), "opaque": int(promoted[1]),
                                 "unknown_transparent": int(promoted[2]), "unknown_opaque": int(promoted[3])},
            "special_indices": special,
            "micromaps_without_reuse": int(len(index)),
            "micromaps_after_special_indices": int(packer.needing),
            "micromaps": int(len(triangles)),
            "data_bytes": int(len(data)), "data_bytes_without_reuse": int(bytes_no_reuse),
            "data_and_record_bytes": int(len(data) + triangles.nbytes),
            "bytes": int(len(data) + triangles.nbytes + index.nbytes),
        },
    }
    return OmmResult(data, triangles, index, usage, summary)
