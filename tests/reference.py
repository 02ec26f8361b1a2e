"""Brute-force reference for map baking, written independently of omaps' kernels.

Plain numpy: texel states by direct comparison, addressing by ``np.pad`` (wrap / edge /
symmetric), and region-texel overlap by the separating-axis test on open convex polygons
(interiors overlap iff no axis among the edge normals separates the projections, touching
counts as separated). Exact for dyadic coordinates.
"""

import numpy as np

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
    ok = np.ones(np.shape(x0), dtype=bool)
    for n in _axes(poly):
        p = poly @ n
        pmin, pmax = p.min(), p.max()
        corners = np.stack([x0 * n[0] + y0 * n[1], (x0 + size) * n[0] + y0 * n[1],
                            x0 * n[0] + (y0 + size) * n[1], (x0 + size) * n[0] + (y0 + size) * n[1]])
        qmin, qmax = corners.min(axis=0), corners.max(axis=0)
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


def square_map(states_img, n, filter="nearest", wrap="clamp"):
    h, w = states_img.shape
    texels = Addressed(states_img, wrap, 4)
    out = np.empty((n, n), dtype=np.uint8)
    for j in range(n):
        for i in range(n):
            x0, x1 = i * w / n, (i + 1) * w / n
            y0, y1 = j * h / n, (j + 1) * h / n
            poly = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
            out[j, i] = region_state(texels, poly, filter)
    return out


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
