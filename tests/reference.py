"""Brute-force reference for map baking, written independently of omaps' kernels.

Plain numpy: texel states by direct comparison, addressing by ``np.pad`` (wrap / edge /
symmetric), and region-texel overlap by the separating-axis test on open convex polygons
(interiors overlap iff no axis among the edge normals separates the projections, touching
counts as separated). Exact for dyadic coordinates. The exact bilinear extremes (below) use
rational arithmetic, with a float64 numba twin for benchmarks.
"""

import math
from fractions import Fraction

import numpy as np
from numba import njit

T, O, C = 0, 1, 2
PAD_MODES = {"wrap": "wrap", "clamp": "edge", "mirror": "symmetric"}


def texel_states(alpha8, mode="levels", t_max=30.0, o_min=225.0, cutoff=0.5):
    a = np.asarray(alpha8, dtype=np.float64)
    if mode == "levels":
        return np.where(a <= t_max, T, np.where(a >= o_min, O, C)).astype(np.uint8)
    return np.where(a > cutoff * 255.0, O, T).astype(np.uint8)


def _axes(poly):
    e = np.roll(poly, -1, axis=0) - poly
    normals = np.stack([-e[:, 1], e[:, 0]], axis=1)
    return np.concatenate([normals, [[1.0, 0.0], [0.0, 1.0]]])


def overlapping_squares(poly, x0, y0, size):
    """Mask of squares [x0, x0+size] x [y0, y0+size] (arrays) whose interior meets the polygon's."""
    poly = np.asarray(poly, dtype=np.float64)
    x0, y0 = np.broadcast_arrays(np.asarray(x0, dtype=np.float64), np.asarray(y0, dtype=np.float64))
    ok = np.ones(x0.shape, dtype=bool)
    for n in _axes(poly):
        p = poly @ n
        pmin, pmax = p.min(), p.max()
        # the square's projection: its corner (x0, y0) plus the extreme corner offsets along n
        q = x0 * n[0] + y0 * n[1]
        qmin = q + size * (min(n[0], 0.0) + min(n[1], 0.0))
        qmax = q + size * (max(n[0], 0.0) + max(n[1], 0.0))
        ok &= np.maximum(pmin, qmin) < np.minimum(pmax, qmax)
    return ok


def read_texels(poly_texel, filter):
    """Integer texel indices (unaddressed) that a hit inside the polygon can read."""
    poly = np.asarray(poly_texel, dtype=np.float64)
    lo = np.floor(poly.min(axis=0)).astype(int) - 2
    hi = np.ceil(poly.max(axis=0)).astype(int) + 2
    ys, xs = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
    xs, ys = xs.ravel(), ys.ravel()
    if filter == "nearest":  # texel (x, y) covers [x, x+1] x [y, y+1]
        m = overlapping_squares(poly, xs.astype(float), ys.astype(float), 1.0)
    else:  # a bilinear tap has non-zero weight on the open square (x-0.5, x+1.5) x (y-0.5, y+1.5)
        m = overlapping_squares(poly, xs - 0.5, ys - 0.5, 2.0)
    return xs[m], ys[m]


class Addressed:
    """The state image padded once by ``margin`` texels with the addressing mode."""

    def __init__(self, states_img, wrap, margin):
        self.m = int(margin)
        self.padded = np.pad(states_img, self.m, mode=PAD_MODES[wrap])  # handles pads wider than the image

    def __getitem__(self, yx):
        ys, xs = yx
        return self.padded[ys + self.m, xs + self.m]


def region_state(texels, poly_texel, filter="nearest"):
    xs, ys = read_texels(poly_texel, filter)
    if len(xs) == 0:
        raise ValueError("region reads nothing")
    vals = texels[ys, xs]
    if np.all(vals == T):
        return T
    if np.all(vals == O):
        return O
    return C


def _interval_overlaps(lo, hi, cells):
    """(len(lo), len(cells)) mask: open interval (lo, hi) meets open (cells, cells + 1)."""
    return np.maximum(lo[:, None], cells[None, :]) < np.minimum(hi[:, None], cells[None, :] + 1.0)


