"""Hit -> region state, and the any-hit shader itself, as numba functions a filter calls.

A state function ``(table, tri, b1, b2) -> T/O/C`` reads one scheme's *stored* data: nothing
(``none``: always C), a per-triangle 2-bit micromap through the bird curve, a hierarchical
micromap by descent from its root (``succinctL``: rank queries on the triangle's tree;
``csmL``: references of the scene's merged DAG), or a pair's square
map through its codec's random-access ``lookup`` (the raw ``sqN`` map included), chosen by
its codec's format code (``codecs.block_state``, built from the codec registry). The shader is
``alpha_test.sample_passes`` on the material's texture values -- the same numbers and comparison
the bakers classified -- times the interpolated COLOR_0 alpha.
"""

from __future__ import annotations

import numpy as np
from numba import carray, njit

from .. import birdcurve, pair, states
from ..budget import HIT_LEVEL
from ..codecs import MAX_BLOCK_BYTES, block_state, csm_lookup, pair_block_state, read_state, succinct_lookup
from ..alpha_test import passes
from ..sampling import sample_texture
from .embree import f64_ptr, i8_ptr, i32_ptr, i64_ptr, u8_ptr, u16_ptr
from .tables import (T_COUNT, T_MAP_CODEC, T_MAP_DATA, T_MAP_FORMAT, T_MAP_LEVEL, T_MAP_OFFSET, T_MAP_PARAM, T_MAP_ROW, T_MAP_ROW_BYTES, T_MAT_FILTER, T_MAT_H, T_MAT_INCL,
                     T_MAT_TEX_START, T_MAT_THR, T_MAT_W, T_MAT_WRAP_U, T_MAT_WRAP_V, T_TEX, T_TRI_CORNER,
                     T_TRI_MAT, T_TRI_UV, T_TRI_VALPHA)

__all__ = ["clamp_bary", "hit_texel", "shader_alpha_test", "no_map_state", "micro_map_state", "mixed_map_state", "pair_map_state",
           "succinct_map_state", "csm_map_state", "state_function"]


@njit(cache=True, inline="always")
def clamp_bary(b1, b2):
    """Embree's barycentrics, clamped onto the triangle (every consumer uses the same point)."""
    b1 = max(np.float64(b1), 0.0)
    b2 = max(np.float64(b2), 0.0)
    s = b1 + b2
    if s > 1.0:
        b1 /= s
        b2 /= s
    return b1, b2


@njit(cache=True, inline="always")
def hit_texel(uv, tri, b1, b2, w, h):
    """The texel coordinate (x, y) of alpha triangle ``tri``'s hit at clamped barycentrics (b1,
    b2) in a ``w`` x ``h`` texture: its vertices' UVs (``uv``: 6 per triangle) interpolated,
    times the size. The shader fetches there; ``trace.memory`` counts the lines it reads."""
    w0 = 1.0 - b1 - b2
    o = 6 * tri
    u = w0 * uv[o] + b1 * uv[o + 2] + b2 * uv[o + 4]
    v = w0 * uv[o + 1] + b1 * uv[o + 3] + b2 * uv[o + 5]
    return u * w, v * h


@njit(cache=True)
def shader_alpha_test(table, tri, b1, b2):
    """The any-hit shader: the material's texture value at the hit (mip level 0, its filter and
    wrap, ``sampling.sample_texture``) times the interpolated vertex alpha, compared with the
    material's threshold (``alpha_test.AlphaTest``)."""
    m = i32_ptr(table[T_TRI_MAT])[tri]
    w = i64_ptr(table[T_MAT_W])[m]
    h = i64_ptr(table[T_MAT_H])[m]
    x, y = hit_texel(f64_ptr(table[T_TRI_UV]), tri, b1, b2, w, h)
    tex = carray(u16_ptr(table[T_TEX] + 2 * i64_ptr(table[T_MAT_TEX_START])[m]), (h, w))
    a = sample_texture(tex, i64_ptr(table[T_MAT_FILTER])[m], i64_ptr(table[T_MAT_WRAP_U])[m],
                       i64_ptr(table[T_MAT_WRAP_V])[m], x, y)
    va = f64_ptr(table[T_TRI_VALPHA])
    w0 = 1.0 - b1 - b2
    c = w0 * va[3 * tri] + b1 * va[3 * tri + 1] + b2 * va[3 * tri + 2]
    if c != 1.0:
        a = a * c
    thr = f64_ptr(table[T_MAT_THR])[m]
    return passes(a, thr, i64_ptr(table[T_MAT_INCL])[m] != 0)


@njit(cache=True)
def no_map_state(table, tri, b1, b2):
    return states.C


@njit(cache=True)
def micro_map_state(table, tri, b1, b2):
    """Raw 2-bit micromap of the triangle, micro-triangle from the bird curve."""
    k = birdcurve.bary_to_index(b1, b2, table[T_MAP_PARAM])
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    return read_state(u8_ptr(table[T_MAP_DATA]), row * table[T_MAP_ROW_BYTES], k)


