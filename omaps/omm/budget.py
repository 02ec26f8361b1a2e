"""``omaps omm --budget BYTES``: per triangle the subdivision level (and 2- or 4-state format)
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

from typing import NamedTuple

import numpy as np
from numba import njit

from .. import states
from ..budget import HIT_LEVEL
from ..errors import InputError
from ..bake import GROW_TEXEL, bake_micromaps, dynamic_levels
from ..bake.micromap import check_uv_triangles, flag_table
from ..rows import unique_rows
from ..scene.alpha import distinct_rows
from .. import omm_format
from .resolve import resolve

__all__ = ["budget_levels", "GeometryBudget", "FINEST_TEXELS"]

FINEST_TEXELS = 0.25


MERGE_MAX_LEVEL = 5  # merged (shared) micromaps are offered up to this level (1024 micro-triangles)
MERGE_SHARES = (2, 4, 8, 16)  # a level's distinct contents merged into 1/2, 1/4, ... as many micromaps
PROGRESS_CHUNK = 1 << 22  # the pricing bakes a level's items in pieces of this many micro-triangles
MERGE_MAX_WORK = 5e8  # contents^2 x micro-triangles: above it a level offers no merged variants
VARIANTS = 1 + len(MERGE_SHARES)


@njit(cache=True)
def _merge_loss(a, wa, b, wb, limit):
    """Value lost when contents a and b (T/O/C rows, per-cell weights) share their meet, summed
    cell by cell; once the sum reaches ``limit`` the rest is not added (the weights are not
    negative, so the whole sum would reach it too): the sum so far is returned."""
    s = 0.0
    for c in range(len(a)):
        if a[c] != b[c]:
            if a[c] != 2:
                s += wa[c]
            if b[c] != 2:
                s += wb[c]
            if s >= limit:
                return s
    return s


@njit(cache=True)
def _agglomerate(cont, w):
    """Greedy agglomeration of contents (K, n) with per-cell weights (K, n): repeatedly merge the
    two clusters whose meet (cells where they agree, else C) loses the least value. Returns the
    merges in order: (K - 1, 2) cluster indices (the first keeps the meet)."""
    k = cont.shape[0]
    a = cont.copy()
    ww = w.copy()
    cut = (w >= 0).all()  # a loss stops at the best so far (``_merge_loss``) only when none can fall
    alive = np.ones(k, np.bool_)
    best = np.full(k, np.inf)
    arg = np.full(k, -1, np.int64)
    for i in range(k):
        for j in range(i + 1, k):
            s = _merge_loss(a[i], ww[i], a[j], ww[j], best[i] if cut else np.inf)
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
                        s = _merge_loss(a[r], ww[r], a[q], ww[q], best[r] if cut else np.inf)
                        if s < best[r]:
                            best[r] = s
                            arg[r] = q
        for r in range(i):  # row i's new meet may be the best partner of an earlier row
            if alive[r]:
                s = _merge_loss(a[r], ww[r], a[i], ww[i], best[r] if cut else np.inf)
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
    """The levels whose micromaps are offered: those of which one fits the budget (0, 1, ... up
    to the last that fits)."""
    return [lvl for lvl in range(max_level + 1) if _min_bytes(lvl) <= budget]


def _min_bytes(lvl: int) -> int:
    """The fewest bytes a stored level-``lvl`` micromap takes: 2-state, with its record."""
    return omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE) + omm_format.TRIANGLE_RECORD.itemsize


def _base_level(budget: int, max_level: int) -> int:
    """The finest level priced for every item (-1: none fits): the merged variants' finest, or
    the finest offered when that is coarser. Finer levels are priced on demand (``_Pricing``)."""
    levels = _priced_levels(budget, max_level)
    return min(levels[-1], MERGE_MAX_LEVEL) if levels else -1


def _pricing_work(items, settings, budget: int) -> int:
    """Micro-triangles the first pricing bakes for a geometry's items: each item once, at the
    base level or its own finest if coarser (``_Pricing``)."""
    cap = items[5]
    base = _base_level(budget, settings.max_level)
    return int(np.sum(np.left_shift(1, 2 * np.minimum(cap, base)))) if base >= 0 else 0


def _meet(rows: np.ndarray) -> np.ndarray:
    """T/O/C rows (n, 4**L) one level coarser, (n, 4**(L-1)): a micro-triangle's four children
    (4k .. 4k+3 in the bird-curve order) tile it, so its state is their meet: T where all four
    are T, O where all four are O, else C -- what the baker gives the coarse micro-triangle, its
    region being the union of theirs (its flag the OR of their flags)."""
    q = rows.reshape(len(rows), -1, 4)
    return np.where((q == q[:, :, :1]).all(axis=2), q[:, :, 0], np.uint8(states.C)).astype(np.uint8)


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


def _rows_down(grid, sat, tris, target, low, progress) -> dict:
    """T/O/C rows of items at every level ``low`` .. ``target[i]`` (at least ``low`` each): each item
    baked once, at its ``target``, the coarser levels its meets (``_meet``). Returns {level:
    (item positions, rows)}, positions into ``target``, ascending."""
    out = {}
    for top in np.unique(target):
        who = np.flatnonzero(target == top)
        s3, _ = _bake_counted(grid, tris[who], int(top), sat, progress)
        rows = s3.reshape(len(who), -1)
        for lvl in range(int(top), low - 1, -1):
            out.setdefault(lvl, []).append((who, rows))
            if lvl > low:
                rows = _meet(rows)
    res = {}
    for lvl, parts in out.items():
        who = np.concatenate([w for w, _ in parts])
        rows = np.concatenate([r for _, r in parts])
        order = np.argsort(who, kind="stable")
        res[lvl] = (who[order], rows[order])
    return res


def _add_rows(where: dict, lvl: int, sel, *rows) -> None:
    """Add the items ``sel`` and their rows (one array or more, a row an item) to ``where[lvl]``,
    items ascending."""
    old = where.get(lvl)
    if old is not None:
        sel, rows = np.concatenate([old[0], sel]), [np.concatenate([a, b]) for a, b in zip(old[1:], rows)]
    order = np.argsort(sel, kind="stable")
    where[lvl] = (sel[order], *(r[order] for r in rows))


class _Pricing:
    """One geometry's options: per item (its distinct UV triangle) and option column (level L
    exact, then L's merged variants, ``VARIANTS`` columns a level) the bytes, the value, the
    content id of the stored micromap (-1 for none; ids are per level) and the level it bakes
    (``eff``); per column the merge, None or (cluster per item (-1: exact), meets, stored rows).

    Levels up to the base level (``_base_level``) are priced for every item, from one bake each
    at its finest such level (the coarser ones its meets). A finer level is priced only for the
    *classes* asked for (``price``): a class is the items of one base-level content; an item's
    finer contents meet down to its class's, so a finer micromap is shared only within a class,
    and an item not priced at a level keeps the level below's option there (as an item whose
    level is capped). ``_adopt``'s certificate says which classes must be priced for its choice
    to be the one every level priced would give.

    A level that starts no greedy (``_choose``'s lazy levels) is priced in two steps: its rows are
    baked (``held``: the certificate then bounds each content's micromap by its items' values) and
    resolved -- the greedy offered them -- only for the contents the certificate asks for
    (``resolve_held``)."""

    def __init__(self, g, items, settings, budget: int, progress=None):
        self.g, self.settings, self.items = g, settings, items
        tris, unknown, weight, reps, inv, cap = items
        self.special = settings.special
        self.max_level = settings.max_level
        n, ni = len(tris), len(reps)
        self.ni = ni
        self.wsum = np.bincount(inv, weights=np.nan_to_num(weight), minlength=ni)
        cols = (self.max_level + 1) * VARIANTS
        self.nbytes = np.zeros((ni, cols), np.int64)
        self.ids = np.full((ni, cols), -1, np.int64)
        self.eff = np.zeros((ni, cols), np.int64)  # the level an option really bakes
        self.value = np.zeros((ni, cols))
        self.merge = [None] * cols
        hits = np.asarray(g.hits, np.int64) if g.hits is not None and len(g.hits) else np.zeros((0, 2), np.int64)
        self.hits = hits
        self.h_item = inv[hits[:, 0]]
        self.n_hits = np.bincount(self.h_item, minlength=ni)
        self.total = float(self.wsum.sum()) + len(hits)
        self.grid = g.test.grid()
        self.sat = flag_table(self.grid)
        self.utris = tris[reps]
        self.unknown_item = unknown[reps]
        levels = _priced_levels(budget, self.max_level)
        if not levels and not self.special and n:
            raise InputError(f"the budget of {budget} bytes is below one level-0 micromap ({_min_bytes(0)} bytes "
                             f"with its record), and without special indices every triangle stores one")
        self.base = _base_level(budget, self.max_level)
        self.fine_levels = [lvl for lvl in levels if lvl > self.base]
        self.fine = {}  # fine level -> (items, rows3, stored), items ascending
        self.held = {}  # fine level -> (items, rows3) baked but not resolved (not offered), items ascending
        self.coarse = {}  # level <= base -> (items, rows3, stored), items ascending
        self.priced_to = np.minimum(cap, self.base)  # the finest level priced per item
        self.klass = np.full(ni, -1, np.int64)
        self.n_classes = 0
        self.class_mixed = np.zeros(0, bool)  # per class: not all C (its finer contents are never uniform)
        if self.base < 0:  # a budget below one level-0 micromap: uniform, so a special index
            for lvl in range(self.max_level + 1):
                self._fill_fine(lvl)
            return
        rows = _rows_down(self.grid, self.sat, self.utris, np.minimum(cap, self.base), 0, progress)
        for lvl in range(self.base + 1):
            sel, r3 = rows.get(lvl, (np.zeros(0, np.int64), np.zeros((0, 4 ** lvl), np.uint8)))
            r3 = self._unknown_c(sel, r3)
            self.coarse[lvl] = (sel, r3, self._fill(lvl, sel, r3, None))
        # classes: items offered finer levels whose base content is not uniform T or O (a uniform
        # T or O content stays so at every finer level: nothing to gain, and the base's is as free)
        sel, r3 = rows.get(self.base, (np.zeros(0, np.int64), np.zeros((0, 4 ** self.base), np.uint8)))
        r3 = self._unknown_c(sel, r3)
        known_uniform = (r3 == r3[:, :1]).all(axis=1) & (r3[:, 0] != states.C)
        ok = (cap[sel] > self.base) & ~known_uniform
        if ok.any():
            uniq, cls = unique_rows(r3[ok])
            self.n_classes = len(uniq)
            self.klass[sel[ok]] = cls
            first = np.zeros(self.n_classes, np.int64)
            first[cls[::-1]] = np.arange(len(cls))[::-1]
            self.class_mixed = ~(r3[ok][first] == states.C).all(axis=1)
        for lvl in range(self.base + 1, self.max_level + 1):
            self._fill_fine(lvl)

    def _unknown_c(self, sel, r3):
        if self.g.unknown is not None:
            r3 = r3.copy()
            r3[self.unknown_item[sel]] = states.C
        return r3

    def lower_bound_bytes(self, lvl: int) -> int:
        """Fewest bytes every item offered level ``lvl`` at it stores: one micromap per class of
        mixed content (T and O, or a known state and C) -- its finer contents are never uniform,
        and two classes' never equal."""
        if not self.n_classes:
            return 0
        cap = self.items[5]
        has = np.zeros(self.n_classes, bool)
        m = (self.klass >= 0) & (cap >= lvl)
        has[self.klass[m]] = True
        return int(np.count_nonzero(has & self.class_mixed)) * _min_bytes(lvl)

    def unpriced(self, lvl: int):
        """Items offered level ``lvl`` but not priced there, and their classes."""
        who = np.flatnonzero((self.klass >= 0) & (self.items[5] >= lvl) & (self.priced_to < lvl))
        return who, self.klass[who]

    def price(self, lvl: int, classes, progress=None, lazy=frozenset()) -> int:
        """Price level ``lvl`` (and the levels between) for every item of ``classes``; returns the
        micro-triangles baked. The rows of ``lazy`` levels are only baked (``held``)."""
        # held rows are bounded per T/O/C content (``held_contents``): in 4-state two stored rows are
        # equal only where their contents are (a C micro-triangle stays unknown), not in 2-state
        assert not lazy or self.settings.format_code == omm_format.FORMAT_4_STATE, "--budget stores 4-state"
        cap = self.items[5]
        want = np.isin(self.klass, np.asarray(list(classes), np.int64)) & (self.klass >= 0)
        target = np.where(want, np.minimum(cap, lvl), self.priced_to)
        who = np.flatnonzero(target > self.priced_to)
        if not len(who):
            return 0
        work = int(np.sum(np.left_shift(1, 2 * target[who])))
        # each item baked at its target, meets down to its first unpriced level
        for low in np.unique(self.priced_to[who] + 1):
            part = who[self.priced_to[who] + 1 == low]
            rows = _rows_down(self.grid, self.sat, self.utris[part], target[part], int(low), progress)
            for L, (pos, r3) in rows.items():
                sel = part[pos]
                r3 = self._unknown_c(sel, r3)
                if L in lazy:
                    _add_rows(self.held, L, sel, r3)
                else:
                    _add_rows(self.fine, L, sel, r3, self._resolve(sel, r3, L))
        first = int(self.priced_to[who].min()) + 1
        self.priced_to[who] = target[who]
        for L in range(first, self.max_level + 1):
            self._fill_fine(L)
        return work

    def held_contents(self):
        """Per level of ``held`` rows: the items, the content of each (items of one T/O/C row
        store one micromap, or once resolved several: never one with another content), their
        values there, and the bytes of their micromaps: 2-state without a C micro-triangle, else
        4-state (an all-C row, worth nothing, may also be free: no bound counts it)."""
        out = []
        for lvl, (sel, r3) in sorted(self.held.items()):
            content = unique_rows(r3)[1]
            known = (r3 != states.C).sum(axis=1)
            b = np.where(known == 4 ** lvl, _min_bytes(lvl),
                         omm_format.micromap_bytes(lvl, omm_format.FORMAT_4_STATE) + omm_format.TRIANGLE_RECORD.itemsize)
            out.append((lvl, sel, content, self._valuer(lvl, sel)[3](r3), b))
        return out

    def resolve_held(self, lvl: int, contents) -> None:
        """Resolve the ``held`` rows of level ``lvl`` of ``contents`` (as ``held_contents`` numbers
        them): the greedy is offered them."""
        sel, r3 = self.held.pop(lvl)
        content = unique_rows(r3)[1]
        now = np.isin(content, np.asarray(list(contents), np.int64))
        if not now.all():
            self.held[lvl] = (sel[~now], r3[~now])
        _add_rows(self.fine, lvl, sel[now], r3[now], self._resolve(sel[now], r3[now], lvl))
        for L in range(lvl, self.max_level + 1):
            self._fill_fine(L)

    def _valuer(self, lvl, sel):
        """For the items ``sel`` (ascending) at level ``lvl``: the position of every item in
        ``sel`` (-1: none), the view hits on them (position, cell at the level) and the value of
        rows of theirs (a function of T/O/C rows, one per item of ``sel``)."""
        nc = 4 ** lvl
        row = np.full(self.ni, -1, np.int64)
        row[sel] = np.arange(len(sel))
        hr = row[self.h_item]
        hok = hr >= 0
        h_sel, h_cell = hr[hok], self.hits[hok, 1] >> (2 * (HIT_LEVEL - lvl))
        wsum = self.wsum

        def values(states_of_sel):  # value of every selected item with these T/O/C rows
            known = states_of_sel != states.C
            v = wsum[sel] * known.sum(axis=1) / nc
            return v + np.bincount(h_sel[known[h_sel, h_cell]], minlength=len(sel))

        return row, h_sel, h_cell, values

    def _resolve(self, sel, r3, lvl):
        s = self.settings
        nc = 4 ** lvl
        return resolve(np.ascontiguousarray(r3).ravel(), np.arange(len(sel) + 1, dtype=np.int64) * nc, lvl,
                       self.g.test, self.utris[sel], s.format_code, s.promotion, s.seed).reshape(len(sel), nc)

    def _fill_fine(self, lvl):
        sel, r3, stored = self.fine.get(lvl, (np.zeros(0, np.int64), np.zeros((0, 4 ** lvl), np.uint8), None))
        self._fill(lvl, sel, r3, stored)

    def _fill(self, lvl, sel, rows3, stored):
        """Level ``lvl``'s columns: the items ``sel`` (ascending) priced from their T/O/C rows (and
        stored rows, resolved here when None); the others keep the level below's option."""
        settings, special, record = self.settings, self.special, omm_format.TRIANGLE_RECORD.itemsize
        g, ni, wsum = self.g, self.ni, self.wsum
        nbytes, value, ids, eff, merge = self.nbytes, self.value, self.ids, self.eff, self.merge
        c0 = lvl * VARIANTS
        nc = 4 ** lvl
        rest = np.setdiff1d(np.arange(ni), sel)  # not offered: as the level below
        if lvl and len(rest):
            prev = c0 - VARIANTS  # the level below's exact column
            nbytes[rest, c0:c0 + VARIANTS] = nbytes[rest, prev][:, None]
            value[rest, c0:c0 + VARIANTS] = value[rest, prev][:, None]
            ids[rest, c0:c0 + VARIANTS] = ids[rest, prev][:, None]
            eff[rest, c0:c0 + VARIANTS] = eff[rest, prev][:, None]
        elif len(rest):
            nbytes[rest, :VARIANTS] = 0
        if not len(sel):
            return stored

        def price(rows3, stored):
            """bytes of T/O/C rows and their stored rows."""
            known = (rows3 != states.C).sum(axis=1)
            uniform = (stored == stored[:, :1]).all(axis=1)
            b = np.where(known == nc, omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE),
                         omm_format.micromap_bytes(lvl, omm_format.FORMAT_4_STATE)) + record
            return np.where(uniform & special, 0, b)

        if stored is None:
            stored = self._resolve(sel, rows3, lvl)  # what the packer stores
        row, h_sel, h_cell, values = self._valuer(lvl, sel)
        b = price(rows3, stored)
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
            mrows = resolve(flat, np.arange(len(meets) + 1) * nc, lvl, g.test, self.utris[sel[rep]],
                            settings.format_code, settings.promotion, settings.seed).reshape(len(meets), nc)
            st3 = np.where(label[:, None] >= 0, meets[np.maximum(label, 0)], rows3)
            st = np.where(label[:, None] >= 0, mrows[np.maximum(label, 0)], stored)
            nbytes[sel, c] = price(st3, st)
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
        return stored

    def rows(self, choice: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What every item stores under the option columns ``choice``: its T/O/C micromap and the
        stored one (a merged option's meet and the cluster's row), flat, item after item, each at
        its option's level (``eff``) -- the rows the pricing baked and resolved, so the build
        bakes nothing again. None where a level was never baked (a budget below every stored
        micromap: every item at level 0, for special indices)."""
        level = self.eff[np.arange(self.ni), choice]
        starts = np.zeros(self.ni + 1, np.int64)
        np.cumsum(np.left_shift(np.int64(1), 2 * level), out=starts[1:])
        s3 = np.empty(int(starts[-1]), np.uint8)
        st = np.empty_like(s3)
        for lvl in np.unique(level):
            lvl = int(lvl)
            sel, r3, stored = (self.coarse if lvl <= self.base else self.fine).get(lvl, (None, None, None))
            if stored is None:  # nothing baked there (a budget below every stored micromap): the build bakes
                return None
            who = np.flatnonzero(level == lvl)
            pos = np.searchsorted(sel, who)
            if not (pos < len(sel)).all() or not np.array_equal(sel[np.minimum(pos, len(sel) - 1)], who):
                raise AssertionError(f"level {lvl} was chosen for items the pricing did not bake there")
            a, b = r3[pos], stored[pos]
            for c in np.unique(choice[who]):  # merged options: the cluster's meet and stored row
                if self.merge[c] is not None:
                    label, meets, mrows = self.merge[c]
                    m = (choice[who] == c) & (label[who] >= 0)  # (none where the option is the level below's)
                    if m.any():
                        a[m], b[m] = meets[label[who[m]]], mrows[label[who[m]]]
            flat = starts[who][:, None] + np.arange(1 << (2 * lvl))
            s3[flat], st[flat] = a, b
        return s3, st, starts


def _merged(rows3, stored, nbytes, w, h_row, h_cell, lvl) -> list:
    """Per share of ``MERGE_SHARES`` (while it leaves at least two micromaps), the stored rows'
    clusters: (cluster per row, -1 for a row that stores nothing, and each cluster's meet: T or
    O where all its rows agree, else C). Rows are clustered by their T/O/C content, weighted by
    the value each cell holds (its rows' weights spread by area, plus their hits)."""
    nc = rows3.shape[1]
    paid = np.flatnonzero(nbytes > 0)
    if len(paid) < 4:
        return []
    uniq, cinv = unique_rows(rows3[paid])
    k = len(uniq)
    cont = np.empty((k, nc), np.uint8)
    cont[cinv] = rows3[paid]
    if k < 4 or float(k) * k * nc > MERGE_MAX_WORK:
        return []
    # each content's rows' weights spread over its cells: every cell the same sum, in the rows'
    # order (as ``np.add.at`` of the rows adds them), so one per content, repeated
    cw = np.repeat(np.bincount(cinv, w[paid] / nc, minlength=k)[:, None], nc, axis=1)
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
    idv = np.where(nbytes > 0, ids, -1).ravel() + 1
    key = np.asarray(lv, np.int64).ravel() * (int(idv.max(initial=0)) + 1) + idv  # (level, id) in that order
    keys, gid = np.unique(key, return_inverse=True)
    gid = gid.reshape(n_items, n_levels)
    gbytes = np.zeros(len(keys), np.int64)
    gbytes[gid.ravel()] = nbytes.ravel()
    return gid, gbytes


def _stored(gid, gbytes, level) -> int:
    ref = np.bincount(gid[np.arange(len(level)), level], minlength=len(gbytes))
    return int(gbytes[ref > 0].sum())


def _kept(gid) -> np.ndarray:
    """Per item, the first of its options in each group (the one the greedy counts and moves to)."""
    order = np.argsort(gid, axis=1, kind="stable")
    srt = np.take_along_axis(gid, order, axis=1)
    first = np.ones(gid.shape, bool)
    first[:, 1:] = srt[:, 1:] != srt[:, :-1]
    keep = np.zeros(gid.shape, bool)
    np.put_along_axis(keep, order, first, axis=1)
    return keep


@njit(cache=True)
def _greedy_setup(value, gid, keep, level, n_groups):
    """``_adopt``'s state: per group its members now (``ref``), the sum of the gains of the
    options in it that gain (``gsum``, summed in the order ``np.bincount`` sums the options: item
    after item, option after option), and its kept options, in that same order (``first``: the
    start of each group's, ``members``: item * columns + option)."""
    n, m = gid.shape
    ref = np.zeros(n_groups, np.int64)
    gsum = np.zeros(n_groups)
    first = np.zeros(n_groups + 1, np.int64)
    for i in range(n):
        ref[gid[i, level[i]]] += 1
        cur = value[i, level[i]]
        for c in range(m):
            if keep[i, c]:
                first[gid[i, c] + 1] += 1
                gain = value[i, c] - cur
                if gain > 0:
                    gsum[gid[i, c]] += gain
    for g in range(n_groups):
        first[g + 1] += first[g]
    members = np.empty(first[n_groups], np.int64)
    fill = first[:n_groups].copy()
    for i in range(n):
        for c in range(m):
            if keep[i, c]:
                g = gid[i, c]
                members[fill[g]] = i * m + c
                fill[g] += 1
    return ref, gsum, first, members


@njit(cache=True)
def _greedy_pick(gsum, ref, gbytes, room):
    """The group the greedy adopts next: the free one (stored already, or of no bytes) that gains
    the most, else the one that gains the most per byte within ``room``; the first such (as
    ``np.argmax``). Returns (group, -1 when none gains within the room; whether it is free; its
    value per byte)."""
    best_free, best, rate = -1, -1, -np.inf
    for g in range(len(gsum)):
        if not gsum[g] > 0:
            continue
        cost = 0 if ref[g] > 0 else gbytes[g]
        if cost > room:
            continue
        if cost == 0:
            if best_free < 0 or gsum[g] > gsum[best_free]:
                best_free = g
        elif best_free < 0:
            r = gsum[g] / cost
            if r > rate:
                best, rate = g, r
    if best_free >= 0:
        return best_free, True, np.inf
    return best, False, rate


@njit(cache=True)
def _greedy_move(chosen, value, gid, keep, level, ref, gsum, gbytes, first, members, seen):
    """Every item with an option in group ``chosen`` that gains moves to it (its kept option
    there); the sums of the groups whose gains that changed (every kept option of a mover) are
    summed again, each in ``np.bincount``'s order, so they are exactly what summing them all
    anew gives. Returns the change in bytes stored."""
    m = gid.shape[1]
    delta = 0
    movers = []
    for e in range(first[chosen], first[chosen + 1]):
        i, c = members[e] // m, members[e] % m
        if value[i, c] - value[i, level[i]] > 0:
            movers.append((i, c))
    touched = []
    for i, c in movers:
        old = gid[i, level[i]]
        ref[old] -= 1
        if ref[old] == 0:
            delta -= gbytes[old]
        level[i] = c
        ref[chosen] += 1
        if ref[chosen] == 1:
            delta += gbytes[chosen]
        for k in range(m):
            g = gid[i, k]
            if keep[i, k] and not seen[g]:
                seen[g] = True
                touched.append(g)
    for g in touched:
        seen[g] = False
        s = 0.0
        for e in range(first[g], first[g + 1]):
            i, c = members[e] // m, members[e] % m
            gain = value[i, c] - value[i, level[i]]
            if gain > 0:
                s += gain
        gsum[g] = s
    return delta


def _doubt(watch, cur, room: int, rate: float, doubt: dict) -> None:
    """The certificate at one step of the greedy (``_adopt``'s ``watch``): adds to ``doubt`` the
    classes whose best case, against the items' values now (``cur``), reaches ``rate`` per byte
    within ``room`` bytes."""
    for key, least, who, cls, best in watch:
        if least > room or not len(who):
            continue
        bound = np.bincount(cls, np.maximum(best - cur[who], 0.0))
        bad = np.flatnonzero((bound > 0) & (bound >= rate * least * (1 - 1e-9)))
        if len(bad):
            doubt.setdefault(key, set()).update(bad.tolist())


def _adopt(value, gid, gbytes, budget: int, start=None, watch=()) -> tuple[np.ndarray, int, dict]:
    """Greedy over groups: repeatedly move every item that gains by it to the group with the most
    value per new byte (a group already stored, or free, first), while the bytes stored -- each
    group with a member once -- stay within the budget. Items only ever gain. (An item's options
    in one group store the same micromap, so they are worth the same: one of them counts.)
    Only the groups a move changes are summed again (``_greedy_move``): the steps are those of
    summing every group anew at each (``tests/test_omm_budget_greedy.py`` keeps that one).

    ``watch``: options not priced, as (key, fewest bytes, items, their classes, best value per
    item): a class's options at the key's level are one new micromap each (at least those
    bytes), worth at most its items' best values. Returns the levels, the bytes stored and the
    certificate's answer: per key the classes whose bound reached a step's chosen value per
    byte, or stayed affordable when the greedy ended (the choice may then differ from the one
    with them priced), empty when the choice is the same."""
    n_items, n_cols = value.shape
    value = np.ascontiguousarray(value, np.float64)
    gid = np.ascontiguousarray(gid, np.int64)
    gbytes = np.ascontiguousarray(gbytes, np.int64)
    level = np.zeros(n_items, np.int64) if start is None else np.array(start, np.int64)
    rows = np.arange(n_items)
    keep = _kept(gid)
    doubt: dict = {}

    def check(room, rate):
        if watch:
            _doubt(watch, value[rows, level], room, rate, doubt)

    ref, gsum, starts, members = _greedy_setup(value, gid, keep, level, len(gbytes))
    stored = int(gbytes[ref > 0].sum())
    seen = np.zeros(len(gbytes), bool)
    while True:
        chosen, free, rate = _greedy_pick(gsum, ref, gbytes, budget - stored)
        if chosen < 0:
            check(budget - stored, 0.0)
            return level, stored, doubt
        if not free:
            check(budget - stored, float(rate))
        stored += int(_greedy_move(chosen, value, gid, keep, level, ref, gsum, gbytes, starts, members, seen))


def _choose(pricings, budget: int) -> tuple:
    """The greedy's choice over every geometry's options (``_adopt``, from nothing and from the two
    most valuable uniform columns that fit), pricing finer levels for the classes its certificate
    names until it names none: the choice is then the one with every level priced."""
    while True:
        nbytes = np.concatenate([p.nbytes for p in pricings])
        value = np.concatenate([p.value for p in pricings])
        ids, off = [], 0  # content ids are per geometry (its own texture and promotion): never shared across
        for p in pricings:
            ids.append(np.where(p.ids >= 0, p.ids + off, -1))
            off += int(p.ids.max(initial=-1)) + 1
        eff = np.concatenate([p.eff for p in pricings])
        gid, gbytes = _groups(nbytes, np.concatenate(ids), eff)
        rows = np.arange(len(value))
        watch, base = [], 0
        for gi, p in enumerate(pricings):
            best = p.wsum + p.n_hits
            for lvl in p.fine_levels:
                who, cls = p.unpriced(lvl)
                watch.append(((gi, lvl), _min_bytes(lvl), who + base, cls, best[who]))
            # baked, not resolved: each content's micromap, once resolved, is one or more groups,
            # each worth at most the content's items' values there, for those bytes
            for lvl, who, content, worth, b in p.held_contents():
                for least in np.unique(b):
                    m = b == least
                    watch.append((("resolve", gi, lvl), int(least), who[m] + base, content[m], worth[m]))
            base += p.ni
        # a uniform column at a level is a start only where every item there fits: a level whose
        # classes alone need more than the budget is out (its unpriced items could only add bytes)
        top = max((p.max_level for p in pricings), default=-1)
        out_levels = set()
        for lvl in range(top + 1):
            if sum(p.lower_bound_bytes(lvl) for p in pricings if lvl in p.fine_levels) > budget:
                out_levels.add(lvl)
        # levels from which every column up is out start no greedy, nor do their rows change a
        # column that may start one: they are resolved only where the certificate asks (``held``)
        lazy = set()
        for lvl in range(top, -1, -1):
            if lvl not in out_levels:
                break
            lazy.add(lvl)
        need = {(gi, lvl): set(range(p.n_classes)) for gi, p in enumerate(pricings) for lvl in p.fine_levels
                if lvl not in out_levels and len(p.unpriced(lvl)[0])}
        if not need:
            best, stored, doubt = _adopt(value, gid, gbytes, budget, watch=watch)
            fits = [c for c in range(value.shape[1]) if c // VARIANTS not in out_levels
                    and _stored(gid, gbytes, np.full(len(value), c)) <= budget]
            for c in sorted(fits, key=lambda c: -value[:, c].sum())[:2]:
                c2, s2, d2 = _adopt(value, gid, gbytes, budget, np.full(len(value), c), watch)
                for k, v in d2.items():
                    doubt.setdefault(k, set()).update(v)
                if value[rows, c2].sum() > value[rows, best].sum():
                    best, stored = c2, s2
            need = doubt
        if not need:
            return nbytes, value, best, stored
        for key, contents in need.items():  # (before any bake: the contents are numbered by the rows held now)
            if key[0] == "resolve":
                pricings[key[1]].resolve_held(key[2], contents)
        finest: dict = {}  # (geometry, class) -> the finest level asked: one bake prices it and the levels between
        for key, classes in need.items():
            if key[0] == "resolve":
                continue
            gi, lvl = key
            for c in classes:
                finest[gi, c] = max(finest.get((gi, c), lvl), lvl)
        jobs = {}
        for (gi, c), lvl in finest.items():
            jobs.setdefault((gi, lvl), set()).add(c)
        jobs = [(gi, lvl, classes) for (gi, lvl), classes in sorted(jobs.items())]
        for gi, lvl, classes in jobs:  # (not counted by the progress: its total is known before the first)
            pricings[gi].price(lvl, classes, lazy=lazy)


class GeometryBudget(NamedTuple):
    """The budget's plan for one geometry: each triangle's level, the merged micromaps it stores
    ({triangle: (T/O/C meet, stored row)}), and every triangle's micromap as the pricing baked
    and resolved it -- T/O/C states (``states3``) and OMM states (``stored``), flat, triangle
    after triangle at its level (``bake.micro_starts(levels)``), merged ones included -- so the
    build stage bakes nothing twice (None: not baked, the build bakes them)."""

    levels: np.ndarray
    merged: dict
    states3: np.ndarray
    stored: np.ndarray


def budget_levels(geometries, settings, budget: int, progress=None) -> tuple[list[GeometryBudget], dict]:
    """Per geometry its plan (``GeometryBudget``: the level of each triangle, the merged
    micromaps it stores and every triangle's baked micromap), and a report (bytes stored,
    expected savings). ``progress``
    (``pipeline.Progress``): its stage "pricing" counts the micro-triangles baked to price the
    options, its total known before the first (the levels finer than the base level that the
    certificate asks for are not counted).

    Items that store the same micromap at a level share its bytes, so the choice is made per
    group of such items (``_adopt``); the bytes counted are exactly those the packer stores.
    Levels up to the base level are priced for every item from one bake each; a finer level
    only for the classes whose best case could change the choice (``_choose``)."""
    items = [_items(g, settings) for g in geometries]
    budget = int(budget)
    if progress is not None:
        progress.stage("pricing", sum(_pricing_work(it, settings, budget) for it in items), "micro-triangles")
    pricings = [_Pricing(g, it, settings, budget, progress) for g, it in zip(geometries, items)]
    if not pricings:
        return [], {"budget_bytes": budget, "stored_bytes": 0, "items": 0}
    nbytes, value, best, stored = _choose(pricings, budget)
    rows = np.arange(len(value))
    if stored > budget:  # without special indices even the coarsest micromaps may not fit
        raise InputError(f"the budget of {budget} bytes is below the {stored} bytes the coarsest micromaps need "
                         f"(without special indices every triangle stores one)")
    out, k = [], 0
    merged = 0
    for p in pricings:
        inv, choice = p.items[4], best[k:k + p.ni]
        level = p.eff[np.arange(len(choice)), choice]
        over = {}
        for c in np.unique(choice):
            if p.merge[c] is None:
                continue
            label, meets, mrows = p.merge[c]
            sel = np.flatnonzero((choice == c) & (label >= 0))
            for t in np.flatnonzero(np.isin(inv, sel)):
                over[int(t)] = (meets[label[inv[t]]], mrows[label[inv[t]]])
            merged += len(sel)
        baked = p.rows(choice)
        s3 = st = None
        if baked is not None:
            n_micro = np.left_shift(np.int64(1), 2 * level[inv])
            first = np.zeros(len(inv) + 1, np.int64)
            np.cumsum(n_micro, out=first[1:])
            src = np.repeat(baked[2][inv] - first[:-1], n_micro) + np.arange(int(first[-1]))  # item rows per triangle
            s3, st = baked[0][src], baked[1][src]
        out.append(GeometryBudget(level[inv].astype(np.int64), over, s3, st))
        k += p.ni
    total = float(sum(p.total for p in pricings))
    return out, {"budget_bytes": budget, "stored_bytes": stored, "items": int(len(best)),
                 "merged_items": merged,
                 "expected_tests_saved_fraction": float(value[rows, best].sum()) / total if total > 0 else 0.0}
