"""The alpha test an any-hit shader runs, and the opaque fraction of a micro-triangle.

An ``AlphaTest`` is the per-texel value the shader compares (alpha, times glTF's base colour
factor), the threshold and whether equality passes (omaps' ``--cutoff``: alpha > cutoff, like
``StateRule``; glTF's alphaCutoff: alpha >= cutoff), the filter and the addressing of u and v.
Its texel states (T/O, or C for a blended material's partial alpha) feed the baker; the test
itself, evaluated at sample points, gives a C micro-triangle's opaque fraction, which decides
its promotion (unknown-opaque or unknown-transparent, or O / T in 2-state output).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .. import birdcurve, states
from ..errors import InputError
from ..sampling import FILTERS, footprint_grid, sample_texture, wrap_code
from ..texel_states import StateRule
from ..texture import AlphaTexture

# Opaque fractions are measured at the centroids of the level-K sub-triangles of a micro-triangle,
# K the smallest giving 16 samples per texel of its area, at most 3 (64 samples).
SAMPLES_PER_TEXEL = 16
MAX_SAMPLE_LEVEL = 3
STATE_RULES = ("test", "blend", "unknown")


@dataclass(frozen=True)
class AlphaTest:
    """``value[y, x]`` (float64) passes when ``value > threshold`` (``>=`` if ``inclusive``).

    ``rule`` says how texels become states: ``test`` (O where the test passes, T elsewhere) or
    ``blend`` (an alpha-blended material: T only where value is 0, O only where it is 1, C
    between; the test then only decides promotions) or ``unknown`` (every texel C: a texture
    that could not be read). With ``test``, a texel whose value lies within ``tolerance`` of the
    threshold is C: a shader computing alpha * factor in its own float precision may decide it
    either way."""

    name: str
    value: np.ndarray
    threshold: float
    inclusive: bool = False
    filter: str = "nearest"
    wrap_u: str = "clamp"
    wrap_v: str = "clamp"
    rule: str = "test"
    tolerance: float = 0.0

    def __post_init__(self):
        if self.filter not in FILTERS:
            raise InputError(f"unknown filter {self.filter!r} (choose from {', '.join(FILTERS)})", self.name)
        wrap_code(self.wrap_u)
        wrap_code(self.wrap_v)
        if self.rule not in STATE_RULES:
            raise InputError(f"unknown state rule {self.rule!r}", self.name)
        if self.value.ndim != 2 or self.value.size == 0:
            raise InputError(f"alpha must be a non-empty 2-D array, got shape {self.value.shape}", self.name)

    @classmethod
    def from_cutoff(cls, texture: AlphaTexture, cutoff: float, filter="nearest", wrap="clamp"):
        """omaps' cutoff rule (``StateRule('cutoff')``): opaque iff alpha8 > cutoff * 255."""
        StateRule("cutoff", cutoff=cutoff)  # validates the cutoff
        return cls(texture.name, texture.alpha8, cutoff * 255.0, False, filter, wrap, wrap)

    @property
    def width(self) -> int:
        return int(self.value.shape[1])

    @property
    def height(self) -> int:
        return int(self.value.shape[0])

    def texel_states(self) -> np.ndarray:
        v = self.value
        if self.rule == "unknown":
            return np.full(v.shape, states.C, dtype=np.uint8)
        if self.rule == "blend":
            out = np.full(v.shape, states.C, dtype=np.uint8)
            out[v <= 0.0] = states.T
            out[v >= 1.0] = states.O
            return out
        passes = v >= self.threshold if self.inclusive else v > self.threshold
        out = np.where(passes, states.O, states.T).astype(np.uint8)
        if self.tolerance > 0:
            out[np.abs(v - self.threshold) <= self.tolerance] = states.C
        return out

    def grid(self):
        return footprint_grid(self.texel_states(), self.filter, self.wrap_u, self.wrap_v)

    def codes(self) -> tuple[int, int, int]:
        """(filter 0 nearest / 1 linear, wrap code of u, of v) for the numba kernels."""
        return FILTERS.index(self.filter), wrap_code(self.wrap_u), wrap_code(self.wrap_v)


@njit(cache=True)
def sample_passes(value, threshold, inclusive, filt, mode_u, mode_v, x, y):
    """The alpha test at texel coordinate (x, y): the fetch ``sampling.sample_texture`` (the
    tracer's too) compared with the threshold."""
    a = sample_texture(value, filt, mode_u, mode_v, x, y)
    return a >= threshold if inclusive else a > threshold


@njit(cache=True)
def micro_vertices(index, level):
    """Barycentric (b1, b2) of micro-triangle ``index``'s vertices (p0, p1, p2), walking the
    bird curve's digits from the top (the children of ``omaps.birdcurve``): a (3, 2) array."""
    a1, a2, b1, b2, c1, c2 = _micro_vertices(index, level)
    return np.array([[a1, a2], [b1, b2], [c1, c2]])


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
def micro_fraction(value, threshold, inclusive, filt, mode_u, mode_v, tri_texel, index, level, samples, k):
    """Fraction of the sample points of micro-triangle ``index`` where the alpha test passes,
    and the micro-triangle's centroid (texel coordinates). The points are the centroids of its
    level-``k`` sub-triangles, ``samples[(4**k - 1) // 3:][:4**k]``."""
    a1, a2, b1, b2, c1, c2 = _micro_vertices(index, level)
    # the micro-triangle's vertices in texel coordinates
    t = tri_texel
    qax = (1.0 - a1 - a2) * t[0, 0] + a1 * t[1, 0] + a2 * t[2, 0]
    qay = (1.0 - a1 - a2) * t[0, 1] + a1 * t[1, 1] + a2 * t[2, 1]
    qbx = (1.0 - b1 - b2) * t[0, 0] + b1 * t[1, 0] + b2 * t[2, 0]
    qby = (1.0 - b1 - b2) * t[0, 1] + b1 * t[1, 1] + b2 * t[2, 1]
    qcx = (1.0 - c1 - c2) * t[0, 0] + c1 * t[1, 0] + c2 * t[2, 0]
    qcy = (1.0 - c1 - c2) * t[0, 1] + c1 * t[1, 1] + c2 * t[2, 1]
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
    return hits / n, (qax + qbx + qcx) / 3.0, (qay + qby + qcy) / 3.0


def sample_points() -> np.ndarray:
    """Barycentric (b1, b2) of the centroids of the level-K sub-triangles, K = 0 .. 3 one after
    the other (level K starts at row (4**K - 1) / 3)."""
    return np.ascontiguousarray(np.concatenate([birdcurve.micro_triangles(k).mean(axis=1)
                                                for k in range(MAX_SAMPLE_LEVEL + 1)]))


def texel_triangles(test: AlphaTest, tris_uv) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(tris_uv, dtype=np.float64) * np.array([test.width, test.height], dtype=np.float64))


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


def opaque_fractions(test: AlphaTest, tris_uv, levels, starts) -> np.ndarray:
    """Opaque fraction (of the sample points) of every micro-triangle, float64, flat like
    ``bake.bake_levels``' states."""
    tris = texel_triangles(test, tris_uv)
    lv = np.ascontiguousarray(np.broadcast_to(np.asarray(levels), (len(tris),)), dtype=np.int64)
    out = np.empty(int(starts[-1]), dtype=np.float64)
    filt, mu, mv = test.codes()
    _fractions(test.value, float(test.threshold), bool(test.inclusive), filt, mu, mv, tris, lv,
               np.asarray(starts, dtype=np.int64), sample_points(), sample_levels(tris, lv), out)
    return out
