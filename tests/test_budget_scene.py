"""A byte budget over a scene: the weights, the per-half known fractions, the tracer's mixed maps
read back against each chosen codec's own decoder, and the OMM budget's bytes and states."""

import json

import numpy as np
import pytest
from conftest import SCENES, needs_scenes
from gltf_files import QUAD_POS, write_quad_gltf
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps import states
from omaps.alpha_test import MaterialRules
from omaps.budget import PAIR_OPTIONS, half_known, pair_option_bytes, triangle_weights
from omaps.cli import main
from omaps.codecs import get_codec
from omaps.omm import budget as omm_budget
from omaps.pair import CORNERS
from omaps.scene import alpha_triangles, load_scene


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([1, 2, 4, 8]), st.data())
def test_half_known_against_sub_cell_counting(n, data):
    m = np.array(data.draw(st.lists(st.integers(0, 2), min_size=n * n, max_size=n * n)), np.uint8).reshape(1, n, n)
    k = 8  # sub-cells per cell side: centres on the diagonal count half to each triangle
    c = (np.arange(n * k) + 0.5) / (n * k)
    u, v = np.meshgrid(c, c)  # [row v, column u]
    cell = m[0][(v * n).astype(int), (u * n).astype(int)]
    known = cell != states.C
    wa = (v < u) + 0.5 * (v == u)
    expect = [(known * wa).sum() / wa.sum(), (known * (1 - wa)).sum() / (1 - wa).sum()]
    np.testing.assert_allclose(half_known(m)[0], expect, rtol=1e-12)


def test_pair_option_bytes_are_the_codecs_blocks():
    b = pair_option_bytes()
    assert b[0] == 0 and list(b[1:]) == [get_codec(o).block_bytes for o in PAIR_OPTIONS[1:]]
    assert dict(zip(PAIR_OPTIONS, b))["sq64"] == 64 * 64 // 4 and dict(zip(PAIR_OPTIONS, b))["vq4x64"] == 256


def test_triangle_weights_sum_world_area_over_instances(tmp_path):
    path = tmp_path / "two.gltf"
    alpha = np.zeros((8, 8), np.uint8)
    alpha[:, 4:] = 255
    write_quad_gltf(path, alpha, nodes=[{}, {"scale": [2.0, 3.0, 1.0], "translation": [5, 0, 0]}])
    scene = load_scene(str(path))
    at = alpha_triangles(scene, MaterialRules())
    w = triangle_weights(scene, at)
    quad_tri_area = 0.5 * float(np.prod(QUAD_POS.max(axis=0)[:2] - QUAD_POS.min(axis=0)[:2]))
    np.testing.assert_allclose(w, quad_tri_area * (1 + 2 * 3), rtol=1e-6)


@needs_scenes
@pytest.mark.long
def test_trace_budget_reads_each_pair_through_its_own_codec():
    from omaps.schemes import get_scheme
    from omaps.trace import prepare
    from omaps.trace.budget import budget_maps
    from omaps.codecs import format_names
    from omaps.trace.lookups import mixed_map_state
    from omaps.trace.tables import T_MAP_FORMAT, T_MAP_OFFSET, scheme_tables

    scene = load_scene(str(SCENES / "palm.glb"))
    prep = prepare(scene, [get_scheme("none")])
    at = prep.alpha
    budget = 48 * len(at.pair_first)  # between uniform vq2 and vq4: several options must be chosen
    sm = budget_maps(at, prep.tests, get_scheme(f"budget:{budget}", None, "fast"), triangle_weights(scene, at))
    assert sm.map_bytes <= budget and sum(sm.info["choices"].values()) == len(at.pair_first)
    assert len(sm.info["choices"]) >= 2
    table = scheme_tables(prep.base, sm).table
    fmt, off = sm.extra[T_MAP_FORMAT], sm.extra[T_MAP_OFFSET]
    rng = np.random.default_rng(3)
    decoded = {}
    for tri in rng.choice(at.count, 300, replace=False):
        b1, b2 = rng.random(2)
        if b1 + b2 > 1:
            b1, b2 = 1 - b1, 1 - b2
        row = sm.rows[tri]
        option = format_names()[fmt[row]]  # the format code is its codec's (the registry's)
        if option == "none":
            expect = states.C
        else:
            codec = get_codec(option)
            if row not in decoded:
                decoded[row] = codec.decode(sm.data[off[row]:off[row] + codec.block_bytes].tobytes())
            w = np.array([1 - b1 - b2, b1, b2])
            s, t = w @ CORNERS[at.corners[tri]].astype(float)  # the hit in its pair's square
            n = codec.map_size
            expect = decoded[row][min(int(t * n), n - 1), min(int(s * n), n - 1)]
        assert mixed_map_state(table, tri, b1, b2) == expect


