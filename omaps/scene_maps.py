"""Opacity maps of a scene's alpha-tested triangles: baked with their real UVs, then encoded.

Per *pair* (``omaps.pairing``) the square map lies over the pair's (s, t) parameterisation: the
N x N cell (i, j) covers s in [i/N, (i+1)/N], t in [j/N, (j+1)/N]; its part in triangle A
(t <= s) and its part in B (t >= s) are mapped to texture space by each triangle's own affine UV
map, and the cell is T (O) only if every footprint cell (texel or bilinear dual cell, with the
material's wrap) that either part overlaps is T (O). Per *triangle*, ``triL`` micromaps do the
same for the bird-curve micro-triangles. docs/FORMAT.md "Scenes" gives the mappings.

Robustness: a hit's cell (from barycentrics) and its texel (from interpolated UVs) come from two
floating-point computations of the same point. Each region is grown by ``EPS_TEXEL`` texels in
texture space (the Minkowski sum with a square) before rasterising, so a hit on a region's edge
can never read a texel the region did not count. Cost: a texel that a region only touches, or
misses by less than EPS_TEXEL, counts too.

Work is done per prototype mesh and per distinct (material, UVs) region set: instances and
repeated leaf cards share maps, as a BLAS shares them between instances.
"""

from __future__ import annotations

import hashlib
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
from numba import njit
from tqdm import tqdm

from . import birdcurve, maps, raster, states
from .pairing import Pairing, pair_triangles
from .sampling import footprint_grid
from .scene import Scene

EPS_TEXEL = 2.0 ** -20  # region growth in texels; far above float64 rounding of texel coordinates


# --------------------------------------------------------------------------------------------
# texel states of the scene's materials

def opaque_threshold(material) -> float:
    """8-bit alpha at or above which a sample is opaque: glTF's ``factor * alpha >= cutoff`` with
    alpha = texture alpha / 255, solved for the texture alpha."""
    f = material.base_colour[3]
    return np.inf if f <= 0 else material.cutoff * 255.0 / f


def texel_states(scene: Scene, mi: int) -> np.ndarray:
    """T/O state of every texel of material ``mi``'s base colour texture (one white texel when
    it has none)."""
    m = scene.materials[mi]
    alpha = scene.textures[m.texture].alpha if m.texture >= 0 else np.full((1, 1), 255, np.uint8)
    return np.where(alpha >= opaque_threshold(m), states.O, states.T).astype(np.uint8)


@dataclass
class GridTable:
    """Footprint grids of all materials, flattened for numba (``material`` indexes the rows)."""

    flags: np.ndarray  # uint8, all grids one after another
    start: np.ndarray  # int64 (M,)
    rows: np.ndarray  # int64 (M,)
    cols: np.ndarray
    period_x: np.ndarray
    period_y: np.ndarray
    offset: np.ndarray  # float64 (M,)
    width: np.ndarray  # texture size in texels
    height: np.ndarray


def grid_table(scene: Scene) -> GridTable:
    parts, rows = [], []
    start = 0
    for mi, m in enumerate(scene.materials):
        s = texel_states(scene, mi)
        g = footprint_grid(s, m.filter, m.wrap_u, m.wrap_v)
        parts.append(g.flags.ravel())
        rows.append((start, g.flags.shape[0], g.flags.shape[1], g.period_x, g.period_y, g.offset, g.width, g.height))
        start += g.flags.size
    r = np.array(rows, dtype=np.float64)
    i = r[:, :5].astype(np.int64)
    return GridTable(np.concatenate(parts).astype(np.uint8), i[:, 0], i[:, 1], i[:, 2], i[:, 3], i[:, 4],
                     r[:, 5].copy(), r[:, 6].astype(np.int64), r[:, 7].astype(np.int64))


# --------------------------------------------------------------------------------------------
# geometry kernels

@njit(cache=True)
def _clip(poly, k, a, b, c, out):
    """Convex polygon poly[:k] clipped to a*x + b*y + c >= 0, written to ``out``; returns the
    vertex count."""
    m = 0
    for i in range(k):
        p0 = poly[i]
        p1 = poly[(i + 1) % k]
        d0 = a * p0[0] + b * p0[1] + c
        d1 = a * p1[0] + b * p1[1] + c
        if d0 >= 0:
            out[m] = p0
            m += 1
        if (d0 >= 0) != (d1 >= 0):
            f = d0 / (d0 - d1)
            out[m, 0] = p0[0] + f * (p1[0] - p0[0])
            out[m, 1] = p0[1] + f * (p1[1] - p0[1])
            m += 1
    return m


