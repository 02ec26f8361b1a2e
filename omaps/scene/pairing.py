"""Triangle pairing: pairs of triangles that share an edge and a material, one map per pair.

The deck's square maps cover a *pair* of triangles (the hardware primitive of "Fast Triangle
Pairing for Ray Tracing", Aman & Fenney 2023). Pairing is a matching in the graph whose nodes
are triangles and whose links are shared edges (vertices welded by position) within one material;
we maximise the number of pairs with a greedy matching (fewest free neighbours first) followed
by augmenting-path search (each found path adds one pair; a path search that meets an odd cycle
may miss a path, so the result is maximal and usually, not provably, maximum).

Each triangle then gets the square's corners of its three vertices (docs/FORMAT.md "Pairs in a
scene"): for the pair (A, B), A's vertex off the shared edge ``c`` goes to (1, 0), the vertex
after it in A's order to (1, 1), the one after that to (0, 0); B's vertex off the edge goes to
(0, 1), its two edge vertices to the corners their welded twins have in A. An unpaired triangle
is an A without a B: vertex 0 -> (0, 0), 1 -> (1, 0), 2 -> (1, 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..pair import CORNER_00, CORNER_01, CORNER_10, CORNER_11, CORNERS  # noqa: F401 (CORNERS re-exported)
from ..checks import typed
from ..errors import InputError

__all__ = ["Pairing", "pair_triangles", "weld", "adjacency", "CORNERS"]


@dataclass(frozen=True)
class Pairing:
    """``first``/``second``: triangle indices of each pair (second = -1 for a lone triangle);
    ``corners``: (T, 3) corner codes of every triangle's vertices (-1 for triangles not asked for);
    ``pair_of``: (T,) pair index of every triangle (-1 when not asked for)."""

    first: np.ndarray
    second: np.ndarray
    corners: np.ndarray
    pair_of: np.ndarray

    @property
    def n_pairs(self) -> int:
        return int(np.count_nonzero(self.second >= 0))

    @property
    def paired_fraction(self) -> float:
        n = len(self.first) + self.n_pairs  # triangles covered
        return 2 * self.n_pairs / n if n else 0.0


def weld(positions: np.ndarray) -> np.ndarray:
    """Vertex ids with equal positions merged."""
    _, ids = np.unique(np.asarray(positions), axis=0, return_inverse=True)
    return ids.ravel().astype(np.int64)


def adjacency(triangles: np.ndarray, material: np.ndarray, welded: np.ndarray, selected: np.ndarray):
    """CSR neighbour lists (offsets, neighbours) of the selected triangles: two triangles are
    neighbours when they share a welded edge and have the same material. Degenerate triangles
    (two welded vertices equal) have no neighbours."""
    t = np.asarray(triangles, dtype=np.int64)
    n = len(t)
    w = welded[t]  # (T, 3)
    ok = selected & (w[:, 0] != w[:, 1]) & (w[:, 1] != w[:, 2]) & (w[:, 0] != w[:, 2])
    tri = np.repeat(np.arange(n), 3)
    a = w[:, [0, 1, 2]].ravel()
    b = w[:, [1, 2, 0]].ravel()
    keep = np.repeat(ok, 3)
    tri, lo, hi = tri[keep], np.minimum(a, b)[keep], np.maximum(a, b)[keep]
    mat = np.asarray(material, dtype=np.int64)[tri]
    order = np.lexsort((tri, hi, lo, mat))
    tri, lo, hi, mat = tri[order], lo[order], hi[order], mat[order]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1]) & (mat[1:] == mat[:-1])
    starts = np.concatenate([[0], np.flatnonzero(~same) + 1, [len(tri)]]).astype(np.int64)
    src, dst = _edge_links(tri, starts)
    both_src = np.concatenate([src, dst])
    both_dst = np.concatenate([dst, src])
    order = np.lexsort((both_dst, both_src))
    both_src, both_dst = both_src[order], both_dst[order]
    if len(both_src):  # drop repeated links (two triangles sharing two edges)
        keep = np.ones(len(both_src), bool)
        keep[1:] = (both_src[1:] != both_src[:-1]) | (both_dst[1:] != both_dst[:-1])
        both_src, both_dst = both_src[keep], both_dst[keep]
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.add.at(offsets, both_src + 1, 1)
    return np.cumsum(offsets), both_dst.astype(np.int64)


@njit(cache=True)
def _edge_links(tri, starts):
    """Links between every two triangles in each run tri[starts[r]:starts[r + 1]] of equal edge keys."""
    cnt = 0
    for r in range(len(starts) - 1):
        k = starts[r + 1] - starts[r]
        cnt += k * (k - 1) // 2
    src = np.empty(cnt, np.int64)
    dst = np.empty(cnt, np.int64)
    c = 0
    for r in range(len(starts) - 1):
        for x in range(starts[r], starts[r + 1]):
            for y in range(x + 1, starts[r + 1]):
                if tri[x] != tri[y]:
                    src[c] = tri[x]
                    dst[c] = tri[y]
                    c += 1
    return src[:c], dst[:c]


@njit(cache=True)
def greedy_matching(offsets, nbrs):
    """Match triangles with the fewest free neighbours first (a bucket queue on free degree)."""
    n = len(offsets) - 1
    mate = np.full(n, -1, np.int64)
    deg = np.empty(n, np.int64)
    for v in range(n):
        deg[v] = offsets[v + 1] - offsets[v]
    maxd = 0
    for v in range(n):
        maxd = max(maxd, deg[v])
    # buckets as doubly linked lists
    head = np.full(maxd + 1, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    prv = np.full(n, -1, np.int64)
    for v in range(n):
        d = deg[v]
        nxt[v] = head[d]
        if head[d] >= 0:
            prv[head[d]] = v
        head[d] = v
    active = np.ones(n, np.bool_)

    def unlink(v):
        d = deg[v]
        if prv[v] >= 0:
            nxt[prv[v]] = nxt[v]
        else:
            head[d] = nxt[v]
        if nxt[v] >= 0:
            prv[nxt[v]] = prv[v]
        nxt[v] = -1
        prv[v] = -1

    def push(v):
        d = deg[v]
        prv[v] = -1
        nxt[v] = head[d]
        if head[d] >= 0:
            prv[head[d]] = v
        head[d] = v

    def retire(v):
        unlink(v)
        active[v] = False
        for k in range(offsets[v], offsets[v + 1]):
            u = nbrs[k]
            if active[u]:
                unlink(u)
                deg[u] -= 1
                push(u)

    while True:
        v = -1
        for d in range(1, maxd + 1):
            if head[d] >= 0:
                v = head[d]
                break
        if v < 0:
            break
        best = -1
        for k in range(offsets[v], offsets[v + 1]):
            u = nbrs[k]
            if active[u] and (best < 0 or deg[u] < deg[best]):
                best = u
        mate[v] = best
        mate[best] = v
        retire(v)
        retire(best)
    return mate


@njit(cache=True)
def augment_paths(offsets, nbrs, mate, max_rounds):
    """Grow a matching along augmenting paths found by breadth-first search from free nodes.

    The search alternates: from an outer node w (the root, or a matched node reached through
    its mate) it tries every neighbour v; a free v ends the path, a matched v continues to its
    mate. Each node is visited once per search, so every applied path is simple and valid."""
    n = len(offsets) - 1
    came = np.full(n, -1, np.int64)  # inner node v -> outer node it was reached from
    mark = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    total = 0
    for _ in range(max_rounds):
        grown = 0
        for root in range(n):
            if mate[root] >= 0 or offsets[root + 1] == offsets[root]:
                continue
            mark[root] = root
            qh = 0
            qt = 1
            queue[0] = root
            end = -1
            while qh < qt and end < 0:
                w = queue[qh]
                qh += 1
                for k in range(offsets[w], offsets[w + 1]):
                    v = nbrs[k]
                    if mark[v] == root:
                        continue
                    mark[v] = root
                    came[v] = w
                    if mate[v] < 0:
                        end = v
                        break
                    x = mate[v]
                    if mark[x] == root:
                        continue
                    mark[x] = root
                    queue[qt] = x
                    qt += 1
            if end < 0:
                continue
            v = end
            while True:  # v inner, w = came[v] outer; w's old mate is the previous inner node
                w = came[v]
                old = mate[w]
                mate[v] = w
                mate[w] = v
                if w == root:
                    break
                v = old
            grown += 1
        total += grown
        if grown == 0:
            break
    return mate


@typed
def pair_triangles(triangles: np.ndarray, positions: np.ndarray, material: np.ndarray,
                   selected: np.ndarray | None = None, improve: bool = True) -> Pairing:
    """Pair the selected triangles (default: all) of one mesh; see the module docstring."""
    from ..checks import array

    t = array(triangles, "triangles", shape=(None, 3), kinds="iu", dtype=np.int64)
    n = len(t)
    positions = array(positions, "positions", shape=(None, 3), kinds="iuf", dtype=np.float64)
    material = array(material, "material", shape=(n,), kinds="iu")
    if n and (t.min() < 0 or t.max() >= len(positions)):
        raise InputError(f"triangles must index the {len(positions)} positions", param="triangles")
    selected = np.ones(n, bool) if selected is None else array(selected, "selected", shape=(n,), kinds="biu").astype(bool)
    welded = weld(positions)
    offsets, nbrs = adjacency(t, material, welded, selected)
    mate = greedy_matching(offsets, nbrs)
    if improve:
        mate = augment_paths(offsets, nbrs, mate, 50)
    return _assign(t, welded, selected, mate)


def _assign(t, welded, selected, mate) -> Pairing:
    n = len(t)
    idx = np.flatnonzero(selected)
    m = mate[idx]
    first = idx[(m < 0) | (idx < m)]
    second = np.where(mate[first] >= 0, mate[first], -1)
    corners = np.full((n, 3), -1, np.int8)
    pair_of = np.full(n, -1, np.int64)
    pair_of[first] = np.arange(len(first))
    paired = second >= 0
    pair_of[second[paired]] = np.flatnonzero(paired)
    lone = first[~paired]
    corners[lone] = [CORNER_00, CORNER_10, CORNER_11]
    a, b = first[paired], second[paired]
    if len(a):
        wa, wb = welded[t[a]], welded[t[b]]  # (P, 3)
        # c: A's vertex not in B
        in_b = (wa[:, :, None] == wb[:, None, :]).any(axis=2)  # (P, 3)
        c = np.argmin(in_b, axis=1)  # the one False
        rows = np.arange(len(a))
        ca = np.empty((len(a), 3), np.int8)
        ca[rows, c] = CORNER_10
        ca[rows, (c + 1) % 3] = CORNER_11
        ca[rows, (c + 2) % 3] = CORNER_00
        corners[a] = ca
        w00 = wa[rows, (c + 2) % 3]
        w11 = wa[rows, (c + 1) % 3]
        cb = np.full((len(a), 3), CORNER_01, np.int8)
        cb[wb == w00[:, None]] = CORNER_00
        cb[wb == w11[:, None]] = CORNER_11
        corners[b] = cb
    return Pairing(first.astype(np.int64), second.astype(np.int64), corners, pair_of)


def is_valid_matching(offsets, nbrs, mate) -> bool:
    n = len(offsets) - 1
    for v in range(n):
        u = mate[v]
        if u >= 0 and (mate[u] != v or u not in nbrs[offsets[v]:offsets[v + 1]]):
            return False
    return True
