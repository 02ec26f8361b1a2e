"""Opaque fractions: how much of a region the alpha test finds opaque, measured by sampling it.

A C region (a micro-triangle, a square map's cell) is neither all T nor all O; its opaque
fraction -- the share of sample points inside it where ``alpha_test.sample_passes`` (the shader's
own test) passes -- decides what it becomes when it must be O or T (``omaps.promotion``): the
OMM's unknown-opaque / unknown-transparent and 2-state outputs, and the tracer's 2-state mode.

* micro-triangles: the centroids of their level-K sub-triangles, K the smallest giving 16 samples
  per texel of the micro-triangle's area, at most 3 (64 samples);
* square cells of a pair: K x K points of the cell, each mapped through the pair triangle it
  lies in (``pair.square_uv``).

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.coverage import micro_fractions
    >>> from omaps.texture import load_alpha
    >>> test = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8)))
    >>> micro_fractions(test, np.array([[[0, 0], [1, 0], [0, 1]]]), 0).round(2).tolist()
    [0.25]
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from . import birdcurve
from .birdcurve import bary_point
from .alpha_test import AlphaTest, passes, sample_passes
from .pair import square_uv
from .parallel import fetch_add
from .sampling import address, blend

__all__ = ["micro_fractions", "cell_fractions", "micro_corners", "micro_corners_of", "micro_hits_with", "SAMPLES_PER_TEXEL",
           "MAX_SAMPLE_LEVEL", "CELL_SAMPLES"]

SAMPLES_PER_TEXEL = 16
MAX_SAMPLE_LEVEL = 3
CELL_SAMPLES = 4  # K x K points per square cell


@njit(cache=True)
def micro_corners(tri_texel, index, level):
    """Texel coordinates (ax, ay, bx, by, cx, cy) of micro-triangle ``index``'s vertices."""
    t = tri_texel
    (a1, a2), (b1, b2), (c1, c2) = birdcurve.micro_vertices(index, level)
    return _corners(t[0, 0], t[0, 1], t[1, 0], t[1, 1], t[2, 0], t[2, 1], a1, a2, b1, b2, c1, c2)


@njit(cache=True, inline="always")
def micro_corners_of(tris_texel, t, index, level, table):
    """``micro_corners`` of triangle ``t`` of ``tris_texel`` (T, 3, 2), for kernels that hold
    every triangle (no view of one is made) and visit its micro-triangles in no order: the
    barycentric vertices come from ``table`` (``birdcurve.vertex_table()``)."""
    (a1, a2), (b1, b2), (c1, c2) = birdcurve.table_vertices(table, index, level)
    return _corners(tris_texel[t, 0, 0], tris_texel[t, 0, 1], tris_texel[t, 1, 0], tris_texel[t, 1, 1],
                    tris_texel[t, 2, 0], tris_texel[t, 2, 1], a1, a2, b1, b2, c1, c2)


@njit(cache=True, inline="always")
def _corners(t0x, t0y, t1x, t1y, t2x, t2y, a1, a2, b1, b2, c1, c2):
    """Texel coordinates of barycentric vertices (a1, a2), (b1, b2), (c1, c2) of the texel-space
    triangle (t0, t1, t2) given as scalars."""
    return (bary_point(a1, a2, t0x, t1x, t2x), bary_point(a1, a2, t0y, t1y, t2y),
            bary_point(b1, b2, t0x, t1x, t2x), bary_point(b1, b2, t0y, t1y, t2y),
            bary_point(c1, c2, t0x, t1x, t2x), bary_point(c1, c2, t0y, t1y, t2y))


BLOCK = 16  # points counted between two checks of the count (16 ran 2-6 % faster than 8, 4 slower)
TAPS = 8  # texels per side of the block of taps ``micro_hits_with`` reads first (larger regions: texel by texel)


