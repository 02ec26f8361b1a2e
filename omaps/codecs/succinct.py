"""Succinct micromaps (``succinctL``): a level-L micromap as its pruned 4-way subdivision tree,
stored as bit sequences with a rank directory, read without decompressing.

The tree is the bird curve's hierarchy: the root is the whole triangle, and the children of
micro-triangle p at level l are 4p .. 4p + 3 at level l + 1 (``omaps.birdcurve``). A node whose
micro-triangles all have one state is a leaf holding that state; any other node is internal and
has 4 children. Nodes at level L are always leaves. The nodes are numbered in level order (the
root 0; the children of the r-th internal node, counted from 0 in that order, are
1 + 4r + c, c = 0..3) and stored as (docs/FORMAT.md, "Hierarchical micromaps"):

==========================  =====================================================================
field                       bits
==========================  =====================================================================
``n_T``                     ``w`` = ``header_bits(L)``: the nodes above level L
``T``                       ``n_T``: per node above level L, in level order, 1 internal, 0 leaf
rank directory              ``w`` each, ``n_T // 64`` entries: entry j-1 = the ones of T[0, 64 j)
leaf states                 2 each (T 0, O 1, C 2), every leaf (level L included) in level order
==========================  =====================================================================

Bit k of a blob is bit (k mod 8) of byte k div 8 (``codecs.bits``). ``lookup`` descends from the
root along micro-triangle k's base-4 digits with one rank query per level (the directory entry of
the 64-bit word, plus the popcount of the part of the word before the position): O(L) reads.

Example::

    >>> import numpy as np
    >>> from omaps.codecs import succinct_encode, succinct_decode, succinct_lookup, succinct_bits
    >>> m = np.zeros(16, np.uint8); m[4:8] = 1; m[9] = 2     # level 2: child 1 all O, child 2 mixed
    >>> blob = succinct_encode(m, 2)
    >>> succinct_bits(m, 2), len(blob)         # w = 3, n_T = 5 T bits, 7 leaves of 2 bits
    (22, 3)
    >>> bool((succinct_decode(blob, 2) == m).all()), int(succinct_lookup(np.frombuffer(blob, np.uint8), 0, 2, 9))
    (True, 2)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..birdcurve import MAX_LEVEL
from ..errors import InputError
from .bits import bit_length, get_bits, kernel_bytes
from ..checks import typed

__all__ = ["header_bits", "tree_counts", "encoded_bits", "encode", "encode_many", "encode_dag", "succinct_encode_dag", "decode", "lookup", "blob_bits", "check",
           "pair_encode", "pair_lookup",
           "uniform_levels", "succinct_encode", "succinct_encode_many", "succinct_decode", "succinct_lookup", "succinct_check",
           "succinct_bits"]


def header_bits(level: int) -> int:
    """Width w of the node count ``n_T`` and of each rank-directory entry: enough bits for the
    most nodes a level-L tree can have above level L, (4^L - 1) / 3 (0 at level 0)."""
    return int((4 ** int(level) - 1) // 3).bit_length()


@njit(cache=True, inline="always")
def _header_bits(level):
    return bit_length((np.int64(1) << (2 * level)) // 3)  # (4^L - 1) / 3


@njit(cache=True, inline="always")
def _popcount(x):
    """Ones of a non-negative int64 below 2^63."""
    x = x - ((x >> 1) & 0x5555555555555555)
    x = (x & 0x3333333333333333) + ((x >> 2) & 0x3333333333333333)
    x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0F
    return (x * 0x0101010101010101 >> 56) & 0xFF


@njit(cache=True, inline="always")
def _rank(data, t0, d0, w, i):
    """Ones of T[0, i): the directory entry of i's 64-bit word plus the popcount of the word's
    bits before i (read as two fields of at most 32 bits)."""
    word = i >> 6
    c = np.int64(0)
    if word > 0:
        c = get_bits(data, d0 + w * (word - 1), w)
    rem = i & 63
    base = t0 + (word << 6)
    if rem > 32:
        c += _popcount(get_bits(data, base, 32)) + _popcount(get_bits(data, base + 32, rem - 32))
    elif rem > 0:
        c += _popcount(get_bits(data, base, rem))
    return c


@njit(cache=True)
def lookup(data, start, level, k):
    """State of micro-triangle ``k`` of the level-``level`` succinct micromap whose blob starts at
    bit ``start`` of the uint8 array ``data``: a descent from the root, one rank query per level.
    The blob is one ``encode`` wrote or ``check`` passed (the kernel reads without bounds checks).

    Parameters
    ----------
    data : ndarray of uint8
        The bytes holding the blob.
    start : int
        The blob's first bit.
    level : int
        The micromap's level L.
    k : int
        The micro-triangle, in bird-curve order (0 <= k < 4^L).

    Returns
    -------
    int
        0 (T), 1 (O) or 2 (C).

    Examples
    --------
    >>> import numpy as np
    >>> m = np.repeat(np.array([0, 1, 2, 1], np.uint8), 4)
    >>> data = np.frombuffer(encode(m, 2), np.uint8)
    >>> [int(lookup(data, 0, 2, k)) for k in (0, 5, 10, 15)]
    [0, 1, 2, 1]
    """
    w = _header_bits(level)
    n_t = get_bits(data, start, w) if w > 0 else np.int64(0)
    t0 = start + w
    d0 = t0 + n_t
    s0 = d0 + w * (n_t >> 6)
    pos = np.int64(0)
    for d in range(level):
        if pos >= n_t or (data[(t0 + pos) >> 3] >> ((t0 + pos) & 7)) & 1 == 0:
            break
        pos = 1 + 4 * _rank(data, t0, d0, w, pos) + ((k >> (2 * (level - 1 - d))) & 3)
    leaf = pos - _rank(data, t0, d0, w, min(pos, n_t))
    return get_bits(data, s0 + 2 * leaf, 2)


@njit(cache=True, inline="always")
def _size(n_t, n_int, w):
    return w + n_t + w * (n_t >> 6) + 2 * (1 + 3 * n_int)


@njit(cache=True)
def blob_bits(data, start, level):
    """Size in bits of the level-``level`` blob at bit ``start`` of ``data``, read from its header
    and one rank query: w + n_T + w · (n_T div 64) + 2 · (1 + 3 · ones of T)."""
    w = _header_bits(level)
    n_t = get_bits(data, start, w) if w > 0 else np.int64(0)
    t0 = start + w
    return _size(n_t, _rank(data, t0, t0 + n_t, w, n_t), w)


@njit(cache=True)
def pair_lookup(data, level, second, k):
    """State of micro-triangle ``k`` of a pair's first (``second`` False) or second triangle in
    the pair's block ``data`` (``pair_encode``): the second tree starts at the byte after the
    first, whose size its header and one rank query give (``blob_bits``)."""
    start = np.int64(0)
    if second:
        start = 8 * ((blob_bits(data, 0, level) + 7) >> 3)
    return lookup(data, start, level, k)


@njit(cache=True)
def _uniform_levels(m, level, uni, off):
    """Per node of every level l (at ``uni[off[l] + p]``): its state if its micro-triangles all
    have it, else 3; bottom-up from the map itself at level L."""
    n = m.shape[0]
    for p in range(n):
        uni[off[level] + p] = m[p]
    for lv in range(level - 1, -1, -1):
        for p in range(np.int64(1) << (2 * lv)):
            c = off[lv + 1] + 4 * p
            a = uni[c]
            if a != 3 and uni[c + 1] == a and uni[c + 2] == a and uni[c + 3] == a:
                uni[off[lv] + p] = a
            else:
                uni[off[lv] + p] = 3


def _offsets(level: int) -> np.ndarray:
    return np.array([(4 ** lv - 1) // 3 for lv in range(level + 2)], np.int64)


def uniform_levels(m, level: int) -> list[np.ndarray]:
    """The pruned tree of one micromap, level by level: entry l (4^l values) holds each level-l
    node's state when its subtree is uniform, else 3.

    Examples
    --------
    >>> import numpy as np
    >>> [u.tolist() for u in uniform_levels(np.array([1, 1, 1, 1], np.uint8), 1)]
    [[1], [1, 1, 1, 1]]
    """
    m = _check(m, level)
    off = _offsets(level)
    uni = np.empty(off[-1], np.uint8)
    _uniform_levels(m, level, uni, off)
    return [uni[off[lv]:off[lv + 1]] for lv in range(level + 1)]


@njit(cache=True, inline="always")
def _counts(uni, off, level):
    """(n_T, internal nodes) of a pruned tree."""
    n_int = 0
    n_int_above = 0  # internal nodes above level L - 1: each has 4 children above level L
    for lv in range(level):
        for p in range(off[lv], off[lv + 1]):
            if uni[p] == 3:
                n_int += 1
                if lv < level - 1:
                    n_int_above += 1
    n_t = 1 + 4 * n_int_above if level > 0 else 0
    return n_t, n_int


@njit(cache=True, inline="always")
def _put(out, pos, v, n):
    for b in range(n):
        if (v >> b) & 1:
            out[(pos + b) >> 3] |= np.uint8(1 << ((pos + b) & 7))


@njit(cache=True, inline="always")
def _header(out, base, n_t, w):
    """Write a blob's ``n_T`` at bit ``base``; the bits where its T sequence, rank directory and
    leaf states start."""
    _put(out, base, n_t, w)
    t0 = base + w
    d0 = t0 + n_t
    return t0, d0, d0 + w * (n_t >> 6)


@njit(cache=True)
def _sizes(maps, level, off):
    w = _header_bits(level)
    uni = np.empty(off[level + 1], np.uint8)
    out = np.empty(maps.shape[0], np.int64)
    for i in range(maps.shape[0]):
        _uniform_levels(maps[i], level, uni, off)
        n_t, n_int = _counts(uni, off, level)
        out[i] = _size(n_t, n_int, w)
    return out


@njit(cache=True)
def _write(maps, level, off, out, byte_start):
    """Each map's blob into ``out`` (zeroed) from byte ``byte_start[i]``."""
    w = _header_bits(level)
    uni = np.empty(off[level + 1], np.uint8)
    for i in range(maps.shape[0]):
        _uniform_levels(maps[i], level, uni, off)
        n_t, n_int = _counts(uni, off, level)
        t0, d0, s0 = _header(out, 8 * byte_start[i], n_t, w)
        tp = 0
        lp = 0
        ones = 0
        for lv in range(level + 1):
            for p in range(np.int64(1) << (2 * lv)):
                if lv > 0 and uni[off[lv - 1] + (p >> 2)] != 3:
                    continue  # inside a uniform ancestor: no node
                s = uni[off[lv] + p]
                if lv < level:
                    if tp > 0 and tp & 63 == 0:
                        _put(out, d0 + w * ((tp >> 6) - 1), ones, w)
                    if s == 3:
                        _put(out, t0 + tp, 1, 1)
                        ones += 1
                    tp += 1
                if s != 3:
                    _put(out, s0 + 2 * lp, s, 2)
                    lp += 1
        if n_t > 0 and n_t & 63 == 0:
            _put(out, d0 + w * ((n_t >> 6) - 1), ones, w)


