"""The tracer's 2-state mode: square maps with every C cell resolved to O or T, so no ray ever
runs the any-hit shader (the deck's future work "hash/dither {O, C, T} -> {O, T}").

This is not conservative: it trades exact visibility for zero alpha tests, as hardware that
forces 2-state micromaps does. Each C cell of a pair's square map (``sqN`` or a codec's decoded
map) becomes O or T by ``omaps.omm.resolve``'s rule on the cell's opaque fraction -- the share
of K x K sample points of the cell, mapped through the pair's triangles to texture space, that
pass the material's alpha test -- with ``hashed`` comparing it to a threshold hashed from the
cell centre's texel position. T and O cells keep their states.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import states
from .omm.alpha_test import sample_passes
from .omm.resolve import PROMOTIONS, resolve_regions
from .sampling import wrap_code
from .scene_maps import pair_weights

MODES = PROMOTIONS  # nearest (majority), opaque, transparent, hashed
SAMPLES = 4  # K: K x K sample points per cell


@njit(cache=True)
def _st_to_uv(uv6, has_b, s, t):
    """Texture (u, v) of square point (s, t) of a pair (``scene_maps.pair_weights``); ok False
    where a lone triangle has no B."""
    tri = 0 if t <= s else 1
    if tri == 1 and not has_b:
        return 0.0, 0.0, False
    w0, w1, w2 = pair_weights(tri, s, t)
    o = 3 * tri
    u = w0 * uv6[o, 0] + w1 * uv6[o + 1, 0] + w2 * uv6[o + 2, 0]
    v = w0 * uv6[o, 1] + w1 * uv6[o + 1, 1] + w2 * uv6[o + 2, 1]
    return u, v, True


@njit(cache=True, parallel=True)
def _fractions(uv, has_b, n, k, value, thr, filt, mode_u, mode_v, frac, centre):
    """Per pair (uv (P, 6, 2) corner UVs) and cell: opaque fraction of the K x K samples that land
    on a triangle, and the cell centre in texel coordinates."""
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
                            if sample_passes(value, thr, True, filt, mode_u, mode_v, u * w, v * h):
                                hits += 1
                frac[p, j, i] = hits / total if total else 0.0
                u, v, ok = _st_to_uv(uv[p], has_b[p], (i + 0.5) / n, (j + 0.5) / n)
                if not ok:  # a lone triangle's missing half: its cells are never hit
                    u, v, ok = _st_to_uv(uv[p], has_b[p], (j + 0.5) / n, (j + 0.5) / n)
                centre[p, j, i, 0] = u * w
                centre[p, j, i, 1] = v * h


def cell_fractions(scene, uv: np.ndarray, has_b: np.ndarray, material: np.ndarray, n: int,
                   k: int = SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Opaque fraction (P, n, n) and texel-space centre (P, n, n, 2) of every cell of every
    pair (corner UVs ``uv`` (P, 6, 2) as ``scene_maps.pair_corner_uvs`` gives them)."""
    from .scene_maps import opaque_threshold

    p = len(uv)
    frac = np.zeros((p, n, n))
    centre = np.zeros((p, n, n, 2))
    for mi in np.unique(material):
        sel = np.flatnonzero(material == mi)
        m = scene.materials[mi]
        value = scene.textures[m.texture].alpha if m.texture >= 0 else np.full((1, 1), 255, np.uint8)
        f = np.zeros((len(sel), n, n))
        c = np.zeros((len(sel), n, n, 2))
        _fractions(np.ascontiguousarray(uv[sel]), np.ascontiguousarray(has_b[sel]), n, k,
                   np.ascontiguousarray(value), float(opaque_threshold(m)), 0 if m.filter == "nearest" else 1,
                   wrap_code(m.wrap_u), wrap_code(m.wrap_v), f, c)
        frac[sel] = f
        centre[sel] = c
    return frac, centre


def decoded_pair_maps(sm, at) -> np.ndarray:
    """The (P, n, n) map every pair's hits read in a square or codec scheme."""
    rb = sm.row_bytes
    n_rows = len(sm.data) // rb
    rows = sm.data.reshape(n_rows, rb)
    if sm.kind == "codec":
        uniq = np.stack([sm.codec.decode(r.tobytes()) for r in rows])
    elif sm.kind == "square":
        n = sm.param
        cells = np.stack([(rows >> (2 * q)) & 3 for q in range(4)], axis=-1).reshape(n_rows, -1)[:, :n * n]
        uniq = cells.reshape(n_rows, n, n).astype(np.uint8)
    else:
        raise ValueError(f"2-state maps need a square or codec scheme, not {sm.kind!r}")
    return uniq[sm.rows[at.pair_first]]


def two_state_maps(scene, at, sm, mode: str, seed: int = 0, cache: dict | None = None):
    """A ``scene_maps.SchemeMaps`` of kind "square" (states 0 and 1 only) for scheme ``sm``."""
    from . import scene_maps

    if mode not in MODES:
        raise ValueError(f"unknown 2-state mode {mode!r} (choose from {', '.join(MODES)})")
    n = sm.param
    cache = {} if cache is None else cache
    if "pairs" not in cache:  # the same for every scheme and rule
        uv, has_b, mat = scene_maps.pair_corner_uvs(at)
        cache["pairs"] = (uv, has_b, mat) + scene_maps.distinct_rows(uv, has_b, mat)
    uv, has_b, mat, reps, inverse = cache["pairs"]
    key = ("fractions", n)
    if key not in cache:
        cache[key] = cell_fractions(scene, uv[reps], has_b[reps], mat[reps], n)
    frac, centre = cache[key]
    three = decoded_pair_maps(sm, at)[reps]
    two = resolve_regions(three, frac, centre, mode, seed)
    assert not np.any((three != states.C) & (two != three))  # known cells keep their state
    uniq, inv_u = scene_maps._dedupe_maps(two)
    rows = inv_u[inverse[at.pair]].astype(np.int32)
    data = scene_maps.pack_2bit(uniq.reshape(len(uniq), -1))
    n_pairs = len(at.pair_first)
    return scene_maps.SchemeMaps(f"{sm.name}/{mode}", "square", n, rows, data.ravel(), data.shape[1],
                                 n_pairs * n * n // 8, len(uniq), 1.0)


def coverage_error(run, ref) -> dict:
    """Per-pixel visibility error of a 2-state run against the alpha-tested reference: pixels
    whose hit differs, split into those where the 2-state ray stopped earlier (a transparent
    region taken as opaque) and later (an opaque region taken as transparent)."""
    a, b = run.primary, ref.primary
    n = a.dist.size
    differ = (a.inst != b.inst) | (a.geom != b.geom) | (a.prim != b.prim) | (a.dist != b.dist)
    early = differ & (a.dist < b.dist)
    late = differ & (a.dist > b.dist)
    return {"differing_pixels": int(differ.sum()), "differing_fraction": float(differ.sum()) / n,
            "stopped_early_fraction": float(early.sum()) / n, "passed_through_fraction": float(late.sum()) / n,
            "alpha_tests_per_primary_ray": float(a.tests.sum()) / n}
