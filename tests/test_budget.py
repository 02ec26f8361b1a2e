"""The byte-budget allocation: within the budget, optimal where the greedy hull walk is exact,
and never further from the brute-force optimum than one step's value."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps.allocate import allocate, upper_hull
from omaps.budget import parse_bytes
from omaps.errors import InputError


def brute_force(nbytes, value, budget):
    best = -1.0
    for combo in itertools.product(range(nbytes.shape[1]), repeat=nbytes.shape[0]):
        idx = np.arange(len(combo)), np.array(combo)
        if nbytes[idx].sum() <= budget:
            best = max(best, value[idx].sum())
    return best


instances = st.integers(1, 4).flatmap(lambda p: st.integers(1, 4).flatmap(lambda k: st.tuples(
    st.lists(st.lists(st.integers(0, 40), min_size=k, max_size=k), min_size=p, max_size=p),
    st.lists(st.lists(st.floats(0, 10, allow_nan=False), min_size=k, max_size=k), min_size=p, max_size=p))))


@settings(max_examples=300, deadline=None)
@given(instances, st.integers(0, 200))
def test_within_budget_and_near_the_optimum(inst, budget):
    nbytes, value = np.array(inst[0]), np.array(inst[1])
    cheapest = nbytes.min(axis=1).sum()
    if cheapest > budget:
        with pytest.raises(InputError):
            allocate(nbytes, value, budget)
        return
    choice = allocate(nbytes, value, budget)
    idx = np.arange(len(choice)), choice
    assert nbytes[idx].sum() <= budget
    got = value[idx].sum()
    best = brute_force(nbytes, value, budget)
    assert got <= best + 1e-9
    # the greedy hull walk loses at most one step: the largest value any single option adds
    assert got >= best - (value.max(axis=1) - value.min(axis=1)).max() - 1e-9


def test_exact_when_the_budget_ends_on_a_step():
    """A budget that the walk spends with no step skipped (a prefix of the steps by falling value
    per byte) gives the exact optimum: an integral optimum of the LP relaxation."""
    rng = np.random.default_rng(0)
    nbytes = np.tile([0, 4, 16, 32, 64], (6, 1))
    value = np.sort(rng.random((6, 5)), axis=1) * np.arange(1, 7)[:, None]
    value[:, 0] = 0
    steps = []
    for p in range(6):
        h = [int(i) for i in upper_hull(nbytes[p], value[p])]
        steps += [((value[p, b] - value[p, a]) / (nbytes[p, b] - nbytes[p, a]), nbytes[p, b] - nbytes[p, a])
                  for a, b in zip(h, h[1:])]
    steps.sort(key=lambda s: -s[0])
    budgets = np.cumsum([c for _, c in steps])
    for budget in budgets[:: max(1, len(budgets) // 6)]:
        choice = allocate(nbytes, value, int(budget))
        idx = np.arange(6), choice
        assert nbytes[idx].sum() == budget
        assert value[idx].sum() >= brute_force(nbytes, value, int(budget)) - 1e-9


def test_hull_drops_dominated_and_concave_points():
    nbytes = np.array([0, 10, 20, 30, 20, 40])
    value = np.array([0.0, 1.0, 5.0, 5.0, 4.0, 6.0])
    # (10, 1) lies under the segment (0,0)-(20,5); (30, 5) adds no value; (20, 4) is beaten by (20, 5)
    assert [int(i) for i in upper_hull(nbytes, value)] == [0, 2, 5]


def test_parse_bytes():
    assert parse_bytes("1263936") == 1263936
    assert parse_bytes("1.5KiB") == 1536 and parse_bytes("2MB") == 2_000_000 and parse_bytes("1 MiB") == 1 << 20
    for bad in ("", "12 parsecs", "-3KiB", "1e3"):
        with pytest.raises(InputError):
            parse_bytes(bad)
