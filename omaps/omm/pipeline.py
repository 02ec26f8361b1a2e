"""The OMM pipeline: geometries in, the buffers an engine uploads out (data, triangle records,
index buffer, usage histograms), with special indices and reuse of identical micromaps.

A ``Geometry`` is a set of UV triangles with one alpha test (a glTF primitive, or a texture and
a UV array) and its pairing. Each triangle's micromap comes either straight from the texture
(``source`` ``texture``: the micromap baker, at one level or a level per triangle from its texel
area; ``csmL``: the same baker at level L, every micromap also stored in one merged DAG, the
``merged_micromaps`` blob of ``codecs.csm``) or from the deck's square pair maps (a square
scheme of ``omaps.schemes``: ``sqN``, or a codec such as ``vq2`` or ``vq4-paper``: baked by the
pair-square baker, stored by the codec, decoded, then expanded by ``pairs.expand``). Real geometry is baked with growth
``bake.GROW_TEXEL``, as the tracer bakes it.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.omm import Geometry, OmmSettings, build
    >>> from omaps.texture import load_alpha
    >>> test = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8)), "linear", "wrap")
    >>> res = build([Geometry("leaf", test, np.array([[[0, 0], [1, 0], [0, 1]]]))], OmmSettings(level=2))
    >>> res.index.tolist(), res.data.nbytes
    ([0], 4)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .. import __version__, omm_format, states
from .. import rows as omaps_rows
from ..alpha_test import AlphaTest
from ..bake.micromap import (GROW_TEXEL, bake_micromaps, check_level, check_uv_triangles, dynamic_levels, flag_table,
                             locality_order, micro_starts, texel_areas)
from ..errors import InputError
from ..names import PROMOTIONS
from ..omm_format import Packer
from . import resolve
from ..checks import typed

# The square sources (--from SCHEME: the pair baker, the codecs, the encoding workers, the
# expansion) are imported where they are used, so that baking from the texture loads none of
# their modules and kernels: start-up is part of every omm run's time.

__all__ = ["Geometry", "OmmSettings", "OmmResult", "Progress", "build", "GeometryPlan", "plan_geometry", "bake_states",
           "Packer"]

CHUNK_MICRO_TRIANGLES = 1 << 24  # bake this many micro-triangles at a time (bounded memory)


@dataclass(frozen=True)
class Geometry:
    name: str
    test: AlphaTest
    tris_uv: np.ndarray  # (T, 3, 2) UV triangles
    area: np.ndarray | None = None  # (T,) weights of the known-area fraction (default: texel area)
    unknown: np.ndarray | None = None  # (T,) bool: triangles forced fully unknown (scene.gltf's policies)
    info: dict = field(default_factory=dict)  # recorded in omm.json
    # pairing for square sources: per triangle its pair (local index) and corner codes (T, 3);
    # default: triangles 2k and 2k+1 in the corpus convention (``pairs.corpus_pairing``)
    pair_of: np.ndarray | None = None
    corners: np.ndarray | None = None
    weight: np.ndarray | None = None  # (T,) expected candidate hits, for --budget (default: ``area``)
    # (H, 2) int64 for --budget: candidate hits of a view (triangle, micro-triangle at budget.HIT_LEVEL),
    # each worth one alpha test where its micro-triangle is known, on top of ``weight`` spread by area
    hits: np.ndarray | None = None

    def areas(self, tris: np.ndarray) -> np.ndarray:
        """Weights of the known-area fraction: ``area``, else the triangles' texel areas."""
        if self.area is None:
            return texel_areas(tris, self.test.width, self.test.height)
        return np.asarray(self.area, dtype=np.float64)

    def pairing(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pair_of (T,), corners (T, 3), pairs (P, 2): triangles A and B, -1 for none)."""
        n = len(self.tris_uv)
        if self.pair_of is None:
            from .pairs import corpus_pairing

            return corpus_pairing(n)
        pair_of = np.asarray(self.pair_of, dtype=np.int64)
        corners = np.asarray(self.corners, dtype=np.int8).reshape(n, 3)
        p = int(pair_of.max()) + 1 if n else 0
        out = np.full((p, 2), -1, np.int64)
        is_b = np.isin(corners, [3]).any(axis=1)  # B holds corner (0, 1)
        out[pair_of[~is_b], 0] = np.flatnonzero(~is_b)
        out[pair_of[is_b], 1] = np.flatnonzero(is_b)
        return pair_of, corners, out


@dataclass(frozen=True)
class OmmSettings:
    format: str = "4state"
    level: int = 4
    dynamic_scale: float | None = None  # texels per micro-triangle edge; None: ``level`` for all
    max_level: int = 8
    promotion: str = "nearest"
    special: bool = True
    dedup: bool = True
    source: str = "texture"  # texture, csmL, or a square scheme (``schemes.square_scheme_choices``)
    encoder: str | None = None  # codec encoder and effort (None: the codec's defaults)
    effort: str | None = None
    seed: int = 0  # of the hashed promotion
    jobs: int = 1  # worker processes encoding --from maps (the output does not depend on it)
    budget: int | None = None  # bytes of micromap data + records: levels and formats per triangle (omm.budget)

    def __post_init__(self):
        from .. import checks

        checks.choice(self.format, "format", tuple(omm_format.FORMAT_NAMES))
        checks.choice(self.promotion, "promote", PROMOTIONS)
        if self.dynamic_scale is not None:
            checks.number(self.dynamic_scale, "dynamic", 0, open_lo=True)
        checks.text(self.source, "source")
        checks.integer(self.seed, "seed", 0)
        checks.integer(self.jobs, "jobs", 1)
        checks.boolean(self.special, "special")
        checks.boolean(self.dedup, "dedup")
        if self.budget is not None:
            checks.integer(self.budget, "budget", 1)
        if self.format not in omm_format.FORMAT_NAMES:
            raise InputError(f"unknown OMM format {self.format!r} (choose from {', '.join(omm_format.FORMAT_NAMES)})",
                             param="format")
        if self.promotion not in PROMOTIONS:
            raise InputError(f"unknown promotion {self.promotion!r} (choose from {', '.join(PROMOTIONS)})",
                             param="promote")
        check_level(self.level)
        check_level(self.max_level, "max_level")
        if self.budget is not None and (self.dynamic_scale is not None or self.source != "texture"):
            raise InputError("budget chooses each triangle's level from the texture: drop dynamic and source",
                             param=("budget", "dynamic", "source"))
        if self.budget is not None and self.format != "4state":
            raise InputError("budget chooses each micromap's format (2-state where it has no unknown region): "
                             "drop format", param=("budget", "format"))
        if self.source != "texture":
            s = self.scheme
            if s.kind != "square" and not (s.kind == "micromap" and s.representation == "csm"):
                from ..schemes import square_scheme_choices

                raise InputError(f"source takes texture, a square scheme ({square_scheme_choices()}) or csmL, "
                                 f"L = 0 .. {omm_format.MAX_LEVEL} (the micromaps at level L, also stored as one "
                                 f"merged DAG), not {self.source!r}", param="source")
            if self.dynamic_scale is not None:
                fixed = "csmL fixes the level to L" if s.kind == "micromap" else "square pair maps fix the level to log2 N"
                raise InputError(f"dynamic needs the texture source: {fixed}", param="dynamic")

    @property
    def scheme(self):
        """The square scheme of a ``--from`` source (None for ``texture``)."""
        if self.source == "texture":
            return None
        from ..schemes import get_scheme

        return get_scheme(self.source, self.encoder, self.effort)

    @property
    def merged_level(self) -> int | None:
        """The level L of a ``csmL`` source (the micromaps also stored as one merged DAG), else None."""
        s = self.scheme
        return s.level if s is not None and s.kind == "micromap" else None

    @property
    def format_code(self) -> int:
        return omm_format.FORMAT_NAMES[self.format]


@dataclass
class OmmResult:
    """The buffers, as written to disk: ``data`` (uint8), ``triangles`` (TRIANGLE_RECORD),
    ``index`` (int32 per input triangle), ``usage`` and ``summary`` (the two JSON files) and,
    for a square source, the stored pair maps ``pair_blocks`` and ``pair_records``; for a ``csmL``
    source, ``merged_micromaps``: every input triangle's micromap (T/O/C, before the format's
    resolution of C) as one merged DAG, a root per triangle in index order (``codecs.csm``'s blob)."""

    data: np.ndarray
    triangles: np.ndarray
    index: np.ndarray
    usage: dict
    summary: dict
    pair_blocks: bytes | None = None
    pair_records: np.ndarray | None = None  # PAIR_RECORD per triangle, with pair_blocks
    merged_micromaps: bytes | None = None  # a csmL source's blob

    def micromap_states(self, i: int) -> np.ndarray:
        """States of micromap ``i`` (0..3), decoded from ``data``."""
        rec = self.triangles[i]
        nbytes = omm_format.micromap_bytes(rec["level"], rec["format"])
        raw = self.data[rec["data_offset"]:rec["data_offset"] + nbytes]
        return omm_format.unpack(raw[None], int(rec["level"]), int(rec["format"]))[0]

    def triangle_states(self, t: int) -> np.ndarray:
        """States of input triangle ``t``: its micromap's, or one state for a special index."""
        i = int(self.index[t])
        if i >= 0:
            return self.micromap_states(i)
        return np.array([-1 - i], dtype=np.uint8)


def chunk_ranges(levels: np.ndarray):
    """Triangle ranges [a, b) of at most CHUNK_MICRO_TRIANGLES micro-triangles (at least one):
    the chunks ``build`` bakes, resolves and packs one after the other."""
    sizes = np.left_shift(np.int64(1), 2 * levels)
    n = len(levels)
    a = 0
    while a < n:
        total = np.cumsum(sizes[a:])
        b = a + max(int(np.searchsorted(total, CHUNK_MICRO_TRIANGLES, side="right")), 1)
        b = min(b, n)
        yield a, b
        a = b


def _pair_states(g: Geometry, grid, tris: np.ndarray, scheme, jobs: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """T/O/C micromaps (flat) at level log2 N of every triangle from its pair's square map, stored
    and decoded by the scheme's codec; the blocks (P, bytes) and the pairing records."""
    pair_of, corners, prs = g.pairing()
    from ..bake.square import bake_pair_squares
    from ..pair import corner_uvs
    from ..workers import encode_maps
    from .pairs import expand

    uv, has_b = corner_uvs(tris, corners, prs[:, 0], prs[:, 1])  # every pair has an A
    squares = bake_pair_squares(grid, uv, has_b, scheme.codec.map_size, GROW_TEXEL)
    if g.unknown is not None:  # a pair with an unknown triangle is all C
        unknown = np.zeros(len(prs), bool)
        np.logical_or.at(unknown, pair_of, np.asarray(g.unknown, bool))
        squares[unknown] = states.C
    blocks, decoded = encode_maps(scheme.codec, squares, scheme.encoder, scheme.effort, jobs)
    rec = np.zeros(len(tris), dtype=omm_format.PAIR_RECORD)
    rec["pair"] = pair_of
    rec["corners"] = corners
    return expand(decoded, pair_of, corners).ravel(), blocks, rec


def _triangle_levels(test: AlphaTest, tris: np.ndarray, settings: OmmSettings, n_map: int | None) -> np.ndarray:
    if settings.merged_level is not None:
        return np.full(len(tris), settings.merged_level, dtype=np.int64)
    if n_map is not None:
        from .pairs import level_of_size

        return np.full(len(tris), level_of_size(n_map), dtype=np.int64)
    if settings.dynamic_scale is not None:
        return dynamic_levels(tris, test.width, test.height, settings.dynamic_scale, settings.max_level)
    return np.full(len(tris), settings.level, dtype=np.int64)


class Progress(Protocol):
    """What ``build`` reports as it goes (a progress bar): a stage begins with its total known
    (``stage``: "pricing", micro-triangles, with --budget; then "baking", the micro-triangles
    of the triangles baked: identical ones once), and advances until its steps add up to that
    total."""

    def stage(self, name: str, total: int, unit: str) -> None: ...

    def advance(self, n: int = 1) -> None: ...


@dataclass
class GeometryPlan:
    """What the plan stage (``plan_geometry``) decided for one geometry: the triangles to bake (the
    distinct ones: instanced and repeated foliage cards are baked and resolved once), each one's
    subdivision level, how many input triangles each stands for, their known-area weights, the
    triangles forced unknown, and which baked triangle each input triangle takes (``inverse``; None:
    one to one). Baked from a texture with no budget, the distinct triangles come in
    ``bake.micromap.locality_order`` (neighbours in the texture one after another): the bake,
    resolve and pack stages then read and write their arrays in order, not at random (about a
    tenth less CPU at a million triangles). ``merged``: with a budget, micromaps shared by merging
    (triangle -> (its 3-state meet, its stored row)); ``baked``: with a budget, every triangle's
    micromap as its pricing baked and resolved it ((T/O/C states, OMM states), flat at
    ``micro_starts(levels)``), which the bake and resolve stages then take as they are."""

    tris: np.ndarray
    levels: np.ndarray
    weight: np.ndarray
    area: np.ndarray
    unknown: np.ndarray | None
    inverse: np.ndarray | None
    merged: dict
    n_input: int
    baked: tuple | None = None


def plan_geometry(g: Geometry, settings: OmmSettings, n_map: int | None = None, budget_plan=None) -> GeometryPlan:
    """The plan stage: check a geometry's UV triangles and choose each one's level (one level,
    ``dynamic_levels`` from its texel area, log2 N of a square source ``n_map``, or the budget's
    ``budget_plan`` (levels, merged[, states3, stored]): a ``omm.budget.GeometryBudget``); with ``dedup`` (and neither
    a square source nor a budget), identical triangles -- the same UVs, level and unknown flag --
    are planned once."""
    tris = check_uv_triangles(g.tris_uv) if len(g.tris_uv) else np.zeros((0, 3, 2))
    n_tris = len(tris)
    baked = None
    if budget_plan is None:
        levels, merged = _triangle_levels(g.test, tris, settings, n_map), {}
    else:
        levels, merged = budget_plan[0], budget_plan[1]
        if len(budget_plan) > 2 and budget_plan[2] is not None:
            baked = (budget_plan[2], budget_plan[3])
    area = g.areas(tris)
    unknown = None if g.unknown is None else np.asarray(g.unknown, dtype=bool)
    inverse = None
    if settings.dedup and n_map is None and budget_plan is None and len(tris):  # (no reuse: a micromap each)
        # (the level and the unknown flag join the key only where they differ between triangles)
        key = [np.ascontiguousarray(tris, dtype=np.float64).reshape(len(tris), 6).view(np.uint64)]
        key += [] if (levels == levels[0]).all() else [levels.astype(np.uint64)[:, None]]
        key += [] if unknown is None or (unknown == unknown[0]).all() else [unknown.astype(np.uint64)[:, None]]
        first_of, inverse = omaps_rows.first_occurrences(key[0] if len(key) == 1 else np.concatenate(key, axis=1))
        if len(first_of) == len(tris):
            inverse = None
    if inverse is None:
        weight = np.ones(len(tris), dtype=np.int64)
    else:
        weight = np.bincount(inverse, minlength=len(first_of))
        area = np.bincount(inverse, weights=area, minlength=len(first_of))
        tris, levels = np.take(tris, first_of, axis=0), levels[first_of]
        unknown = None if unknown is None else unknown[first_of]
    if n_map is None and budget_plan is None and len(tris) > 1:  # the bake's order, for all stages
        order = locality_order(tris, g.test.width, g.test.height)
        rank = np.empty(len(order), dtype=np.int64)
        rank[order] = np.arange(len(order))
        inverse = rank if inverse is None else rank[inverse]
        # (np.take: tris[order] gathered the 48-byte rows one call each, 112 ms against 32 for a million)
        tris, levels, weight, area = np.take(tris, order, axis=0), levels[order], weight[order], area[order]
        unknown = None if unknown is None else unknown[order]
    return GeometryPlan(tris, levels, weight, area, unknown, inverse, merged, n_tris, baked)


def bake_states(grid, tris: np.ndarray, levels: np.ndarray, sat=None, unknown=None) -> tuple[np.ndarray, np.ndarray]:
    """The bake stage: 3-state micromaps (T/O/C, flat, bird-curve order) of UV triangles at their
    levels from a footprint grid (``AlphaTest.grid``), grown by ``GROW_TEXEL`` as the tracer bakes,
    and the start of each triangle's states; a triangle flagged ``unknown`` is all C. ``sat``: the
    grid's ``flag_table`` when the caller bakes several chunks of one grid."""
    s3, starts = bake_micromaps(grid, tris, levels, GROW_TEXEL, sat)
    if unknown is not None:
        for i in np.flatnonzero(unknown):
            s3[starts[i]:starts[i + 1]] = states.C
    return s3, starts


def _counts_of(s3: np.ndarray, omm: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``resolve_counted``'s counts of micromaps already resolved: per triangle (T, 7) its T, O and
    C micro-triangles, then how many C ones are OMM state 0, 1, 2, 3."""
    n = len(starts) - 1
    tri = np.repeat(np.arange(n), np.diff(starts))
    key = tri * 7 + np.where(s3 == states.C, 3 + omm.astype(np.int64), s3)
    out = np.bincount(key, minlength=7 * n).reshape(n, 7)
    out[:, 2] = out[:, 3:].sum(axis=1)
    return out


@typed
def build(geometries: list[Geometry], settings: OmmSettings = OmmSettings(),
          progress: Progress | None = None, *, plans: list[GeometryPlan] | None = None,
          chunks=None) -> OmmResult:
    """Bake every geometry's micromaps and pack them into the standard buffers; ``progress``:
    told of each stage and step (``Progress``). ``plans`` (each geometry's ``plan_geometry``) and
    ``chunks`` (an iterator of ``resolve_counted``'s (OMM states, counts) for each chunk of each
    plan, in order: ``chunk_ranges``) let a caller run the plan, bake and resolve stages
    elsewhere (``omm.split``): the pack and the statistics are then this function's own.

    The stages, each public over arrays: plan (``plan_geometry``: levels, identical triangles
    once; with a budget, ``omm.budget.budget_levels`` first), bake (``bake_states``, or a square
    source's pair maps stored, decoded and expanded), resolve (``omm.resolve.resolve_counted``:
    unknown regions to the OMM states the format holds, with counts), pack (``Packer``: special
    indices, reuse of identical micromaps)."""
    scheme = settings.scheme
    merged_level = settings.merged_level
    n_map = scheme.codec.map_size if scheme is not None and merged_level is None else None
    fmt = settings.format_code
    if merged_level is not None and chunks is not None:
        raise InputError("a csmL source is baked in one process (its DAG needs every micromap's states)",
                         param="chunks")
    builder = None
    if merged_level is not None:
        from ..codecs import CsmBuilder

        builder = CsmBuilder(merged_level)
    merged_roots = []
    packer = Packer(fmt, settings.special, settings.dedup)
    index_parts, blocks_all, records_all, geo_info = [], [], [], []
    n_blocks_total = 0
    counts3 = np.zeros(3, dtype=np.int64)
    promoted = np.zeros(4, dtype=np.int64)
    known_area = total_area = 0.0
    micro_total = 0
    level_hist: dict[int, int] = {}
    bytes_no_reuse = 0
    first = 0
    plan, budget_report = (None, None)
    if settings.budget is not None:
        from .budget import budget_levels

        plan, budget_report = budget_levels(geometries, settings, settings.budget, progress)
    if plans is None:
        plans = [plan_geometry(g, settings, n_map, plan[gi] if plan is not None else None)
                 for gi, g in enumerate(geometries)]
    if progress is not None:
        progress.stage("baking", sum(int(np.sum(np.left_shift(np.int64(1), 2 * gp.levels))) for gp in plans),
                       "micro-triangles")
    for gi, g in enumerate(geometries):
        gp = plans[gi]
        tris, levels, weight, area, unknown, inverse, merged = (gp.tris, gp.levels, gp.weight, gp.area, gp.unknown,
                                                                gp.inverse, gp.merged)
        n_tris = gp.n_input
        grid = g.test.grid() if gp.baked is None and chunks is None else None
        sat = flag_table(grid) if n_map is None and grid is not None else None
        idx = np.empty(len(tris), dtype=np.int32)
        roots = np.empty(len(tris), dtype=np.int64) if builder is not None else None
        n_blocks = 0
        if gp.baked is not None:
            starts_all = micro_starts(levels)
        if n_map is not None:
            s3_all, blk, rec = _pair_states(g, grid, tris, scheme, settings.jobs)
            starts_all = micro_starts(levels)
            rec["pair"] += n_blocks_total
            blocks_all.append(blk)
            records_all.append(rec)
            n_blocks = len(blk)
        for a, b in chunk_ranges(levels):
            lv = levels[a:b]
            chunk_unknown = None if unknown is None else unknown[a:b]
            if chunks is not None:  # baked and resolved elsewhere
                omm, tri_counts = next(chunks)
                starts = micro_starts(lv)
            elif gp.baked is not None:  # --budget: the pricing's own bake and resolve, merged rows included
                s3 = gp.baked[0][starts_all[a]:starts_all[b]]
                omm = gp.baked[1][starts_all[a]:starts_all[b]]
                starts = starts_all[a:b + 1] - starts_all[a]
                tri_counts = _counts_of(s3, omm, starts)
            elif n_map is None:
                s3, starts = bake_states(grid, tris[a:b], lv, sat, chunk_unknown)
            else:
                s3 = s3_all[starts_all[a]:starts_all[b]]
                starts = starts_all[a:b + 1] - starts_all[a]
                if chunk_unknown is not None:
                    for i in np.flatnonzero(chunk_unknown):
                        s3[starts[i]:starts[i + 1]] = states.C
            if builder is not None:  # the T/O/C states, before resolve overwrites them
                roots[a:b] = builder.add_states(s3.reshape(b - a, -1))
            if gp.baked is None and chunks is None:
                mine = [t for t in merged if a <= t < b]  # --budget: micromaps shared by merging (their meet)
                for t in mine:
                    s3[starts[t - a]:starts[t - a + 1]] = merged[t][0]
                # in place: the T/O/C states are not read again (square sources: a chunk of their own array)
                omm, tri_counts = resolve.resolve_counted(s3, starts, lv, g.test, tris[a:b], fmt, settings.promotion,
                                                          settings.seed, out=s3)
                for t in mine:  # one stored row for the whole group: its unknowns' hint codes too
                    row = merged[t][1]
                    omm[starts[t - a]:starts[t - a + 1]] = row
                    tri_counts[t - a, 3:] = np.bincount(np.where(merged[t][0] == states.C, row, 4), minlength=5)[:4]
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
                if plan is None:
                    idx[a + sel] = packer.add(rows, int(lvl), weights=w[sel])
                    bytes_no_reuse += int(w[sel].sum()) * omm_format.micromap_bytes(int(lvl), fmt)
                else:  # a micromap with no unknown micro-triangle is stored 2-state (the budget's bytes)
                    two = (rows <= omm_format.OPAQUE).all(axis=1)
                    for f, part in ((omm_format.FORMAT_2_STATE, two), (fmt, ~two)):
                        if part.any():
                            idx[a + sel[part]] = packer.add(rows[part], int(lvl), f)
                            bytes_no_reuse += int(part.sum()) * omm_format.micromap_bytes(int(lvl), f)
                level_hist[int(lvl)] = level_hist.get(int(lvl), 0) + int(w[sel].sum())
            if progress is not None:
                progress.advance(int(starts[-1]))
        index_parts.append(idx if inverse is None else idx[inverse])
        if roots is not None:
            merged_roots.append(roots if inverse is None else roots[inverse])
        info = {"name": g.name, "first_triangle": first, "triangles": n_tris, "texture": g.test.name,
                "width": g.test.width, "height": g.test.height, "filter": g.test.filter,
                "wrap_u": g.test.wrap_u, "wrap_v": g.test.wrap_v, "threshold": g.test.threshold,
                "inclusive": g.test.inclusive, "state_rule": g.test.rule, **g.info}
        if n_map is not None:
            info["pairs"] = n_blocks
            info["first_pair_block"] = n_blocks_total
        geo_info.append(info)
        n_blocks_total += n_blocks
        first += n_tris
    index = np.concatenate(index_parts) if index_parts else np.zeros(0, dtype=np.int32)
    triangles = packer.record_array()
    data = packer.data()
    usage = omm_format.usage_histograms(triangles["level"], triangles["format"], index)
    special = {str(int(v)): int(np.count_nonzero(index == v)) for v in omm_format.SPECIAL_INDEX}
    summary = {
        "omaps": __version__,
        "format": settings.format, "format_code": fmt,
        "settings": {"source": settings.source,
                     "level": None if (settings.dynamic_scale or n_map or merged_level is not None
                                       or settings.budget is not None) else settings.level,
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
    if budget_report is not None:
        summary["budget"] = budget_report
    if builder is not None:
        from ..codecs import csm_pack, csm_treelets

        every = np.concatenate(merged_roots) if merged_roots else np.zeros(0, np.int64)
        nodes, distinct, inverse_u = builder.finish(every)
        blob = csm_pack(*csm_treelets(nodes, distinct[inverse_u]))
        summary["merged_micromaps"] = {"scheme": scheme.name, "level": merged_level, "micromaps": int(len(every)),
                                       "nodes": int(len(nodes)), "bytes": len(blob)}
        return OmmResult(data, triangles, index, usage, summary, merged_micromaps=blob)
    if scheme is not None:
        codec = scheme.codec
        summary["pair_blocks"] = {"scheme": scheme.name, "codec": codec.name, "block_bytes": codec.block_bytes,
                                  "blocks": n_blocks_total, "map_size": codec.map_size, **scheme.settings()}
        blocks = np.concatenate(blocks_all).tobytes() if blocks_all else b""
        records = np.concatenate(records_all) if records_all else np.zeros(0, omm_format.PAIR_RECORD)
        return OmmResult(data, triangles, index, usage, summary, blocks, records)
    return OmmResult(data, triangles, index, usage, summary)