@njit(cache=True, inline="always")
def _hits_from(taps, ox, oy, nx, ny, threshold, inclusive, qax, qay, qbx, qby, qcx, qcy, samples, first, n, need):
    """``micro_hits_with`` under the linear filter, every point reading its four taps from
    ``taps``: texel (x, y) at ``taps[y - oy, x - ox]``, ``nx`` x ``ny`` of them (the texture
    itself, or a block of it); -1 when some point's taps leave them. Points go in blocks of BLOCK
    with no branch (the compiler vectorises a block), the count checked after each block."""
    if nx < 2 or ny < 2:
        return -1
    last_x = np.uint64(nx - 2)  # the last first tap inside: x0 and x0 + 1 both in [0, nx)
    last_y = np.uint64(ny - 2)
    step = min(n, BLOCK)
    hits = 0
    outside = False
    for b in range(first, first + n, step):
        for s in range(np.uint64(b), np.uint64(b + step)):
            fx = bary_point(samples[s, 0], samples[s, 1], qax, qbx, qcx) - 0.5
            fy = bary_point(samples[s, 0], samples[s, 1], qay, qby, qcy) - 0.5
            x0 = int(math.floor(fx))
            y0 = int(math.floor(fy))
            ux = np.uint64(x0 - ox)  # a tap before the first wraps to a large index: outside too
            uy = np.uint64(y0 - oy)
            outside |= (ux > last_x) | (uy > last_y)
            ux = min(ux, last_x)  # (the reads stay in memory; the count is then not used)
            uy = min(uy, last_y)
            a = blend(np.float64(taps[uy, ux]), np.float64(taps[uy, ux + 1]), np.float64(taps[uy + 1, ux]),
                      np.float64(taps[uy + 1, ux + 1]), fx - x0, fy - y0)
            hits += passes(a, threshold, inclusive)
        if outside:
            return -1
        if hits >= need or (need <= n and hits + (first + n - b - step) < need):
            break
    return hits


