"""Common-subtree-merged micromaps (``csmL``): the level-L micromaps of a whole set (a scene's
triangles, a texture's pair) as one directed acyclic graph of distinct subtrees, read by descent.

Each micromap is its pruned 4-way tree over the bird curve's hierarchy (``codecs.succinct``): a
node whose micro-triangles all have one state is that state, any other node has 4 children
(micro-triangles 4p .. 4p + 3 of the next level). Nodes are hash-consed bottom-up over the whole
set: a node is a *reference* -- a uniform subtree is the reference 0, 1 or 2 (its state, T, O,
C), a mixed one 3 + the index of its entry in the node array, which holds its 4 children's
references -- and two subtrees with equal children are stored once, whatever their level or
micromap. A blob (docs/FORMAT.md, "Hierarchical micromaps"), W = ``ref_bits(N)``:

=================  ===========================================================================
field              bits
=================  ===========================================================================
``N``              32: the distinct mixed nodes
node array         4 · W per node, node i at 32 + 4 W i: its children c = 0..3, W bits each
roots              W per micromap, micromap t at 32 + 4 W N + W t: its root's reference
=================  ===========================================================================

``lookup`` starts at micromap t's root and follows child ``(k >> 2 (L - 1 - d)) & 3`` of
micro-triangle k at each level d until a reference below 3: at most L reads of W bits.

Example::

    >>> import numpy as np
    >>> from omaps.codecs import csm_encode, csm_decode, csm_lookup
    >>> a = np.zeros(16, np.uint8); a[9] = 2; b = np.ones(16, np.uint8); b[9] = 2
    >>> blob, nodes = csm_encode(np.stack([a, b]), 2)
    >>> nodes, len(blob)           # 4 mixed nodes; W = 3 bits per reference: 32 + 3 * (16 + 2) bits
    (4, 11)
    >>> bool((csm_decode(blob, 2, 2) == np.stack([a, b])).all()), int(csm_lookup(np.frombuffer(blob, np.uint8), 2, 1, 9))
    (True, 2)
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from ..birdcurve import MAX_LEVEL
from ..errors import InputError
from .bits import bit_length, get_bits, kernel_bytes
from ..checks import typed

__all__ = ["ref_bits", "build", "Builder", "treelets", "pack", "encode", "decode", "unpack", "lookup", "blob_bits", "check",
           "HEADER_BITS", "csm_build", "csm_treelets", "csm_encode", "csm_decode", "csm_unpack", "csm_lookup", "csm_bits",
           "csm_pack", "csm_check", "CsmBuilder"]

HEADER_BITS = 32


def ref_bits(n_nodes: int) -> int:
    """Width W of a reference in a set of ``n_nodes`` distinct mixed nodes: enough for 2 + N."""
    return int(n_nodes + 2).bit_length()


@typed
def blob_bits(n_nodes: int, n_maps: int) -> int:
    """Exact size in bits of a set's blob: 32 + W · (4 N + P)."""
    return HEADER_BITS + ref_bits(n_nodes) * (4 * int(n_nodes) + int(n_maps))


@njit(cache=True, inline="always")
def _ref_bits(n_nodes):
    return bit_length(n_nodes + 2)


@njit(cache=True, inline="always")
def _hash(a, b, c, d):
    h = (a * 0x1E3779B97F4A7C15) ^ (b * 0x7F4A7C159E3779B9) ^ (c * 0x14D049BB133111EB) ^ (d * 0x3F58476D1CE4E5B9)
    h ^= h >> 29
    return h


