"""The hierarchical micromaps (``succinctL``, ``csmL``): lossless, read by descent, and exactly the
bits docs/FORMAT.md ("Hierarchical micromaps") states.

Each codec is compared with an independent reference written here in plain Python: the pruned
tree found by a recursive descent over the unpruned tree (a node is uniform when its slice of the
micromap has one state), its bit sequences assembled field by field (succinct), and its distinct
subtrees counted by a canonical string of each (csm).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from conftest import SCENES, needs_scenes

from omaps import states
from omaps.codecs import (csm_bits, csm_build, csm_decode, csm_encode, csm_lookup, csm_pack, csm_treelets,
                          succinct_bits, succinct_decode, succinct_encode, succinct_encode_dag, succinct_encode_many,
                          succinct_lookup)
from omaps.errors import InputError
from omaps.schemes import get_scheme


# ---- the independent reference ---------------------------------------------------------------

def uniform(m, level, lv, p):
    """The state of node p at level lv when its micro-triangles all share it, else None."""
    n = 4 ** (level - lv)
    part = set(m[p * n:(p + 1) * n].tolist())
    return part.pop() if len(part) == 1 else None


def ref_state(m, level, k, lv=0, p=0):
    """Micro-triangle k's state by a recursive descent of the unpruned tree: stop at the first
    uniform node on k's path."""
    s = uniform(m, level, lv, p)
    if s is not None:
        return s
    return ref_state(m, level, k, lv + 1, 4 * p + ((k >> (2 * (level - 1 - lv))) & 3))


