"""Ray-traced evaluation: alpha tests per ray with opacity maps read in Embree's any-hit path.

Per candidate hit on an alpha-tested triangle, the filter function (a numba ``cfunc``, one per
scheme) looks the hit's region state up in the scheme's *stored* data -- a raw 2-bit map, a
micromap through the bird curve, or a codec block by random access -- and then: T -> reject,
O -> accept, C -> run the alpha test (sample the base colour alpha with the material's filter
and wrap, compare with the cut-off) and count it. Scheme ``none`` alpha-tests every candidate.

Counting is per *distinct* candidate of a ray (instance, triangle): Embree may report one hit
twice (spatial splits, or an edge shared by two triangles reported for both is two candidates,
counted as two), and a repeated report is one candidate and at most one alpha test.

Shadow rays are occlusion rays towards a directional light from each primary hit. The
*deferred* mode (the deck's future work) first looks for an O hit along the ray, recording C
candidates without testing them, and alpha-tests the recorded candidates only when no O hit
exists: same occlusion, fewer tests.

The ray loops run in numba and call rtcIntersect1 / rtcOccluded1 through their addresses.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import carray, cfunc, njit, prange, types

from . import birdcurve, pair, states
from .embree import (ARGS_WORDS, CONTEXT_BYTES, RAYHIT_WORDS, RTC_FEATURE_FLAG_ALL, RTC_INVALID_GEOMETRY_ID,
                     W_GEOM, W_INST, W_PRIM, W_TFAR, W_U, W_V, call3, f32_ptr, f64_ptr, i8_ptr, i32_ptr,
                     i64_ptr, u8_ptr, u32_ptr)
from .sampling import sample_texture, wrap_code

# ---- the table of addresses a filter reads (int64 words) -------------------------------------
T_PROTO_OF_INST, T_ALPHA_BASE, T_TRI_MAT, T_TRI_UV, T_TRI_CORNER = 0, 1, 2, 3, 4
T_MAT_TEX_START, T_MAT_W, T_MAT_H, T_MAT_WRAP_U, T_MAT_WRAP_V, T_MAT_FILTER, T_MAT_THR, T_TEX = 5, 6, 7, 8, 9, 10, 11, 12
T_MAP_ROW, T_MAP_DATA, T_MAP_ROW_BYTES, T_MAP_PARAM = 13, 14, 15, 16
TABLE_WORDS = 17

# ---- a query context: Embree's part, then ours (int64 words) -----------------------------------
C0 = CONTEXT_BYTES // 8
C_TABLE, C_MODE, C_CAND, C_TESTS, C_CALLS = C0, C0 + 1, C0 + 2, C0 + 3, C0 + 4
C_SET_KEYS, C_SET_STAMPS, C_STAMP, C_SET_FULL = C0 + 5, C0 + 6, C0 + 7, C0 + 8
C_REC_N, C_REC_TRI, C_REC_BARY, C_REC_CAP = C0 + 9, C0 + 10, C0 + 11, C0 + 12
CONTEXT_WORDS = C0 + 16
SET_SIZE = 1024  # distinct candidates per ray we can tell apart (power of two)
REC_CAP = 512  # C candidates a deferred shadow ray can record
MODE_NORMAL, MODE_RECORD = 0, 1

NEAREST, LINEAR = 0, 1


# ---- hit -> region, the alpha test -------------------------------------------------------------

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
def hit_st(corners, tri, b1, b2):
    """(s, t) of a hit in its pair's square: the barycentric combination of the square corners
    of the triangle's three vertices (codes of omaps.pairing.CORNERS)."""
    w0 = 1.0 - b1 - b2
    s = 0.0
    t = 0.0
    for k in range(3):
        w = w0 if k == 0 else (b1 if k == 1 else b2)
        c = corners[3 * tri + k]
        if c == 1 or c == 2:
            s += w
        if c >= 2:
            t += w
    return s, t