@njit(cache=True)
def _intern(nodes, n, slots, a, b, c, d):
    """The reference of the mixed node with children (a, b, c, d), added when new: (reference,
    nodes, n, slots), the arrays grown (and the open-addressing table rehashed) as needed."""
    mask = slots.shape[0] - 1
    h = _hash(a, b, c, d) & mask
    while True:
        i = slots[h]
        if i < 0:
            if n == nodes.shape[0]:  # grow the node array and the table, rehash
                bigger = np.empty((2 * nodes.shape[0], 4), np.int64)
                bigger[:n] = nodes[:n]
                nodes = bigger
                slots = np.full(2 * nodes.shape[0], -1, np.int64)
                mask = slots.shape[0] - 1
                for j in range(n):
                    g = _hash(nodes[j, 0], nodes[j, 1], nodes[j, 2], nodes[j, 3]) & mask
                    while slots[g] >= 0:
                        g = (g + 1) & mask
                    slots[g] = j
                h = _hash(a, b, c, d) & mask
                continue
            nodes[n, 0] = a
            nodes[n, 1] = b
            nodes[n, 2] = c
            nodes[n, 3] = d
            slots[h] = n
            return 3 + n, nodes, n + 1, slots
        if nodes[i, 0] == a and nodes[i, 1] == b and nodes[i, 2] == c and nodes[i, 3] == d:
            return 3 + i, nodes, n, slots
        h = (h + 1) & mask


@njit(cache=True)
def _empty_table():
    cap = 1 << 10
    return np.empty((cap, 4), np.int64), 0, np.full(2 * cap, -1, np.int64)


@njit(cache=True)
def _build(maps, level):
    """Hash-consing over every map, bottom-up: (node array (N, 4) int64, roots (P,) int64)."""
    nodes, n, slots = _empty_table()
    roots, nodes, n, slots = _states_roots(maps, level, nodes, n, slots)
    return nodes[:n].copy(), roots


@njit(cache=True)
def _states_roots(maps, level, nodes, n, slots):
    """Each map's root reference from its states (P, 4^L), hash-consed bottom-up into the table:
    (roots, nodes, n, slots)."""
    refs = np.empty(maps.shape[1], np.int64)
    roots = np.empty(maps.shape[0], np.int64)
    for t in range(maps.shape[0]):
        size = maps.shape[1]
        for p in range(size):
            refs[p] = maps[t, p]
        for lv in range(level - 1, -1, -1):
            size >>= 2
            for p in range(size):
                a = refs[4 * p]
                b = refs[4 * p + 1]
                c = refs[4 * p + 2]
                d = refs[4 * p + 3]
                if a < 3 and a == b and a == c and a == d:
                    refs[p] = a
                    continue
                refs[p], nodes, n, slots = _intern(nodes, n, slots, a, b, c, d)
        roots[t] = refs[0]
    return roots, nodes, n, slots


@njit(cache=True)
def _runs_roots(runs, starts, level, nodes, n, slots):
    """Each map's root reference from its runs ``runs[starts[t]:starts[t + 1]]`` (node level,
    node index, state; in micro-triangle order, covering the map exactly), hash-consed into the
    table: (roots, nodes, n, slots); a root is -1 where the runs do not tile the map."""
    roots = np.empty(len(starts) - 1, np.int64)
    st_k = np.empty(level + 2, np.int64)  # the open path: node index, next child, children so far
    st_c = np.empty(level + 2, np.int64)
    st_r = np.empty((level + 2, 4), np.int64)
    for t in range(len(starts) - 1):
        ptr, hi = starts[t], starts[t + 1]
        roots[t] = -1
        if ptr >= hi:
            continue
        if runs[ptr, 0] == 0:
            if runs[ptr, 1] == 0 and ptr + 1 == hi:
                roots[t] = runs[ptr, 2]
            continue
        top = 0
        st_k[0] = 0
        st_c[0] = 0
        while True:
            c = st_c[top]
            if c == 4:  # the node's children are known: it is uniform or a mixed node
                a, b, cc, d = st_r[top, 0], st_r[top, 1], st_r[top, 2], st_r[top, 3]
                if a < 3 and a == b and a == cc and a == d:
                    ref = a
                else:
                    ref, nodes, n, slots = _intern(nodes, n, slots, a, b, cc, d)
                if top == 0:
                    if ptr == hi:
                        roots[t] = ref
                    break
                top -= 1
                st_r[top, st_c[top]] = ref
                st_c[top] += 1
                continue
            if ptr >= hi:
                break
            k = 4 * st_k[top] + c
            lv = runs[ptr, 0]
            if lv == top + 1:  # a run is this child
                if runs[ptr, 1] != k:
                    break
                st_r[top, c] = runs[ptr, 2]
                st_c[top] += 1
                ptr += 1
            elif lv > top + 1 and top + 1 < level:  # runs below it: descend
                top += 1
                st_k[top] = k
                st_c[top] = 0
            else:
                break
    return roots, nodes, n, slots


