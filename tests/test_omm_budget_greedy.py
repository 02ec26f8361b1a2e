"""The budget's greedy (``omaps.omm.budget._adopt``), which sums again only the groups a move
changes, against the plain one that sums every group anew at each step, and its agglomeration of
contents (losses that stop at the best so far; cell weights summed once per content), against the
one that sums every loss whole (references in tests/reference_budget.py): the same levels, bytes,
certificate, merges and merged variants, ties included."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from omaps.omm import budget as omm_budget

import reference_budget as reference  # noqa: E402  (the plain greedy and agglomeration)


@st.composite
def instances(draw):
    """Options of a few items: bytes, values (small integers for ties, or floats), contents
    shared between items (and within an item), the level each option bakes, a start and a
    certificate's watch list."""
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    n_items, n_cols = draw(st.integers(1, 14)), draw(st.integers(1, 9))
    nbytes = rng.integers(0, 70, (n_items, n_cols)) if draw(st.booleans()) else rng.choice([8, 16, 24], (n_items, n_cols))
    nbytes[rng.random((n_items, n_cols)) < 0.2] = 0
    if draw(st.booleans()):
        value = rng.integers(0, 5, (n_items, n_cols)).astype(np.float64)  # ties
    else:
        value = rng.random((n_items, n_cols)) * rng.choice([1e-3, 1.0, 1e6])
    if draw(st.booleans()):
        value = np.sort(value, axis=1)
    eff = np.sort(rng.integers(0, 4, (n_items, n_cols)), axis=1)
    ids = np.where(nbytes > 0, rng.integers(0, draw(st.integers(1, 4)), (n_items, n_cols)), -1)
    for lvl in np.unique(eff):  # one content at a level: one size
        for c in np.unique(ids[ids >= 0]):
            m = (eff == lvl) & (ids == c)
            if m.any():
                nbytes[m] = nbytes[m].max()
    gid, gbytes = omm_budget._groups(nbytes, ids, eff)
    budget = draw(st.integers(0, 400))
    start = None
    if draw(st.booleans()):
        start = np.full(n_items, rng.integers(0, n_cols)) if draw(st.booleans()) else rng.integers(0, n_cols, n_items)
    watch = []
    for k in range(draw(st.integers(0, 2))):
        who = np.flatnonzero(rng.random(n_items) < 0.6)
        cls = rng.integers(0, 3, len(who))
        watch.append(((0, k), int(rng.integers(1, 60)), who, cls, value.max(axis=1)[who] + rng.random(len(who))))
    return value, gid, gbytes, budget, start, watch


@settings(max_examples=400, deadline=None)
@given(instances())
def test_incremental_greedy_is_the_plain_one(inst):
    value, gid, gbytes, budget, start, watch = inst
    level, stored, doubt = omm_budget._adopt(value, gid, gbytes, budget, start, watch)
    level_ref, stored_ref, doubt_ref = reference._adopt(value, gid, gbytes, budget, start, watch)
    np.testing.assert_array_equal(level, level_ref)
    assert stored == stored_ref
    assert doubt == doubt_ref