@njit(cache=True, inline="always")
def read_2bit(data, start, k):
    return (data[start + (k >> 2)] >> (2 * (k & 3))) & 3


@njit(cache=True)
def alpha_test(table, tri, b1, b2):
    """The any-hit shader: base colour alpha at the hit (mip level 0, the material's filter and
    wrap, fetched by ``sampling.sample_texture``), opaque iff at or above the material's
    threshold."""
    m = i32_ptr(table[T_TRI_MAT])[tri]
    uv = f64_ptr(table[T_TRI_UV])
    w0 = 1.0 - b1 - b2
    o = 6 * tri
    u = w0 * uv[o] + b1 * uv[o + 2] + b2 * uv[o + 4]
    v = w0 * uv[o + 1] + b1 * uv[o + 3] + b2 * uv[o + 5]
    w = i64_ptr(table[T_MAT_W])[m]
    h = i64_ptr(table[T_MAT_H])[m]
    tex = carray(u8_ptr(table[T_TEX] + i64_ptr(table[T_MAT_TEX_START])[m]), (h, w))
    filt = 0 if i64_ptr(table[T_MAT_FILTER])[m] == NEAREST else 1
    a = sample_texture(tex, filt, i64_ptr(table[T_MAT_WRAP_U])[m], i64_ptr(table[T_MAT_WRAP_V])[m], u * w, v * h)
    thr = f64_ptr(table[T_MAT_THR])[m]
    return a >= thr


@njit(cache=True)
def no_map_state(table, tri, b1, b2):
    return states.C


@njit(cache=True)
def square_map_state(table, tri, b1, b2):
    """Raw N x N 2-bit map of the pair: cell (i, j) is region k = j * N + i."""
    s, t = hit_st(i8_ptr(table[T_TRI_CORNER]), tri, b1, b2)
    n = table[T_MAP_PARAM]
    i, j = pair.uv_to_cell(s, t, n)
    row = i32_ptr(table[T_MAP_ROW])[tri]
    return read_2bit(u8_ptr(table[T_MAP_DATA]), row * table[T_MAP_ROW_BYTES], j * n + i)


@njit(cache=True)
def micro_map_state(table, tri, b1, b2):
    """Raw 2-bit micromap of the triangle, micro-triangle from the bird curve."""
    k = birdcurve.bary_to_index(b1, b2, table[T_MAP_PARAM])
    row = i32_ptr(table[T_MAP_ROW])[tri]
    return read_2bit(u8_ptr(table[T_MAP_DATA]), row * table[T_MAP_ROW_BYTES], k)


_CODEC_STATES: dict = {}


def codec_map_state(codec):
    """A state function reading the pair's encoded block with the codec's random-access lookup."""
    key = codec.name
    if key not in _CODEC_STATES:
        lookup = codec.lookup

        @njit
        def state(table, tri, b1, b2):
            s, t = hit_st(i8_ptr(table[T_TRI_CORNER]), tri, b1, b2)
            n = table[T_MAP_PARAM]
            i, j = pair.uv_to_cell(s, t, n)
            rb = table[T_MAP_ROW_BYTES]
            row = np.int64(i32_ptr(table[T_MAP_ROW])[tri])
            return lookup(carray(u8_ptr(table[T_MAP_DATA] + row * rb), rb), i, j)
        _CODEC_STATES[key] = state
    return _CODEC_STATES[key]


# ---- the filter --------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _seen_before(ctx, key):
    """Insert ``key`` into the ray's candidate set; True if it was there already."""
    keys = i64_ptr(ctx[C_SET_KEYS])
    stamps = i64_ptr(ctx[C_SET_STAMPS])
    stamp = ctx[C_STAMP]
    h = (key * 0x9E3779B97F4A7C15) >> 20
    for probe in range(SET_SIZE):
        slot = (h + probe) & (SET_SIZE - 1)
        if stamps[slot] != stamp:
            stamps[slot] = stamp
            keys[slot] = key
            return False
        if keys[slot] == key:
            return True
    ctx[C_SET_FULL] += 1
    return False