@njit(cache=True)
def _compare(nodes, ra, rb, stack):
    """-1, 0 or 1 as the micromap of reference ``ra`` comes before, equals or follows that of
    ``rb`` in lexicographic order of their states (micro-triangle order); ``stack`` (4 L + 8, 2)."""
    stack[0, 0] = ra
    stack[0, 1] = rb
    top = 1
    while top > 0:
        top -= 1
        a, b = stack[top, 0], stack[top, 1]
        if a == b:
            continue
        if a < 3 and b < 3:
            return -1 if a < b else 1
        for c in range(3, -1, -1):  # child 0 on top: compared first
            stack[top, 0] = nodes[a - 3, c] if a >= 3 else a
            stack[top, 1] = nodes[b - 3, c] if b >= 3 else b
            top += 1
    return 0


@njit(cache=True)
def _sort_maps(nodes, refs, level):
    """The references ``refs`` (distinct) sorted by their micromaps' states (``_compare``): a
    bottom-up merge sort."""
    a = refs.copy()
    b = np.empty_like(a)
    stack = np.empty((4 * level + 8, 2), np.int64)
    width = 1
    m = len(a)
    while width < m:
        for lo in range(0, m, 2 * width):
            mid = min(lo + width, m)
            hi = min(lo + 2 * width, m)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if _compare(nodes, a[j], a[i], stack) < 0:
                    b[k] = a[j]
                    j += 1
                else:
                    b[k] = a[i]
                    i += 1
                k += 1
            while i < mid:
                b[k] = a[i]
                i += 1
                k += 1
            while j < hi:
                b[k] = a[j]
                j += 1
                k += 1
        a, b = b, a
        width *= 2
    return a


@njit(cache=True)
def _renumber(nodes, roots, level):
    """Each node's index as ``_build`` numbers them over the maps of ``roots`` in that order:
    per map, the mixed nodes of each depth from L - 1 up to 0, in micro-triangle order, a node
    taking the next index where it first appears."""
    new = np.full(len(nodes), -1, np.int64)
    nxt = 0
    cap = 1024
    depth_nodes = np.empty(cap, np.int64)  # one map's tree, depth by depth
    depth_start = np.empty(level + 2, np.int64)
    for r in roots:
        if r < 3:
            continue
        depth_nodes[0] = r
        depth_start[0] = 0
        depth_start[1] = 1
        end = 1
        for d in range(1, level + 1):
            for i in range(depth_start[d - 1], depth_start[d]):
                for c in range(4):
                    ch = nodes[depth_nodes[i] - 3, c]
                    if ch >= 3:
                        if end == cap:
                            cap *= 2
                            bigger = np.empty(cap, np.int64)
                            bigger[:end] = depth_nodes[:end]
                            depth_nodes = bigger
                        depth_nodes[end] = ch
                        end += 1
            depth_start[d + 1] = end
        for d in range(level - 1, -1, -1):
            for i in range(depth_start[d], depth_start[d + 1]):
                j = depth_nodes[i] - 3
                if new[j] < 0:
                    new[j] = nxt
                    nxt += 1
    return new


def _renamed(refs: np.ndarray, new: np.ndarray) -> np.ndarray:
    """References with each node's index replaced by ``new``'s."""
    out = refs.copy()
    mixed = refs >= 3
    out[mixed] = 3 + new[refs[mixed] - 3]
    return out