@njit(cache=True, _nrt=False)
def micro_hits_with(value, threshold, inclusive, filt, mode_u, mode_v, corners, samples, k, need, taps):
    """Sample points of a micro-triangle (``micro_corners``) where the alpha test passes, of its
    4**k points (the centroids of its level-``k`` sub-triangles,
    ``samples[(4**k - 1) // 3:][:4**k]``), counted until the count can no longer end on the other
    side of ``need``: the result is >= need exactly when the full count is (``need`` > 4**k counts
    them all). ``taps`` (TAPS, TAPS): scratch (a kernel's, reused).

    Each point's answer is ``alpha_test.sample_passes``' -- the shader's fetch
    (``sampling.sample_texture``) compared with the threshold -- with the same arithmetic. This
    is the 4-state resolve's inner loop, so under the linear filter the points go in blocks
    (``_hits_from``): each point reads its four taps from the texture itself while they all lie
    inside it, or on a wrap axis inside one period of it (where addressing changes nothing but
    the period); a micro-triangle reaching the texture's edge reads the taps around its corners'
    box first (when they fit in ``taps``), each addressed once; else, or when a point's taps
    would leave that block, every point samples the texture on its own."""
    qax, qay, qbx, qby, qcx, qcy = corners
    first = ((1 << (2 * k)) - 1) // 3
    n = 1 << (2 * k)
    h, w = value.shape
    if filt == 1:
        xmin, ymin = min(min(qax, qbx), qcx), min(min(qay, qby), qcy)  # the corners' box
        xmax, ymax = max(max(qax, qbx), qcx), max(max(qay, qby), qcy)
        # on a wrap axis the texture repeats: a region whose taps lie within one period reads the
        # texture's own texels, whole periods over (the same points and arithmetic; the taps'
        # indices only skip the addressing)
        ox = (int(math.floor(xmin - 0.5)) // w) * w if mode_u == 0 else 0
        oy = (int(math.floor(ymin - 0.5)) // h) * h if mode_v == 0 else 0
        hits = _hits_from(value, ox, oy, w, h, threshold, inclusive, qax, qay, qbx, qby, qcx, qcy, samples, first, n,
                          need)
        if hits >= 0:
            return hits
        # the block: taps floor(p - 0.5) and + 1 of every point p of the corners' box widened by
        # e, far beyond the rounding of a point (a convex combination of the corners), so every
        # point's taps are in it
        e = 1e-6 * (1.0 + max(abs(xmin), abs(xmax)) + max(abs(ymin), abs(ymax)))
        bx = int(math.floor(xmin - 0.5 - e))
        by = int(math.floor(ymin - 0.5 - e))
        nx = int(math.floor(xmax - 0.5 + e)) - bx + 2
        ny = int(math.floor(ymax - 0.5 + e)) - by + 2
        if nx <= TAPS and ny <= TAPS:
            for j in range(np.uint64(ny)):  # unsigned indices: no negative-index checks
                row = address(by + np.int64(j), h, mode_v)
                for i in range(np.uint64(nx)):
                    taps[j, i] = np.float64(value[row, address(bx + np.int64(i), w, mode_u)])
            hits = _hits_from(taps, bx, by, nx, ny, threshold, inclusive, qax, qay, qbx, qby, qcx, qcy, samples,
                              first, n, need)
            if hits >= 0:
                return hits
    hits = 0
    for s in range(first, first + n):
        w1 = samples[s, 0]
        w2 = samples[s, 1]
        hits += sample_passes(value, threshold, inclusive, filt, mode_u, mode_v, bary_point(w1, w2, qax, qbx, qcx),
                              bary_point(w1, w2, qay, qby, qcy))
        # one rarely taken branch per point: the count reached ``need``, or cannot any more
        if hits == need or (need <= n and hits + (first + n - 1 - s) < need):
            break
    return hits


@njit(cache=True)
def micro_fraction(value, threshold, inclusive, filt, mode_u, mode_v, tri_texel, index, level, samples, k, taps):
    """Fraction of the sample points of micro-triangle ``index`` where the alpha test passes,
    and the micro-triangle's centroid (texel coordinates). The points are the centroids of its
    level-``k`` sub-triangles, ``samples[(4**k - 1) // 3:][:4**k]``; ``taps`` ``micro_hits_with``'s
    scratch."""
    q = micro_corners(tri_texel, index, level)
    n = 1 << (2 * k)
    hits = micro_hits_with(value, threshold, inclusive, filt, mode_u, mode_v, q, samples, k, n + 1, taps)
    return hits / n, (q[0] + q[2] + q[4]) / 3.0, (q[1] + q[3] + q[5]) / 3.0


def sample_points() -> np.ndarray:
    """Barycentric (b1, b2) of the centroids of the level-K sub-triangles, K = 0 .. 3 one after
    the other (level K starts at row (4**K - 1) / 3)."""
    return np.ascontiguousarray(np.concatenate([birdcurve.micro_triangles(k).mean(axis=1)
                                                for k in range(MAX_SAMPLE_LEVEL + 1)]))


def texel_triangles(test: AlphaTest, tris_uv) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(tris_uv, dtype=np.float64)
                                * np.array([test.width, test.height], dtype=np.float64))


def sample_levels(tris_texel: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Per triangle, the sample level K of its micro-triangles (see SAMPLES_PER_TEXEL)."""
    t = tris_texel
    area = 0.5 * np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
                        - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0]))
    want = np.maximum(SAMPLES_PER_TEXEL * area / np.power(4.0, levels), 1.0)
    return np.clip(np.ceil(np.log(want) / np.log(4.0) - 1e-9), 0, MAX_SAMPLE_LEVEL).astype(np.int64)


@njit(cache=True, parallel=True)
def _fractions(value, threshold, inclusive, filt, mu, mv, tris, levels, starts, samples, sample_k, out, n_workers):
    next_t = np.zeros(1, np.int64)
    for worker in prange(n_workers):  # each thread takes the next t as it frees up (``omaps.parallel``)
        while True:
            t = fetch_add(next_t, 1)
            if t >= tris.shape[0]:
                break
            taps = np.empty((TAPS, TAPS))
            for k in range(starts[t + 1] - starts[t]):
                f, _, _ = micro_fraction(value, threshold, inclusive, filt, mu, mv, tris[t], k, levels[t], samples,
                                         sample_k[t], taps)
                out[starts[t] + k] = f


def micro_fractions(test: AlphaTest, tris_uv, levels, starts=None) -> np.ndarray:
    """Opaque fraction of every micro-triangle of UV triangles (T, 3, 2), triangle t at
    ``levels[t]`` (or one level for all), flat in bird-curve order like
    ``bake.micromap.bake_micromaps``' states (``starts`` its offsets)."""
    from .bake.micromap import micro_starts

    tris = texel_triangles(test, tris_uv)
    lv = np.array(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)  # writable: one specialisation
    starts = micro_starts(lv) if starts is None else np.asarray(starts, dtype=np.int64)
    out = np.empty(int(starts[-1]), dtype=np.float64)
    filt, mu, mv = test.codes()
    _fractions(test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, lv, starts,
               sample_points(), sample_levels(tris, lv), out, numba.get_num_threads())
    return out


@njit(cache=True)
def _st_to_uv(uv6, has_b, s, t):
    """Texture (u, v) of square point (s, t) of a pair; ok False where a lone triangle has no B."""
    tri = 0 if t <= s else 1
    if tri == 1 and not has_b:
        return 0.0, 0.0, False
    u, v = square_uv(uv6, 3 * tri, tri, s, t)
    return u, v, True


@njit(cache=True, parallel=True)
def _cell_fractions(uv, has_b, n, k, value, thr, inclusive, filt, mode_u, mode_v, frac, centre, n_workers):
    h, w = value.shape
    next_p = np.zeros(1, np.int64)
    for worker in prange(n_workers):  # each thread takes the next p as it frees up (``omaps.parallel``)
        while True:
            p = fetch_add(next_p, 1)
            if p >= uv.shape[0]:
                break
            for j in range(n):
                for i in range(n):
                    hits = 0
                    total = 0
                    for b in range(k):
                        for a in range(k):
                            s = (i + (a + 0.5) / k) / n
                            t = (j + (b + 0.5) / k) / n
                            u, v, ok = _st_to_uv(uv[p], has_b[p], s, t)
                            if ok:
                                total += 1
                                if sample_passes(value, thr, inclusive, filt, mode_u, mode_v, u * w, v * h):
                                    hits += 1
                    frac[p, j, i] = hits / total if total else 0.0
                    u, v, ok = _st_to_uv(uv[p], has_b[p], (i + 0.5) / n, (j + 0.5) / n)
                    if not ok:  # a lone triangle's missing half: its cells are never hit
                        u, v, ok = _st_to_uv(uv[p], has_b[p], (j + 0.5) / n, (j + 0.5) / n)
                    centre[p, j, i, 0] = u * w
                    centre[p, j, i, 1] = v * h


def cell_fractions(test: AlphaTest, corner_uv: np.ndarray, has_b: np.ndarray, n: int,
                   k: int = CELL_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Opaque fraction (P, n, n) and texel-space centre (P, n, n, 2) of every cell of pairs with
    corner UVs (P, 6, 2) (``bake.square``'s layout), from K x K points per cell."""
    p = len(corner_uv)
    frac = np.zeros((p, n, n))
    centre = np.zeros((p, n, n, 2))
    filt, mu, mv = test.codes()
    _cell_fractions(np.ascontiguousarray(corner_uv, dtype=np.float64), np.ascontiguousarray(has_b, dtype=np.bool_),
                    n, k, np.ascontiguousarray(test.value), float(test.threshold), bool(test.inclusive), filt, mu, mv,
                    frac, centre, numba.get_num_threads())
    return frac, centre