@njit(cache=True)
def _decode(data, start, level):
    w = _header_bits(level)
    n_t = get_bits(data, start, w) if w > 0 else np.int64(0)
    t0 = start + w
    s0 = t0 + n_t + w * (n_t >> 6)
    prev = np.zeros(1, np.uint8)
    tp = 0
    lp = 0
    for lv in range(level + 1):
        cur = np.empty(np.int64(1) << (2 * lv), np.uint8)
        for p in range(cur.shape[0]):
            if lv > 0 and prev[p >> 2] != 3:
                cur[p] = prev[p >> 2]
                continue
            internal = False
            if lv < level:
                internal = tp < n_t and (data[(t0 + tp) >> 3] >> ((t0 + tp) & 7)) & 1 == 1
                tp += 1
            if internal:
                cur[p] = 3
            else:
                cur[p] = get_bits(data, s0 + 2 * lp, 2)
                lp += 1
        prev = cur
    return prev


@njit(cache=True)
def _validate(data, start, level):
    """0 if the blob at bit ``start`` is a level-``level`` tree every lookup reads inside
    ``data``, else the number of the first rule it breaks (``check``'s messages); its size in
    bits."""
    nbits = 8 * np.int64(data.shape[0])
    w = _header_bits(level)
    if start + w > nbits:
        return 1, np.int64(0)
    n_t = get_bits(data, start, w) if w > 0 else np.int64(0)
    if level > 0 and (n_t < 1 or n_t > (np.int64(1) << (2 * level)) // 3 or n_t % 4 != 1):
        return 2, np.int64(0)
    t0 = start + w
    d0 = t0 + n_t
    s0 = d0 + w * (n_t >> 6)
    if s0 > nbits:
        return 3, np.int64(0)
    # the T bits level by level: a level's nodes are 4 per internal node of the one above
    nodes = np.int64(1)
    tp = np.int64(0)
    ones = np.int64(0)
    for lv in range(level):
        if tp + nodes > n_t:
            return 4, np.int64(0)
        internal = np.int64(0)
        for i in range(tp, tp + nodes):
            if i > 0 and i & 63 == 0 and get_bits(data, d0 + w * ((i >> 6) - 1), w) != ones:
                return 5, np.int64(0)
            if (data[(t0 + i) >> 3] >> ((t0 + i) & 7)) & 1:
                internal += 1
                ones += 1
        tp += nodes
        nodes = 4 * internal
    if tp != n_t:
        return 4, np.int64(0)
    if n_t > 0 and n_t & 63 == 0 and get_bits(data, d0 + w * ((n_t >> 6) - 1), w) != ones:
        return 5, np.int64(0)
    size = _size(n_t, ones, w)
    if start + size > nbits:
        return 6, np.int64(0)
    for j in range(1 + 3 * ones):
        if get_bits(data, s0 + 2 * j, 2) > 2:
            return 7, np.int64(0)
    return 0, size


_PROBLEMS = {1: "its header runs past the end of the data", 2: "its node count n_T is no level-{L} tree's",
             3: "its T bits and rank directory run past the end of the data",
             4: "its T bits are not a level-{L} tree's in level order",
             5: "a rank directory entry is not the ones of T before it",
             6: "its leaf states run past the end of the data", 7: "a leaf holds code 3, which is no state"}


@typed
def check(data, level: int, start: int = 0) -> int:
    """The size in bits of the level-``level`` succinct blob at bit ``start`` of ``data`` (bytes
    or uint8), after checking every field a lookup reads: an InputError unless the header, the
    T bits (a level-order tree), the rank directory and the leaf states are consistent and lie
    inside ``data``. A blob that passes is read by ``lookup`` and ``decode`` within its bytes.

    Examples
    --------
    >>> check(encode([0, 1, 2, 1], 1), 1)
    10
    >>> check(b"\\xff", 1)
    Traceback (most recent call last):
    ...
    omaps.errors.InputError: a level-1 succinct micromap is corrupt: its leaf states run past the end of the data
    """
    if not isinstance(level, (int, np.integer)) or not 0 <= level <= MAX_LEVEL:
        raise InputError(f"a succinct micromap's level is an integer in 0..{MAX_LEVEL}, got {level!r}")
    buf = kernel_bytes(data)
    if buf.ndim != 1:
        raise InputError(f"data must be bytes or a 1-D uint8 array, got shape {buf.shape}", param="data")
    if not isinstance(start, (int, np.integer)) or not 0 <= start <= 8 * len(buf):
        raise InputError(f"a succinct micromap's start bit is in 0..{8 * len(buf)}, got {start!r}")
    err, size = _validate(buf, np.int64(start), int(level))
    if err:
        raise InputError(f"a level-{level} succinct micromap is corrupt: " + _PROBLEMS[err].format(L=level))
    return int(size)


def _check(m, level: int, many: bool = False) -> np.ndarray:
    from ..checks import array, integer

    level = integer(level, "level", 0, MAX_LEVEL)
    a = array(m, "maps" if many else "m", kinds="biu")
    if a.size and (a.min() < 0 or a.max() > 2):
        raise InputError(f"a level-{level} micromap holds states 0..2", param="maps" if many else "m")
    a = np.ascontiguousarray(a, dtype=np.uint8)
    shape = (a.shape[0], 4 ** level) if many and a.ndim == 2 else (4 ** level,)
    if a.shape != shape:
        raise InputError(f"a level-{level} micromap holds {4 ** level} states 0..2, got shape {a.shape}")
    return a


def tree_counts(m, level: int) -> tuple[int, int]:
    """(n_T, internal nodes) of one micromap's pruned tree: the nodes above level L and the
    internal ones among them; it has 1 + 3 · internal leaves."""
    uni = np.concatenate(uniform_levels(m, level))
    n_t, n_int = _counts(uni, _offsets(level), level)
    return int(n_t), int(n_int)


def encoded_bits(maps, level: int) -> np.ndarray:
    """Exact size in bits of each micromap's blob, (P, 4^L) -> (P,) int64:
    w + n_T + w · (n_T div 64) + 2 · (1 + 3 · internal), w = ``header_bits(L)``."""
    a = _check(np.atleast_2d(maps), level, many=True)
    return _sizes(a, level, _offsets(level))


@typed
def encode_many(maps, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Micromaps (P, 4^L) -> (data, byte offsets (P + 1,), bits (P,)): blob i is
    ``data[offsets[i]:offsets[i + 1]]``, each starting on a byte, ``bits[i]`` of it used."""
    a = _check(np.atleast_2d(maps), level, many=True)
    off = _offsets(level)
    bits = _sizes(a, level, off)
    starts = np.zeros(len(a) + 1, np.int64)
    np.cumsum((bits + 7) // 8, out=starts[1:])
    data = np.zeros(int(starts[-1]), np.uint8)
    _write(a, level, off, data, starts)
    return data, starts, bits


@njit(cache=True)
def _expand(nodes, root, level, queue, ends):
    """The pruned tree under DAG reference ``root`` in level order: references at depth d in
    ``queue[ends[d]:ends[d + 1]]`` (``queue`` grown as needed, returned); -1 if a reference at
    depth L is a node (the DAG is deeper than the level) or names no node."""
    queue[0] = root
    ends[0] = 0
    ends[1] = 1
    n = 1
    for lv in range(level + 1):
        for i in range(ends[lv], ends[lv + 1]):
            r = queue[i]
            if r < 3:
                continue
            if lv == level or r - 3 >= nodes.shape[0]:
                return queue, -1
            if n + 4 > queue.shape[0]:
                bigger = np.empty(2 * queue.shape[0] + 4, np.int64)
                bigger[:n] = queue[:n]
                queue = bigger
            for c in range(4):
                queue[n] = nodes[r - 3, c]
                n += 1
        if lv < level:
            ends[lv + 2] = n
    return queue, n


@njit(cache=True)
def _dag_blobs(nodes, roots, level, out, byte_start):
    """Each root's bits (``out`` None) or its blob written into ``out`` (zeroed) from byte
    ``byte_start[i]``: the same fields as ``_write``, the tree read from the DAG. Returns the
    bits per root, -1 where ``_expand`` refused."""
    w = _header_bits(level)
    queue = np.empty(64, np.int64)
    ends = np.empty(level + 2, np.int64)
    bits = np.empty(roots.shape[0], np.int64)
    for t in range(roots.shape[0]):
        queue, n = _expand(nodes, roots[t], level, queue, ends)
        if n < 0:
            bits[t] = -1
            continue
        n_t = ends[level]
        bits[t] = _size(n_t, (n - 1) >> 2, w)  # every internal node added its 4 children
        if out is None:
            continue
        t0, d0, s0 = _header(out, 8 * byte_start[t], n_t, w)
        ones = 0
        lp = 0
        for i in range(n):
            r = queue[i]
            if i < n_t:
                if i > 0 and i & 63 == 0:
                    _put(out, d0 + w * ((i >> 6) - 1), ones, w)
                if r >= 3:
                    _put(out, t0 + i, 1, 1)
                    ones += 1
            if r < 3:
                _put(out, s0 + 2 * lp, r, 2)
                lp += 1
        if n_t > 0 and n_t & 63 == 0:
            _put(out, d0 + w * ((n_t >> 6) - 1), ones, w)
    return bits


@typed
def encode_dag(nodes, roots, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blobs of micromaps given as a merged DAG (``csm.build``'s or ``csm.Builder``'s nodes
    and roots: a reference 0..2 a uniform subtree, 3 + i node i) -> (data, byte offsets (P + 1,),
    bits (P,)), byte for byte ``encode_many`` of the micromaps the roots stand for, without
    their 4^L states: each tree is read from the DAG, so a fine level costs its nodes.

    Examples
    --------
    >>> import numpy as np
    >>> from omaps.codecs import csm_build
    >>> maps = np.array([[0, 0, 0, 1] * 4, [2] * 16])
    >>> data, starts, bits = encode_dag(*csm_build(maps, 2), 2)
    >>> data.tobytes() == encode_many(maps, 2)[0].tobytes(), bits.tolist()
    (True, [40, 6])
    """
    from ..checks import integer
    from .csm import checked_dag

    level = integer(level, "level", 0, MAX_LEVEL)
    nodes, roots = checked_dag(nodes, roots)
    bits = _dag_blobs(nodes, roots, level, None, np.zeros(0, np.int64))
    if (bits < 0).any():
        raise InputError(f"the tree of root {int(np.flatnonzero(bits < 0)[0])} is deeper than level {level}",
                         param="roots")
    starts = np.zeros(len(roots) + 1, np.int64)
    np.cumsum((bits + 7) // 8, out=starts[1:])
    data = np.zeros(int(starts[-1]), np.uint8)
    _dag_blobs(nodes, roots, level, data, starts)
    return data, starts, bits


def pair_encode(first, second, has_second, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs' blocks: micromaps (P, 4^L) of each pair's first and second triangle -> (data, byte
    offsets (P + 1,)): pair i's block ``data[starts[i]:starts[i + 1]]`` is the first triangle's
    blob, then the second's from the next byte (none where ``has_second[i]`` is False), read by
    ``pair_lookup``.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.array([[0, 1, 2, 1]], np.uint8); b = np.array([[1, 1, 1, 1]], np.uint8)
    >>> data, starts = pair_encode(a, b, np.array([True]), 1)
    >>> starts.tolist(), [int(pair_lookup(data, 1, s, 2)) for s in (False, True)]
    ([0, 3], [2, 1])
    """
    a = _check(np.atleast_2d(first), level, many=True)
    has = np.asarray(has_second, bool).ravel()
    b = _check(np.atleast_2d(second), level, many=True)
    if len(b) != len(a) or len(has) != len(a):
        raise ValueError(f"pair_encode: {len(a)} first, {len(b)} second micromaps and {len(has)} flags")
    if len(a) == 0:
        return np.zeros(0, np.uint8), np.zeros(1, np.int64)
    # blobs interleaved: first of pair 0, second of pair 0 (or nothing), first of pair 1, ...
    both = np.empty((2 * len(a), a.shape[1]), np.uint8)
    both[0::2], both[1::2] = a, b
    keep = np.ones(2 * len(a), bool)
    keep[1::2] = has
    data, starts, _ = encode_many(both[keep], level)
    owner = np.repeat(np.arange(len(a)), 1 + has.astype(np.int64))  # the pair of each kept blob
    pair_starts = np.zeros(len(a) + 1, np.int64)
    pair_starts[1:] = starts[1:][np.r_[owner[1:] != owner[:-1], True]]
    return data, pair_starts


@typed
def encode(m, level: int) -> bytes:
    """One micromap (4^L states in bird-curve order) -> its blob, ``ceil(bits / 8)`` bytes."""
    data, _, _ = encode_many(_check(m, level)[None], level)
    return data.tobytes()


@typed
def decode(data: bytes | bytearray | np.ndarray, level: int, start: int = 0) -> np.ndarray:
    """The micromap (4^L states) of the blob at bit ``start`` of ``data`` (bytes or uint8); an
    InputError for a blob ``check`` refuses."""
    buf = kernel_bytes(data)
    if buf.ndim != 1:
        raise InputError(f"data must be bytes or a 1-D uint8 array, got shape {buf.shape}", param="data")
    check(buf, level, start)
    return _decode(buf, int(start), int(level))


@typed
def succinct_bits(maps, level: int):
    """Exact size in bits of one micromap's blob (an int), or of each of many (P, 4^L) (an array)."""
    bits = encoded_bits(maps, level)
    return int(bits[0]) if np.ndim(maps) == 1 else bits


# the package API's names (``omaps.codecs``)
succinct_encode, succinct_encode_many, succinct_decode, succinct_lookup = encode, encode_many, decode, lookup
succinct_check = check
succinct_encode_dag = encode_dag