_FILTERS: dict = {}


def make_filter(state_fn):
    """The Embree filter (RTCFilterFunctionN) of a scheme, as a numba cfunc."""
    if state_fn in _FILTERS:
        return _FILTERS[state_fn]

    @cfunc(types.void(types.CPointer(types.int64)))
    def filt(args):
        valid = i32_ptr(args[0])
        ctx = i64_ptr(args[2])
        hitf = f32_ptr(args[4])
        hitu = u32_ptr(args[4])
        n = args[5] & 0xFFFFFFFF
        table = i64_ptr(ctx[C_TABLE])
        proto_of = i32_ptr(table[T_PROTO_OF_INST])
        base = i64_ptr(table[T_ALPHA_BASE])
        for r in range(n):
            if valid[r] == 0:
                continue
            inst = np.int64(hitu[7 * n + r])
            prim = np.int64(hitu[5 * n + r])
            tri = base[proto_of[inst]] + prim
            b1, b2 = clamp_bary(hitf[3 * n + r], hitf[4 * n + r])
            ctx[C_CALLS] += 1
            repeat = _seen_before(ctx, (inst << 32) | prim)
            if not repeat:
                ctx[C_CAND] += 1
            state = state_fn(table, tri, b1, b2)
            if state == states.C:
                if ctx[C_MODE] == MODE_RECORD:
                    if not repeat:
                        k = ctx[C_REC_N]
                        if k < ctx[C_REC_CAP]:
                            i64_ptr(ctx[C_REC_TRI])[k] = tri
                            f64_ptr(ctx[C_REC_BARY])[2 * k] = b1
                            f64_ptr(ctx[C_REC_BARY])[2 * k + 1] = b2
                        ctx[C_REC_N] = k + 1
                    valid[r] = 0
                    continue
                if not repeat:
                    ctx[C_TESTS] += 1
                if not alpha_test(table, tri, b1, b2):
                    valid[r] = 0
            elif state == states.T:
                valid[r] = 0
    _FILTERS[state_fn] = filt
    return filt


# ---- the ray loops -------------------------------------------------------------------------------

@njit(cache=True)
def _aligned(words):
    """A zeroed int64 array of ``words`` elements whose data starts on a 64-byte boundary."""
    a = np.zeros(words + 8, np.int64)
    off = ((-a.ctypes.data) & 63) // 8
    return a[off:off + words]


