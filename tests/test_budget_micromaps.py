"""Succinct micromaps as byte-budget options: a pair's option ``succinctL`` costs the bytes of its
two triangles' own trees (different from pair to pair) and keeps the level-L micromaps exactly.

The references are independent of the budget code: each triangle's micromap baked on its own and
encoded with the codec's public ``succinct_encode`` (the bytes), decoded with ``succinct_decode``
(the block stored for the pair), and the bird curve's micro-triangle of a hit (the tracer's read).
"""

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from gltf_files import write_quad_gltf
from omaps import birdcurve, states
from omaps.budget import PAIR_OPTIONS, triangle_weights
from omaps.cli import main
from omaps.codecs import budget_options, codec_names, entry, format_names, get_codec, succinct_decode, succinct_encode
from omaps.errors import InputError
from omaps.schemes import get_scheme

GRID = 4  # quads per side: 16 pairs, each over its own part of the texture


def write_grid(path):
    """A GRID x GRID grid of unit quads, quad (i, j) textured with cell (i, j) of a 64 x 64 alpha
    image of blobs of different sizes: pairs with different maps, some uniform."""
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:64, 0:64]
    alpha = np.zeros((64, 64), np.uint8)
    for _ in range(14):
        cx, cy, r = rng.uniform(0, 64), rng.uniform(0, 64), rng.uniform(2, 9)
        alpha[(x - cx) ** 2 + (y - cy) ** 2 < r * r] = 255
    alpha[:16, :16] = 255  # one cell fully opaque
    pos, uv, idx = [], [], []
    for j in range(GRID):
        for i in range(GRID):
            base = len(pos)
            pos += [[i, j, 0], [i + 1, j, 0], [i + 1, j + 1, 0], [i, j + 1, 0]]
            u0, u1, v0, v1 = i / GRID, (i + 1) / GRID, j / GRID, (j + 1) / GRID
            uv += [[u0, v1], [u1, v1], [u1, v0], [u0, v0]]
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return write_quad_gltf(path, alpha, positions=np.array(pos, np.float32), uvs=np.array(uv, np.float32),
                           indices=np.array(idx, np.uint16))


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    from omaps.scene import load_scene
    from omaps.trace import prepare

    path = write_grid(tmp_path_factory.mktemp("grid") / "grid.gltf")
    scene = load_scene(path)
    prep = prepare(scene, [get_scheme("none")])
    return path, scene, prep


def baked(prep, level):
    """Each alpha triangle's level-L micromap, baked triangle by triangle (no distinct rows)."""
    from omaps.bake import GROW_TEXEL, bake_micromaps

    at = prep.alpha
    out = np.empty((at.count, 4 ** level), np.uint8)
    for t in range(at.count):
        s, _ = bake_micromaps(prep.tests[int(at.material[t])].grid(), at.uv[t:t + 1], level, GROW_TEXEL)
        out[t] = s.reshape(-1)
    out[at.unknown] = states.C
    return out


def test_registry_declares_succinct_options_of_variable_bytes():
    assert "succinct6" in budget_options(variable=True) and "succinct6" not in budget_options()
    assert PAIR_OPTIONS == ("none",) + budget_options()  # the default options: fixed bytes
    e = entry("succinct6")
    assert e.variable and e.budget and e.level == 6 and e.block_bytes == 0
    assert not any(n.startswith("succinct") for n in codec_names())  # not a square codec
    assert not any(o.startswith("csm") for o in budget_options(variable=True))  # shared across the scene
    with pytest.raises(InputError, match="not a square map"):
        get_codec("succinct6")
    codes = [entry(o).code for o in budget_options(variable=True)]
    assert len(set(codes)) == len(codes) and all(format_names()[entry(o).code] == o for o in budget_options(True))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 5), st.integers(1, 4), st.integers(0, 2 ** 32 - 1))
def test_pair_blocks_read_each_triangle(level, n_pairs, seed):
    """A pair's block is its first triangle's blob then its second's (when it has one), each as
    ``succinct_encode`` writes it alone; the pair lookup reads either triangle's states."""
    rng = np.random.default_rng(seed)
    coarse = rng.integers(0, level + 1, (2, n_pairs))
    maps = [[np.repeat(rng.integers(0, 3, 4 ** int(c)), 4 ** (level - int(c))).astype(np.uint8) for c in row]
            for row in coarse]
    first, second = np.stack(maps[0]), np.stack(maps[1])
    has = rng.random(n_pairs) < 0.7
    data, starts = entry(f"succinct{level}").make().encode_pairs(first, second, has)
    lookup = entry(f"succinct{level}").lookup()
    for p in range(n_pairs):
        blobs = [succinct_encode(first[p], level)] + ([succinct_encode(second[p], level)] if has[p] else [])
        block = data[starts[p]:starts[p + 1]]
        assert block.tobytes() == b"".join(blobs)
        for k in range(4 ** level):
            assert lookup(block, level, False, k) == first[p, k]
            if has[p]:
                assert lookup(block, level, True, k) == second[p, k]