def square_map(states_img, n, filter="nearest", wrap="clamp"):
    """The N x N map over the whole texture: cell (i, j) is [i w/N, (i+1) w/N] x [j h/N, (j+1) h/N].
    An axis-aligned cell meets a texel's read square iff their x and y intervals overlap (the
    separating axes of two axis-aligned boxes), so the texels a cell reads are rows x columns, and
    the count of its non-T (non-O) texels is mask_y @ image @ mask_x^T, all cells at once."""
    h, w = states_img.shape
    m = 4
    padded = Addressed(states_img, wrap, m).padded
    k = np.arange(n)
    # the read square of texel x: [x, x+1] (nearest), (x-0.5, x+1.5) (a bilinear tap): as unit
    # cells after halving the coordinates of the linear one
    if filter == "nearest":
        cx, cy, s = np.arange(-m, w + m, dtype=np.float64), np.arange(-m, h + m, dtype=np.float64), 1.0
    else:
        cx, cy, s = np.arange(-m, w + m) - 0.5, np.arange(-m, h + m) - 0.5, 2.0
    mx = _interval_overlaps(k * w / n / s, (k + 1) * w / n / s, cx / s).astype(np.float32)
    my = _interval_overlaps(k * h / n / s, (k + 1) * h / n / s, cy / s).astype(np.float32)
    if not (mx.any(axis=1).all() and my.any(axis=1).all()):
        raise ValueError("region reads nothing")
    # texel counts (< 2^24, exact in float32)
    non_t = (my @ (padded != T).astype(np.float32)) @ mx.T
    non_o = (my @ (padded != O).astype(np.float32)) @ mx.T
    return np.where(non_t == 0, T, np.where(non_o == 0, O, C)).astype(np.uint8)


def subdivide(tri, level):
    """Micro-triangles of a triangle (3, 2) by midpoint subdivision, in any order: the reference
    only needs the set (the order is checked separately against the specification's figure)."""
    tris = [np.asarray(tri, dtype=np.float64)]
    for _ in range(level):
        nxt = []
        for a, b, c in tris:
            ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
            nxt += [np.array(t) for t in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])]
        tris = nxt
    return tris


def triangle_states(states_img, tri_uv, level, filter="nearest", wrap="clamp"):
    """Dict from micro-triangle (its sorted vertex tuple) to state."""
    h, w = states_img.shape
    scale = np.array([w, h], dtype=np.float64)
    tri_texel = np.asarray(tri_uv) * scale
    texels = Addressed(states_img, wrap, np.abs(tri_texel).max() + 4)
    out = {}
    for t in subdivide(tri_uv, level):
        key = tuple(sorted(map(tuple, np.round(t, 12))))
        out[key] = region_state(texels, t * scale, filter)
    return out


# ---- exact bilinear ---------------------------------------------------------------------------
# The bilinear alpha at texel coordinate p interpolates the four texels around p - 1/2: it is
# bilinear on each "dual" square between texel centres, [i - 1/2, i + 1/2] x [j - 1/2, j + 1/2].
# Its extremes over a convex polygon are found by enumerating candidate points (not by clipping,
# as omaps does): the polygon's vertices, where its edges cross the dual grid lines, the dual grid
# points inside it, and the stationary point of the quadratic along each edge piece within one
# dual square. Along a grid line the function is linear, and inside a square it has only a
# saddle, so these candidates hold both extremes. Generic arithmetic: pass Fractions for exact.

def _tap(values, wrap_u, wrap_v, x, y):
    """Texel (x, y), any integers, addressed like np.pad's wrap / edge / symmetric."""
    h, w = values.shape
    return values[_address(y, h, wrap_v), _address(x, w, wrap_u)]


def _address(i, n, mode):
    if mode == "wrap":
        return i % n
    if mode == "clamp":
        return min(max(i, 0), n - 1)
    r = i % (2 * n)  # mirror: ... 1 0 | 0 1 ... n-1 | n-1 ...
    return r if r < n else 2 * n - 1 - r


