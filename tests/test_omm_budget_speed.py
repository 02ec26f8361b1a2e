"""The budget's pricing: coarse levels as meets of the finest baked, finer levels priced only where
the greedy's certificate asks, and the plan the same as pricing every level for every item."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from omaps.alpha_test import StateRule
from omaps.bake import GROW_TEXEL, bake_micromaps
from omaps.omm import budget as omm_budget
from omaps.omm.pipeline import Geometry, OmmSettings, build
from omaps.omm.resolve import resolve
from omaps.texture import load_alpha

import reference_budget as reference  # noqa: E402  (the pricing before the certificate: every level baked)


def _test(alpha, filt="nearest"):
    return StateRule("cutoff").alpha_test(load_alpha(alpha), filt, "wrap")


def _tris(rng, n, spread=1.0):
    c = rng.random((n, 1, 2)) * spread
    return c + (rng.random((n, 3, 2)) - 0.5) * rng.uniform(0.05, 0.6, (n, 1, 1))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.sampled_from(["nearest", "linear"]), st.integers(2, 5),
       st.sampled_from([4, 8, 16, 32]))
def test_meet_of_the_finer_level_is_the_bake(seed, filt, level, size):
    rng = np.random.default_rng(seed)
    alpha = (rng.random((size, size)) < rng.uniform(0.1, 0.9)).astype(np.uint8) * 255
    if rng.random() < 0.5:  # smooth alpha: mixed bilinear cells
        alpha = rng.integers(0, 256, (size, size), dtype=np.uint8)
    test = _test(alpha, filt)
    grid = test.grid()
    tris = _tris(rng, 12, 2.0)
    fine, _ = bake_micromaps(grid, tris, level, GROW_TEXEL)
    coarse, _ = bake_micromaps(grid, tris, level - 1, GROW_TEXEL)
    np.testing.assert_array_equal(omm_budget._meet(fine.reshape(len(tris), -1)), coarse.reshape(len(tris), -1))


def _geometry(seed, n=60, size=64, period=(2, 6), filt="nearest"):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    alpha = ((np.sin(xx / rng.uniform(*period)) + np.cos(yy / rng.uniform(*period)) + rng.normal(0, 0.3, (size, size)))
             > 0).astype(np.uint8) * 255
    tris = _tris(rng, n)
    tris = np.concatenate([tris, tris[:n // 4]])  # repeated UVs: items standing for several triangles
    return Geometry("g", _test(alpha, filt), tris)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("fraction", [0.02, 0.1, 0.5])
def test_plan_is_every_level_priced_plan(seed, fraction):
    g = [_geometry(seed), _geometry(seed + 10, 30)]
    full = sum(len(x.tris_uv) for x in g) * (4 ** 6 // 4 + 8)
    budget = max(int(full * fraction), 64)
    s = OmmSettings(budget=budget, max_level=7)
    plan, rep = omm_budget.budget_levels(g, s, budget)
    plan_ref, rep_ref = reference.budget_levels(g, s, budget)
    assert rep == rep_ref
    assert rep["stored_bytes"] <= budget
    for p, (lv_ref, over_ref) in zip(plan, plan_ref):
        lv, over = p.levels, p.merged
        np.testing.assert_array_equal(lv, lv_ref)
        assert over.keys() == over_ref.keys()
        for t in over:
            np.testing.assert_array_equal(over[t][0], over_ref[t][0])
            np.testing.assert_array_equal(over[t][1], over_ref[t][1])


@pytest.mark.parametrize("seed,max_level", [(0, 6), (2, 7), (3, 7)])
def test_levels_that_start_no_greedy_are_resolved_where_the_certificate_asks(seed, max_level):
    """Large triangles over a fine texture: levels 6 and up are out (their classes alone exceed the
    budget), so the rows the certificate asks for are baked and held, and only the contents whose
    bound reaches a step's value per byte are resolved -- the plan still every level priced's."""
    g = [_geometry(seed, 40, 512, (1, 3), "linear")]
    budget = 6000
    s = OmmSettings(budget=budget, max_level=max_level)
    pricings = [omm_budget._Pricing(x, omm_budget._items(x, s), s, budget) for x in g]
    omm_budget._choose(pricings, budget)
    # level 6 is lazy (rows held there): some of its rows were never resolved, some were when asked
    assert any(6 in p.held and 6 in p.fine for p in pricings)
    plan, rep = omm_budget.budget_levels(g, s, budget)
    plan_ref, rep_ref = reference.budget_levels(g, s, budget)
    assert rep == rep_ref
    for p, (lv_ref, over_ref) in zip(plan, plan_ref):
        np.testing.assert_array_equal(p.levels, lv_ref)
        assert p.merged.keys() == over_ref.keys()


@pytest.mark.parametrize("seed,promotion", [(3, "nearest"), (4, "nearest"), (5, "hashed")])
def test_budgeted_bake_states_are_the_bakers_at_each_level(seed, promotion):
    """The build stores the pricing's own bake and resolve: each triangle's micromap must be what
    the baker and the resolve give that triangle alone at its level."""
    g = _geometry(seed, 80)
    budget = 3000
    s = OmmSettings(budget=budget, max_level=7, promotion=promotion, seed=seed)
    res = build([g], s)
    summary = res.summary
    assert summary["budget"]["stored_bytes"] <= budget
    assert summary["statistics"]["data_and_record_bytes"] == summary["budget"]["stored_bytes"]
    plan, _ = omm_budget.budget_levels([g], s, budget)
    levels, merged = plan[0].levels, plan[0].merged
    grid = g.test.grid()
    for t in range(len(g.tris_uv)):
        if t in merged:
            continue  # a merged micromap stores its cluster's meet (checked in test_budget_scene)
        s3, _ = bake_micromaps(grid, g.tris_uv[t:t + 1], int(levels[t]), GROW_TEXEL)
        got = np.asarray(res.triangle_states(t))  # OMM states: 2 and 3 are the two unknowns
        np.testing.assert_array_equal(np.minimum(got, 2), s3)
        hint = resolve(s3, np.array([0, len(s3)]), int(levels[t]), g.test, g.tris_uv[t:t + 1], s.format_code,
                       promotion, seed)
        np.testing.assert_array_equal(got, hint)
