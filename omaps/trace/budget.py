"""The maps of a ``budget:BYTES`` scheme: per pair the option -- no map, a raw square up to
64 x 64 or a codec that opts in (``budget.PAIR_OPTIONS``) by default, or the options the scheme
names, ``succinctL`` (the pair's two level-L micromaps as succinct trees) among them -- that saves
the most expected alpha tests for the bytes, all prototype pairs together within the budget
(``omaps.budget.allocate``).

A pair's expected alpha tests saved by an option are its triangles' weights (expected candidate
hits: world area times instances, or counts from a low-resolution trace) times the known
fraction of each triangle's half of the option's *decoded* map, so a lossy codec is valued by
what it really keeps; a ``succinctL`` option keeps the level-L micromaps exactly (each
triangle's known share of its micro-triangles, which have equal areas). An option's bytes are
its codec's block, or for ``succinctL`` the pair's own two trees (bytes that differ from pair to
pair). The tracer reads a pair's map through its format code (``lookups.mixed_map_state``);
bytes count every prototype pair's map, as for uniform schemes (a real per-pair format and
offset word is reported apart, as ``index_bytes``).
"""

from __future__ import annotations

import numpy as np

from .. import states
from ..budget import PAIR_OPTIONS, allocate, half_known
from ..codecs import entry, get_codec
from ..rows import unique_rows
from .maps import SchemeMaps, dedupe_maps, encode_cached, micromap_states, pair_square_states
from .tables import T_MAP_FORMAT, T_MAP_OFFSET

__all__ = ["budget_maps", "scene_view_samples", "view_samples", "view_prior", "view_weights", "INDEX_BYTES_PER_PAIR", "VIEW_PRIOR"]

INDEX_BYTES_PER_PAIR = 4  # a per-pair word: format code (5 bits) + byte offset (27 bits)


def _square_options(at, tests, scheme, options, w_a, w_b, jobs, progress, cache):
    """Per square option: (bytes per pair, value per pair, (data, starts) of the distinct
    blocks, pair -> distinct block, known share per pair)."""
    out = {}
    if not options:
        return out
    pair_states, pair_inverse = pair_square_states(at, tests, sorted({get_codec(o).map_size for o in options}), cache)
    n_pairs = len(at.pair_first)
    for o in options:
        codec = get_codec(o)
        uniq, inv_u = dedupe_maps(pair_states[codec.map_size])
        enc, eff, _ = codec.fallback(scheme.encoder, scheme.effort)  # (the scheme's notes say so)
        blocks, dec = encode_cached(codec, uniq, enc, eff, jobs, progress, cache)
        rows = inv_u[pair_inverse]
        half = half_known(dec)[rows]
        known = (dec != states.C).reshape(len(dec), -1).mean(axis=1)[rows]
        starts = codec.block_bytes * np.arange(len(blocks) + 1, dtype=np.int64)
        out[o] = (np.full(n_pairs, codec.block_bytes, np.int64), w_a * half[:, 0] + w_b * half[:, 1],
                  (blocks.ravel(), starts), rows, known)
    return out


def _micromap_options(at, tests, options, w_a, w_b, cache):
    """``_square_options`` for the options that store a pair's micromaps (``CodecEntry.level``):
    each distinct (first, second) micromap pair encoded once, its bytes the option's cost."""
    out = {}
    has_b = at.pair_second >= 0
    for o in options:
        pm = entry(o).make()
        key = ("micromaps", pm.level)
        if cache is None or key not in cache:
            baked = micromap_states(at, tests, pm.level)
            if cache is None:
                cache = {}
            cache[key] = baked
        st, inv_t = cache[key]
        a = inv_t[at.pair_first]
        b = np.where(has_b, inv_t[np.maximum(at.pair_second, 0)], -1)
        combos, rows = unique_rows(np.stack([a, b], axis=1))
        rows = np.asarray(rows).ravel()
        data, starts = pm.encode_pairs(st[combos[:, 0]], st[np.maximum(combos[:, 1], 0)], combos[:, 1] >= 0)
        kt = (st != states.C).mean(axis=1)  # micro-triangles have equal areas
        ka, kb = kt[a], np.where(has_b, kt[np.maximum(b, 0)], 0.0)
        out[o] = (np.diff(starts)[rows], w_a * ka + w_b * kb, (data, starts), rows, (ka + kb) / (1.0 + has_b))
    return out