class Builder:
    """``build`` without the states: micromaps added as *runs* (``bake_micromap_runs``: the
    node level, node index and state of each span of micro-triangles the baker decided at once,
    in micro-triangle order) are hash-consed into one table as they come, so a set of level-L
    micromaps needs memory for its distinct nodes and one chunk of runs, never 4^L states per
    micromap. ``finish`` numbers the nodes as ``build`` does over the distinct micromaps in sorted
    order (``np.unique``), so its blob is byte for byte ``build``'s.

    Example::

        >>> import numpy as np
        >>> b = Builder(1)
        >>> runs = np.array([[1, 0, 0], [1, 1, 1], [1, 2, 1], [1, 3, 1], [0, 0, 1]])
        >>> b.add(runs, np.array([0, 4, 5])).tolist()        # the maps 0111 and 1111
        [3, 1]
        >>> nodes, uniq, inverse = b.finish(np.array([3, 1, 3]))
        >>> nodes.tolist(), uniq.tolist(), inverse.tolist()  # as build(np.unique(maps, axis=0))
        ([[0, 1, 1, 1]], [3, 1], [0, 1, 0])
    """

    def __init__(self, level: int):
        from ..checks import integer

        self.level = integer(level, "level", 0, MAX_LEVEL)
        self._nodes, self._n, self._slots = _empty_table()

    @property
    def n_nodes(self) -> int:
        """The distinct mixed nodes so far."""
        return int(self._n)

    def add(self, runs: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Each map's root reference (int64 (P,)) from its runs ``runs[starts[t]:starts[t + 1]]``
        ((R, 3) integers); a ``ValueError`` when a map's runs do not tile it in order."""
        runs = np.ascontiguousarray(runs)
        if runs.dtype not in (np.int32, np.int64):
            runs = runs.astype(np.int64)
        roots, self._nodes, self._n, self._slots = _runs_roots(runs, np.ascontiguousarray(starts, dtype=np.int64),
                                                               self.level, self._nodes, self._n, self._slots)
        if (roots < 0).any():
            raise ValueError(f"the runs of map {int(np.flatnonzero(roots < 0)[0])} do not tile its micro-triangles "
                             "in order")
        return roots

    def add_states(self, maps) -> np.ndarray:
        """Each map's root reference (int64 (P,)) from its states (P, 4^L) of 0..2 (an InputError
        naming ``maps`` otherwise): ``add`` for maps already baked state by state."""
        m = _check(maps, self.level)
        roots, self._nodes, self._n, self._slots = _states_roots(m, self.level, self._nodes, self._n, self._slots)
        return roots

    def finish(self, roots: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(nodes (N, 4), the distinct maps' roots in sorted order of their states, each of
        ``roots``' index among them): ``build``'s nodes and roots of the distinct maps as
        ``np.unique(maps, axis=0)`` orders them, for the maps whose roots ``add`` returned. Only
        nodes those maps reach are kept."""
        roots = np.asarray(roots, dtype=np.int64)
        distinct = _sort_maps(self._nodes[:self._n], np.unique(roots), self.level)
        new = _renumber(self._nodes[:self._n], distinct, self.level)
        keep = np.flatnonzero(new >= 0)
        nodes = np.empty((len(keep), 4), np.int64)
        nodes[new[keep]] = _renamed(self._nodes[keep], new)
        remap = _renamed(distinct, new)
        order = np.argsort(distinct)  # each root's place among the distinct, found by value
        inverse = order[np.searchsorted(distinct[order], roots)]
        return nodes, remap, inverse


def _check(maps, level: int) -> np.ndarray:
    from ..checks import array, integer

    level = integer(level, "level", 0, MAX_LEVEL)
    a = array(maps, "maps", kinds="biu")
    if a.size and (a.min() < 0 or a.max() > 2):
        raise InputError(f"csm stores micromaps of states 0..2", param="maps")
    a = np.ascontiguousarray(a, dtype=np.uint8)
    if a.ndim != 2 or a.shape[1] != 4 ** level or (a.size and a.max() > 2):
        raise InputError(f"csm stores level-{level} micromaps (P, {4 ** level}) of states 0..2, got shape {a.shape}")
    return a


@typed
def build(maps, level: int) -> tuple[np.ndarray, np.ndarray]:
    """The merged DAG of micromaps (P, 4^L): (nodes (N, 4) int64: each distinct mixed node's
    children's references, roots (P,) int64: each micromap's root reference); a reference is a
    state 0..2 (a uniform subtree) or 3 + a node's index.

    Examples
    --------
    >>> import numpy as np
    >>> nodes, roots = build(np.array([[0, 1, 1, 1], [1, 1, 1, 1], [0, 1, 1, 1]]), 1)
    >>> nodes.tolist(), roots.tolist()
    ([[0, 1, 1, 1]], [3, 1, 3])
    """
    return _build(_check(maps, level), int(level))


LINE_BITS = 512  # a 64-byte cache line: the unit a treelet is sized to


def checked_dag(nodes, roots) -> tuple[np.ndarray, np.ndarray]:
    """A merged DAG as given by a caller, checked: nodes (M, 4) and roots (P,) int64, each a
    reference 0 .. 2 + M; an InputError naming ``nodes`` otherwise."""
    from ..checks import array

    nodes = array(nodes, "nodes", kinds="iu", dtype=np.int64)
    if nodes.size % 4:
        raise InputError(f"nodes must have shape (M, 4), got {nodes.shape}", param="nodes")
    nodes = np.ascontiguousarray(nodes).reshape(-1, 4)
    roots = np.ascontiguousarray(array(roots, "roots", kinds="iu", dtype=np.int64)).ravel()
    if (nodes.size and (nodes.min() < 0 or nodes.max() >= 3 + len(nodes))) or (
            roots.size and (roots.min() < 0 or roots.max() >= 3 + len(nodes))):
        raise InputError("nodes and roots must hold references 0 .. 2 + M", param="nodes")
    return nodes, roots


@njit(cache=True)
def _treelet_order(nodes, roots, per_line):
    """Each node's index in the treelet layout (``treelets``), or -1 for a node no root
    reaches; -2 in ``new[0]`` if the nodes form a cycle."""
    n = nodes.shape[0]
    new = np.full(n, -1, np.int64)
    claimed = np.zeros(n, np.bool_)
    on_path = np.zeros(n, np.bool_)
    nxt = 0
    cap = 4 * n + 8
    t_node = np.empty(cap, np.int64)  # tasks: a treelet's top node, its phase, its members in ``mem``
    t_phase = np.empty(cap, np.int64)
    t_start = np.empty(cap, np.int64)
    t_len = np.empty(cap, np.int64)
    mem = np.empty(n + 1, np.int64)  # members of the treelets formed and not yet placed, a stack
    m_top = 0
    path = np.empty(n + 1, np.int64)  # ``place``'s path of nodes waiting for their children
    path_c = np.empty(n + 1, np.int64)
    front = np.empty(4 * per_line, np.int64)
    for r in roots:
        if r < 3 or claimed[r - 3]:
            continue
        top = 1
        t_node[0], t_phase[0] = r - 3, 0
        while top > 0:
            top -= 1
            v, phase = t_node[top], t_phase[top]
            if phase == 0:  # form the treelet: v, then breadth first while the line has room
                if claimed[v]:
                    continue
                start = m_top
                claimed[v] = True
                mem[m_top] = v
                m_top += 1
                i = start
                while i < m_top and m_top - start < per_line:
                    for c in range(4):
                        ch = nodes[mem[i], c]
                        if ch >= 3 and not claimed[ch - 3] and m_top - start < per_line:
                            claimed[ch - 3] = True
                            mem[m_top] = ch - 3
                            m_top += 1
                    i += 1
                nf = 0
                for i in range(start, m_top):
                    for c in range(4):
                        ch = nodes[mem[i], c]
                        if ch >= 3 and not claimed[ch - 3]:
                            front[nf] = ch - 3
                            nf += 1
                t_node[top], t_phase[top], t_start[top], t_len[top] = v, 1, start, m_top - start
                top += 1
                for f in range(nf - 1, -1, -1):  # the subtrees below it first, the first on top
                    t_node[top], t_phase[top] = front[f], 0
                    top += 1
                continue
            # place the treelet, deepest members first, each after every node it references
            for i in range(t_start[top] + t_len[top] - 1, t_start[top] - 1, -1):
                if new[mem[i]] >= 0:
                    continue
                depth = 1
                path[0], path_c[0] = mem[i], 0
                on_path[mem[i]] = True
                while depth > 0:
                    u = path[depth - 1]
                    c = path_c[depth - 1]
                    if c == 4:
                        new[u] = nxt
                        nxt += 1
                        on_path[u] = False
                        depth -= 1
                        continue
                    path_c[depth - 1] = c + 1
                    ch = nodes[u, c]
                    if ch >= 3 and new[ch - 3] < 0:
                        if on_path[ch - 3]:
                            new[0] = -2
                            return new
                        on_path[ch - 3] = True
                        path[depth], path_c[depth] = ch - 3, 0
                        depth += 1
            m_top = t_start[top]
    return new


@typed
def treelets(nodes: ArrayLike, roots: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """The same DAG renumbered into 64-byte *treelets*: (nodes, roots) that ``pack`` lays out so
    that a descent reads one line for several levels (``pack`` writes whatever order it is
    given; ``encode`` and the tracer's maps use this one).

    From each root in turn, a treelet is a node and its not yet placed mixed descendants, breadth
    first, as many as one line holds (``512 // (4 W)``, at least 2); the subtrees below it are
    laid out first, each a treelet in turn, then the treelet, deepest members first, so that
    every node still follows the nodes it references (the format's rule). A node shared by
    several parents is placed once, with the first to reach it. Nodes no root reaches are
    dropped.

    Examples
    --------
    >>> import numpy as np
    >>> nodes, roots = build(np.array([[0, 1, 1, 1, 0, 0, 0, 0, 2, 2, 2, 2, 0, 0, 0, 1]]), 2)
    >>> nodes.tolist(), roots.tolist()              # build: bottom up
    ([[0, 1, 1, 1], [0, 0, 0, 1], [3, 0, 2, 4]], [5])
    >>> nodes, roots = treelets(nodes, roots)
    >>> nodes.tolist(), roots.tolist()              # one treelet, its deepest members first
    ([[0, 0, 0, 1], [0, 1, 1, 1], [4, 0, 2, 3]], [5])
    """
    nodes, roots = checked_dag(nodes, roots)
    per_line = max(2, LINE_BITS // (4 * ref_bits(len(nodes))))
    new = _treelet_order(nodes, roots, per_line)
    if len(new) and new[0] == -2:
        raise InputError("nodes must form no cycle (a node that reaches itself)", param="nodes")
    keep = np.flatnonzero(new >= 0)
    out = np.empty((len(keep), 4), np.int64)
    out[new[keep]] = _renamed(nodes[keep], new)
    return out, _renamed(roots, new)


@njit(cache=True)
def _pack(nodes, roots, w, out):
    n = nodes.shape[0]
    for j in range(32):
        if (n >> j) & 1:
            out[j >> 3] |= np.uint8(1 << (j & 7))
    pos = 32
    for i in range(n):
        for c in range(4):
            v = nodes[i, c]
            for b in range(w):
                if (v >> b) & 1:
                    out[(pos + b) >> 3] |= np.uint8(1 << ((pos + b) & 7))
            pos += w
    for t in range(roots.shape[0]):
        v = roots[t]
        for b in range(w):
            if (v >> b) & 1:
                out[(pos + b) >> 3] |= np.uint8(1 << ((pos + b) & 7))
        pos += w


@typed
def pack(nodes: ArrayLike, roots: ArrayLike) -> bytes:
    """The blob of a merged DAG (``build``'s nodes and any roots: a micromap's root may be listed
    for each triangle that uses it), ``ceil(blob_bits / 8)`` bytes."""
    nodes, roots = checked_dag(nodes, roots)
    if len(nodes) >= 1 << 32:
        raise InputError("a csm set holds fewer than 2^32 mixed nodes")
    out = np.zeros(-(-blob_bits(len(nodes), len(roots)) // 8), np.uint8)
    _pack(nodes, roots, ref_bits(len(nodes)), out)
    return out.tobytes()


@typed
def encode(maps, level: int) -> tuple[bytes, int]:
    """A set of micromaps (P, 4^L) -> (its blob, ``ceil(blob_bits / 8)`` bytes; the number N of
    distinct mixed nodes)."""
    nodes, roots = treelets(*build(maps, level))
    return pack(nodes, roots), len(nodes)


@njit(cache=True)
def lookup(data, level, t, k):
    """State of micro-triangle ``k`` of micromap ``t`` of the level-``level`` set whose blob is
    the uint8 array ``data``: from the root, one W-bit reference read per level. The blob is one
    ``encode`` wrote or ``check`` passed (the kernel reads without bounds checks).

    Examples
    --------
    >>> import numpy as np
    >>> blob, _ = encode(np.repeat(np.array([[0, 1, 2, 1]], np.uint8), 4, axis=1), 2)
    >>> [int(lookup(np.frombuffer(blob, np.uint8), 2, 0, k)) for k in (0, 5, 10, 15)]
    [0, 1, 2, 1]
    """
    n = get_bits(data, 0, 32)
    w = _ref_bits(n)
    ref = get_bits(data, HEADER_BITS + w * (4 * n + t), w)
    for d in range(level):
        if ref < 3:
            return ref
        ref = get_bits(data, HEADER_BITS + w * (4 * (ref - 3) + ((k >> (2 * (level - 1 - d))) & 3)), w)
    return ref


@njit(cache=True)
def _validate(data, n, w, level, n_maps):
    """0 if every reference of the blob (N = ``n`` nodes, W = ``w``) names a state or an earlier
    node and every root's descent ends on a state within ``level`` reads; else the first broken
    rule (``check``'s messages)."""
    height = np.empty(n, np.int64)  # the most reads from the node to a state
    for i in range(n):
        h = np.int64(1)
        for c in range(4):
            r = get_bits(data, HEADER_BITS + w * (4 * i + c), w)
            if r >= 3 + i:
                return 1
            if r >= 3 and height[r - 3] + 1 > h:
                h = height[r - 3] + 1
        height[i] = h
    for t in range(n_maps):
        r = get_bits(data, HEADER_BITS + w * (4 * n + t), w)
        if r >= 3 + n:
            return 2
        if r >= 3 and height[r - 3] > level:
            return 3
    return 0


_PROBLEMS = {1: "a node references itself, a later node or no node (nodes are stored children first)",
             2: "a root references no node", 3: "a root's descent is deeper than the level"}


@typed
def check(data, level: int, n_maps: int) -> np.ndarray:
    """``data`` (bytes or uint8) as the uint8 array of a level-``level`` set of ``n_maps``
    micromaps, after checking every field a lookup reads: an InputError unless the node count,
    the node array and the roots lie inside ``data``, each node's children are states or earlier
    nodes, and each root's descent ends on a state within ``level`` reads. A blob that passes is
    read by ``lookup`` and ``decode`` within its bytes and ends every descent on a state.

    Examples
    --------
    >>> blob, _ = encode([[0, 1, 2, 1]], 1)
    >>> len(check(blob, 1, 1))
    6
    >>> check(blob, 0, 1)
    Traceback (most recent call last):
    ...
    omaps.errors.InputError: a level-0 csm set is corrupt: a root's descent is deeper than the level
    """
    if not isinstance(level, (int, np.integer)) or not 0 <= level <= MAX_LEVEL:
        raise InputError(f"a csm micromap's level is an integer in 0..{MAX_LEVEL}, got {level!r}")
    if not isinstance(n_maps, (int, np.integer)) or n_maps < 0:
        raise InputError(f"a csm set's micromap count is a non-negative integer, got {n_maps!r}")
    buf = kernel_bytes(data)
    if buf.ndim != 1:
        raise InputError(f"data must be bytes or a 1-D uint8 array, got shape {buf.shape}", param="data")
    if len(buf) * 8 < HEADER_BITS:
        raise InputError(f"a csm set is at least {HEADER_BITS} bits (its node count), got {8 * len(buf)}")
    n = int(get_bits(buf, 0, 32))
    need = blob_bits(n, int(n_maps))
    if need > 8 * len(buf):
        raise InputError(f"a csm set of {n} nodes and {n_maps} micromaps is {need} bits, the data {8 * len(buf)}")
    err = _validate(buf, n, ref_bits(n), int(level), int(n_maps))
    if err:
        raise InputError(f"a level-{level} csm set is corrupt: {_PROBLEMS[err]}")
    return buf


@njit(cache=True)
def _decode(data, level, n_maps):
    n = get_bits(data, 0, 32)
    w = _ref_bits(n)
    out = np.empty((n_maps, np.int64(1) << (2 * level)), np.uint8)
    for t in range(n_maps):
        cur = np.empty(1, np.int64)
        cur[0] = get_bits(data, HEADER_BITS + w * (4 * n + t), w)
        for lv in range(level):
            nxt = np.empty(4 * cur.shape[0], np.int64)
            for p in range(cur.shape[0]):
                r = cur[p]
                for c in range(4):
                    nxt[4 * p + c] = r if r < 3 else get_bits(data, HEADER_BITS + w * (4 * (r - 3) + c), w)
            cur = nxt
        for p in range(cur.shape[0]):
            out[t, p] = cur[p]
    return out


@typed
def decode(data, level: int, n_maps: int) -> np.ndarray:
    """The ``n_maps`` micromaps (n_maps, 4^L) of a set's blob (bytes or uint8 array); an
    InputError for a blob ``check`` refuses."""
    buf = check(data, level, n_maps)
    return _decode(buf, int(level), int(n_maps))


@njit(cache=True)
def _unpack(data, n_maps):
    n = get_bits(data, 0, 32)
    w = _ref_bits(n)
    nodes = np.empty((n, 4), np.int64)
    for i in range(n):
        for c in range(4):
            nodes[i, c] = get_bits(data, HEADER_BITS + w * (4 * i + c), w)
    roots = np.empty(n_maps, np.int64)
    for t in range(n_maps):
        roots[t] = get_bits(data, HEADER_BITS + w * (4 * n + t), w)
    return nodes, roots


@typed
def unpack(data, level: int, n_maps: int) -> tuple[np.ndarray, np.ndarray]:
    """A set's blob (bytes or uint8 array) back into its DAG: (nodes (N, 4), roots (n_maps,))
    int64 references, which ``pack`` writes again byte for byte; an InputError for a blob
    ``check`` refuses.

    Examples
    --------
    >>> blob, _ = encode([[0, 1, 2, 1], [1, 1, 1, 1]], 1)
    >>> nodes, roots = unpack(blob, 1, 2)
    >>> nodes.tolist(), roots.tolist(), pack(nodes, roots) == blob
    ([[0, 1, 2, 1]], [3, 1], True)
    """
    buf = check(data, level, n_maps)
    return _unpack(buf, int(n_maps))


# the package API's names (``omaps.codecs``)
csm_build, csm_pack, csm_encode, csm_decode, csm_lookup, csm_bits = build, pack, encode, decode, lookup, blob_bits
csm_treelets = treelets
csm_check = check
csm_unpack = unpack
CsmBuilder = Builder