def bilinear_at(values, wrap_u, wrap_v, x, y):
    """The bilinear alpha at texel coordinate (x, y) (numbers of any exact type)."""
    fx, fy = x - Fraction(1, 2), y - Fraction(1, 2)
    x0, y0 = math.floor(fx), math.floor(fy)
    ax, ay = fx - x0, fy - y0
    t = [[_exact(_tap(values, wrap_u, wrap_v, x0 + i, y0 + j)) for i in (0, 1)] for j in (0, 1)]
    top = t[0][0] + ax * (t[0][1] - t[0][0])
    bot = t[1][0] + ax * (t[1][1] - t[1][0])
    return top + ay * (bot - top)


def _exact(v):
    """A texel value as an exact number: an int for integer values (cheaper than a Fraction)."""
    f = float(v)
    return int(f) if f.is_integer() else Fraction(f)


def _inside_many(poly, pts):
    """``_inside`` for many points: float64 cross products decide where they are far from 0
    (their rounding error is below 1e-9 of the terms' size); the few others exactly."""
    pf = np.array([[float(x), float(y)] for x, y in poly])
    q = np.array([[float(x), float(y)] for x, y in pts]).reshape(-1, 2)
    a, b = pf, np.roll(pf, -1, axis=0)
    t1 = (b[:, 0] - a[:, 0])[None, :] * (q[:, 1, None] - a[None, :, 1])
    t2 = (b[:, 1] - a[:, 1])[None, :] * (q[:, 0, None] - a[None, :, 0])
    cross = t1 - t2
    sure = np.abs(cross) > 1e-9 * (np.abs(t1) + np.abs(t2)) + 1e-300
    out = []
    for k, p in enumerate(pts):
        if sure[k].all():
            out.append(bool(np.all(cross[k] > 0) or np.all(cross[k] < 0)))
        else:
            out.append(_inside(poly, p))
    return out


def _inside(poly, p):
    s = [(b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) for a, b in zip(poly, poly[1:] + poly[:1])]
    return all(v >= 0 for v in s) or all(v <= 0 for v in s)


def bilinear_extremes(values, wrap_u, wrap_v, poly_texel):
    """Exact (min, max) Fractions of the bilinear alpha over a convex polygon (texel coords)."""
    half = Fraction(1, 2)
    poly = [(Fraction(float(x)), Fraction(float(y))) for x, y in poly_texel]
    xs = [p[0] for p in poly]
    ys = [p[1] for p in poly]
    gx = [i + half for i in range(math.floor(min(xs)) - 1, math.ceil(max(xs)) + 1)]
    gy = [j + half for j in range(math.floor(min(ys)) - 1, math.ceil(max(ys)) + 1)]
    memo = {}

    def at(x, y):  # the alpha at a point, each point computed once
        if (x, y) not in memo:
            memo[x, y] = bilinear_at(values, wrap_u, wrap_v, x, y)
        return memo[x, y]

    cands = list(poly)
    grid = [(x, y) for x in gx for y in gy]
    cands += [p for p, inside in zip(grid, _inside_many(poly, grid)) if inside]
    for a, b in zip(poly, poly[1:] + poly[:1]):
        d = (b[0] - a[0], b[1] - a[1])
        ts = {Fraction(0), Fraction(1)}
        for axis, lines in ((0, gx), (1, gy)):
            if d[axis] != 0:
                ts |= {(g - a[axis]) / d[axis] for g in lines if 0 < (g - a[axis]) / d[axis] < 1}
        ts = sorted(ts)
        for t in ts:
            cands.append((a[0] + t * d[0], a[1] + t * d[1]))
        for t0, t1 in zip(ts, ts[1:]):  # one dual square per piece: a quadratic in t
            f0 = at(a[0] + t0 * d[0], a[1] + t0 * d[1])
            tm = (t0 + t1) / 2
            fm = at(a[0] + tm * d[0], a[1] + tm * d[1])
            f1 = at(a[0] + t1 * d[0], a[1] + t1 * d[1])
            # q(u) = f0 + c1 u + c2 u^2 on u in [0, 1] through the three values
            c2 = 2 * (f0 + f1 - 2 * fm)
            c1 = f1 - f0 - c2
            if c2 != 0:
                u = -c1 / (2 * c2)
                if 0 < u < 1:
                    t = t0 + u * (t1 - t0)
                    cands.append((a[0] + t * d[0], a[1] + t * d[1]))
    vals = [at(x, y) for x, y in cands]
    return min(vals), max(vals)