@njit(cache=True)
def _area2(poly, k):
    a = 0.0
    for i in range(k):
        j = (i + 1) % k
        a += poly[i, 0] * poly[j, 1] - poly[j, 0] * poly[i, 1]
    return a


@njit(cache=True)
def _grid_view(gt_flags, start, rows, cols):
    return gt_flags[start:start + rows * cols].reshape(rows, cols)


@njit(cache=True)
def region_flag(flags, px, py, off, w, h, uvpoly, k, eps, pts):
    """OR of the footprint flags a UV polygon (k <= 8 vertices) grown by eps texels can read
    (``pts``: scratch of 8 points)."""
    for i in range(k):
        pts[i, 0] = uvpoly[i, 0] * w + off
        pts[i, 1] = uvpoly[i, 1] * h + off
    return raster.polygon_flags(flags, px, py, pts[:k], eps)


@njit(cache=True, inline="always")
def pair_weights(tri, s, t):
    """Weights of a square point (s, t) on the corners of triangle A (tri 0: (0,0), (1,0), (1,1),
    where t <= s) or B (tri 1: (0,0), (1,1), (0,1)), as docs/FORMAT.md's "Scenes" states."""
    if tri == 0:
        return 1.0 - s, s - t, t
    return 1.0 - t, s, t - s


@njit(cache=True)
def bake_pairs_kernel(uv, has_b, mat, n, eps, gflags, gstart, grows, gcols, gpx, gpy, goff, gw, gh):
    """Flags (P, n, n) of square maps. uv (P, 6, 2): UVs at corners (0,0), (1,0), (1,1) of A,
    then (0,0), (1,1), (0,1) of B. Flag 0 marks a cell no triangle reaches (a lone triangle's
    B half)."""
    npairs = uv.shape[0]
    out = np.zeros((npairs, n, n), np.uint8)
    rect = np.empty((4, 2))
    poly = np.empty((8, 2))
    poly_uv = np.empty((8, 2))
    scratch = np.empty((8, 2))
    for p in range(npairs):
        m = mat[p]
        flags = _grid_view(gflags, gstart[m], grows[m], gcols[m])
        for j in range(n):
            for i in range(n):
                s0 = i / n
                s1 = (i + 1) / n
                t0 = j / n
                t1 = (j + 1) / n
                rect[0, 0] = s0
                rect[0, 1] = t0
                rect[1, 0] = s1
                rect[1, 1] = t0
                rect[2, 0] = s1
                rect[2, 1] = t1
                rect[3, 0] = s0
                rect[3, 1] = t1
                acc = 0
                for tri in range(2):
                    if tri == 1 and not has_b[p]:
                        continue
                    if tri == 0:
                        if i < j:
                            continue  # wholly above the diagonal
                        k = _clip(rect, 4, 1.0, -1.0, 0.0, poly)  # s - t >= 0
                    else:
                        if i > j:
                            continue
                        k = _clip(rect, 4, -1.0, 1.0, 0.0, poly)  # t - s >= 0
                    if k < 3 or abs(_area2(poly, k)) <= 0.0:
                        continue
                    for v in range(k):
                        s = poly[v, 0]
                        t = poly[v, 1]
                        w0, w1, w2 = pair_weights(tri, s, t)
                        b = 3 * tri
                        for d in range(2):
                            poly_uv[v, d] = w0 * uv[p, b, d] + w1 * uv[p, b + 1, d] + w2 * uv[p, b + 2, d]
                    acc |= region_flag(flags, gpx[m], gpy[m], goff[m], gw[m], gh[m], poly_uv, k, eps, scratch)
                out[p, j, i] = acc
    return out