@njit(cache=True)
def _new_context(table_addr, keys, stamps, rec_tri, rec_bary):
    ctx = _aligned(CONTEXT_WORDS)
    ctx[0] = -1  # RTCRayQueryContext: instID[0] (and instPrimID[0]) = RTC_INVALID_GEOMETRY_ID
    ctx[C_TABLE] = table_addr
    ctx[C_SET_KEYS] = keys.ctypes.data
    ctx[C_SET_STAMPS] = stamps.ctypes.data
    ctx[C_REC_TRI] = rec_tri.ctypes.data
    ctx[C_REC_BARY] = rec_bary.ctypes.data
    ctx[C_REC_CAP] = rec_tri.size
    return ctx


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
def trace_primary(fn, scene, filt, table_addr, cam, w, h, inst, geom, prim, dist, bu, bv, cand, tests, calls, full):
    """Closest hits of the camera's rays; per pixel the hit (instance, geometry, primitive,
    distance, barycentrics) and the counts of distinct candidates and alpha tests."""
    for y in prange(h):
        rh = _aligned(RAYHIT_WORDS // 2).view(np.uint32)
        rf = rh.view(np.float32)
        keys = np.zeros(SET_SIZE, np.int64)
        stamps = np.full(SET_SIZE, -1, np.int64)
        ctx = _new_context(table_addr, keys, stamps, np.zeros(1, np.int64), np.zeros(2, np.float64))
        args = _aligned(ARGS_WORDS)
        args[0] = np.int64(RTC_FEATURE_FLAG_ALL) << 32
        args[1] = ctx.ctypes.data
        args[2] = filt
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
                 overflow):
    """Occlusion rays towards the light (direction ``light``) from every primary hit. Deferred:
    first an occlusion query that records C candidates untested; if it finds no O hit, the
    recorded candidates are alpha-tested in order until one is opaque."""
    for y in prange(h):
        rh = _aligned(RAYHIT_WORDS // 2).view(np.uint32)
        rf = rh.view(np.float32)
        keys = np.zeros(SET_SIZE, np.int64)
        stamps = np.full(SET_SIZE, -1, np.int64)
        rec_tri = np.zeros(REC_CAP, np.int64)
        rec_bary = np.zeros(2 * REC_CAP, np.float64)
        ctx = _new_context(table_addr, keys, stamps, rec_tri, rec_bary)
        table = i64_ptr(table_addr)
        args = _aligned(ARGS_WORDS)
        args[0] = np.int64(RTC_FEATURE_FLAG_ALL) << 32
        args[1] = ctx.ctypes.data
        args[2] = filt
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
                        if alpha_test(table, rec_tri[k], rec_bary[2 * k], rec_bary[2 * k + 1]):
                            occ = True
                            break
            occluded[y, x] = 1 if occ else 0
            cand[y, x] = n_cand
            tests[y, x] = n_tests


# ---- Python side ---------------------------------------------------------------------------------

@dataclass
class Camera:
    eye: np.ndarray
    target: np.ndarray
    fov: float  # vertical field of view, degrees

    def basis(self, width: int, height: int) -> np.ndarray:
        f = np.asarray(self.target, float) - np.asarray(self.eye, float)
        f /= np.linalg.norm(f)
        up = np.array([0.0, 1.0, 0.0])
        if abs(f @ up) > 0.999:
            up = np.array([0.0, 0.0, 1.0])
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        th = math.tan(math.radians(self.fov) / 2)
        return np.concatenate([self.eye, f, r * th * width / height, u * th]).astype(np.float64)

    def to_json(self) -> dict:
        return {"eye": [float(x) for x in self.eye], "target": [float(x) for x in self.target], "fov": self.fov}


def default_camera(bounds: np.ndarray) -> Camera:
    """A low, grazing view through the foliage. A wide scene (a forest) is crossed along its
    diagonal from just inside one corner, eye at an eighth of the scene's height, looking slightly
    up; a compact one (a tree) is framed whole from the side, low, through its crown."""
    lo, hi = bounds
    size = hi - lo
    height = size[1]
    if float(np.hypot(size[0], size[2])) >= 3 * height:
        eye = lo + size * np.array([0.03, 0.12, 0.03])
        target = lo + size * np.array([0.97, 0.2, 0.97])
        return Camera(eye, target, 60.0)
    c = (lo + hi) / 2
    radius = float(np.linalg.norm(size)) / 2
    d = radius / math.sin(math.radians(50) / 2)
    direction = np.array([-0.6, 0.08, -0.8])
    direction /= np.linalg.norm(direction)
    return Camera(c + d * direction, c, 50.0)


@dataclass
class TraceTables:
    """Everything a filter reads, with the int64 table of addresses (one per scheme)."""

    arrays: dict = field(default_factory=dict)
    table: np.ndarray = None

    @property
    def address(self) -> int:
        return int(self.table.ctypes.data)


def base_tables(scene, at, proto_of_instance) -> dict:
    """Arrays shared by every scheme: geometry of the alpha triangles, materials, textures."""
    tex_parts, starts = [], []
    tex_start = {}
    pos = 0
    for mi, m in enumerate(scene.materials):
        key = m.texture
        if key not in tex_start:
            a = scene.textures[key].alpha if key >= 0 else np.full((1, 1), 255, np.uint8)
            tex_start[key] = (pos, a.shape[1], a.shape[0])
            tex_parts.append(a.ravel())
            pos += a.size
        starts.append(tex_start[key])
    from .scene_maps import opaque_threshold

    st = np.array(starts, dtype=np.int64).reshape(-1, 3)
    return {
        T_PROTO_OF_INST: np.ascontiguousarray(proto_of_instance, dtype=np.int32),
        T_ALPHA_BASE: np.ascontiguousarray(at.base, dtype=np.int64),
        T_TRI_MAT: np.ascontiguousarray(at.material, dtype=np.int32),
        T_TRI_UV: np.ascontiguousarray(at.uv, dtype=np.float64),
        T_TRI_CORNER: np.ascontiguousarray(at.corners, dtype=np.int8),
        T_MAT_TEX_START: np.ascontiguousarray(st[:, 0]),
        T_MAT_W: np.ascontiguousarray(st[:, 1]),
        T_MAT_H: np.ascontiguousarray(st[:, 2]),
        T_MAT_WRAP_U: np.array([wrap_code(m.wrap_u) for m in scene.materials], np.int64),
        T_MAT_WRAP_V: np.array([wrap_code(m.wrap_v) for m in scene.materials], np.int64),
        T_MAT_FILTER: np.array([NEAREST if m.filter == "nearest" else LINEAR for m in scene.materials], np.int64),
        T_MAT_THR: np.array([opaque_threshold(m) for m in scene.materials], np.float64),
        T_TEX: np.concatenate(tex_parts).astype(np.uint8),
    }


def scheme_tables(base: dict, sm) -> TraceTables:
    arrays = dict(base)
    arrays[T_MAP_ROW] = np.ascontiguousarray(sm.rows, dtype=np.int32)
    arrays[T_MAP_DATA] = np.ascontiguousarray(sm.data, dtype=np.uint8)
    table = np.zeros(TABLE_WORDS, np.int64)
    for k, a in arrays.items():
        table[k] = a.ctypes.data
    table[T_MAP_ROW_BYTES] = sm.row_bytes
    table[T_MAP_PARAM] = sm.param
    return TraceTables(arrays, table)


def state_function(sm):
    if sm.kind == "none":
        return no_map_state
    if sm.kind == "square":
        return square_map_state
    if sm.kind == "tri":
        return micro_map_state
    return codec_map_state(sm.codec)


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
                  cand, tests, calls, full)
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
                 deferred, w, h, dist, occ, cand, tests, overflow)
    dt = time.perf_counter() - t0
    return ShadowResult(occ, cand, tests, int(np.isfinite(dist).sum()), dt, int(overflow.sum()))


