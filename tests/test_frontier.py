"""The Pareto front (omaps.frontier), the frontier charts of trace and eval, and the frontier page."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from omaps.frontier import front_mask, gaps

DOCS = Path(__file__).resolve().parents[1] / "docs"


def brute_front(cost, value, larger):
    out = []
    for i in range(len(cost)):
        beaten = False
        for j in range(len(cost)):
            better = value[j] > value[i] if larger else value[j] < value[i]
            no_worse = value[j] >= value[i] if larger else value[j] <= value[i]
            if cost[j] <= cost[i] and no_worse and (cost[j] < cost[i] or better):
                beaten = True
        out.append(not beaten)
    return out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6)), min_size=1, max_size=12), st.booleans())
def test_front_mask_is_the_non_dominated_points(pts, larger):
    cost, value = [p[0] for p in pts], [p[1] for p in pts]
    mask = front_mask(cost, value, larger)
    assert mask.tolist() == brute_front(cost, value, larger)
    assert mask.any()  # the cheapest best point is never dominated
    # along the front, more cost buys a strictly better value
    f = sorted({(c, v) for c, v, m in zip(cost, value, mask) if m})
    for (c0, v0), (c1, v1) in zip(f, f[1:]):
        assert c1 > c0 and ((v1 > v0) if larger else (v1 < v0))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.one_of(st.none(), st.integers(0, 6))), min_size=1, max_size=10))
def test_gaps_are_each_cost_over_the_least_cost_with_no_more_tests(pts):
    tests, cost = [p[0] for p in pts], [p[1] for p in pts]
    got = gaps(tests, cost)
    for i, (t, c) in enumerate(pts):
        refs = [d for u, d in pts if u <= t and d is not None]
        if c is None or (min(refs) == 0 and c != 0):
            assert got[i] is None
        else:
            assert got[i] == (1.0 if c == min(refs) else c / min(refs)) and got[i] >= 1
    # a point on the front of cost against tests has gap 1
    known = [(t, c) for t, c in pts if c is not None]
    mask = front_mask([c for _, c in known], [t for t, _ in known]) if known else []
    assert all(g == 1.0 for g, m in zip([g for g, (_, c) in zip(got, pts) if c is not None], mask) if m)


def _report(memory: bool) -> dict:
    schemes = {"none": {"alpha_tests_per_primary_ray": 1.0, "map_bytes": 0}}
    settings_ = {"none": {"kind": "none"}}
    for k, (n, b, t) in enumerate([("tri4", 240_000, 0.26), ("csm4", 9_000, 0.26), ("vq4", 120_000, 0.25),
                                   ("vq4x64", 480_000, 0.17), ("sq16", 120_000, 0.29)]):
        r = {"alpha_tests_per_primary_ray": t, "map_bytes": b}
        if memory:
            r["memory"] = {"own": {"map_bytes": b, "map_lines_per_ray": 0.3 + 0.1 * k},
                           "shared": {"map_bytes": b // (2 if n != "csm4" else 1), "map_lines_per_ray": 0.5 + 0.1 * k}}
        schemes[n] = r
        settings_[n] = {"kind": "micromap", "level": 4} if n.startswith(("tri", "csm")) else {"kind": "square",
                                                                                                "codec": n}
    settings_["csm4"]["representation"] = "csm"
    return {"schemes": schemes, "settings": {"schemes": settings_}, "camera": {"width": 64, "height": 64},
            "scene": {"file": "palm.glb"}}


@pytest.mark.parametrize("memory", [False, True])
def test_frontier_plot(tmp_path, memory):
    from omaps.trace.pictures import _frontier_points, frontier_plot

    rep = _report(memory)
    frontier_plot(str(tmp_path / "f.png"), rep)
    w = Image.open(tmp_path / "f.png").size[0]
    assert (w > 1200) == memory  # a second panel (lines per ray) only when memory was measured
    labels = [p[1] for p in _frontier_points(rep)]
    assert ("tri4 OMM" in labels) == memory and ("vq4 shared" in labels) == memory
    assert "csm4 shared" not in labels  # the same bytes: one point


def _with_texture(rep: dict, none_lines: float) -> dict:
    """``_report(True)`` with texture lines: each scheme's alpha tests read lines in proportion
    to them, ``none``'s ``none_lines``."""
    rep["schemes"]["none"]["memory"] = {"texture_lines_per_ray": none_lines,
                                        **{lay: {"map_bytes": 0, "map_lines_per_ray": 0.0,
                                                 "total_lines_per_ray": none_lines} for lay in ("own", "shared")}}
    for n, r in rep["schemes"].items():
        if n == "none":
            continue
        tex = none_lines * r["alpha_tests_per_primary_ray"]
        r["memory"]["texture_lines_per_ray"] = tex
        for lay in ("own", "shared"):
            r["memory"][lay]["total_lines_per_ray"] = r["memory"][lay]["map_lines_per_ray"] + tex
            r["memory"][lay]["map_reads_per_lookup"] = 1.0
    return rep