def budget_maps(at, tests: dict, scheme, weights: np.ndarray, jobs: int = 1, progress: bool = False,
                options=None, cache: dict | None = None) -> SchemeMaps:
    """The budget scheme's maps for the alpha triangles ``at`` with per-triangle ``weights``.
    ``options``: the pair options (``none`` first), by default the scheme's (``Scheme.options``)
    or ``budget.PAIR_OPTIONS``. ``cache``: the run's ``Prepared.cache``: flags baked and maps
    encoded by its uniform schemes."""
    options = tuple(options or getattr(scheme, "options", None) or PAIR_OPTIONS)
    n_pairs = len(at.pair_first)
    w_a = weights[at.pair_first]
    w_b = np.where(at.pair_second >= 0, weights[np.maximum(at.pair_second, 0)], 0.0)
    square = [o for o in options if o != "none" and not entry(o).variable]
    made = {**_square_options(at, tests, scheme, square, w_a, w_b, jobs, progress, cache),
            **_micromap_options(at, tests, [o for o in options if o != "none" and entry(o).variable], w_a, w_b,
                                cache)}
    nbytes = np.zeros((n_pairs, len(options)), np.int64)
    value = np.zeros((n_pairs, len(options)))
    for k, o in enumerate(options):
        if o != "none":
            nbytes[:, k], value[:, k] = made[o][0], made[o][1]
    choice = allocate(nbytes, value, scheme.budget)
    # rows of the table: the distinct (option, block) pairs chosen; data: their blocks, in that order
    fmt_parts, off_parts, data_parts = [], [], []
    pair_row = np.zeros(n_pairs, np.int64)
    known = np.zeros(n_pairs)
    row0 = off = 0
    for k, o in enumerate(options):
        sel = np.flatnonzero(choice == k)
        if len(sel) == 0:
            continue
        if o == "none":
            used, inv, code = np.zeros(1, np.int64), np.zeros(len(sel), np.int64), 0
            lengths, gathered = np.zeros(1, np.int64), np.zeros(0, np.uint8)
        else:
            _, _, (data, starts), rows, kf = made[o]
            used, inv = np.unique(rows[sel], return_inverse=True)
            lengths = starts[used + 1] - starts[used]
            begin = np.repeat(starts[used] - np.cumsum(lengths) + lengths, lengths)
            gathered = data[begin + np.arange(int(lengths.sum()))]
            known[sel] = kf[sel]
            code = entry(o).code  # its format code (the registry's)
        pair_row[sel] = row0 + inv.ravel()
        fmt_parts.append(np.full(len(used), code, np.int32))
        off_parts.append(off + np.cumsum(lengths) - lengths)
        data_parts.append(gathered)
        row0 += len(used)
        off += int(lengths.sum())
    data = np.concatenate(data_parts + [np.zeros(1, np.uint8)])  # never empty: the table needs an address
    counts = np.bincount(choice, minlength=len(options))
    map_bytes = int(nbytes[np.arange(n_pairs), choice].sum())
    info = {"budget_bytes": int(scheme.budget), "choices": {o: int(c) for o, c in zip(options, counts) if c},
            "index_bytes": INDEX_BYTES_PER_PAIR * n_pairs,
            "expected_tests_saved_fraction": float(value[np.arange(n_pairs), choice].sum() / max(
                (w_a + w_b).sum(), 1e-300))}
    return SchemeMaps(scheme.name, "mixed", 0, pair_row[at.pair].astype(np.int32), data, len(data), map_bytes, row0,
                      float(known.mean()) if n_pairs else 0.0, None, scheme,
                      {T_MAP_FORMAT: np.concatenate(fmt_parts), T_MAP_OFFSET: np.concatenate(off_parts).astype(np.int64)},
                      info)
