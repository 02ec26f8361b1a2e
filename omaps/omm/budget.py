"""``omaps omm --budget BYTES``: per triangle the subdivision level (and 2- or 4-state format)
that saves the most expected any-hit calls for the micromap bytes, every geometry together
within the budget (``omaps.budget.allocate``).

An option is a level L of the triangle's micromap, as the micromap baker bakes it. Its value is
the triangle's weight (``Geometry.weight``: world area times instances for a scene, texel area
for a texture and UVs) times its known fraction at L (micro-triangles split the triangle into
equal areas). Its bytes are what the engine stores: nothing for a uniform micromap (a special
index), else the micromap's data plus its 8-byte triangle record; a micromap with no unknown
micro-triangle is stored 2-state (1 bit each, exactly as the 4-state map says), the others
4-state. Triangles with identical UVs share one micromap, so the allocation is per distinct
triangle with the weights of its copies summed; the packer's reuse of identical micromaps can
only spend less. Levels are offered up to ``max_level`` and no finer than
``FINEST_TEXELS`` texels per micro-triangle edge (finer ones read the same footprint cells).
"""

from __future__ import annotations

import numpy as np

from .. import states
from ..bake import GROW_TEXEL, bake_micromaps, dynamic_levels
from ..bake.micromap import check_uv_triangles, flag_table
from ..scene.alpha import distinct_rows
from . import format as omm_format
from .resolve import resolve

__all__ = ["budget_levels", "FINEST_TEXELS"]

FINEST_TEXELS = 0.25


def _options(g, settings, budget: int):
    """Per triangle its item (its distinct UV triangle), and per item the option bytes (I, L+1),
    known fractions (I, L+1), weight (I,) and the content id of its stored micromap per level
    (I, L+1; -1 for none): the packer stores one micromap per (level, content)."""
    max_level, special = settings.max_level, settings.special
    tris = check_uv_triangles(g.tris_uv) if len(g.tris_uv) else np.zeros((0, 3, 2))
    n = len(tris)
    weight = g.areas(tris) if g.weight is None else np.asarray(g.weight, np.float64)
    unknown = np.zeros(n, bool) if g.unknown is None else np.asarray(g.unknown, bool)
    reps, inv = distinct_rows(tris, unknown)
    wsum = np.bincount(inv, weights=np.nan_to_num(weight), minlength=len(reps))
    cap = dynamic_levels(tris[reps], g.test.width, g.test.height, FINEST_TEXELS, max_level)
    cap[unknown[reps]] = 0  # all unknown: nothing to gain at any level
    record = omm_format.TRIANGLE_RECORD.itemsize
    nbytes = np.zeros((len(reps), max_level + 1), np.int64)
    frac = np.zeros((len(reps), max_level + 1))
    ids = np.full((len(reps), max_level + 1), -1, np.int64)
    eff = np.zeros((len(reps), max_level + 1), np.int64)  # the level an option really bakes
    grid = g.test.grid()
    sat = flag_table(grid)
    for lvl in range(max_level + 1):
        sel = np.flatnonzero(cap >= lvl)
        if omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE) + record > budget:
            sel = sel[:0]  # no micromap of this level fits the budget
        if len(sel):
            s3, starts = bake_micromaps(grid, tris[reps[sel]], lvl, GROW_TEXEL, sat)
            if g.unknown is not None:
                s3.reshape(len(sel), -1)[unknown[reps[sel]]] = states.C
            stored = resolve(s3, starts, lvl, g.test, tris[reps[sel]], settings.format_code, settings.promotion,
                             settings.seed).reshape(len(sel), 4 ** lvl)  # what the packer stores
            known = (s3.reshape(len(sel), -1) != states.C).sum(axis=1)
            uniform = (stored == stored[:, :1]).all(axis=1)
            fmt = np.where(known == 4 ** lvl, omm_format.FORMAT_2_STATE, omm_format.FORMAT_4_STATE)
            b = np.where(fmt == omm_format.FORMAT_2_STATE, omm_format.micromap_bytes(lvl, omm_format.FORMAT_2_STATE),
                         omm_format.micromap_bytes(lvl, omm_format.FORMAT_4_STATE)) + record
            nbytes[sel, lvl] = np.where(uniform & special, 0, b)
            frac[sel, lvl] = known / 4 ** lvl
            _, content = np.unique(np.ascontiguousarray(stored).view(np.dtype((np.void, stored.shape[1]))).ravel(),
                                   return_inverse=True)
            ids[sel, lvl] = np.where(nbytes[sel, lvl] > 0, content.ravel(), -1)
            eff[sel, lvl] = lvl
        rest = np.setdiff1d(np.arange(len(reps)), sel)  # not offered: as the level below
        if lvl and len(rest):
            nbytes[rest, lvl] = nbytes[rest, lvl - 1]
            frac[rest, lvl] = frac[rest, lvl - 1]
            ids[rest, lvl] = ids[rest, lvl - 1]
            eff[rest, lvl] = eff[rest, lvl - 1]
        elif len(rest):
            nbytes[rest, 0] = 0  # a budget below one level-0 micromap: uniform, so a special index
    return inv, nbytes, frac, wsum, ids, eff


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


