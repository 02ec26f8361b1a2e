"""The ray loops: primary rays from a camera and shadow rays towards a directional light, in
parallel numba calling ``rtcIntersect1`` / ``rtcOccluded1`` through their addresses.

Shadow rays start at each primary hit. The *deferred* mode (the deck's future work) first looks
for an O hit along the ray, recording C candidates without testing them, and alpha-tests the
recorded candidates only when no O hit exists: same occlusion, fewer tests.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange

from ..parallel import fetch_add
from .embree import (ARGS_WORDS, RAYHIT_WORDS, RTC_FEATURE_FLAG_ALL, RTC_INVALID_GEOMETRY_ID, W_GEOM, W_INST,
                     W_PRIM, W_TFAR, W_U, W_V, call3, i64_ptr)
from .lookups import shader_alpha_test
from .tables import (C_CALLS, C_CAND, C_MODE, C_REC_BARY, C_REC_CAP, C_REC_N, C_REC_TRI, C_SET_FULL, C_SET_KEYS,
                     C_SET_STAMPS, C_STAMP, C_TABLE, C_TESTS, CONTEXT_WORDS, MODE_NORMAL, MODE_RECORD, REC_CAP,
                     SET_SIZE, TraceTables)

__all__ = ["PrimaryResult", "ShadowResult", "run_primary", "run_shadow"]


@njit(cache=True)
def _aligned(words):
    """A zeroed int64 array of ``words`` elements whose data starts on a 64-byte boundary."""
    a = np.zeros(words + 8, np.int64)
    off = ((-a.ctypes.data) & 63) // 8
    return a[off:off + words]


@njit(cache=True)
def _new_context(table_addr, rec_cap):
    """A ray query context for the filter (``tables``' C_* words) that owns what it points at: one
    64-byte-aligned buffer holds the context words, the candidate set's keys and stamps and a
    record of ``rec_cap`` candidates (triangles, then their barycentrics as float64). The
    filter reaches them through raw addresses, so they must live as long as the context: numba
    frees an array after its last use in the kernel, and the context is the one array the
    kernel uses while it traces. Returns (context, record triangles, record barycentrics)."""
    buf = _aligned(CONTEXT_WORDS + 2 * SET_SIZE + 3 * rec_cap)
    ctx = buf[:CONTEXT_WORDS]  # a view: it keeps the whole buffer alive
    keys = buf[CONTEXT_WORDS:CONTEXT_WORDS + SET_SIZE]
    stamps = buf[CONTEXT_WORDS + SET_SIZE:CONTEXT_WORDS + 2 * SET_SIZE]
    stamps[:] = -1
    rec_tri = buf[CONTEXT_WORDS + 2 * SET_SIZE:CONTEXT_WORDS + 2 * SET_SIZE + rec_cap]
    rec_bary = buf[CONTEXT_WORDS + 2 * SET_SIZE + rec_cap:].view(np.float64)
    ctx[0] = -1  # RTCRayQueryContext: instID[0] (and instPrimID[0]) = RTC_INVALID_GEOMETRY_ID
    ctx[C_TABLE] = table_addr
    ctx[C_SET_KEYS] = keys.ctypes.data
    ctx[C_SET_STAMPS] = stamps.ctypes.data
    ctx[C_REC_TRI] = rec_tri.ctypes.data
    ctx[C_REC_BARY] = rec_bary.ctypes.data
    ctx[C_REC_CAP] = rec_cap
    return ctx, rec_tri, rec_bary


@njit(cache=True)
def _row_query(table_addr, filt, rec_cap):
    """What a thread traces one image row with: the ray-hit buffer (as uint32 and float32), the
    query context (``_new_context``) with its record arrays, and the arguments of Embree's
    intersect / occluded call (feature mask, context, filter)."""
    rh = _aligned(RAYHIT_WORDS // 2).view(np.uint32)
    rf = rh.view(np.float32)
    ctx, rec_tri, rec_bary = _new_context(table_addr, rec_cap)
    args = _aligned(ARGS_WORDS)
    args[0] = np.int64(RTC_FEATURE_FLAG_ALL) << 32
    args[1] = ctx.ctypes.data
    args[2] = filt
    return rh, rf, ctx, args, rec_tri, rec_bary


@njit(cache=True, inline="always")
def _set_ray(rh, ox, oy, oz, dx, dy, dz, tnear, tfar):
    f = rh.view(np.float32)
    f[0] = ox
    f[1] = oy
    f[2] = oz
    f[3] = tnear
    f[4] = dx
    f[5] = dy
    f[6] = dz
    f[7] = 0.0
    f[W_TFAR] = tfar
    rh[9] = 0xFFFFFFFF  # mask
    rh[10] = 0
    rh[11] = 0
    rh[W_GEOM] = RTC_INVALID_GEOMETRY_ID
    rh[W_INST] = RTC_INVALID_GEOMETRY_ID


@njit(cache=True, inline="always")
def _camera_dir(cam, x, y, w, h):
    """Direction through pixel (x, y): cam = eye(3), forward(3), right(3), up(3) with right and
    up scaled by the half-extent of the image plane at distance 1."""
    sx = (2.0 * (x + 0.5) / w - 1.0)
    sy = (1.0 - 2.0 * (y + 0.5) / h)
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx / n, dy / n, dz / n


@njit(cache=True, inline="always")
def _start_ray(ctx, mode, stamp):
    ctx[C_MODE] = mode
    ctx[C_CAND] = 0
    ctx[C_TESTS] = 0
    ctx[C_REC_N] = 0
    ctx[C_STAMP] = stamp


@njit(parallel=True, cache=True)
def trace_primary(fn, scene, filt, table_addr, cam, w, h, inst, geom, prim, dist, bu, bv, cand, tests, calls, full,
                  n_workers):
    """Closest hits of the camera's rays; per pixel the hit (instance, geometry, primitive,
    distance, barycentrics) and the counts of distinct candidates and alpha tests."""
    next_y = np.zeros(1, np.int64)
    for worker in prange(n_workers):  # each thread takes the next y as it frees up (``omaps.parallel``)
        while True:
            y = fetch_add(next_y, 1)
            if y >= h:
                break
            rh, rf, ctx, args, _, _ = _row_query(table_addr, filt, 1)  # (primary rays record nothing)
            for x in range(w):
                dx, dy, dz = _camera_dir(cam, x, y, w, h)
                _set_ray(rh, cam[0], cam[1], cam[2], dx, dy, dz, 0.0, np.inf)
                _start_ray(ctx, MODE_NORMAL, y * w + x)
                ctx[C_CALLS] = 0
                call3(fn, scene, rh.ctypes.data, args.ctypes.data)
                g = rh[W_GEOM]
                if g == RTC_INVALID_GEOMETRY_ID:
                    inst[y, x] = -1
                    geom[y, x] = -1
                    prim[y, x] = -1
                    dist[y, x] = np.inf
                else:
                    inst[y, x] = rh[W_INST]
                    geom[y, x] = g
                    prim[y, x] = rh[W_PRIM]
                    dist[y, x] = rf[W_TFAR]
                    bu[y, x] = rf[W_U]
                    bv[y, x] = rf[W_V]
                cand[y, x] = ctx[C_CAND]
                tests[y, x] = ctx[C_TESTS]
                calls[y, x] = ctx[C_CALLS]
            full[y] = ctx[C_SET_FULL]


@njit(parallel=True, cache=True)
def trace_shadow(fn, scene, filt, table_addr, cam, light, tnear, deferred, w, h, dist, occluded, cand, tests,
                 overflow, n_workers):
    """Occlusion rays towards the light (direction ``light``) from every primary hit. Deferred:
    first an occlusion query that records C candidates untested; if it finds no O hit, the
    recorded candidates are alpha-tested in order until one is opaque."""
    next_y = np.zeros(1, np.int64)
    for worker in prange(n_workers):  # each thread takes the next y as it frees up (``omaps.parallel``)
        while True:
            y = fetch_add(next_y, 1)
            if y >= h:
                break
            rh, rf, ctx, args, rec_tri, rec_bary = _row_query(table_addr, filt, REC_CAP)
            table = i64_ptr(table_addr)
            for x in range(w):
                occluded[y, x] = 0
                cand[y, x] = 0
                tests[y, x] = 0
                t = dist[y, x]
                if not np.isfinite(t):
                    continue
                dx, dy, dz = _camera_dir(cam, x, y, w, h)
                ox = cam[0] + t * dx
                oy = cam[1] + t * dy
                oz = cam[2] + t * dz
                stamp = 2 * (y * w + x)
                _set_ray(rh, ox, oy, oz, light[0], light[1], light[2], tnear, np.inf)
                _start_ray(ctx, MODE_RECORD if deferred else MODE_NORMAL, stamp)
                call3(fn, scene, rh.ctypes.data, args.ctypes.data)
                occ = rf[W_TFAR] == -np.inf
                n_cand = ctx[C_CAND]
                n_tests = ctx[C_TESTS]
                if deferred and not occ:
                    nrec = ctx[C_REC_N]
                    if nrec > REC_CAP:  # too many to remember: trace again the ordinary way
                        overflow[y] += 1
                        _set_ray(rh, ox, oy, oz, light[0], light[1], light[2], tnear, np.inf)
                        _start_ray(ctx, MODE_NORMAL, stamp + 1)
                        call3(fn, scene, rh.ctypes.data, args.ctypes.data)
                        occ = rf[W_TFAR] == -np.inf
                        n_tests += ctx[C_TESTS]
                    else:
                        for k in range(nrec):
                            n_tests += 1
                            if shader_alpha_test(table, rec_tri[k], rec_bary[2 * k], rec_bary[2 * k + 1]):
                                occ = True
                                break
                occluded[y, x] = 1 if occ else 0
                cand[y, x] = n_cand
                tests[y, x] = n_tests


@dataclass
class PrimaryResult:
    inst: np.ndarray
    geom: np.ndarray
    prim: np.ndarray
    dist: np.ndarray
    u: np.ndarray
    v: np.ndarray
    candidates: np.ndarray
    tests: np.ndarray
    calls: np.ndarray
    seconds: float
    set_full: int


@dataclass
class ShadowResult:
    occluded: np.ndarray
    candidates: np.ndarray
    tests: np.ndarray
    rays: int
    seconds: float
    overflow: int


def run_primary(bvh, tables: TraceTables | None, filt_addr: int, cam: np.ndarray, w: int, h: int) -> PrimaryResult:
    from .embree import lib

    shape = (h, w)
    inst = np.empty(shape, np.int32)
    geom = np.empty(shape, np.int32)
    prim = np.empty(shape, np.int32)
    dist = np.empty(shape, np.float32)
    bu = np.zeros(shape, np.float32)
    bv = np.zeros(shape, np.float32)
    cand = np.empty(shape, np.int32)
    tests = np.empty(shape, np.int32)
    calls = np.empty(shape, np.int32)
    full = np.zeros(h, np.int64)
    table_addr = tables.address if tables is not None else 0
    t0 = time.perf_counter()
    trace_primary(lib().intersect1, bvh.handle, filt_addr, table_addr, cam, w, h, inst, geom, prim, dist, bu, bv,
                  cand, tests, calls, full, numba.get_num_threads())
    dt = time.perf_counter() - t0
    return PrimaryResult(inst, geom, prim, dist, bu, bv, cand, tests, calls, dt, int(full.sum()))


def run_shadow(bvh, tables: TraceTables | None, filt_addr: int, cam: np.ndarray, light: np.ndarray, tnear: float,
               deferred: bool, dist: np.ndarray) -> ShadowResult:
    from .embree import lib

    h, w = dist.shape
    occ = np.empty((h, w), np.uint8)
    cand = np.empty((h, w), np.int32)
    tests = np.empty((h, w), np.int32)
    overflow = np.zeros(h, np.int64)
    table_addr = tables.address if tables is not None else 0
    t0 = time.perf_counter()
    trace_shadow(lib().occluded1, bvh.handle, filt_addr, table_addr, cam, np.asarray(light, np.float64), tnear,
                 deferred, w, h, dist, occ, cand, tests, overflow, numba.get_num_threads())
    dt = time.perf_counter() - t0
    return ShadowResult(occ, cand, tests, int(np.isfinite(dist).sum()), dt, int(overflow.sum()))