def exact_state(lo, hi, mode="cutoff", cutoff=0.5, t_max=30.0, o_min=225.0):
    """The corpus rules (8-bit alpha) on a region's exact alpha range."""
    if mode == "levels":
        return T if hi <= Fraction(t_max) else (O if lo >= Fraction(o_min) else C)
    c = Fraction(cutoff) * 255
    return O if lo > c else (T if hi <= c else C)


def bilinear_triangle_states(alpha8, tri_uv, level, wrap="clamp", **rule):
    """Dict from micro-triangle (its sorted vertex tuple) to its exact bilinear state."""
    h, w = alpha8.shape
    scale = np.array([w, h], dtype=np.float64)
    out = {}
    for t in subdivide(tri_uv, level):
        key = tuple(sorted(map(tuple, np.round(t, 12))))
        out[key] = exact_state(*bilinear_extremes(alpha8, wrap, wrap, list(t * scale)), **rule)
    return out


def bilinear_square_map(alpha8, n, wrap="clamp", **rule):
    """The corpus pair's N x N map (cells in texel space) with exact bilinear states."""
    h, w = alpha8.shape
    out = np.empty((n, n), dtype=np.uint8)
    for j in range(n):
        for i in range(n):
            x0, x1 = i * w / n, (i + 1) * w / n
            y0, y1 = j * h / n, (j + 1) * h / n
            lo, hi = bilinear_extremes(alpha8, wrap, wrap, [[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
            out[j, i] = exact_state(lo, hi, **rule)
    return out


# The same candidate points in float64 and numba, for benchmarks over millions of regions
# (tests check it against the rational version above).

@njit(cache=True)
def _addr_f(i, n, mode):
    if mode == 0:
        return i % n
    if mode == 1:
        return min(max(i, 0), n - 1)
    r = i % (2 * n)
    return r if r < n else 2 * n - 1 - r


@njit(cache=True)
def _bilinear_f(values, mode, x, y):
    h, w = values.shape
    fx = x - 0.5
    fy = y - 0.5
    x0 = math.floor(fx)
    y0 = math.floor(fy)
    ax = fx - x0
    ay = fy - y0
    xa, xb = _addr_f(x0, w, mode), _addr_f(x0 + 1, w, mode)
    ya, yb = _addr_f(y0, h, mode), _addr_f(y0 + 1, h, mode)
    top = values[ya, xa] + ax * (values[ya, xb] - values[ya, xa])
    bot = values[yb, xa] + ax * (values[yb, xb] - values[yb, xa])
    return top + ay * (bot - top)


@njit(cache=True)
def bilinear_extremes_many(values, mode, tris):
    """(min, max) of the bilinear alpha over each triangle of ``tris`` (R, 3, 2) in texel
    coordinates; ``mode`` 0 wrap, 1 clamp, 2 mirror."""
    out = np.empty((tris.shape[0], 2))
    ts = np.empty(4096)
    for r in range(tris.shape[0]):
        p = tris[r]
        mn = np.inf
        mx = -np.inf
        x_lo = math.floor(min(p[0, 0], min(p[1, 0], p[2, 0])) - 0.5)
        x_hi = math.ceil(max(p[0, 0], max(p[1, 0], p[2, 0])) - 0.5)
        y_lo = math.floor(min(p[0, 1], min(p[1, 1], p[2, 1])) - 0.5)
        y_hi = math.ceil(max(p[0, 1], max(p[1, 1], p[2, 1])) - 0.5)
        area = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[1, 1] - p[0, 1]) * (p[2, 0] - p[0, 0])
        for i in range(x_lo, x_hi + 1):  # grid points inside
            for j in range(y_lo, y_hi + 1):
                gx = i + 0.5
                gy = j + 0.5
                inside = True
                for e in range(3):
                    a = p[e]
                    b = p[(e + 1) % 3]
                    cr = (b[0] - a[0]) * (gy - a[1]) - (b[1] - a[1]) * (gx - a[0])
                    if cr * area < 0:
                        inside = False
                if inside:
                    v = _bilinear_f(values, mode, gx, gy)
                    mn = min(mn, v)
                    mx = max(mx, v)
        for e in range(3):
            a = p[e]
            b = p[(e + 1) % 3]
            dx = b[0] - a[0]
            dy = b[1] - a[1]
            n = 0
            ts[n] = 0.0
            ts[n + 1] = 1.0
            n = 2
            if dx != 0:
                for i in range(x_lo, x_hi + 1):
                    t = (i + 0.5 - a[0]) / dx
                    if 0 < t < 1 and n < ts.shape[0]:
                        ts[n] = t
                        n += 1
            if dy != 0:
                for j in range(y_lo, y_hi + 1):
                    t = (j + 0.5 - a[1]) / dy
                    if 0 < t < 1 and n < ts.shape[0]:
                        ts[n] = t
                        n += 1
            tt = np.sort(ts[:n])
            for k in range(n):
                v = _bilinear_f(values, mode, a[0] + tt[k] * dx, a[1] + tt[k] * dy)
                mn = min(mn, v)
                mx = max(mx, v)
            for k in range(n - 1):
                t0 = tt[k]
                t1 = tt[k + 1]
                if t1 - t0 <= 0:
                    continue
                tm = 0.5 * (t0 + t1)
                f0 = _bilinear_f(values, mode, a[0] + t0 * dx, a[1] + t0 * dy)
                fm = _bilinear_f(values, mode, a[0] + tm * dx, a[1] + tm * dy)
                f1 = _bilinear_f(values, mode, a[0] + t1 * dx, a[1] + t1 * dy)
                c2 = 2.0 * (f0 + f1 - 2.0 * fm)
                c1 = f1 - f0 - c2
                if c2 != 0.0:
                    u = -c1 / (2.0 * c2)
                    if 0.0 < u < 1.0:
                        t = t0 + u * (t1 - t0)
                        v = _bilinear_f(values, mode, a[0] + t * dx, a[1] + t * dy)
                        mn = min(mn, v)
                        mx = max(mx, v)
        out[r, 0] = mn
        out[r, 1] = mx
    return out


# ---- the corpus pair's square (docs/FORMAT.md) ------------------------------------------------

def hit_to_uv(triangle, b1, b2):
    """(u, v) of a hit with barycentrics (b1, b2) -- the weights of p1 and p2 -- on the corpus
    pair's triangle 0 (A: (0,0), (1,0), (1,1)) or 1 (B: (0,0), (1,1), (0,1))."""
    if triangle == 0:
        return b1 + b2, b2
    return b1, b1 + b2


def hit_to_cell(triangle, b1, b2, n):
    """Square cell (i, j) of an n x n map that a hit on the corpus pair reads; the far edges
    u = 1, v = 1 belong to the last cell."""
    u, v = hit_to_uv(triangle, b1, b2)
    return min(max(math.floor(u * n), 0), n - 1), min(max(math.floor(v * n), 0), n - 1)


def square_cells(n):
    """The n*n cells as rectangles in UV, shape (n*n, 4, 2), in map order (j-major)."""
    j, i = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    u0, u1, v0, v1 = (i / n).ravel(), ((i + 1) / n).ravel(), (j / n).ravel(), ((j + 1) / n).ravel()
    return np.stack([np.stack([u0, v0], -1), np.stack([u1, v0], -1),
                     np.stack([u1, v1], -1), np.stack([u0, v1], -1)], axis=1)