@needs_scenes
@pytest.mark.long
def test_trace_budget_changes_no_pixel_and_stays_within_bytes(tmp_path):
    out = tmp_path / "t.json"
    pairs = 1920
    assert main(["trace", str(SCENES / "palm.glb"), "--schemes", f"none,vq4,budget:{64 * pairs},budget:0",
                 "--effort", "fast", "--size", "48", "--quiet", "--json", str(out),
                 "--plot-budget", str(tmp_path / "b.png")]) == 0
    r = json.loads(out.read_text())["schemes"]
    assert r["vq4"]["map_bytes"] == 64 * pairs
    b = r[f"budget:{64 * pairs}"]
    assert b["differing_pixels"] == 0 and 0 < b["map_bytes"] <= 64 * pairs
    assert sum(b["choices"].values()) == pairs
    zero = r["budget:0"]
    assert zero["map_bytes"] == 0 and zero["choices"] == {"none": pairs}
    assert zero["alpha_tests_per_primary_ray"] == r["none"]["alpha_tests_per_primary_ray"]
    assert (tmp_path / "b.png").stat().st_size > 0


def test_budget_scheme_names():
    from omaps.errors import InputError
    from omaps.schemes import get_scheme

    assert get_scheme("budget:1.5KiB").budget == 1536
    with pytest.raises(InputError):
        get_scheme("budget:lots")


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 6), st.integers(1, 4), st.integers(0, 400), st.integers(0, 2 ** 31))
def test_adopt_stays_within_the_bytes_it_stores(n_items, n_levels, budget, seed):
    rng = np.random.default_rng(seed)
    nbytes = np.sort(rng.integers(0, 90, (n_items, n_levels)), axis=1)
    nbytes[:, 0] = 0
    value = np.sort(rng.random((n_items, n_levels)), axis=1)
    ids = np.where(nbytes > 0, rng.integers(0, 3, (n_items, n_levels)), -1)
    # items sharing an id at a level store one micromap: make their bytes agree, as contents do
    for lvl in range(n_levels):
        for c in np.unique(ids[:, lvl][ids[:, lvl] >= 0]):
            nbytes[ids[:, lvl] == c, lvl] = nbytes[ids[:, lvl] == c, lvl].max()
    gid, gbytes = omm_budget._groups(nbytes, ids)
    level, stored, _ = omm_budget._adopt(value, gid, gbytes, budget)
    held = {(int(lvl), int(ids[i, lvl])): int(nbytes[i, lvl]) for i, lvl in enumerate(level) if nbytes[i, lvl] > 0}
    assert stored == sum(held.values()) <= budget
    # nothing free is left: every option whose micromap is already stored (or costs nothing) and
    # gains has been taken
    for i, lvl in enumerate(level):
        for up in range(lvl + 1, n_levels):
            if value[i, up] > value[i, lvl] and (nbytes[i, up] == 0 or (up, int(ids[i, up])) in held):
                pytest.fail(f"item {i} left a free gain at level {up}")