def _adopt(value, gid, gbytes, budget: int, start=None) -> tuple[np.ndarray, int]:
    """Greedy over groups: repeatedly raise every item of the group with the most value per new
    byte (a group already stored, or free, first) to the group's level, while the bytes stored
    -- each group with a member once -- stay within the budget."""
    n_items = len(value)
    level = np.zeros(n_items, np.int64) if start is None else np.array(start, np.int64)
    col = np.arange(value.shape[1])[None, :]
    rows = np.arange(n_items)
    while True:
        ref = np.bincount(gid[rows, level], minlength=len(gbytes))
        stored = int(gbytes[ref > 0].sum())
        gain = value - value[rows, level][:, None]
        up = (col > level[:, None]) & (gain > 0)
        gsum = np.bincount(gid[up], gain[up], minlength=len(gbytes))
        cost = np.where(ref > 0, 0, gbytes)
        ok = (gsum > 0) & (cost <= budget - stored)
        if not ok.any():
            return level, stored
        free = ok & (cost == 0)
        score = np.where(free, gsum, -np.inf) if free.any() else np.where(ok, gsum / np.maximum(cost, 1), -np.inf)
        g = int(np.argmax(score))
        movers = up & (gid == g)
        moved = movers.any(axis=1)
        level[moved] = value.shape[1] - 1 - np.argmax(movers[moved, ::-1], axis=1)  # its last option in g


def budget_levels(geometries, settings, budget: int) -> tuple[list[np.ndarray], dict]:
    """Per geometry the level of each triangle, and a report (bytes stored, expected savings).

    Items that store the same micromap at a level share its bytes, so the choice is made per
    group of such items (``_adopt``); the bytes counted are exactly those the packer stores."""
    parts = [_options(g, settings, budget) for g in geometries]
    if not parts:
        return [], {"budget_bytes": int(budget), "stored_bytes": 0, "items": 0}
    nbytes = np.concatenate([p[1] for p in parts])
    value = np.concatenate([p[3][:, None] * p[2] for p in parts])
    ids, off = [], 0  # content ids are per geometry (its own texture and promotion): never shared across
    for p in parts:
        ids.append(np.where(p[4] >= 0, p[4] + off, -1))
        off += int(p[4].max(initial=-1)) + 1
    eff = np.concatenate([p[5] for p in parts])
    gid, gbytes = _groups(nbytes, np.concatenate(ids), eff)
    choice, stored = _adopt(value, gid, gbytes, int(budget))
    # also from the finest uniform level that fits: the greedy never ends below a uniform bake
    rows = np.arange(len(value))
    fits = [lvl for lvl in range(value.shape[1]) if _stored(gid, gbytes, np.full(len(value), lvl)) <= budget]
    if fits:
        c2, s2 = _adopt(value, gid, gbytes, int(budget), np.full(len(value), max(fits)))
        if value[rows, c2].sum() > value[rows, choice].sum():
            choice, stored = c2, s2
    level = eff[np.arange(len(choice)), choice]
    out, k = [], 0
    for p in parts:
        out.append(level[k:k + len(p[1])][p[0]].astype(np.int64))
        k += len(p[1])
    total = float(sum(p[3].sum() for p in parts))
    return out, {"budget_bytes": int(budget), "stored_bytes": stored, "items": int(len(choice)),
                 "expected_tests_saved_fraction": float(value[np.arange(len(choice)), choice].sum()) / total
                 if total > 0 else 0.0}