# ---- a whole run: prepare once, trace every scheme ------------------------------------------------

@dataclass
class Prepared:
    scene: object
    alpha: object  # scene_maps.AlphaTriangles
    maps: dict  # name -> scene_maps.SchemeMaps
    bvh: object  # embree.InstancedScene
    base: dict
    proto_of_instance: np.ndarray
    opaque_tris: list  # per mesh: mesh triangle indices of geometry 0, in primID order
    timings: dict
    device: object = None


def prepare(scene, names: list[str], jobs: int = 1, effort: str = "medium", progress: bool = False,
            embree_config: str = "") -> Prepared:
    """Pair, bake and encode every scheme's maps, and build the Embree scene."""
    from . import embree, scene_maps

    timings = {}
    t0 = time.perf_counter()
    at = scene_maps.alpha_triangles(scene)
    timings["pair_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    gt = scene_maps.grid_table(scene)
    maps_ = scene_maps.build_scheme_maps(at, gt, names, jobs, effort, progress)
    timings["bake_encode_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    device = embree.Device(embree_config)
    alpha = scene.alpha_tested()
    protos, opaque_tris = [], []
    for k, mesh in enumerate(scene.meshes):
        op = np.flatnonzero(~alpha[mesh.material])
        opaque_tris.append(op)
        protos.append((mesh.positions, mesh.triangles[op], mesh.triangles[at.mesh_tri[at.base[k]:at.base[k + 1]]]))
    bvh = embree.InstancedScene(device, protos, scene.instances)
    timings["bvh_s"] = time.perf_counter() - t0
    proto_of = np.array([mi for mi, _ in scene.instances], np.int32)
    return Prepared(scene, at, maps_, bvh, base_tables(scene, at, proto_of), proto_of, opaque_tris, timings, device)


@dataclass
class SchemeRun:
    name: str
    primary: PrimaryResult
    shadow: ShadowResult | None = None
    deferred: ShadowResult | None = None


def trace_scheme(prep: Prepared, name: str | None, cam: np.ndarray, w: int, h: int, light=None, tnear: float = 0.0,
                 deferred: bool = False) -> SchemeRun:
    """Trace one scheme (``None``: opaque-only traversal, no filter at all)."""
    if name is None:
        tables, filt = None, 0
    else:
        sm = prep.maps[name]
        tables = scheme_tables(prep.base, sm)
        filt = make_filter(state_function(sm)).address
    primary = run_primary(prep.bvh, tables, filt, cam, w, h)
    run = SchemeRun(name or "opaque", primary)
    if light is not None:
        run.shadow = run_shadow(prep.bvh, tables, filt, cam, light, tnear, False, primary.dist)
        if deferred:
            run.deferred = run_shadow(prep.bvh, tables, filt, cam, light, tnear, True, primary.dist)
    return run


def differing_pixels(a: PrimaryResult, b: PrimaryResult) -> int:
    """Pixels whose visible result differs: hit instance, geometry, triangle or distance."""
    d = (a.inst != b.inst) | (a.geom != b.geom) | (a.prim != b.prim) | (a.dist != b.dist)
    return int(np.count_nonzero(d))


def summary(run: SchemeRun, ref: SchemeRun, sm, w: int, h: int) -> dict:
    n = w * h
    p = run.primary
    out = {
        "alpha_tests_per_primary_ray": float(p.tests.sum()) / n,
        "candidates_per_primary_ray": float(p.candidates.sum()) / n,
        "filter_calls_per_primary_ray": float(p.calls.sum()) / n,
        "differing_pixels": differing_pixels(p, ref.primary),
        "primary_rays_per_second": n / p.seconds if p.seconds > 0 else None,
        "candidate_set_overflows": p.set_full,  # candidates met with a full set (counted as new)
    }
    rays, secs = n, p.seconds
    if run.shadow is not None:
        s = run.shadow
        out["alpha_tests_per_shadow_ray"] = float(s.tests.sum()) / max(s.rays, 1)
        out["candidates_per_shadow_ray"] = float(s.candidates.sum()) / max(s.rays, 1)
        out["differing_shadow_rays"] = int(np.count_nonzero(s.occluded != ref.shadow.occluded))
        out["shadow_rays_per_second"] = s.rays / s.seconds if s.seconds > 0 else None
        rays += s.rays
        secs += s.seconds
    if run.deferred is not None:
        d = run.deferred
        normal = float(run.shadow.tests.sum())
        out["deferred_alpha_tests_per_shadow_ray"] = float(d.tests.sum()) / max(d.rays, 1)
        out["deferred_tests_saved"] = int(normal - d.tests.sum())
        out["deferred_tests_saved_fraction"] = (normal - float(d.tests.sum())) / normal if normal else 0.0
        out["deferred_differing_shadow_rays"] = int(np.count_nonzero(d.occluded != run.shadow.occluded))
        out["deferred_record_overflows"] = d.overflow
    out["rays_per_second"] = rays / secs if secs > 0 else None
    if sm is not None:
        out["map_bytes"] = int(sm.map_bytes)
        out["distinct_maps"] = int(sm.distinct_maps)
        out["known_fraction"] = sm.known_fraction
    return out