def test_omm_budget_texture_input(tmp_path):
    from PIL import Image

    _, alpha = _leaf()

    Image.fromarray(alpha).save(tmp_path / "leaf.png")
    rng = np.random.default_rng(5)
    centre = rng.random((40, 1, 2)) * 0.8 + 0.1
    uvs = centre + (rng.random((40, 3, 2)) - 0.5) * 0.25
    np.save(tmp_path / "uvs.npy", uvs)
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "l3"),
                 "--level", "3", "--quiet"]) == 0
    l3 = json.loads((tmp_path / "l3" / "omm.json").read_text())["statistics"]
    budget = l3["data_and_record_bytes"]
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "b"),
                 "--budget", str(budget), "--quiet"]) == 0
    summary = json.loads((tmp_path / "b" / "omm.json").read_text())
    st_b = summary["statistics"]
    assert st_b["data_and_record_bytes"] == summary["budget"]["stored_bytes"] <= budget
    assert st_b["known_area_fraction"] >= l3["known_area_fraction"]  # the uniform bake is one of its choices
    assert main(["omm", "--verify", str(tmp_path / "b")]) == 0  # re-bake, and known states against the test
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "x"),
                 "--budget", str(budget), "--level", "2"]) == 2


def _leaf():
    n = 64
    y, x = np.mgrid[0:n, 0:n] / n
    alpha = (((x - 0.5) / 0.42) ** 2 + ((y - 0.5) / 0.3) ** 2 < 1).astype(np.uint8) * 255
    alpha[(np.abs(y - 0.5) < 0.02)] = 0  # a vein cut through it
    return "leaf", alpha


@settings(max_examples=40, deadline=None)
@given(st.integers(4, 12), st.sampled_from([1, 2]), st.integers(0, 2 ** 31))
def test_merged_micromaps_are_meets_of_their_members(n_rows, level, seed):
    rng = np.random.default_rng(seed)
    n = 4 ** level
    base = rng.integers(0, 3, (3, n)).astype(np.uint8)  # a few patterns, members perturbed: clusters to find
    rows3 = base[rng.integers(0, 3, n_rows)]
    flip = rng.random(rows3.shape) < 0.2
    rows3 = np.where(flip, rng.integers(0, 3, rows3.shape), rows3).astype(np.uint8)
    nbytes = np.where(rng.random(n_rows) < 0.9, 20, 0)
    hits = rng.integers(0, n_rows, 30)
    cells = rng.integers(0, n, 30)
    for label, meets in omm_budget._merged(rows3, rows3, nbytes, rng.random(n_rows), hits, cells, level):
        assert (label[nbytes == 0] == -1).all() and (label[nbytes > 0] >= 0).all()
        assert len(np.unique(label[label >= 0])) == len(meets) < len(np.unique(rows3[nbytes > 0], axis=0))
        for c, m in enumerate(meets):
            members = rows3[label == c]
            agree = (members == members[0]).all(axis=0)
            # the meet: a member's state where every member agrees, unknown elsewhere -- never another state
            np.testing.assert_array_equal(m, np.where(agree, members[0], states.C))


def test_omm_budget_no_special_below_one_micromap_is_an_input_error(tmp_path):
    from PIL import Image

    _, alpha = _leaf()
    Image.fromarray(alpha).save(tmp_path / "leaf.png")
    uvs = np.array([[[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]], [[0.2, 0.2], [0.8, 0.3], [0.3, 0.7]]])
    np.save(tmp_path / "uvs.npy", uvs)
    out = tmp_path / "o8"  # below one level-0 micromap (1 byte) and its record (8): it cannot be priced as free
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(out),
                 "--budget", "8", "--no-special", "--quiet"]) == 2
    assert not out.exists()
    for budget in (9, 40):  # the two level-0 micromaps are both all unknown: one stored, shared
        assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / f"{budget}"),
                     "--budget", str(budget), "--no-special", "--quiet"]) == 0
        st_ok = json.loads((tmp_path / f"{budget}" / "omm.json").read_text())["statistics"]
        assert 9 <= st_ok["data_and_record_bytes"] <= budget and st_ok["special_indices"] == {k: 0 for k in st_ok["special_indices"]}


def _recount(summary_dir):
    """Bytes of the micromaps an OMM folder stores, from its records alone."""
    from omaps.omm import files
    from omaps import omm_format

    res = files.read(str(summary_dir))
    return sum(omm_format.micromap_bytes(int(r["level"]), int(r["format"])) + omm_format.TRIANGLE_RECORD.itemsize
               for r in res.triangles), res