def ref_succinct_bits(m, level):
    """The succinct blob as a list of bits, built field by field in level order."""
    queue, t_bits, leaves = [(0, 0)], [], []
    for lv, p in queue:  # the queue grows while it is read: breadth first
        s = uniform(m, level, lv, p)
        if lv < level:
            t_bits.append(0 if s is not None else 1)
        if s is not None:
            leaves.append(s)
        else:
            queue += [(lv + 1, 4 * p + c) for c in range(4)]
    w = ((4 ** level - 1) // 3).bit_length()

    def field(v, n):
        return [(v >> b) & 1 for b in range(n)]

    out = field(len(t_bits), w) + t_bits
    for j in range(1, len(t_bits) // 64 + 1):
        out += field(sum(t_bits[:64 * j]), w)
    for s in leaves:
        out += field(s, 2)
    return out


def pack_bits(bits):
    out = bytearray((len(bits) + 7) // 8)
    for i, b in enumerate(bits):
        out[i >> 3] |= b << (i & 7)
    return bytes(out)


def canonical(m, level, lv, p):
    """A uniform subtree's state, or a mixed one's canonical string of its children."""
    s = uniform(m, level, lv, p)
    if s is not None:
        return str(s)
    return "(" + ",".join(canonical(m, level, lv + 1, 4 * p + c) for c in range(4)) + ")"


def mixed_subtrees(m, level, lv=0, p=0, out=None):
    """Canonical strings of every mixed subtree of a micromap."""
    out = set() if out is None else out
    key = canonical(m, level, lv, p)
    if key.startswith("("):
        out.add(key)
        for c in range(4):
            mixed_subtrees(m, level, lv + 1, 4 * p + c, out)
    return out


# ---- micromaps with structure: uniform regions at random levels, then a few single states ----

@st.composite
def micromaps(draw, max_level=5, count=1):
    level = draw(st.integers(0, max_level))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    out = []
    for _ in range(count):
        coarse = int(rng.integers(0, level + 1))
        m = np.repeat(rng.integers(0, 3, 4 ** coarse), 4 ** (level - coarse)).astype(np.uint8)
        flips = rng.integers(0, 4 ** level, int(rng.integers(0, 1 + 4 ** level // 4)))
        m[flips] = rng.integers(0, 3, len(flips))
        out.append(m)
    return level, np.stack(out)


@settings(max_examples=60)
@given(micromaps())
def test_succinct_lossless_and_exact_layout(case):
    level, maps = case
    m = maps[0]
    blob = succinct_encode(m, level)
    data = np.frombuffer(blob, np.uint8)
    bits = ref_succinct_bits(m, level)
    assert blob == pack_bits(bits)  # every field where docs/FORMAT.md puts it
    assert succinct_bits(m, level) == len(bits)
    np.testing.assert_array_equal(succinct_decode(blob, level), m)
    for k in range(4 ** level):
        assert succinct_lookup(data, 0, level, k) == m[k] == ref_state(m, level, k)


@settings(max_examples=40)
@given(micromaps(max_level=4, count=3))
def test_csm_lossless_and_merged(case):
    level, maps = case
    blob, n_nodes = csm_encode(maps, level)
    data = np.frombuffer(blob, np.uint8)
    assert len(blob) * 8 - 8 < csm_bits(n_nodes, len(maps)) <= len(blob) * 8
    distinct = set().union(*(mixed_subtrees(m, level) for m in maps))
    assert n_nodes == len(distinct)  # each distinct mixed subtree once, at whatever level
    np.testing.assert_array_equal(csm_decode(blob, level, len(maps)), maps)
    for t, m in enumerate(maps):
        for k in range(4 ** level):
            assert csm_lookup(data, level, t, k) == m[k] == ref_state(m, level, k)


def test_csm_layout_fields():
    """Header N, then 4 W-bit children per node, then a W-bit root per micromap."""
    a = np.zeros(16, np.uint8)
    a[9] = 2
    maps = np.stack([a, a, np.ones(16, np.uint8)])
    nodes, roots = csm_treelets(*csm_build(maps, 2))
    blob, n = csm_encode(maps, 2)
    w = (n + 2).bit_length()
    fields = list(nodes.ravel()) + list(roots)
    bits = [(n >> b) & 1 for b in range(32)] + [(int(v) >> b) & 1 for v in fields for b in range(w)]
    assert blob == pack_bits(bits)
    assert roots.tolist() == [3 + 1, 3 + 1, 1]  # equal micromaps share their root; a uniform one is its state
    assert nodes.tolist() == [[0, 2, 0, 0], [0, 0, 3, 0]]


@settings(max_examples=60)
@given(micromaps(max_level=5, count=3))
def test_succinct_from_the_dag_is_the_blob_of_the_states(case):
    """A tree read from the merged DAG (no states) writes the same bytes as the states do, for
    the DAG in build's order and in treelets."""
    level, maps = case
    data, starts, bits = succinct_encode_many(maps, level)
    nodes, roots = csm_build(maps, level)
    for n, r in ((nodes, roots), csm_treelets(nodes, roots)):
        d2, s2, b2 = succinct_encode_dag(n, r, level)
        assert d2.tobytes() == data.tobytes() and s2.tolist() == starts.tolist() and b2.tolist() == bits.tolist()
    for i, m in enumerate(maps):
        assert data[starts[i]:starts[i + 1]].tobytes() == pack_bits(ref_succinct_bits(m, level))


def test_succinct_from_a_dag_refuses_a_tree_deeper_than_its_level():
    nodes, roots = csm_build(np.array([[0, 1, 2, 0] * 4]), 2)
    with pytest.raises(InputError, match="deeper than level 1") as e:
        succinct_encode_dag(nodes, roots, 1)
    assert e.value.param == "roots"
    with pytest.raises(InputError, match="must hold references"):
        succinct_encode_dag(nodes, [3 + len(nodes)], 2)


def ref_children_first(nodes, roots):
    """The format's rule, read plainly: every reference names a state or an earlier node."""
    return all(r < 3 + i for i, row in enumerate(nodes.tolist()) for r in row) and all(r < 3 + len(nodes)
                                                                                      for r in roots.tolist())


@settings(max_examples=40)
@given(micromaps(max_level=5, count=3))
def test_csm_treelets_keep_every_map_and_the_format_rule(case):
    """The treelet layout renumbers the DAG: the same nodes (as sets of subtrees), children
    still first, every map decoded and looked up as before."""
    level, maps = case
    nodes, roots = csm_build(maps, level)
    tn, tr = csm_treelets(nodes, roots)
    assert len(tn) == len(nodes) and ref_children_first(tn, tr)
    blob = csm_pack(tn, tr)
    np.testing.assert_array_equal(csm_decode(blob, level, len(maps)), maps)
    data = np.frombuffer(blob, np.uint8)
    for t, m in enumerate(maps):
        for k in range(0, 4 ** level, 3):
            assert csm_lookup(data, level, t, k) == m[k]


def test_csm_treelet_holds_a_node_with_its_children():
    """One map whose every node is mixed and distinct (21 nodes at level 2 of 4 x 4 + 4 + 1):
    W = 5 bits, a line holds 512 // 20 = 25 nodes, so the whole tree is one treelet: the root
    last, its four children just before it, the sixteen grandchildren before them."""
    rng = np.random.default_rng(3)
    while True:
        m = rng.integers(0, 3, 64).astype(np.uint8)
        nodes, roots = csm_build(m[None], 3)
        if len(nodes) == 21:
            break
    tn, tr = csm_treelets(nodes, roots)
    assert tr.tolist() == [3 + 20]
    assert sorted(tn[20].tolist()) == [3 + 16, 3 + 17, 3 + 18, 3 + 19]
    assert sorted(r for i in range(16, 20) for r in tn[i].tolist()) == [3 + j for j in range(16)]


def test_csm_treelets_refuse_a_cycle_and_drop_unreached_nodes():
    with pytest.raises(InputError, match="cycle") as e:
        csm_treelets([[0, 1, 2, 4], [0, 1, 2, 3]], [3])
    assert e.value.param == "nodes"
    with pytest.raises(InputError, match="references"):
        csm_treelets([[0, 1, 2, 9]], [3])
    nodes, roots = csm_treelets([[0, 1, 2, 0], [0, 1, 1, 1]], [4])  # node 0 unreached
    assert nodes.tolist() == [[0, 1, 1, 1]] and roots.tolist() == [3]


def _lines_per_lookup(blob, level, lookups):
    from omaps.trace.memory import _walk_csm

    data = np.frombuffer(blob, np.uint8)
    out = np.empty(64, np.int64)
    total = 0
    for t, k in lookups:
        _, p, _ = _walk_csm(out, 0, t, k, data, level)
        total += len(set(out[:p].tolist()))
    return total / len(lookups)


@needs_scenes
def test_csm_treelets_read_fewer_lines():
    """A descent in the treelet layout touches fewer 64-byte lines than in build's bottom-up
    order: the memory model's walk over palm.glb's level-6 micromaps (3,768 triangles, about
    13,000 nodes), 5,000 lookups at random micro-triangles (about 4.2 lines a lookup bottom up,
    4.0 in treelets)."""
    from omaps.scene import load_scene
    from omaps.scene.alpha import alpha_triangles
    from omaps.trace.maps import micromap_states

    scene = load_scene(SCENES / "palm.glb")
    at = alpha_triangles(scene)
    maps, _ = micromap_states(at, {int(m): scene.alpha_test(int(m)) for m in np.unique(at.material)}, 6)
    nodes, roots = csm_build(maps, 6)
    rng = np.random.default_rng(0)
    lookups = list(zip(rng.integers(0, len(maps), 5000).tolist(), rng.integers(0, 4 ** 6, 5000).tolist()))
    plain = _lines_per_lookup(csm_pack(nodes, roots), 6, lookups)
    tree = _lines_per_lookup(csm_pack(*csm_treelets(nodes, roots)), 6, lookups)
    assert tree < 0.97 * plain, (tree, plain)


def test_rank_directory_crossed():
    """Level-6 maps of random states: n_T = 1365 T bits, 21 directory entries read on the way down."""
    rng = np.random.default_rng(5)
    maps = rng.integers(0, 3, (3, 4 ** 6)).astype(np.uint8)
    data, starts, bits = succinct_encode_many(maps, 6)
    for i, m in enumerate(maps):
        assert bits[i] == len(ref_succinct_bits(m, 6))
        for k in range(0, 4 ** 6, 7):
            assert succinct_lookup(data, 8 * starts[i], 6, k) == m[k]


def test_uniform_and_level_zero():
    for level in (0, 1, 3):
        for s in (states.T, states.O, states.C):
            m = np.full(4 ** level, s, np.uint8)
            assert succinct_bits(m, level) == ((4 ** level - 1) // 3).bit_length() + (1 if level else 0) + 2
            blob, n = csm_encode(m[None], level)
            assert n == 0 and csm_bits(0, 1) == 32 + 2
            assert csm_lookup(np.frombuffer(blob, np.uint8), level, 0, 0) == s


def test_schemes_share_the_grammar():
    for name, level, rep in (("tri4", 4, "raw"), ("succinct4", 4, "succinct"), ("csm12", 12, "csm")):
        s = get_scheme(name)
        assert (s.kind, s.level, s.representation) == ("micromap", level, rep)
    assert get_scheme("succinct5").bits_for(64, 64) is None and get_scheme("tri5").bits_for(64, 64) == 4096
    with pytest.raises(Exception, match="succinctL level"):
        get_scheme("succinct13")


@needs_scenes
def test_palm_level6_every_triangle():
    """Every distinct alpha triangle of palm.glb at level 6, through both codecs and the
    reference descent."""
    from omaps.scene import load_scene
    from omaps.scene.alpha import alpha_triangles
    from omaps.trace.maps import micromap_states

    scene = load_scene(SCENES / "palm.glb")
    at = alpha_triangles(scene)
    tests = {int(m): scene.alpha_test(int(m)) for m in np.unique(at.material)}
    maps, _ = micromap_states(at, tests, 6)
    data, starts, bits = succinct_encode_many(maps, 6)
    blob, n_nodes = csm_encode(maps, 6)
    cdata = np.frombuffer(blob, np.uint8)
    np.testing.assert_array_equal(csm_decode(blob, 6, len(maps)), maps)
    rng = np.random.default_rng(0)
    for i, m in enumerate(maps):
        np.testing.assert_array_equal(succinct_decode(data[starts[i]:starts[i + 1]], 6), m)
        ks = rng.integers(0, 4 ** 6, 64)
        for k in ks:
            assert succinct_lookup(data, 8 * starts[i], 6, k) == csm_lookup(cdata, 6, i, k) == m[k]
        if i % 16 == 0:
            assert bits[i] == len(ref_succinct_bits(m, 6))
            assert all(ref_state(m, 6, k) == m[k] for k in ks)
    assert bits.sum() < maps.size * 2 and csm_bits(n_nodes, len(maps)) < maps.size * 2


@needs_scenes
def test_palm_trace_equals_tri():
    """Traced through palm's crown, succinct5 and csm5 make exactly tri5's alpha tests, ray by
    ray, in fewer map bytes."""
    from omaps import trace
    from omaps.scene import load_scene
    from omaps.schemes import parse_schemes

    scene = load_scene(SCENES / "palm.glb")
    names = ["none", "tri5", "succinct5", "csm5"]
    prep = trace.prepare(scene, parse_schemes(names))
    w, h = 48, 32
    cam = trace.Camera(np.array([-70.0, 130.0, -70.0]), np.array([0.0, 175.0, 0.0]), 70.0).basis(w, h)
    light = np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3])
    runs = {n: trace.trace_scheme(prep, n, cam, w, h, light, 1e-3, deferred=True) for n in names}
    tri = runs["tri5"]
    assert tri.primary.tests.sum() < runs["none"].primary.tests.sum()
    for n in ("succinct5", "csm5"):
        np.testing.assert_array_equal(runs[n].primary.tests, tri.primary.tests)
        np.testing.assert_array_equal(runs[n].primary.candidates, tri.primary.candidates)
        np.testing.assert_array_equal(runs[n].shadow.tests, tri.shadow.tests)
        np.testing.assert_array_equal(runs[n].deferred.tests, tri.deferred.tests)
        assert prep.maps[n].map_bytes < prep.maps["tri5"].map_bytes
