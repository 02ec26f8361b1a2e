"""The tree measures of bench/bench_both_fronts_reach.py (the frontier page's reach table) against a
brute force over the micromaps' states: where a lookup's descent ends, the mixed nodes at each
depth of a map's tree, and the first subtree of a descent that fits in a line."""

import importlib.util
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps.codecs import csm_build

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_both_fronts_reach.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_both_fronts_reach", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


reach = _bench()


def blocks(m, level, d):
    """The 4^d blocks of a level-``level`` micromap at depth d (bird-curve order: consecutive)."""
    return m.reshape(4 ** d, 4 ** (level - d))


def brute_depth(m, level, k):
    for d in range(level + 1):
        b = blocks(m, level, d)[k >> (2 * (level - d))]
        if (b == b[0]).all():
            return d
    raise AssertionError


def brute_mixed(m, level):
    return np.array([int(sum(not (b == b[0]).all() for b in blocks(m, level, d))) if d < level else 0
                     for d in range(level + 1)])


maps_strategy = st.integers(1, 3).flatmap(lambda level: st.tuples(
    st.just(level),
    st.lists(st.lists(st.sampled_from([0, 1, 2]), min_size=4 ** level, max_size=4 ** level)
             .map(lambda v: v), min_size=1, max_size=5),
    st.data()))


@settings(max_examples=60, deadline=None)
@given(maps_strategy)
def test_tree_measures_match_the_states(case):
    level, rows, data = case
    # runs of equal states make uniform blocks likely, as real maps have
    maps = np.array([np.repeat(np.array(r[:4 ** level // 4 or 1]), 4)[:4 ** level] if i % 2 else r
                     for i, r in enumerate(rows)], np.uint8).reshape(len(rows), 4 ** level)
    nodes, roots = csm_build(maps, level)
    per_depth = reach.mixed_per_depth(nodes, level)
    for m, r in zip(maps, roots):
        assert per_depth[r].tolist() == brute_mixed(m, level).tolist()
    t = np.array(data.draw(st.lists(st.integers(0, len(maps) - 1), min_size=1, max_size=20)))
    k = np.array(data.draw(st.lists(st.integers(0, 4 ** level - 1), min_size=len(t), max_size=len(t))))
    got = reach.decision_depths(nodes, roots[t], level, k)
    assert got.tolist() == [brute_depth(maps[i], level, int(kk)) for i, kk in zip(t, k)]
    # the first subtree of each descent with at most LINE mixed nodes: its states are the block's
    tree = per_depth.sum(axis=1)
    reach.LINE = 2  # small enough that the levels here have subtrees that do not fit
    try:
        region = reach.region_of(nodes, tree, roots[t], level, k)
        for i, kk, ref in zip(t, k, region):
            m = maps[i]
            for d in range(level + 1):
                b = blocks(m, level, d)[int(kk) >> (2 * (level - d))]
                mixed = sum(brute_mixed(b, level - d)) if len(b) > 1 else 0
                if (b == b[0]).all() or mixed <= reach.LINE:
                    break
            if (b == b[0]).all():
                assert ref == b[0]
            else:
                assert ref >= 3 and tree[ref] == mixed and tree[ref] <= reach.LINE
        route, sub = reach.routes(nodes, tree, roots)

        def walk(b, lv):  # (route nodes, subtrees) of a block of states, brute force
            mixed = not (b == b[0]).all()
            if not mixed:
                return 0, 0
            if sum(brute_mixed(b, lv)) <= reach.LINE:
                return 0, 1
            parts = [walk(q, lv - 1) for q in b.reshape(4, -1)]
            return 1 + sum(p[0] for p in parts), sum(p[1] for p in parts)

        assert [walk(m, level) for m in maps] == list(zip(route.tolist(), sub.tolist()))
    finally:
        reach.LINE = 64
