"""Every scheme's maps for a scene, as the tracer reads them: baked once per distinct pair or
triangle with the core bakers, deduplicated, and stored through the scheme's codec.

Square schemes bake each distinct pair (corner UVs, B or not, material) at the finest size asked
for, with growth ``bake.GROW_TEXEL``; coarser sizes are OR-downsampled, which is exact. Micromap
schemes bake each distinct triangle with the micromap baker; ``succinctL`` stores each distinct
micromap as its succinct tree (a byte offset per row), ``csmL`` the scene's micromaps as one
merged DAG with a root per alpha triangle; both are written from one merged DAG baked straight
from the baker's runs (``baked_tree``, ``hierarchical_maps``), never every micro-triangle's
state. Triangles the scene reader marks unknown get all-C maps (a pair with one such triangle is
all C). Work is done per prototype and shared by its instances, as a BLAS shares it.
"""

from __future__ import annotations

import hashlib
import os

import numpy as np
from tqdm import tqdm

from .. import states
from ..bake import GROW_TEXEL, bake_micromaps, bake_pair_flags, or_downsample
from ..bake.square import flags_to_states
from ..budget import PAIR_OPTIONS
from ..codecs import get_codec
from ..codecs import pack_states
from ..rows import unique_rows
from ..scene.alpha import AlphaTriangles, distinct_rows, pair_corner_uvs
from ..workers import encode_maps as parallel_encode
from .tables import T_MAP_OFFSET, SchemeMaps

__all__ = ["SchemeMaps", "build_scheme_maps", "encode_cached", "default_jobs", "dedupe_maps", "hierarchical_maps",
           "merged_subtree_maps", "baked_tree"]

OFFSET_BYTES = 4  # a succinct micromap's byte offset per triangle, counted in its map bytes


def default_jobs(jobs: int | None) -> int:
    return max(1, os.cpu_count() or 1) if jobs is None else max(1, int(jobs))