def test_incremental_greedy_on_many_shared_groups():
    """Larger instances: hundreds of items sharing a few contents per level, many steps."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        n_items, n_cols = 300, 12
        eff = np.repeat(np.arange(n_cols // 2), 2)[None].repeat(n_items, 0)
        ids = rng.integers(0, 25, (n_items, n_cols))
        nbytes = np.where(rng.random((n_items, n_cols)) < 0.1, 0, (eff + 1) ** 2 * 8)
        ids = np.where(nbytes > 0, ids, -1)
        value = np.sort(rng.random((n_items, n_cols)), axis=1) * rng.random((n_items, 1))
        gid, gbytes = omm_budget._groups(nbytes, ids, eff)
        for budget in (0, 500, 5000, 50000):
            got = omm_budget._adopt(value, gid, gbytes, budget)
            ref = reference._adopt(value, gid, gbytes, budget)
            np.testing.assert_array_equal(got[0], ref[0])
            assert got[1:] == ref[1:]


@settings(max_examples=100, deadline=None)
@given(instances())
def test_group_sums_stay_those_summed_anew(inst):
    """After every move the kept sums are bit for bit ``np.bincount``'s over the whole matrix,
    and the members and bytes stored are the recount's."""
    value, gid, gbytes, budget, start, _ = inst
    n_items, n_cols = value.shape
    rows = np.arange(n_items)
    level = np.zeros(n_items, np.int64) if start is None else np.array(start, np.int64)
    gid = np.ascontiguousarray(gid, np.int64)
    keep = omm_budget._kept(gid)
    ref, gsum, starts, members = omm_budget._greedy_setup(value, gid, keep, level, len(gbytes))
    stored = int(gbytes[ref > 0].sum())
    seen = np.zeros(len(gbytes), bool)
    budget = 10 ** 6  # every step a move
    for _ in range(n_items * n_cols + 1):
        gain = value - value[rows, level][:, None]
        up = keep & (gain > 0)
        np.testing.assert_array_equal(gsum, np.bincount(gid[up], gain[up], minlength=len(gbytes)))
        np.testing.assert_array_equal(ref, np.bincount(gid[rows, level], minlength=len(gbytes)))
        assert stored == int(gbytes[ref > 0].sum())
        chosen, _, _ = omm_budget._greedy_pick(gsum, ref, gbytes, budget - stored)
        if chosen < 0:
            break
        stored += int(omm_budget._greedy_move(chosen, value, gid, keep, level, ref, gsum, gbytes, starts, members,
                                              seen))
    else:
        raise AssertionError("the greedy did not end")


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 24), st.integers(1, 20), st.sampled_from(["float", "int", "zeros", "signed"]))
def test_agglomeration_is_the_plain_one(seed, k, n, weights):
    """Losses that stop once they reach the best so far give the merges that whole losses give:
    ties (integer or zero weights) broken alike, and negative weights summed whole."""
    rng = np.random.default_rng(seed)
    cont = rng.integers(0, 3, (k, n)).astype(np.uint8)
    cont[rng.random(k) < 0.3] = cont[0]  # repeated contents: losses of zero
    if weights == "float":
        w = rng.random((k, n)) * rng.choice([1e-3, 1.0, 1e6], (k, 1))
    elif weights == "int":
        w = rng.integers(0, 3, (k, n)).astype(np.float64)
    elif weights == "zeros":
        w = np.where(rng.random((k, n)) < 0.5, 0.0, 1.0)
    else:  # (no weight is negative in a plan; the losses are then summed whole)
        w = rng.normal(size=(k, n))
    np.testing.assert_array_equal(omm_budget._agglomerate(cont, w), reference._agglomerate(cont, w))


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 3), st.integers(4, 40))
def test_merged_clusters_are_the_plain_ones(seed, lvl, n_rows):
    """The merged variants of a level's rows (``_merged``: contents weighted by their rows'
    weights spread over the cells, plus the view hits on them) are those of the plain pricing."""
    rng = np.random.default_rng(seed)
    nc = 4 ** lvl
    kinds = rng.integers(0, 3, (int(rng.integers(2, 12)), nc)).astype(np.uint8)
    rows3 = kinds[rng.integers(0, len(kinds), n_rows)]
    nbytes = np.where(rng.random(n_rows) < 0.15, 0, 24)
    w = rng.random(n_rows) * rng.choice([1e-2, 1.0, 1e4], n_rows)
    n_hits = int(rng.integers(0, 40))
    h_row, h_cell = rng.integers(0, n_rows, n_hits), rng.integers(0, nc, n_hits)
    got = omm_budget._merged(rows3, None, nbytes, w, h_row, h_cell, lvl)
    ref = reference._merged(rows3, None, nbytes, w, h_row, h_cell, lvl)
    assert len(got) == len(ref)
    for (label, meets), (label_ref, meets_ref) in zip(got, ref):
        np.testing.assert_array_equal(label, label_ref)
        np.testing.assert_array_equal(meets, meets_ref)