def test_budget_scheme_names_its_options():
    s = get_scheme("budget:2KiB:vq4+succinct3+vq4")
    assert s.name == "budget:2048:vq4+succinct3+vq4" and s.options == ("none", "vq4", "succinct3")
    assert get_scheme("budget:2KiB:default+succinct2").options == PAIR_OPTIONS + ("succinct2",)
    assert get_scheme("budget:2KiB").options is None
    with pytest.raises(InputError, match="csmL shares subtrees"):
        get_scheme("budget:2KiB:csm4")
    for bad in ("budget:2KiB:succinct13", "budget:2KiB:tri4", "budget:2KiB:vq4-synth"):
        with pytest.raises(InputError, match="unknown budget option"):
            get_scheme(bad)


@pytest.mark.parametrize("budget", [0, 40, 150, 400, 900, 4000])
def test_budget_with_succinct_options_stays_within_its_exact_bytes(grid, budget):
    """Every pair's bytes recomputed from its own triangles' trees (or its codec's block), summed:
    the scheme's map bytes, within the budget; each pair's stored block decodes to its
    triangles' micromaps and the tracer reads them at the hit's micro-triangle."""
    from omaps.trace.budget import budget_maps
    from omaps.trace.lookups import mixed_map_state
    from omaps.trace.tables import T_MAP_FORMAT, T_MAP_OFFSET, scheme_tables

    _, scene, prep = grid
    at = prep.alpha
    scheme = get_scheme(f"budget:{budget}:sq4+vq2+succinct1+succinct3+succinct5", None, "fast")
    sm = budget_maps(at, prep.tests, scheme, triangle_weights(scene, at))
    fmt, off = sm.extra[T_MAP_FORMAT], sm.extra[T_MAP_OFFSET]
    table = scheme_tables(prep.base, sm).table
    maps = {lv: baked(prep, lv) for lv in (1, 3, 5)}
    rng = np.random.default_rng(budget)
    total = 0
    chosen = set()
    for p in range(len(at.pair_first)):
        tris = [int(at.pair_first[p])] + ([int(at.pair_second[p])] if at.pair_second[p] >= 0 else [])
        row = sm.rows[tris[0]]
        option = format_names()[fmt[row]]
        chosen.add(option)
        if option == "none":
            continue
        if not option.startswith("succinct"):
            total += get_codec(option).block_bytes
            continue
        level = int(option[len("succinct"):])
        blobs = [succinct_encode(maps[level][t], level) for t in tris]
        total += sum(len(b) for b in blobs)
        start = off[row]
        for t, blob in zip(tris, blobs):  # the first triangle's tree, then the second's from the next byte
            stored = sm.data[start:start + len(blob)]
            np.testing.assert_array_equal(succinct_decode(stored, level), maps[level][t])
            start += len(blob)
            for _ in range(12):
                b1, b2 = rng.random(2)
                if b1 + b2 > 1:
                    b1, b2 = 1 - b1, 1 - b2
                k = birdcurve.bary_to_index(b1, b2, level)
                assert mixed_map_state(table, t, b1, b2) == maps[level][t][k]
    assert total == sm.map_bytes <= budget
    assert sum(sm.info["choices"].values()) == len(at.pair_first)
    if budget == 0:
        assert chosen == {"none"}
    if budget >= 400:
        assert any(o.startswith("succinct") for o in chosen)


def test_succinct_options_pay_for_themselves(grid):
    """With the succinct options the budget saves at least what the square options alone save
    (its options include theirs), and a lossless option is valued at the micromap's known share."""
    from omaps.trace.budget import budget_maps

    _, scene, prep = grid
    at = prep.alpha
    w = triangle_weights(scene, at)
    for budget in (100, 300, 1000):
        plain = budget_maps(at, prep.tests, get_scheme(f"budget:{budget}:sq4+vq2", None, "fast"), w)
        more = budget_maps(at, prep.tests, get_scheme(f"budget:{budget}:sq4+vq2+succinct3+succinct4", None, "fast"), w)
        # the greedy is within one step of the optimum: allow the largest single pair's value
        slack = float(w[at.pair_first].max() + w[np.maximum(at.pair_second, 0)].max()) / float(w.sum())
        assert more.info["expected_tests_saved_fraction"] >= plain.info["expected_tests_saved_fraction"] - slack


def test_trace_budget_with_succinct_options_changes_no_pixel(grid, tmp_path):
    path, _, prep = grid
    out = tmp_path / "t.json"
    name = "budget:600:default+succinct2+succinct4"
    assert main(["trace", str(path), "--schemes", f"none,succinct4,{name}", "--size", "40", "--effort", "fast",
                 "--quiet", "--json", str(out)]) == 0
    r = json.loads(out.read_text())["schemes"]
    b = r["budget:600:default+succinct2+succinct4"]
    assert b["differing_pixels"] == 0 and r["succinct4"]["differing_pixels"] == 0
    assert 0 < b["map_bytes"] <= 600 and sum(b["choices"].values()) == len(prep.alpha.pair_first)
    assert b["alpha_tests_per_primary_ray"] < r["none"]["alpha_tests_per_primary_ray"]