def test_frontier_plot_with_texture_lines(tmp_path):
    from omaps.trace.pictures import _total_points, frontier_plot

    rep = _with_texture(_report(True), 1.2)
    frontier_plot(str(tmp_path / "f.png"), rep)
    assert Image.open(tmp_path / "f.png").size[0] > 1900  # three panels
    pts = {p[1]: p for p in _total_points(rep)}
    assert pts["none"][2] == 1.2 and pts["none"][0] == "none"
    assert pts["vq4 shared"][2] == pytest.approx(0.5 + 0.1 * 2 + 1.2 * 0.25)
    assert "csm4 shared" not in pts


@pytest.mark.parametrize("none_lines", [0.3, 3.0])
def test_frontier_page_traffic_paragraph(none_lines):
    """The page's paragraph on map + texture traffic says what the numbers say: whether any map
    reads less in all than ``none``, and which point reads least."""
    mod = _frontier_module()
    rep = _with_texture(_report(True), none_lines)
    tr = mod.traffic(rep)
    totals = {p[1]: p[7] for p in mod._points(rep)}
    best = min(totals, key=totals.get)
    assert tr["ranked"][0][1] == best
    assert [p[1] for p in tr["below"]] == sorted((n for n in totals if totals[n] < none_lines), key=totals.get)
    text = mod.traffic_text("palm", tr)
    if none_lines == 0.3:  # every map's lines exceed the texture lines it saves
        assert not tr["below"] and "no map lowers the total" in text and tr["front"][0][1] == "none"
    else:
        assert tr["below"] and "no map lowers" not in text and f"the least is {best}" in text
    assert all(f"{p[7]:.3f}" in text for p in tr["families"].values())
    # the front of tests against totals, none among the points: nothing dominates a point on it
    pts = [("none", none_lines, 1.0)] + [(p[1], p[7], p[3]) for p in tr["ranked"]]
    for name, x, y in [(p[1], p[7], p[3]) for p in tr["front"]]:
        assert not any(u <= x and t <= y and (u < x or t < y) for _, u, t in pts), name
    plain = _report(True)
    for n, r in plain["schemes"].items():
        for lay in r.get("memory", {}).values():
            lay["map_reads_per_lookup"] = 1.0
    assert mod.traffic(plain) is None  # a run without texture lines: no section


def test_eval_plot_marks_the_front(tmp_path):
    from omaps.corpus import report

    from omaps.corpus.evaluate import TextureResult

    results = [TextureResult("t", 64, 64, {"sq16": 0.4, "vq4": 0.5, "tri3": 0.3},
                             {"sq16": 512, "vq4": 512, "tri3": 256})]
    report.plot_savings(tmp_path / "p.png", results, ["sq16", "vq4", "tri3"])
    assert Image.open(tmp_path / "p.png").size[0] > 500


def _frontier_module():
    spec = importlib.util.spec_from_file_location("docs_frontier", DOCS / "scripts" / "frontier.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.skipif(not (DOCS / "scripts" / "frontier.json").is_file(), reason="no frontier run committed")
def test_frontier_page_is_rendered():
    """docs/frontier.md is what docs/scripts/frontier.py renders from its run's reports, every
    scheme passed, and the hierarchical micromaps give their triL's alpha tests exactly."""
    mod = _frontier_module()
    data = json.loads((DOCS / "scripts" / "frontier.json").read_text(encoding="utf-8"))
    assert (DOCS / "frontier.md").read_text(encoding="utf-8") == mod.render(data), \
        "docs/frontier.md is stale: run python docs/scripts/frontier.py --render-only"
    for scene, d in data["scenes"].items():
        rep = d["report"]
        assert rep["passed"], scene
        sch = rep["schemes"]
        for lv in (4, 6, 8):
            if f"tri{lv}" in sch:
                t = sch[f"tri{lv}"]["alpha_tests_per_primary_ray"]
                assert sch[f"succinct{lv}"]["alpha_tests_per_primary_ray"] == t
                assert sch[f"csm{lv}"]["alpha_tests_per_primary_ray"] == t
                assert sch[f"csm{lv}"]["map_bytes"] < sch[f"tri{lv}"]["map_bytes"]
        assert (DOCS / "img" / f"frontier_{scene}.png").is_file()


def test_the_scripts_scheme_set_for_any_scene():
    """``frontier.py --scene S --level L``: every representation at levels 4, 6, ... up to L
    (and L itself), every scheme a valid one, the page's blocks and squares included."""
    from omaps.schemes import parse_schemes

    mod = _frontier_module()
    for level in (4, 7, 8):
        names = mod.scheme_set(level).split(",")
        parsed = parse_schemes(names)
        assert [s.name for s in parsed] == names
        levels = sorted({*range(4, level + 1, 2), level})
        for k in ("tri", "succinct", "csm"):
            assert [n for n in names if n.startswith(k)] == [f"{k}{lv}" for lv in levels]
        assert {"vq4", "vq4x64", "sq16"} <= set(names)
