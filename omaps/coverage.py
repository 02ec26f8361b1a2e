"""Opaque fractions: how much of a region the alpha test finds opaque, measured by sampling it.

A C region (a micro-triangle, a square map's cell) is neither all T nor all O; its opaque
fraction -- the share of sample points inside it where ``alpha_test.sample_passes`` (the shader's
own test) passes -- decides what it becomes when it must be O or T (``omaps.promotion``): the
OMM's unknown-opaque / unknown-transparent and 2-state outputs, and the tracer's 2-state mode.

* micro-triangles: the centroids of their level-K sub-triangles, K the smallest giving 16 samples
  per texel of the micro-triangle's area, at most 3 (64 samples);
* square cells of a pair: K x K points of the cell, each mapped through the pair triangle it
  lies in (``pair.pair_weights``).

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

import numpy as np
from numba import njit, prange

from . import birdcurve
from .alpha_test import AlphaTest, sample_passes
from .pair import pair_weights

__all__ = ["micro_fractions", "cell_fractions", "micro_vertices", "micro_corners", "micro_hits", "SAMPLES_PER_TEXEL",
           "MAX_SAMPLE_LEVEL", "CELL_SAMPLES"]

SAMPLES_PER_TEXEL = 16
MAX_SAMPLE_LEVEL = 3
CELL_SAMPLES = 4  # K x K points per square cell


@njit(cache=True, inline="always")
def _micro_vertices(index, level):
    a1, a2, b1, b2, c1, c2 = 0.0, 0.0, 1.0, 0.0, 0.0, 1.0  # p0, p1, p2
    for d in range(level - 1, -1, -1):
        c = (index >> (2 * d)) & 3
        m01 = (0.5 * (a1 + b1), 0.5 * (a2 + b2))
        m12 = (0.5 * (b1 + c1), 0.5 * (b2 + c2))
        m02 = (0.5 * (a1 + c1), 0.5 * (a2 + c2))
        if c == 0:
            b1, b2 = m01
            c1, c2 = m02
        elif c == 1:
            a1, a2 = m02
            b1, b2 = m12
            c1, c2 = m01
        elif c == 2:
            a1, a2 = m01
            c1, c2 = m12
        else:
            a1, a2 = m12
            b1, b2 = m02
    return a1, a2, b1, b2, c1, c2


@njit(cache=True)
def micro_vertices(index, level):
    """Barycentric (b1, b2) of micro-triangle ``index``'s vertices (p0, p1, p2), walking the
    bird curve's digits from the top (the children of ``omaps.birdcurve``): a (3, 2) array."""
    a1, a2, b1, b2, c1, c2 = _micro_vertices(index, level)
    return np.array([[a1, a2], [b1, b2], [c1, c2]])


@njit(cache=True)
def micro_corners(tri_texel, index, level):
    """Texel coordinates (ax, ay, bx, by, cx, cy) of micro-triangle ``index``'s vertices."""
    a1, a2, b1, b2, c1, c2 = _micro_vertices(index, level)
    t = tri_texel
    qax = (1.0 - a1 - a2) * t[0, 0] + a1 * t[1, 0] + a2 * t[2, 0]
    qay = (1.0 - a1 - a2) * t[0, 1] + a1 * t[1, 1] + a2 * t[2, 1]
    qbx = (1.0 - b1 - b2) * t[0, 0] + b1 * t[1, 0] + b2 * t[2, 0]
    qby = (1.0 - b1 - b2) * t[0, 1] + b1 * t[1, 1] + b2 * t[2, 1]
    qcx = (1.0 - c1 - c2) * t[0, 0] + c1 * t[1, 0] + c2 * t[2, 0]
    qcy = (1.0 - c1 - c2) * t[0, 1] + c1 * t[1, 1] + c2 * t[2, 1]
    return qax, qay, qbx, qby, qcx, qcy