def test_omm_budget_merges_within_the_bytes_and_stays_exact(tmp_path):
    from PIL import Image

    from omaps.coverage import micro_fractions

    _, alpha = _leaf()
    Image.fromarray(alpha).save(tmp_path / "leaf.png")
    rng = np.random.default_rng(11)
    centre = rng.random((120, 1, 2)) * 0.6 + 0.2
    uvs = centre + (rng.random((120, 3, 2)) - 0.5) * 0.3
    np.save(tmp_path / "uvs.npy", uvs)
    budget = 200  # far below a level-3 bake of 120 triangles: merging must serve
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "b"),
                 "--budget", str(budget), "--max-level", "4", "--quiet"]) == 0
    summary = json.loads((tmp_path / "b" / "omm.json").read_text())
    recount, res = _recount(tmp_path / "b")
    assert recount == summary["statistics"]["data_and_record_bytes"] == summary["budget"]["stored_bytes"] <= budget
    assert summary["budget"]["merged_items"] > 0 and summary["budget"]["weights"] == "area"
    # every known micro-triangle against the alpha test's own coverage (no baker involved)
    idx = res.index
    levels = np.where(idx >= 0, res.triangles["level"][np.maximum(idx, 0)], 0).astype(np.int64)
    from omaps.alpha_test import StateRule
    from omaps.texture import load_alpha

    test = StateRule("cutoff").alpha_test(load_alpha(str(tmp_path / "leaf.png")), "linear", "wrap")
    frac = micro_fractions(test, uvs, levels)
    st_all = np.concatenate([np.broadcast_to(res.triangle_states(t), (4 ** levels[t],)) for t in range(len(uvs))])
    assert not np.any((st_all == 1) & (frac < 1.0)) and not np.any((st_all == 0) & (frac > 0.0))
    assert main(["omm", "--verify", str(tmp_path / "b")]) == 0


@needs_scenes
@pytest.mark.long
def test_omm_budget_view_weights_on_palm(tmp_path):
    out = tmp_path / "palm.glb"
    assert main(["omm", str(SCENES / "palm.glb"), "-o", str(out), "--budget", "3000", "--max-level", "4",
                 "--weights", "view", "--size", "64", "--quiet"]) == 0
    from omaps.omm import gltf_io

    res = gltf_io.read_gltf(str(out))
    b = res.summary["budget"]
    assert b["weights"] == "view" and b["hits"] > 0 and b["size"] == [64, 64]
    assert len(res.data) + res.triangles.nbytes == b["stored_bytes"] <= 3000
    assert main(["omm", "--verify", str(out)]) == 0
    tr = tmp_path / "t.json"
    assert main(["trace", str(out), "--schemes", "omm", "--size", "48", "--quiet", "--json", str(tr)]) == 0
    assert json.loads(tr.read_text())["schemes"]["omm"]["differing_pixels"] == 0
    assert main(["omm", str(SCENES / "palm.glb"), "-o", str(tmp_path / "x.glb"), "--weights", "view",
                 "--quiet"]) == 2  # view weights without a budget


def test_trace_budget_reuses_the_runs_flags_and_blocks(tmp_path):
    from omaps.schemes import parse_schemes
    from omaps.trace import prepare
    from omaps.trace.budget import budget_maps

    rng = np.random.default_rng(2)
    alpha = (rng.random((32, 32)) < 0.5).astype(np.uint8) * 255
    alpha[:, :12] = 255
    scene = load_scene(str(write_quad_gltf(tmp_path / "q.gltf", alpha, nodes=[{}, {"translation": [3, 0, 0]}])))
    schemes = parse_schemes("none,vq2,vq4,budget:100")
    prep = prepare(scene, schemes)
    assert any(k[0] == "encode" and k[1] == "vq4" for k in prep.cache) and ("pair_flags", 64) in prep.cache
    w = triangle_weights(scene, prep.alpha)
    b = schemes[-1]
    shared = budget_maps(prep.alpha, prep.tests, b, w, cache=prep.cache)
    alone = budget_maps(prep.alpha, prep.tests, b, w)
    assert np.array_equal(shared.data, alone.data) and np.array_equal(shared.rows, alone.rows)
    assert shared.info == alone.info and shared.map_bytes <= 100
    assert not prepare(scene, parse_schemes("none,vq4")).cache  # nothing kept without a budget to use it