def dedupe_maps(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return unique_rows(m)


def encode_maps(codec, maps_: np.ndarray, encoder, effort, jobs: int = 1, progress: bool = False):
    """``codec.encode_many`` over worker processes (``workers.encode_maps``), with a progress bar."""
    bar = tqdm(desc=f"encode {codec.name}", unit="chunk", disable=not progress, leave=False)

    def tick(n, total=None):
        if n is None:
            bar.reset(total=total)
        else:
            bar.update(n)

    try:
        return parallel_encode(codec, maps_, encoder, effort, jobs, tick)
    finally:
        bar.close()


def encode_cached(codec, maps_: np.ndarray, encoder, effort, jobs: int = 1, progress: bool = False,
                  cache: dict | None = None):
    """``encode_maps``, remembered in ``cache`` (a run's dict) by codec, encoder, effort and the
    maps' bytes: a budget scheme re-uses what the uniform schemes of the same run encoded."""
    if cache is None:
        return encode_maps(codec, maps_, encoder, effort, jobs, progress)
    m = np.ascontiguousarray(maps_)
    key = ("encode", codec.name, encoder, effort, m.shape, hashlib.blake2b(m.view(np.uint8)).hexdigest())
    if key not in cache:
        cache[key] = encode_maps(codec, m, encoder, effort, jobs, progress)
    return cache[key]


def by_material(materials: np.ndarray, where: np.ndarray | None = None):
    """(material, the indices of ``materials`` that name it) for each material, in order; only
    the indices where ``where`` (bool) holds, when given."""
    idx = np.arange(len(materials)) if where is None else np.flatnonzero(where)
    mat = materials[idx]
    for m in np.unique(mat):
        yield int(m), idx[mat == m]


def _pair_flags(at: AlphaTriangles, tests: dict, n: int):
    """Flags (D, n, n) of the distinct pairs, and every pair's distinct index."""
    uv, has_b, mat = pair_corner_uvs(at)
    unknown = at.unknown[at.pair_first] | ((at.pair_second >= 0) & at.unknown[np.maximum(at.pair_second, 0)])
    reps, inverse = distinct_rows(uv, has_b, mat, unknown)
    flags = np.empty((len(reps), n, n), np.uint8)
    for m, sel in by_material(mat[reps]):
        flags[sel] = bake_pair_flags(tests[m].grid(), uv[reps[sel]], has_b[reps[sel]], n, GROW_TEXEL)
    flags[unknown[reps]] = states.FLAG_C
    return flags, inverse


def micromap_states(at: AlphaTriangles, tests: dict, level: int):
    """States (D, 4**level) of the distinct alpha triangles, and every triangle's distinct index."""
    reps, inverse = distinct_rows(at.uv, at.material, at.unknown)
    out = np.empty((len(reps), 4 ** level), np.uint8)
    for m, sel in by_material(at.material[reps]):
        s, _ = bake_micromaps(tests[m].grid(), at.uv[reps[sel]], level, GROW_TEXEL)
        out[sel] = s.reshape(len(sel), -1)
    out[at.unknown[reps]] = states.C
    return out, inverse


RUNS_PER_CHUNK = 1 << 22  # the runs of one chunk of triangles held at once (``baked_tree``)


def baked_tree(at: AlphaTriangles, tests: dict, level: int, progress: bool = False, name: str = "tree"):
    """Every distinct alpha triangle's level-L micromap baked straight into one merged DAG:
    baked as runs (``bake.bake_micromap_runs``) in chunks of about ``RUNS_PER_CHUNK`` runs,
    hash-consed as they come (``codecs.csm.Builder``): the memory of the DAG and one chunk,
    never 4**L states per triangle. Returns (nodes, the distinct micromaps' roots in sorted order
    of their states, each alpha triangle's distinct micromap, the mean known fraction): the DAG
    ``csm.build`` makes of the distinct states, node for node. ``name``: the progress bar's."""
    from ..bake import bake_micromap_runs
    from ..codecs import CsmBuilder
    from ..flag_table import flag_table

    reps, inv_t = distinct_rows(at.uv, at.material, at.unknown)
    builder = CsmBuilder(level)
    roots = np.full(len(reps), states.C, np.int64)  # unknown triangles: all C
    known_micro = np.zeros(len(reps))  # micro-triangles of each whose state is not C
    todo = ~at.unknown[reps]
    bar = tqdm(total=int(todo.sum()), desc=f"bake {name}", unit="tri", disable=not progress, leave=False)
    for m, sel in by_material(at.material[reps], todo):
        grid = tests[m].grid()
        sat = flag_table(grid)
        chunk, i, per = 16, 0, 64.0  # the rate is a guess at first: a short chunk (one that outgrows its buffer
        while i < len(sel):
            part = sel[i:i + chunk]
            runs, starts = bake_micromap_runs(grid, at.uv[reps[part]], level, GROW_TEXEL, sat,
                                              capacity=int(1.25 * per * len(part)) + 1024)
            roots[part] = builder.add(runs, starts)
            span = np.left_shift(np.int64(1), 2 * (level - runs[:, 0].astype(np.int64)))
            per_tri = np.add.reduceat(np.where(runs[:, 2] != states.C, span, 0), starts[:-1]) if len(runs) else 0
            known_micro[part] = per_tri
            i += len(part)
            bar.update(len(part))
            per = max(1.0, len(runs) / len(part))  # is baked again), then about RUNS_PER_CHUNK runs, growing
            chunk = int(min(4 * len(part), 1 << 16, max(1, RUNS_PER_CHUNK / per)))  # from the rate of the last
    bar.close()
    nodes, distinct, inv_u = builder.finish(roots)
    rows = inv_u[inv_t]
    known = float(np.mean((known_micro / float(4 ** level))[inv_t]))
    return nodes, distinct, rows, known


def merged_subtree_maps(at: AlphaTriangles, tests: dict, scheme, progress: bool = False) -> SchemeMaps:
    """A ``csmL`` or ``succinctL`` scheme's maps, baked straight into a tree (``baked_tree``)."""
    return hierarchical_maps(scheme, baked_tree(at, tests, scheme.level, progress, scheme.name))


def hierarchical_maps(scheme, tree) -> SchemeMaps:
    """A ``succinctL`` or ``csmL`` scheme's maps from the scene's micromaps as a merged DAG
    (``baked_tree``'s (nodes, distinct roots, each alpha triangle's distinct map, known)).

    ``succinct``: the distinct micromaps' blobs, each tree read from the DAG
    (``succinct_encode_dag``), byte-aligned, each row's byte offset in the table word
    ``T_MAP_OFFSET``; map bytes: each triangle's blob plus a 32-bit offset. ``csm``: one blob,
    the DAG in treelets with a root per alpha triangle (``T_MAP_ROW`` is the triangle's own
    index); map bytes: the blob. ``T_MAP_ROW_BYTES`` holds the data's length."""
    from ..codecs import csm_pack, csm_treelets, succinct_encode_dag

    nodes, distinct, rows, known = tree
    level = scheme.level
    if scheme.representation == "succinct":
        data, starts, _ = succinct_encode_dag(nodes, distinct, level)
        sizes = np.diff(starts)
        map_bytes = int(sizes[rows].sum()) + OFFSET_BYTES * len(rows)
        return SchemeMaps(scheme.name, "succinct", level, rows.astype(np.int32), np.append(data, np.uint8(0)),
                          len(data) + 1, map_bytes, len(distinct), known, None, scheme,
                          {T_MAP_OFFSET: np.ascontiguousarray(starts[:-1], dtype=np.int64)})
    data = np.frombuffer(csm_pack(*csm_treelets(nodes, distinct[rows])), np.uint8).copy()
    return SchemeMaps(scheme.name, "csm", level, np.arange(len(rows), dtype=np.int32), data, len(data), len(data),
                      len(distinct), known, None, scheme, info={"csm_nodes": int(len(nodes))})


def pair_square_states(at: AlphaTriangles, tests: dict, sizes, cache: dict | None = None) -> tuple[dict, np.ndarray]:
    """States of the distinct pairs' square maps at each size, and every pair's distinct index.
    ``cache``: a run's dict (``Prepared.cache``) keeping the baked flags for later schemes."""
    finest = max(sizes)
    key = ("pair_flags", finest)
    if cache is not None and key in cache:
        flags, inverse = cache[key]
    else:
        flags, inverse = _pair_flags(at, tests, finest)
        if cache is not None:
            cache[key] = (flags, inverse)
    return {n: flags_to_states(flags if n == finest else or_downsample(flags, finest // n)) for n in sizes}, inverse


def build_scheme_maps(at: AlphaTriangles, tests: dict, schemes, jobs: int = 1,
                      progress: bool = False, scene=None, cache: dict | None = None) -> dict[str, SchemeMaps]:
    """Bake and store every scheme's maps. ``tests``: material -> ``AlphaTest``; ``schemes``:
    ``omaps.schemes.Scheme`` objects (kinds none, micromap, square, and stored: read from
    ``scene``'s file by ``trace.stored``)."""
    all_schemes = schemes
    if not any(s.kind == "budget" for s in schemes):
        cache = None  # nothing would re-use what it holds
    schemes = [s for s in schemes if s.kind != "budget"]  # built once weights are known (trace.budget)
    stored = [s for s in schemes if s.kind == "stored"]
    if stored:
        from .stored import stored_maps

        read = {s.name: stored_maps(at, scene, s) for s in stored}
        rest = build_scheme_maps(at, tests, [s for s in schemes if s.kind != "stored"], jobs, progress, cache=cache)
        return {s.name: read[s.name] if s.name in read else rest[s.name] for s in schemes}
    if not at.count:  # nothing alpha-tested: no maps, the filter is never called
        return {s.name: SchemeMaps(s.name, s.kind, s.level if s.kind == "micromap" else (s.map_size or 0),
                                   np.zeros(0, np.int32), np.zeros(1, np.uint8), s.codec.block_bytes if s.codec else 1,
                                   0, 0, 0.0, s.codec, s) for s in schemes}
    out: dict[str, SchemeMaps] = {}
    n_pairs = len(at.pair_first)
    squares = [s for s in schemes if s.kind == "square"]
    if squares:
        sizes = {s.codec.map_size for s in squares}
        if any(s.kind == "budget" for s in all_schemes):  # bake once at the budget's finest size too
            from ..codecs import entry

            sizes |= {get_codec(o).map_size for s in all_schemes if s.kind == "budget"
                      for o in (s.options or PAIR_OPTIONS) if o != "none" and not entry(o).variable}
        pair_states, pair_inverse = pair_square_states(at, tests, sizes, cache)
    baked: dict[int, tuple] = {}  # level -> micromap_states: triL of one level bakes once
    trees: dict[int, tuple] = {}  # level -> baked_tree: succinctL and csmL of one level bake once
    for s in schemes:
        if s.kind == "none":
            out[s.name] = SchemeMaps(s.name, "none", 0, np.zeros(at.count, np.int32), np.zeros(1, np.uint8), 1, 0, 0,
                                     0.0, None, s)
        elif s.kind == "micromap" and s.representation != "raw":  # succinctL, csmL: from one tree per level
            if s.level not in trees:
                trees[s.level] = baked_tree(at, tests, s.level, progress, s.name)
            out[s.name] = hierarchical_maps(s, trees[s.level])
        elif s.kind == "micromap":
            if s.level not in baked:
                baked[s.level] = micromap_states(at, tests, s.level)
            st, inv_t = baked[s.level]
            uniq, inv_u = dedupe_maps(st)
            data = pack_states(uniq)
            known = float(np.mean((st != states.C).mean(axis=1)[inv_t]))
            out[s.name] = SchemeMaps(s.name, "micromap", s.level, inv_u[inv_t].astype(np.int32), data.ravel().copy(),
                                     data.shape[1], at.count * data.shape[1], len(uniq), known, None, s)
        else:
            codec = s.codec
            uniq, inv_u = dedupe_maps(pair_states[codec.map_size])
            pair_rows = inv_u[pair_inverse]  # every pair -> its distinct map
            blocks, decoded = encode_cached(codec, uniq, s.encoder, s.effort, jobs, progress, cache)
            known = float(np.mean((decoded != states.C).reshape(len(decoded), -1).mean(axis=1)[pair_rows]))
            out[s.name] = SchemeMaps(s.name, "square", codec.map_size, pair_rows[at.pair].astype(np.int32),
                                     blocks.ravel().copy(), codec.block_bytes, n_pairs * codec.block_bytes, len(uniq),
                                     known, codec, s)
    return out