@njit(cache=True)
def micro_hits(value, threshold, inclusive, filt, mode_u, mode_v, corners, samples, k, need):
    """Sample points of a micro-triangle (``micro_corners``) where the alpha test passes, of
    its 4**k points (the centroids of its level-``k`` sub-triangles,
    ``samples[(4**k - 1) // 3:][:4**k]``), counted until the count can no longer end on the
    other side of ``need``: the result is >= need exactly when the full count is (``need`` >
    4**k counts them all)."""
    qax, qay, qbx, qby, qcx, qcy = corners
    first = ((1 << (2 * k)) - 1) // 3
    n = 1 << (2 * k)
    hits = 0
    for s in range(first, first + n):
        w1 = samples[s, 0]
        w2 = samples[s, 1]
        w0 = 1.0 - w1 - w2
        if sample_passes(value, threshold, inclusive, filt, mode_u, mode_v,
                         w0 * qax + w1 * qbx + w2 * qcx, w0 * qay + w1 * qby + w2 * qcy):
            hits += 1
            if hits == need:
                break
        elif need <= n and hits + (first + n - 1 - s) < need:
            break
    return hits


@njit(cache=True)
def micro_fraction(value, threshold, inclusive, filt, mode_u, mode_v, tri_texel, index, level, samples, k):
    """Fraction of the sample points of micro-triangle ``index`` where the alpha test passes,
    and the micro-triangle's centroid (texel coordinates). The points are the centroids of its
    level-``k`` sub-triangles, ``samples[(4**k - 1) // 3:][:4**k]``."""
    q = micro_corners(tri_texel, index, level)
    n = 1 << (2 * k)
    hits = micro_hits(value, threshold, inclusive, filt, mode_u, mode_v, q, samples, k, n + 1)
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
def _fractions(value, threshold, inclusive, filt, mu, mv, tris, levels, starts, samples, sample_k, out):
    for t in prange(tris.shape[0]):
        for k in range(starts[t + 1] - starts[t]):
            f, _, _ = micro_fraction(value, threshold, inclusive, filt, mu, mv, tris[t], k, levels[t], samples,
                                     sample_k[t])
            out[starts[t] + k] = f


def micro_fractions(test: AlphaTest, tris_uv, levels, starts=None) -> np.ndarray:
    """Opaque fraction of every micro-triangle of UV triangles (T, 3, 2), triangle t at
    ``levels[t]`` (or one level for all), flat in bird-curve order like
    ``bake.micromap.bake_micromaps``' states (``starts`` its offsets)."""
    from .bake.micromap import micro_starts

    tris = texel_triangles(test, tris_uv)
    lv = np.ascontiguousarray(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)
    starts = micro_starts(lv) if starts is None else np.asarray(starts, dtype=np.int64)
    out = np.empty(int(starts[-1]), dtype=np.float64)
    filt, mu, mv = test.codes()
    _fractions(test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, lv, starts,
               sample_points(), sample_levels(tris, lv), out)
    return out


@njit(cache=True)
def _st_to_uv(uv6, has_b, s, t):
    """Texture (u, v) of square point (s, t) of a pair; ok False where a lone triangle has no B."""
    tri = 0 if t <= s else 1
    if tri == 1 and not has_b:
        return 0.0, 0.0, False
    w0, w1, w2 = pair_weights(tri, s, t)
    o = 3 * tri
    u = w0 * uv6[o, 0] + w1 * uv6[o + 1, 0] + w2 * uv6[o + 2, 0]
    v = w0 * uv6[o, 1] + w1 * uv6[o + 1, 1] + w2 * uv6[o + 2, 1]
    return u, v, True


@njit(cache=True, parallel=True)
def _cell_fractions(uv, has_b, n, k, value, thr, inclusive, filt, mode_u, mode_v, frac, centre):
    h, w = value.shape
    for p in prange(uv.shape[0]):
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
                    frac, centre)
    return frac, centre
