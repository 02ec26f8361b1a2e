"""The maps of a ``budget:BYTES`` scheme: per pair the option -- no map, a raw square up to
64 x 64, vq2, vq4 or vq4x64 -- that saves the most expected alpha tests for the bytes, all
prototype pairs together within the budget (``omaps.budget.allocate``).

A pair's expected alpha tests saved by an option are its triangles' weights (expected candidate
hits: world area times instances, or counts from a low-resolution trace) times the known
fraction of each triangle's half of the option's *decoded* map, so a lossy codec is valued by
what it really keeps. The tracer reads a pair's map through its format code
(``lookups.mixed_map_state``); bytes count every prototype pair's map, as for uniform schemes
(a real per-pair format and offset word is reported apart, as ``index_bytes``).
"""

from __future__ import annotations

import numpy as np

from .. import states
from ..budget import PAIR_OPTIONS, allocate, half_known, pair_option_bytes
from ..codecs import get_codec
from .maps import SchemeMaps, dedupe_maps, encode_cached, pair_square_states
from .tables import T_MAP_FORMAT, T_MAP_OFFSET

__all__ = ["budget_maps", "scene_view_samples", "view_samples", "view_prior", "view_weights", "INDEX_BYTES_PER_PAIR", "VIEW_PRIOR"]

INDEX_BYTES_PER_PAIR = 4  # a per-pair word: 4-bit format code + 28-bit offset in 16-byte units


def budget_maps(at, tests: dict, scheme, weights: np.ndarray, jobs: int = 1, progress: bool = False,
                options=PAIR_OPTIONS, cache: dict | None = None) -> SchemeMaps:
    """The budget scheme's maps for the alpha triangles ``at`` with per-triangle ``weights``.
    ``cache``: the run's ``Prepared.cache``: flags baked and maps encoded by its uniform schemes."""
    sizes = sorted({get_codec(o).map_size for o in options if o != "none"})
    pair_states, pair_inverse = pair_square_states(at, tests, sizes, cache)
    n_pairs = len(at.pair_first)
    w_a = weights[at.pair_first]
    w_b = np.where(at.pair_second >= 0, weights[np.maximum(at.pair_second, 0)], 0.0)
    nbytes = pair_option_bytes(options)
    value = np.zeros((n_pairs, len(options)))
    decoded: dict[str, tuple] = {}  # option -> (blocks of the distinct maps, pair -> distinct row, pair -> known share)
    for k, o in enumerate(options):
        if o == "none":
            continue
        codec = get_codec(o)
        uniq, inv_u = dedupe_maps(pair_states[codec.map_size])
        blocks, dec = encode_cached(codec, uniq, scheme.encoder, scheme.effort, jobs, progress, cache)
        rows = inv_u[pair_inverse]
        half = half_known(dec)[rows]
        value[:, k] = w_a * half[:, 0] + w_b * half[:, 1]
        decoded[o] = (blocks, rows, (dec != states.C).reshape(len(dec), -1).mean(axis=1)[rows])
    choice = allocate(np.broadcast_to(nbytes, value.shape), value, scheme.budget)
    # rows of the table: the distinct (option, map) pairs chosen; data: their blocks, in that order
    fmt_parts, off_parts, data_parts = [], [], []
    pair_row = np.zeros(n_pairs, np.int64)
    known = np.zeros(n_pairs)
    row0 = off = 0
    for k, o in enumerate(options):
        sel = np.flatnonzero(choice == k)
        if len(sel) == 0:
            continue
        if o == "none":
            used = np.zeros(1, np.int64)
            inv = np.zeros(len(sel), np.int64)
            blk = np.zeros((1, 0), np.uint8)
        else:
            blocks, rows, kf = decoded[o]
            used, inv = np.unique(rows[sel], return_inverse=True)
            blk = blocks[used]
            known[sel] = kf[sel]
        pair_row[sel] = row0 + inv.ravel()
        fmt_parts.append(np.full(len(used), 0 if o == "none" else get_codec(o).code, np.int32))  # its format code
        off_parts.append(off + blk.shape[1] * np.arange(len(used), dtype=np.int64))
        data_parts.append(blk.ravel())
        row0 += len(used)
        off += blk.size
    data = np.concatenate(data_parts + [np.zeros(1, np.uint8)])  # never empty: the table needs an address
    counts = np.bincount(choice, minlength=len(options))
    map_bytes = int(nbytes[choice].sum())
    info = {"budget_bytes": int(scheme.budget), "choices": {o: int(c) for o, c in zip(options, counts) if c},
            "index_bytes": INDEX_BYTES_PER_PAIR * n_pairs,
            "expected_tests_saved_fraction": float(value[np.arange(n_pairs), choice].sum() / max(
                (w_a + w_b).sum(), 1e-300))}
    return SchemeMaps(scheme.name, "mixed", 0, pair_row[at.pair].astype(np.int32), data, 1, map_bytes, row0,
                      float(known.mean()) if n_pairs else 0.0, None, scheme,
                      {T_MAP_FORMAT: np.concatenate(fmt_parts), T_MAP_OFFSET: np.concatenate(off_parts)}, info)