@njit(cache=True)
def bake_micro_kernel(uv, mat, bary, eps, gflags, gstart, grows, gcols, gpx, gpy, goff, gw, gh):
    """Flags (T, M) of per-triangle micromaps: uv (T, 3, 2) per vertex, bary (M, 3, 2) the
    micro-triangles' barycentric (b1, b2) vertices in bird-curve order."""
    nt = uv.shape[0]
    nm = bary.shape[0]
    out = np.zeros((nt, nm), np.uint8)
    poly_uv = np.empty((3, 2))
    scratch = np.empty((8, 2))
    for t in range(nt):
        m = mat[t]
        flags = _grid_view(gflags, gstart[m], grows[m], gcols[m])
        for k in range(nm):
            for v in range(3):
                b1 = bary[k, v, 0]
                b2 = bary[k, v, 1]
                w0 = 1.0 - b1 - b2
                for d in range(2):
                    poly_uv[v, d] = w0 * uv[t, 0, d] + b1 * uv[t, 1, d] + b2 * uv[t, 2, d]
            out[t, k] = region_flag(flags, gpx[m], gpy[m], goff[m], gw[m], gh[m], poly_uv, 3, eps, scratch)
    return out


@njit(cache=True)
def or_downsample(flags, factor):
    """Flags of an n/factor square map from an n one: a coarse cell reads what its fine cells read."""
    p, n, _ = flags.shape
    m = n // factor
    out = np.zeros((p, m, m), np.uint8)
    for q in range(p):
        for j in range(n):
            for i in range(n):
                out[q, j // factor, i // factor] |= flags[q, j, i]
    return out


def flags_to_states(flags: np.ndarray) -> np.ndarray:
    """Flag 0 (a cell no hit can reach) becomes C: a "don't care" that encoders never need to keep."""
    return states.FLAG_TO_STATE[flags]


# --------------------------------------------------------------------------------------------
# the scene's alpha triangles, pairs and distinct bake jobs

@dataclass
class AlphaTriangles:
    """Every alpha-tested triangle of the prototypes, in trace order: prototype p's alpha
    triangles are rows base[p] .. base[p+1]-1, in the order of its alpha geometry (primID)."""

    base: np.ndarray  # int64 (P + 1,)
    mesh_tri: np.ndarray  # int64 (T,) index of the triangle in its mesh
    material: np.ndarray  # int32 (T,)
    uv: np.ndarray  # float64 (T, 3, 2) per vertex
    corners: np.ndarray  # int8 (T, 3) square corner codes of the vertices (omaps.pairing)
    pair: np.ndarray  # int64 (T,) global pair index
    pair_first: np.ndarray  # int64 (Q,) row of the pair's A triangle
    pair_second: np.ndarray  # int64 (Q,) row of its B triangle, -1 for a lone triangle
    paired_fraction: float

    @property
    def count(self) -> int:
        return len(self.mesh_tri)


def alpha_triangles(scene: Scene, improve_pairing: bool = True) -> AlphaTriangles:
    alpha = scene.alpha_tested()
    base, mesh_tri, mat, uv, corners, pair, first, second = [0], [], [], [], [], [], [], []
    row0 = 0
    q0 = 0
    for mesh in scene.meshes:
        sel = alpha[mesh.material]
        rows = np.flatnonzero(sel)
        pr: Pairing = pair_triangles(mesh.triangles, mesh.positions, mesh.material, sel, improve_pairing)
        local = np.full(len(mesh.triangles), -1, np.int64)
        local[rows] = np.arange(len(rows)) + row0
        mesh_tri.append(rows)
        mat.append(mesh.material[rows])
        uv.append(mesh.uvs[mesh.triangles[rows]])
        corners.append(pr.corners[rows])
        pair.append(pr.pair_of[rows] + q0)
        first.append(local[pr.first])
        second.append(np.where(pr.second >= 0, local[np.maximum(pr.second, 0)], -1))
        row0 += len(rows)
        q0 += len(pr.first)
        base.append(row0)
    first_all = np.concatenate(first)
    second_all = np.concatenate(second)
    n = row0
    frac = 2 * int(np.count_nonzero(second_all >= 0)) / n if n else 0.0
    return AlphaTriangles(np.array(base, np.int64), np.concatenate(mesh_tri), np.concatenate(mat).astype(np.int32),
                          np.concatenate(uv).reshape(-1, 3, 2), np.concatenate(corners).astype(np.int8),
                          np.concatenate(pair), first_all, second_all, frac)


def pair_corner_uvs(at: AlphaTriangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pair: UVs at A's corners (0,0), (1,0), (1,1) and B's (0,0), (1,1), (0,1) (zeros for a
    lone triangle), whether B exists, and the material."""
    q = len(at.pair_first)
    out = np.zeros((q, 6, 2))
    a = at.pair_first
    b = at.pair_second
    order_a = np.argsort(at.corners[a], axis=1)  # corner codes 0,1,2 -> (0,0),(1,0),(1,1)
    out[:, 0:3] = np.take_along_axis(at.uv[a], order_a[:, :, None], axis=1)
    has_b = b >= 0
    if has_b.any():
        bb = b[has_b]
        # B's corners are codes 0, 2, 3 -> (0,0), (1,1), (0,1): sort gives exactly that order
        order_b = np.argsort(at.corners[bb], axis=1)
        out[has_b, 3:6] = np.take_along_axis(at.uv[bb], order_b[:, :, None], axis=1)
    return out, has_b, at.material[a]


def distinct_rows(*arrays) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the first occurrence of each distinct row across the arrays, and for every row
    the index of its distinct representative (0..D-1)."""
    parts = [np.ascontiguousarray(a).reshape(len(a), -1) for a in arrays]
    n = len(parts[0])
    keys = [hashlib.blake2b(b"".join(p[i].tobytes() for p in parts), digest_size=16).digest() for i in range(n)]
    seen: dict[bytes, int] = {}
    reps, inverse = [], np.empty(n, np.int64)
    for i, k in enumerate(keys):
        j = seen.get(k)
        if j is None:
            j = seen[k] = len(reps)
            reps.append(i)
        inverse[i] = j
    return np.array(reps, np.int64), inverse


# --------------------------------------------------------------------------------------------
# baking in worker processes

def _grid_args(gt: GridTable):
    return (gt.flags, gt.start, gt.rows, gt.cols, gt.period_x, gt.period_y, gt.offset, gt.width, gt.height)


def _bake_pairs_chunk(args):
    uv, has_b, mat, n, eps, grid = args
    return bake_pairs_kernel(uv, has_b, mat, n, eps, *grid)


def _bake_micro_chunk(args):
    uv, mat, bary, eps, grid = args
    return bake_micro_kernel(uv, mat, bary, eps, *grid)


def _run_chunks(fn, jobs_args, jobs: int, desc: str, progress: bool):
    bar = tqdm(total=len(jobs_args), desc=desc, unit="chunk", disable=not progress, leave=False)
    try:
        if jobs <= 1 or len(jobs_args) <= 1:
            out = []
            for a in jobs_args:
                out.append(fn(a))
                bar.update()
            return out
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            out = []
            for r in pool.map(fn, jobs_args):
                out.append(r)
                bar.update()
            return out
    finally:
        bar.close()


def _chunks(n: int, parts: int):
    edges = np.linspace(0, n, parts + 1).astype(int)
    return [(edges[k], edges[k + 1]) for k in range(parts) if edges[k + 1] > edges[k]]


def default_jobs(jobs: int | None) -> int:
    return max(1, os.cpu_count() or 1) if jobs is None else max(1, int(jobs))


def bake_square_flags(uv, has_b, mat, gt: GridTable, n: int, jobs: int = 1, progress: bool = False,
                      eps: float = EPS_TEXEL) -> np.ndarray:
    """Flags (P, n, n) of the pairs' square maps (see ``bake_pairs_kernel``)."""
    n = maps.check_square_size(n)
    grid = _grid_args(gt)
    bake_pairs_kernel(uv[:1], has_b[:1], mat[:1], 1, eps, *grid)  # compile before forking
    parts = _chunks(len(uv), 8 * jobs if jobs > 1 else 4)
    args = [(uv[a:b], has_b[a:b], mat[a:b], n, eps, grid) for a, b in parts]
    out = _run_chunks(_bake_pairs_chunk, args, jobs, f"bake {n}x{n}", progress)
    return np.concatenate(out) if out else np.zeros((0, n, n), np.uint8)


def bake_micro_flags(uv, mat, gt: GridTable, level: int, jobs: int = 1, progress: bool = False,
                     eps: float = EPS_TEXEL) -> np.ndarray:
    """Flags (T, 4**level) of per-triangle micromaps in bird-curve order."""
    level = maps.check_tri_level(level)
    bary = birdcurve.micro_triangles(level)
    grid = _grid_args(gt)
    bake_micro_kernel(uv[:1], mat[:1], bary[:1], eps, *grid)
    parts = _chunks(len(uv), 8 * jobs if jobs > 1 else 4)
    args = [(uv[a:b], mat[a:b], bary, eps, grid) for a, b in parts]
    out = _run_chunks(_bake_micro_chunk, args, jobs, f"bake tri{level}", progress)
    return np.concatenate(out) if out else np.zeros((0, 4 ** level), np.uint8)


# --------------------------------------------------------------------------------------------
# scheme maps: bake, deduplicate, encode

@dataclass
class SchemeMaps:
    """One scheme's maps as the tracer reads them: alpha triangle t uses row ``rows[t]`` of
    ``data`` (``row_bytes`` each). kind: "none" (no maps), "square" (raw 2-bit N x N map per pair,
    param N), "tri" (raw 2-bit micromap per triangle, param L), "codec" (encoded block per pair)."""

    name: str
    kind: str
    param: int
    rows: np.ndarray  # int32 (T,)
    data: np.ndarray  # uint8 (R * row_bytes,)
    row_bytes: int
    map_bytes: int  # storage of every prototype pair's (or triangle's) map, as a BLAS holds them
    distinct_maps: int
    known_fraction: float  # mean over pairs (triangles for tri) of the fraction of known regions
    codec: object = None


def pack_2bit(states_rows: np.ndarray) -> np.ndarray:
    """Rows of states (R, K) -> (R, ceil(K/4)) bytes; region k at bits 2(k mod 4) of byte k // 4."""
    s = np.asarray(states_rows, dtype=np.uint8)
    r, k = s.shape
    pad = (-k) % 4
    if pad:
        s = np.concatenate([s, np.zeros((r, pad), np.uint8)], axis=1)
    s = s.reshape(r, -1, 4)
    return (s[..., 0] | (s[..., 1] << 2) | (s[..., 2] << 4) | (s[..., 3] << 6)).astype(np.uint8)


def _dedupe_maps(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    flat = np.ascontiguousarray(m).reshape(len(m), -1)
    uniq, inverse = np.unique(flat, axis=0, return_inverse=True)
    return uniq.reshape((len(uniq),) + m.shape[1:]), inverse.ravel()


def _encode_chunk(args):
    from .codecs.registry import get_codec

    name, maps_, encoder, effort = args
    codec = get_codec(name)
    return [codec.encode(m, encoder, effort) for m in maps_]


def parse_trace_schemes(text: str) -> list[str]:
    """Scheme names for the tracer: none, sqN, triL, or a codec name; checked, in order."""
    import re

    from .codecs.registry import codec_names, get_codec
    from .errors import InputError

    names = [n.strip().lower() for n in str(text).split(",") if n.strip()]
    if not names:
        raise InputError("no schemes given")
    out = []
    for n in names:
        if n == "none":
            pass
        elif re.fullmatch(r"sq\d+", n):
            maps.check_square_size(int(n[2:]))
        elif re.fullmatch(r"tri\d+", n):
            maps.check_tri_level(int(n[3:]))
        elif n in codec_names():
            get_codec(n)
        else:
            raise InputError(f"unknown scheme {n!r} for tracing (none, sqN, triL, {', '.join(codec_names())})")
        if n not in out:
            out.append(n)
    return out


def build_scheme_maps(at: AlphaTriangles, gt: GridTable, names: list[str], jobs: int = 1,
                      effort: str = "medium", progress: bool = False, eps: float = EPS_TEXEL) -> dict[str, SchemeMaps]:
    """Bake (once per distinct pair / triangle, at the finest square size asked for) and encode
    every scheme's maps."""
    from .codecs.registry import get_codec
    from .states import is_conservative

    out: dict[str, SchemeMaps] = {}
    if at.count == 0:  # nothing alpha-tested: no maps, the filter is never called
        for name in names:
            kind = "none" if name == "none" else ("square" if name.startswith("sq") else
                                                  "tri" if name.startswith("tri") else "codec")
            codec = get_codec(name) if kind == "codec" else None
            param = codec.map_size if codec else (int(name.lstrip("sqtri")) if kind != "none" else 0)
            out[name] = SchemeMaps(name, kind, param, np.zeros(0, np.int32), np.zeros(1, np.uint8), 1, 0, 0, 0.0,
                                   codec)
        return out
    n_pairs = len(at.pair_first)
    square_sizes = {}
    codecs = {}
    for n in names:
        if n.startswith("sq"):
            square_sizes[n] = int(n[2:])
        elif n not in ("none",) and not n.startswith("tri"):
            codecs[n] = get_codec(n)
            square_sizes[n] = codecs[n].map_size
    pair_states: dict[int, np.ndarray] = {}
    pair_inverse = None
    if square_sizes:
        uv, has_b, mat = pair_corner_uvs(at)
        reps, pair_inverse = distinct_rows(uv, has_b, mat)
        finest = max(square_sizes.values())
        flags = bake_square_flags(uv[reps], has_b[reps], mat[reps], gt, finest, jobs, progress, eps)
        for n in sorted(set(square_sizes.values())):
            f = flags if n == finest else or_downsample(flags, finest // n)
            pair_states[n] = flags_to_states(f)
    for name in names:
        if name == "none":
            out[name] = SchemeMaps(name, "none", 0, np.zeros(at.count, np.int32), np.zeros(1, np.uint8), 1, 0, 0, 0.0)
            continue
        if name.startswith("tri"):
            level = int(name[3:])
            reps_t, inv_t = distinct_rows(at.uv, at.material)
            st = flags_to_states(bake_micro_flags(at.uv[reps_t], at.material[reps_t], gt, level, jobs, progress, eps))
            uniq, inv_u = _dedupe_maps(st)
            rows = inv_u[inv_t].astype(np.int32)
            data = pack_2bit(uniq)
            known = float(np.mean((st != states.C).mean(axis=1)[inv_t])) if at.count else 0.0
            out[name] = SchemeMaps(name, "tri", level, rows, data.ravel(), data.shape[1],
                                   at.count * data.shape[1], len(uniq), known)
            continue
        n = square_sizes[name]
        st = pair_states[n]  # distinct pairs
        uniq, inv_u = _dedupe_maps(st)
        pair_rows = inv_u[pair_inverse]  # every pair -> its distinct map
        known = float(np.mean((st != states.C).reshape(len(st), -1).mean(axis=1)[pair_inverse])) if n_pairs else 0.0
        if name in codecs:
            codec = codecs[name]
            encoder = "best" if "best" in codec.encoders else codec.encoders[0]
            eff = effort if effort in codec.efforts else codec.efforts[0]
            first = [codec.encode(uniq[0], encoder, eff)] if len(uniq) else []  # compiles before forking
            parts = _chunks(len(uniq) - len(first), 8 * jobs if jobs > 1 else 1)
            rest = _run_chunks(_encode_chunk, [(name, uniq[1 + a:1 + b], encoder, eff) for a, b in parts],
                               jobs, f"encode {name}", progress)
            blocks = first + [b for chunk in rest for b in chunk]
            data = np.frombuffer(b"".join(blocks), dtype=np.uint8).reshape(len(uniq), codec.block_bytes)
            decoded = np.stack([codec.decode(b) for b in blocks]) if blocks else uniq
            if not is_conservative(uniq, decoded):
                raise RuntimeError(f"internal error: {name} encoder changed a known state")
            known = float(np.mean((decoded != states.C).reshape(len(decoded), -1).mean(axis=1)[pair_rows])) \
                if n_pairs else 0.0
            out[name] = SchemeMaps(name, "codec", n, pair_rows[at.pair].astype(np.int32), data.ravel().copy(),
                                   codec.block_bytes, n_pairs * codec.block_bytes, len(uniq), known, codec)
        else:
            data = pack_2bit(uniq.reshape(len(uniq), -1))
            out[name] = SchemeMaps(name, "square", n, pair_rows[at.pair].astype(np.int32), data.ravel(),
                                   data.shape[1], n_pairs * data.shape[1], len(uniq), known)
    return out