@njit(cache=True)
def stored_micromap_state(table, tri, b1, b2):
    """A micromap stored in the traced file (scheme ``omm``): the triangle's row has its own
    level and byte offset; 2-bit T/O/C states, micro-triangle from the bird curve."""
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    k = birdcurve.bary_to_index(b1, b2, i32_ptr(table[T_MAP_LEVEL])[row])
    return read_state(u8_ptr(table[T_MAP_DATA]), i64_ptr(table[T_MAP_OFFSET])[row], k)


@njit(cache=True)
def succinct_map_state(table, tri, b1, b2):
    """A succinct micromap (scheme ``succinctL``): the triangle's row has the byte offset of its
    blob (``T_MAP_OFFSET``); micro-triangle from the bird curve, read by descent with rank
    queries (``codecs.succinct``). ``T_MAP_ROW_BYTES``: the data's length."""
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    level = table[T_MAP_PARAM]
    k = birdcurve.bary_to_index(b1, b2, level)
    data = carray(u8_ptr(table[T_MAP_DATA]), table[T_MAP_ROW_BYTES])
    return succinct_lookup(data, 8 * i64_ptr(table[T_MAP_OFFSET])[row], level, k)


@njit(cache=True)
def csm_map_state(table, tri, b1, b2):
    """The scene's merged micromaps (scheme ``csmL``): from the root of the triangle's row, one
    reference per level until a uniform subtree (``codecs.csm``)."""
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    level = table[T_MAP_PARAM]
    k = birdcurve.bary_to_index(b1, b2, level)
    return csm_lookup(carray(u8_ptr(table[T_MAP_DATA]), table[T_MAP_ROW_BYTES]), level, row, k)


@njit(cache=True)
def counting_state(table, tri, b1, b2):
    """No map (every candidate C), counting each triangle's candidate hits and recording where
    they fall: the view weights (``trace.view``). The int64 words: triangles n, record capacity,
    hits recorded, n counts, then per hit ``tri << 2 * HIT_LEVEL | micro-triangle at HIT_LEVEL``.
    Run on one thread: plain increments."""
    c = i64_ptr(table[T_COUNT])
    n = c[0]
    c[3 + tri] += 1
    k = c[2]
    if k < c[1]:
        c[3 + n + k] = (np.int64(tri) << (2 * HIT_LEVEL)) | birdcurve.bary_to_index(b1, b2, HIT_LEVEL)
    c[2] = k + 1
    return states.C


@njit(cache=True, inline="always")
def _pair_block_state(table, tri, b1, b2, fmt, off):
    """The hit's state in a pair's block of format ``fmt`` (its codec's format code, from the codec
    registry; 0 no map) at byte ``off`` of the map data, read with that codec's random-access
    lookup (``codecs.block_state``)."""
    if fmt == 0:
        return states.C
    s, t = pair.hit_st(i8_ptr(table[T_TRI_CORNER]), tri, b1, b2)
    return block_state(fmt, carray(u8_ptr(table[T_MAP_DATA] + off), MAX_BLOCK_BYTES), s, t)


@njit(cache=True)
def mixed_map_state(table, tri, b1, b2):
    """A budget's maps (``trace.budget``): the pair's row has a format code (its codec's) and
    the byte offset of its block; the hit's cell is read with that format's random-access lookup,
    or, for a block of the pair's micromaps, the hit's micro-triangle in its own triangle's tree
    (``codecs.pair_block_state``; the second triangle is the one with the square's corner (0, 1)).
    ``T_MAP_ROW_BYTES``: the data's length."""
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    fmt = i32_ptr(table[T_MAP_FORMAT])[row]
    if fmt == 0:
        return states.C
    off = i64_ptr(table[T_MAP_OFFSET])[row]
    corners = i8_ptr(table[T_TRI_CORNER])
    s, t = pair.hit_st(corners, tri, b1, b2)
    second = (corners[3 * tri] == pair.CORNER_01 or corners[3 * tri + 1] == pair.CORNER_01
              or corners[3 * tri + 2] == pair.CORNER_01)
    data = carray(u8_ptr(table[T_MAP_DATA] + off), table[T_MAP_ROW_BYTES] - off)
    return pair_block_state(fmt, data, s, t, second, b1, b2)


@njit(cache=True)
def pair_map_state(table, tri, b1, b2):
    """One codec's square maps (any ``sqN`` or codec), format code in the table's ``T_MAP_CODEC``
    word: the pair's row of ``T_MAP_ROW_BYTES`` bytes read with the codec's lookup."""
    row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
    return _pair_block_state(table, tri, b1, b2, table[T_MAP_CODEC], row * table[T_MAP_ROW_BYTES])


def state_function(sm):
    """The state function of a scene's scheme maps (``trace.maps.SchemeMaps``)."""
    if sm.kind == "none":
        return no_map_state
    if sm.kind == "micromap":
        return micro_map_state
    if sm.kind == "stored_micromap":
        return stored_micromap_state
    if sm.kind == "succinct":
        return succinct_map_state
    if sm.kind == "csm":
        return csm_map_state
    if sm.kind == "count":
        return counting_state
    if sm.kind == "mixed":
        return mixed_map_state
    return pair_map_state
