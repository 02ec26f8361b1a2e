"""The reference budget pricing: every level up to --max-level baked by the micromap baker for every
item, independent of the meets and of the certificate that ``omaps.omm.budget`` prices with
(tests/test_omm_budget_speed.py compares their plans; bench/bench_omm_budget.py times both).

``omaps omm --budget BYTES``: per triangle the subdivision level (and 2- or 4-state format)
that saves the most expected any-hit calls for the micromap bytes, every geometry together
within the budget.

An option is a level L of the triangle's micromap, as the micromap baker bakes it (exact), or,
for L in 1..``MERGE_MAX_LEVEL``, a *merged* one: the level's distinct T/O/C contents clustered
(``_agglomerate``: the two clusters whose meet loses the least value first) into 1/2, 1/4, ...
as many (``MERGE_SHARES``), each member storing its cluster's meet -- T or O where every member
agrees, C elsewhere. A meet only turns known micro-triangles unknown, so it is as conservative as
the bake, and one micromap serves the whole cluster. An option's value is the triangle's weight
(``Geometry.weight``: world area times instances for a scene, texel area for a texture and UVs)
times its known fraction, plus one per recorded view hit (``Geometry.hits``) in a known
micro-triangle. Its bytes are what the engine stores: nothing for a uniform micromap (a special
index), else the micromap's data plus its 8-byte triangle record; a micromap with no unknown
micro-triangle is stored 2-state (1 bit each, exactly as the 4-state map says), the others
4-state. Triangles with identical UVs are one item; items storing the same micromap at a level
form a group whose bytes are paid once, and a greedy over groups (``_adopt``) chooses; the bytes
it counts are the packer's own. Levels are offered up to ``max_level`` and no finer than
``FINEST_TEXELS`` texels per micro-triangle edge (finer ones read the same footprint cells).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from omaps import states
from omaps.budget import HIT_LEVEL
from omaps.errors import InputError
from omaps.bake import GROW_TEXEL, bake_micromaps, dynamic_levels
from omaps.bake.micromap import check_uv_triangles, flag_table
from omaps.scene.alpha import distinct_rows
from omaps import omm_format
from omaps.omm.budget import _doubt
from omaps.omm.resolve import resolve

__all__ = ["budget_levels", "FINEST_TEXELS"]

FINEST_TEXELS = 0.25


MERGE_MAX_LEVEL = 5  # merged (shared) micromaps are offered up to this level (1024 micro-triangles)
MERGE_SHARES = (2, 4, 8, 16)  # a level's distinct contents merged into 1/2, 1/4, ... as many micromaps
PROGRESS_CHUNK = 1 << 22  # the pricing bakes a level's items in pieces of this many micro-triangles
MERGE_MAX_WORK = 5e8  # contents^2 x micro-triangles: above it a level offers no merged variants
VARIANTS = 1 + len(MERGE_SHARES)


@njit(cache=True)
def _merge_loss(a, wa, b, wb):
    """Value lost when contents a and b (T/O/C rows, per-cell weights) share their meet."""
    s = 0.0
    for c in range(len(a)):
        if a[c] != b[c]:
            if a[c] != 2:
                s += wa[c]
            if b[c] != 2:
                s += wb[c]
    return s


@njit(cache=True)
def _agglomerate(cont, w):
    """Greedy agglomeration of contents (K, n) with per-cell weights (K, n): repeatedly merge the
    two clusters whose meet (cells where they agree, else C) loses the least value. Returns the
    merges in order: (K - 1, 2) cluster indices (the first keeps the meet)."""
    k = cont.shape[0]
    a = cont.copy()
    ww = w.copy()
    alive = np.ones(k, np.bool_)
    best = np.full(k, np.inf)
    arg = np.full(k, -1, np.int64)
    for i in range(k):
        for j in range(i + 1, k):
            s = _merge_loss(a[i], ww[i], a[j], ww[j])
            if s < best[i]:
                best[i] = s
                arg[i] = j
    out = np.empty((max(k - 1, 0), 2), np.int64)
    for step in range(k - 1):
        i = -1
        for r in range(k):
            if alive[r] and arg[r] >= 0 and (i < 0 or best[r] < best[i]):
                i = r
        j = arg[i]
        out[step, 0] = i
        out[step, 1] = j
        for c in range(a.shape[1]):
            if a[i, c] != a[j, c]:
                a[i, c] = 2
            ww[i, c] += ww[j, c]
        alive[j] = False
        best[j] = np.inf
        arg[j] = -1
        for r in range(k):  # rows whose best partner changed, and row i itself: recomputed
            if alive[r] and (r == i or arg[r] == i or arg[r] == j):
                best[r] = np.inf
                arg[r] = -1
                for q in range(r + 1, k):
                    if alive[q]:
                        s = _merge_loss(a[r], ww[r], a[q], ww[q])
                        if s < best[r]:
                            best[r] = s
                            arg[r] = q
        for r in range(i):  # row i's new meet may be the best partner of an earlier row
            if alive[r]:
                s = _merge_loss(a[r], ww[r], a[i], ww[i])
                if s < best[r]:
                    best[r] = s
                    arg[r] = i
    return out


def _labels(k: int, merges: np.ndarray, clusters: int) -> np.ndarray:
    """Cluster of each of k contents after the first k - clusters merges (labels 0..clusters-1)."""
    parent = np.arange(k)
    for i, j in merges[:k - clusters]:
        parent[j] = i
    for _ in range(k):  # flatten (chains are short; k passes bound them)
        nxt = parent[parent]
        if np.array_equal(nxt, parent):
            break
        parent = nxt
    return np.unique(parent, return_inverse=True)[1].ravel()


def _items(g, settings) -> tuple:
    """A geometry's triangles, their unknown flags and weights, its items (distinct UV triangles:
    representatives ``reps``, item of each triangle ``inv``) and the finest level each item is
    offered (``cap``)."""
    tris = check_uv_triangles(g.tris_uv) if len(g.tris_uv) else np.zeros((0, 3, 2))
    n = len(tris)
    weight = g.areas(tris) if g.weight is None else np.asarray(g.weight, np.float64)
    unknown = np.zeros(n, bool) if g.unknown is None else np.asarray(g.unknown, bool)
    reps, inv = distinct_rows(tris, unknown)
    cap = dynamic_levels(tris[reps], g.test.width, g.test.height, FINEST_TEXELS, settings.max_level)
    cap[unknown[reps]] = 0  # all unknown: nothing to gain at any level
    return tris, unknown, weight, reps, inv, cap


def _priced_levels(budget: int, max_level: int) -> list[int]:
    """The levels whose micromaps are offered: those of which one fits the budget."""
    record = omm_format.TRIANGLE_RECORD.itemsize
    return [lvl for lvl in range(max_level + 1)
            if omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE) + record <= budget]


def _pricing_work(items, settings, budget: int) -> int:
    """Micro-triangles ``_options`` bakes for a geometry's items (the pricing's progress)."""
    cap = items[5]
    return sum(int(np.count_nonzero(cap >= lvl)) << (2 * lvl) for lvl in _priced_levels(budget, settings.max_level))


def _bake_counted(grid, tris, lvl, sat, progress):
    """``bake_micromaps`` at one level, in pieces of at most ``PROGRESS_CHUNK`` micro-triangles,
    each advancing ``progress`` by its micro-triangles (the same states as one call)."""
    step = max(PROGRESS_CHUNK >> (2 * lvl), 1)
    if progress is None or len(tris) <= step:
        out = bake_micromaps(grid, tris, lvl, GROW_TEXEL, sat)
        if progress is not None:
            progress.advance(len(tris) << (2 * lvl))
        return out
    parts = []
    for a in range(0, len(tris), step):
        parts.append(bake_micromaps(grid, tris[a:a + step], lvl, GROW_TEXEL, sat)[0])
        progress.advance(len(tris[a:a + step]) << (2 * lvl))
    return np.concatenate(parts), np.arange(len(tris) + 1, dtype=np.int64) << (2 * lvl)


def _options(g, items, settings, budget: int, progress=None):
    """Per triangle its item (its distinct UV triangle); per item and option column (level L
    exact, then L's merged variants, ``VARIANTS`` columns a level) the bytes, the value, the
    content id of the stored micromap (-1 for none; ids are per level) and the level; the total
    weight; per column the merge, None or (cluster per item (-1: exact), meets, stored rows)."""
    max_level, special = settings.max_level, settings.special
    tris, unknown, weight, reps, inv, cap = items
    n = len(tris)
    ni = len(reps)
    wsum = np.bincount(inv, weights=np.nan_to_num(weight), minlength=ni)
    record = omm_format.TRIANGLE_RECORD.itemsize
    cols = (max_level + 1) * VARIANTS
    nbytes = np.zeros((ni, cols), np.int64)
    ids = np.full((ni, cols), -1, np.int64)
    eff = np.zeros((ni, cols), np.int64)  # the level an option really bakes
    value = np.zeros((ni, cols))
    merge = [None] * cols
    hits = np.asarray(g.hits, np.int64) if g.hits is not None and len(g.hits) else np.zeros((0, 2), np.int64)
    h_item = inv[hits[:, 0]]
    grid = g.test.grid()
    sat = flag_table(grid)

    def price(rows3, stored, lvl):
        """bytes, known count, and the known hits per row of T/O/C rows and their stored rows."""
        known = (rows3 != states.C).sum(axis=1)
        uniform = (stored == stored[:, :1]).all(axis=1)
        fmt = np.where(known == 4 ** lvl, omm_format.FORMAT_2_STATE, omm_format.FORMAT_4_STATE)
        b = np.where(fmt == omm_format.FORMAT_2_STATE, omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE),
                     omm_format.micromap_bytes(lvl, omm_format.FORMAT_4_STATE)) + record
        return np.where(uniform & special, 0, b), known

    for lvl in range(max_level + 1):
        c0 = lvl * VARIANTS
        sel = np.flatnonzero(cap >= lvl)
        if omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE) + record > budget:
            if lvl == 0 and not special and n:
                raise InputError(f"the budget of {budget} bytes is below one level-0 micromap "
                                 f"({omm_format.micromap_bytes(0, omm_format.FORMAT_2_STATE) + record} bytes with its "
                                 f"record), and without special indices every triangle stores one")
            sel = sel[:0]  # no micromap of this level fits the budget
        if len(sel):
            nc = 4 ** lvl
            s3, starts = _bake_counted(grid, tris[reps[sel]], lvl, sat, progress)
            if g.unknown is not None:
                s3.reshape(len(sel), -1)[unknown[reps[sel]]] = states.C
            rows3 = s3.reshape(len(sel), nc)
            stored = resolve(s3, starts, lvl, g.test, tris[reps[sel]], settings.format_code, settings.promotion,
                             settings.seed).reshape(len(sel), nc)  # what the packer stores
            row = np.full(ni, -1, np.int64)
            row[sel] = np.arange(len(sel))
            hr = row[h_item]
            hok = hr >= 0
            h_sel, h_cell = hr[hok], hits[hok, 1] >> (2 * (HIT_LEVEL - lvl))

            def values(states_of_sel):  # value of every selected item with these T/O/C rows
                known = states_of_sel != states.C
                v = wsum[sel] * known.sum(axis=1) / nc
                return v + np.bincount(h_sel[known[h_sel, h_cell]], minlength=len(sel))

            b, _ = price(rows3, stored, lvl)
            nbytes[sel, c0] = b
            value[sel, c0] = values(rows3)
            eff[sel, c0:c0 + VARIANTS] = lvl
            all_rows = [stored]
            variants = _merged(rows3, stored, b, wsum[sel], h_sel, h_cell, lvl) if 1 <= lvl <= MERGE_MAX_LEVEL else []
            for v in range(1, VARIANTS):
                c = c0 + v
                if v - 1 >= len(variants):
                    nbytes[sel, c], value[sel, c] = nbytes[sel, c0], value[sel, c0]
                    continue
                label, meets = variants[v - 1]
                rep = np.zeros(len(meets), np.int64)
                rep[label[label >= 0][::-1]] = np.flatnonzero(label >= 0)[::-1]  # a member of each cluster
                flat = np.ascontiguousarray(meets).ravel()
                mrows = resolve(flat, np.arange(len(meets) + 1) * nc, lvl, g.test, tris[reps[sel[rep]]],
                                settings.format_code, settings.promotion, settings.seed).reshape(len(meets), nc)
                st3 = np.where(label[:, None] >= 0, meets[np.maximum(label, 0)], rows3)
                st = np.where(label[:, None] >= 0, mrows[np.maximum(label, 0)], stored)
                nbytes[sel, c], _ = price(st3, st, lvl)
                value[sel, c] = values(st3)
                all_rows.append(st)
                merge[c] = (np.where(row >= 0, label[np.maximum(row, 0)], -1), meets, mrows)
            allr = np.concatenate(all_rows)
            _, content = np.unique(np.ascontiguousarray(allr).view(np.dtype((np.void, nc))).ravel(),
                                   return_inverse=True)
            content = content.ravel().reshape(len(all_rows), len(sel))
            for v in range(VARIANTS):
                src = v if v < len(all_rows) else 0
                ids[sel, c0 + v] = np.where(nbytes[sel, c0 + v] > 0, content[src], -1)
        rest = np.setdiff1d(np.arange(ni), sel)  # not offered: as the level below
        if lvl and len(rest):
            prev = c0 - VARIANTS  # the level below's exact column
            nbytes[rest, c0:c0 + VARIANTS] = nbytes[rest, prev][:, None]
            value[rest, c0:c0 + VARIANTS] = value[rest, prev][:, None]
            ids[rest, c0:c0 + VARIANTS] = ids[rest, prev][:, None]
            eff[rest, c0:c0 + VARIANTS] = eff[rest, prev][:, None]
        elif len(rest):
            nbytes[rest, :VARIANTS] = 0  # a budget below one level-0 micromap: uniform, so a special index
    total = float(wsum.sum()) + len(hits)
    return inv, nbytes, value, total, ids, eff, merge


def _merged(rows3, stored, nbytes, w, h_row, h_cell, lvl) -> list:
    """Per share of ``MERGE_SHARES`` (while it leaves at least two micromaps), the stored rows'
    clusters: (cluster per row, -1 for a row that stores nothing, and each cluster's meet: T or
    O where all its rows agree, else C). Rows are clustered by their T/O/C content, weighted by
    the value each cell holds (its rows' weights spread by area, plus their hits)."""
    nc = rows3.shape[1]
    paid = np.flatnonzero(nbytes > 0)
    if len(paid) < 4:
        return []
    cont, cinv = np.unique(rows3[paid], axis=0, return_inverse=True)
    cinv = cinv.ravel()
    k = len(cont)
    if k < 4 or float(k) * k * nc > MERGE_MAX_WORK:
        return []
    cw = np.zeros((k, nc))
    np.add.at(cw, cinv, (w[paid] / nc)[:, None])
    of_row = np.full(len(rows3), -1, np.int64)
    of_row[paid] = cinv
    hc = of_row[h_row]
    np.add.at(cw, (hc[hc >= 0], h_cell[hc >= 0]), 1.0)
    merges = _agglomerate(np.ascontiguousarray(cont), cw)
    out = []
    for share in MERGE_SHARES:
        clusters = -(-k // share)
        if clusters < 2:
            break
        lab = _labels(k, merges, clusters)
        meets = np.full((clusters, nc), 255, np.uint8)
        for c in range(k):  # the meet: cells where every member agrees keep their state
            m = meets[lab[c]]
            meets[lab[c]] = np.where(m == 255, cont[c], np.where(m == cont[c], m, states.C))
        label = np.full(len(rows3), -1, np.int64)
        label[paid] = lab[cinv]
        out.append((label, meets))
    return out


def _groups(nbytes, ids, eff=None) -> tuple[np.ndarray, np.ndarray]:
    """Per (item, option) its group -- the items storing the same micromap at that option's
    level (``eff``, default the option's index), or the level's free options (special
    indices) -- with each group's bytes."""
    n_items, n_levels = nbytes.shape
    lv = np.broadcast_to(np.arange(n_levels), nbytes.shape) if eff is None else eff
    key = np.stack([lv.ravel(), np.where(nbytes > 0, ids, -1).ravel()], axis=1)
    keys, gid = np.unique(key, axis=0, return_inverse=True)
    gid = gid.reshape(n_items, n_levels)
    gbytes = np.zeros(len(keys), np.int64)
    gbytes[gid.ravel()] = nbytes.ravel()
    return gid, gbytes


def _stored(gid, gbytes, level) -> int:
    ref = np.bincount(gid[np.arange(len(level)), level], minlength=len(gbytes))
    return int(gbytes[ref > 0].sum())


def _adopt(value, gid, gbytes, budget: int, start=None, watch=()) -> tuple[np.ndarray, int, dict]:
    """Greedy over groups: repeatedly move every item that gains by it to the group with the most
    value per new byte (a group already stored, or free, first), while the bytes stored -- each
    group with a member once -- stay within the budget. Items only ever gain. (An item's options
    in one group store the same micromap, so they are worth the same: one of them counts.)

    The plain greedy: every step recounts the members, the gains and their sums over the whole
    (items x options) matrix (tests/test_omm_budget_greedy.py holds ``omaps.omm.budget._adopt``,
    which sums again only the groups a move changes, to it, ``watch`` and its certificate
    included: options not priced, as (key, fewest bytes, items, their classes, best value per
    item); per key the classes whose bound reached a step's chosen value per byte, or stayed
    affordable when the greedy ended, each step tested by the package's ``_doubt``)."""
    n_items, n_cols = value.shape
    level = np.zeros(n_items, np.int64) if start is None else np.array(start, np.int64)
    rows = np.arange(n_items)
    order = np.argsort(gid, axis=1, kind="stable")
    srt = np.take_along_axis(gid, order, axis=1)
    first = np.ones(gid.shape, bool)
    first[:, 1:] = srt[:, 1:] != srt[:, :-1]
    keep = np.zeros(gid.shape, bool)
    np.put_along_axis(keep, order, first, axis=1)
    doubt: dict = {}

    def check(room, rate):  # the certificate's test of a step is the package's own (``_doubt``)
        if watch:
            _doubt(watch, value[rows, level], room, rate, doubt)

    while True:
        ref = np.bincount(gid[rows, level], minlength=len(gbytes))
        stored = int(gbytes[ref > 0].sum())
        gain = value - value[rows, level][:, None]
        up = keep & (gain > 0)
        gsum = np.bincount(gid[up], gain[up], minlength=len(gbytes))
        cost = np.where(ref > 0, 0, gbytes)
        ok = (gsum > 0) & (cost <= budget - stored)
        if not ok.any():
            check(budget - stored, 0.0)
            return level, stored, doubt
        free = ok & (cost == 0)
        score = np.where(free, gsum, -np.inf) if free.any() else np.where(ok, gsum / np.maximum(cost, 1), -np.inf)
        chosen = int(np.argmax(score))
        if not free.any():
            check(budget - stored, float(score[chosen]))
        movers = up & (gid == chosen)
        moved = movers.any(axis=1)
        level[moved] = np.argmax(movers[moved], axis=1)  # its one option in the group


def budget_levels(geometries, settings, budget: int, progress=None) -> tuple[list[tuple[np.ndarray, dict]], dict]:
    """Per geometry the level of each triangle and the merged micromaps it stores ({triangle:
    (T/O/C meet, stored row)}), and a report (bytes stored, expected savings). ``progress``
    (``pipeline.Progress``): its stage "pricing" counts the micro-triangles baked to price the
    options, its total known before the first.

    Items that store the same micromap at a level share its bytes, so the choice is made per
    group of such items (``_adopt``); the bytes counted are exactly those the packer stores."""
    items = [_items(g, settings) for g in geometries]
    if progress is not None:
        progress.stage("pricing", sum(_pricing_work(it, settings, budget) for it in items), "micro-triangles")
    parts = [_options(g, it, settings, budget, progress) for g, it in zip(geometries, items)]
    if not parts:
        return [], {"budget_bytes": int(budget), "stored_bytes": 0, "items": 0}
    nbytes = np.concatenate([p[1] for p in parts])
    value = np.concatenate([p[2] for p in parts])
    ids, off = [], 0  # content ids are per geometry (its own texture and promotion): never shared across
    for p in parts:
        ids.append(np.where(p[4] >= 0, p[4] + off, -1))
        off += int(p[4].max(initial=-1)) + 1
    eff = np.concatenate([p[5] for p in parts])
    gid, gbytes = _groups(nbytes, np.concatenate(ids), eff)
    rows = np.arange(len(value))
    best, stored, _ = _adopt(value, gid, gbytes, int(budget))
    # also from the uniform columns that fit, the two most valuable: the greedy never ends below them
    fits = [c for c in range(value.shape[1]) if _stored(gid, gbytes, np.full(len(value), c)) <= budget]
    for c in sorted(fits, key=lambda c: -value[:, c].sum())[:2]:
        c2, s2, _ = _adopt(value, gid, gbytes, int(budget), np.full(len(value), c))
        if value[rows, c2].sum() > value[rows, best].sum():
            best, stored = c2, s2
    if stored > budget:  # without special indices even the coarsest micromaps may not fit
        raise InputError(f"the budget of {budget} bytes is below the {stored} bytes the coarsest micromaps need "
                         f"(without special indices every triangle stores one)")
    out, k = [], 0
    merged = 0
    for g, p in zip(geometries, parts):
        inv, choice = p[0], best[k:k + len(p[1])]
        level = p[5][np.arange(len(choice)), choice]
        over = {}
        for c in np.unique(choice):
            if p[6][c] is None:
                continue
            label, meets, mrows = p[6][c]
            items = np.flatnonzero((choice == c) & (label >= 0))
            for t in np.flatnonzero(np.isin(inv, items)):
                over[int(t)] = (meets[label[inv[t]]], mrows[label[inv[t]]])
            merged += len(items)
        out.append((level[inv].astype(np.int64), over))
        k += len(p[1])
    total = float(sum(p[3] for p in parts))
    return out, {"budget_bytes": int(budget), "stored_bytes": stored, "items": int(len(best)),
                 "merged_items": merged,
                 "expected_tests_saved_fraction": float(value[rows, best].sum()) / total if total > 0 else 0.0}
