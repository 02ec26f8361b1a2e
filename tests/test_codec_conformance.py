"""What every square codec of the registry must do, built-in or plug-in (docs: "Adding a codec").

Parametrized over ``omaps.codecs.ENTRIES`` (every codec of fixed block bytes; an installed
plug-in's codecs too), the test IDs the codecs' names (``-k rle16`` selects one codec):

* conservative round trip: structured maps (discs with a C rim, stripes, random states, uniform
  maps) of the codec's size, encoded with each of its encoders and efforts, decode to the map
  or to C at every cell (never C -> known, never T <-> O), checked cell by cell here, apart
  from ``Codec.encode_many``'s own check; ``decode``, ``decode_many`` and the random-access
  ``lookup`` agree on the blocks;
* total decoding: any ``block_bytes`` bytes decode to an N x N map of states 0..2 (a raw
  ``sqN`` block holding the unused code 3 is an ``InputError`` saying so), and the lookup gives
  the decoded state at every cell (a sample of a large map's);
* the tracer's dispatch: ``block_state(code, data, s, t)`` on a view of ``MAX_BLOCK_BYTES``
  bytes starting at the block (other bytes after it), as the tracer's any-hit filter calls it,
  equals the lookup at the cell ``uv_to_cell(s, t, N)`` for points all over the square, the
  cell edges and the square's edges included.

Hypothesis is derandomized with no example database (the same examples every run)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numba import njit

from omaps.codecs import ENTRIES, MAX_BLOCK_BYTES, block_state, get_codec
from omaps.codecs.bits import kernel_bytes
from omaps.errors import InputError
from omaps.pair import uv_to_cell

T, O, C = 0, 1, 2
NAMES = [e.name for e in ENTRIES if not e.variable]
KINDS = ("disc", "stripes", "random", "uniform", "checker")


def conformance(n: int):
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=list(HealthCheck))


def make_map(n: int, kind: str, seed: int) -> np.ndarray:
    """An n x n map of states of a kind: a disc (O inside, T outside, a C rim, as a baked map of a
    round leaf), stripes of random states, cells of random states, one state, or a checkerboard
    of T and O (the hardest for a lossy codec); some C cells sprinkled over a few."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:n, :n] + 0.5
    if kind == "disc":
        cx, cy = rng.uniform(-0.2, 1.2, 2) * n
        r = rng.uniform(0.05, 0.9) * n
        rim = rng.uniform(0, 0.15) * n + 0.5
        d = np.hypot(x - cx, y - cy) - r
        m = np.where(d < -rim, O, np.where(d > rim, T, C))
        if rng.random() < 0.5:
            m = np.where(m == C, C, 1 - m)  # T inside, O outside
    elif kind == "stripes":
        period = int(rng.integers(1, max(2, n) + 1))
        coord = x if rng.random() < 0.5 else (x + y if rng.random() < 0.5 else y)
        m = rng.integers(0, 3, size=2 * n + 2)[(coord // period).astype(int)]
    elif kind == "random":
        p = rng.dirichlet(np.ones(3))
        m = rng.choice(3, size=(n, n), p=p)
    elif kind == "uniform":
        m = np.full((n, n), rng.integers(0, 3))
    else:
        size = int(rng.integers(1, max(2, n // 2) + 1))
        m = ((x // size + y // size) % 2).astype(int)
    if rng.random() < 0.3:
        m = np.where(rng.random((n, n)) < rng.uniform(0, 0.2), C, m)
    return m.astype(np.uint8)


def sample_cells(n: int, limit: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """(xs, ys): every cell of an n x n map, or for a large one the edges and a spread sample."""
    ys, xs = np.divmod(np.arange(n * n), n)
    if n * n <= limit:
        return xs, ys
    edge = (xs == 0) | (ys == 0) | (xs == n - 1) | (ys == n - 1)
    keep = edge | (np.arange(n * n) % (n * n // limit + 1) == 0)
    return xs[keep], ys[keep]


def lookups(codec, block: np.ndarray, xs, ys) -> np.ndarray:
    arr = kernel_bytes(block)
    return np.array([codec.lookup(arr, int(x), int(y)) for x, y in zip(xs, ys)], dtype=np.int64)


def _variants(codec) -> list[tuple[str | None, str | None]]:
    """(encoder, effort) choices to encode with: the defaults, then each encoder and effort."""
    out = [(None, None)] + [(e, None) for e in codec.encoders] + [(None, f) for f in codec.efforts]
    return list(dict.fromkeys(out))


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
@conformance(30)
@given(kinds=st.lists(st.sampled_from(KINDS), min_size=1, max_size=3), seed=st.integers(0, 2**32 - 1),
       choice=st.integers(0, 99))
def test_round_trip_is_conservative(name, kinds, seed, choice):
    codec = get_codec(name)
    n = codec.map_size
    maps = np.stack([make_map(n, k, seed + i) for i, k in enumerate(kinds)])
    variants = _variants(codec)
    encoder, effort = variants[choice % len(variants)]
    blocks, decoded = codec.encode_many(maps, encoder, effort)
    assert blocks.dtype == np.uint8 and blocks.shape == (len(maps), codec.block_bytes)
    assert decoded.shape == maps.shape and decoded.max() <= C
    # cell by cell: the map's state, or C where the codec gave up knowing it
    same = decoded == maps
    widened = (decoded == C) & (maps != C)
    assert (same | widened).all(), f"{name}: a cell turned from C to known, or between T and O"
    assert np.array_equal(codec.decode_many(blocks), decoded)
    xs, ys = sample_cells(n, 256)
    for b, d in zip(blocks, decoded):
        assert np.array_equal(codec.decode(b.tobytes()), d)
        assert np.array_equal(lookups(codec, b, xs, ys), d[ys, xs])
    if codec.raw:
        assert np.array_equal(decoded, maps)  # a raw map is the map


def _sane_raw(block: np.ndarray) -> np.ndarray:
    """A raw block with every 2-bit code 3 (unused) turned into 2 (C)."""
    b = block.astype(np.uint8)
    threes = b & (b >> 1) & 0x55  # the low bit of each field holding 3
    return (b & ~threes).astype(np.uint8)


def _blocks(nbytes: int):
    return (st.binary(min_size=nbytes, max_size=nbytes)
            | st.sampled_from((b"\xff" * nbytes, b"\x00" * nbytes, b"\xaa" * nbytes, b"\x55" * nbytes)))


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
@conformance(40)
@given(data=st.data())
def test_any_block_decodes_and_lookup_agrees(name, data):
    codec = get_codec(name)
    n = codec.map_size
    block = np.frombuffer(data.draw(_blocks(codec.block_bytes)), np.uint8).copy()
    try:
        m = codec.decode(block.tobytes())
    except InputError as exc:
        assert codec.raw and "3" in exc.problem, exc.problem  # only a raw map's unused code
        block = _sane_raw(block)
        m = codec.decode(block.tobytes())
    assert m.shape == (n, n) and m.dtype == np.uint8 and m.max() <= C
    assert np.array_equal(codec.decode_many(block[None])[0], m)
    xs, ys = sample_cells(n)
    assert np.array_equal(lookups(codec, block, xs, ys), m[ys, xs])


@njit
def _dispatched(code, data, ss, tt):
    out = np.empty(ss.size, np.uint8)
    for k in range(ss.size):
        out[k] = block_state(code, data, ss[k], tt[k])
    return out


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
@conformance(25)
@given(data=st.data(), seed=st.integers(0, 2**32 - 1))
def test_tracer_dispatch_reads_the_lookups_cell(name, data, seed):
    codec = get_codec(name)
    n = codec.map_size
    rng = np.random.default_rng(seed)
    block = np.frombuffer(data.draw(_blocks(codec.block_bytes)), np.uint8).copy()
    if codec.raw:
        block = _sane_raw(block)
    # the block inside a larger buffer, other bytes after it: the tracer's view of MAX_BLOCK_BYTES
    off = int(rng.integers(0, 16))
    buf = rng.integers(0, 256, off + MAX_BLOCK_BYTES + 16).astype(np.uint8)
    buf[off:off + codec.block_bytes] = block
    view = np.ascontiguousarray(buf[off:off + MAX_BLOCK_BYTES])
    k = np.arange(n + 1) / n  # the cells' edges, 0 and 1 included
    ss = np.concatenate([rng.random(200), k, rng.choice(k, n + 1), [0.0, 1.0, 1.0, 0.0]])
    tt = np.concatenate([rng.random(200), rng.choice(k, n + 1), k, [0.0, 1.0, 0.0, 1.0]])
    got = _dispatched(codec.code, view, ss, tt)
    arr = kernel_bytes(block)
    want = np.array([codec.lookup(arr, *uv_to_cell(float(s), float(t), n)) for s, t in zip(ss, tt)], np.uint8)
    assert np.array_equal(got, want), f"{name}: the tracer's dispatch read another state than the lookup"
    assert codec.code > 0 and get_codec(name).code == next(e.code for e in ENTRIES if e.name == name)
