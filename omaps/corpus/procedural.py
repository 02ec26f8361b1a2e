"""The embedded default corpus: seeded procedural cut-outs drawn by our own code.

Shapes are signed distance fields (negative inside, in pixels) turned into 8-bit coverage with a
soft edge, so every texture has T, O and in-between (C under ``levels``) texels like real
anti-aliased alpha: leaves, a chain-link fence, a grate, grass strips, a fern frond.
"""

from __future__ import annotations

import numpy as np

from ..texture import AlphaTexture

SEED = 20230613  # fixed: the default corpus is the same on every machine


def _grid(w, h):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return x + 0.5, y + 0.5


def _coverage(sdf, edge=1.6):
    """SDF (pixels) to 8-bit coverage with a linear ramp ``edge`` pixels wide."""
    return np.clip(np.round((0.5 - sdf / edge) * 255.0), 0, 255).astype(np.uint8)


def _leaf_sdf(x, y, cx, cy, length, width, angle):
    """A pointed leaf: the lens (vesica) between two circles, length along ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    lx = (x - cx) * c + (y - cy) * s
    ly = -(x - cx) * s + (y - cy) * c
    half_l, half_w = length / 2, width / 2
    r = (half_l ** 2 + half_w ** 2) / (2 * half_w)  # circle through tips and the widest point
    d1 = np.hypot(lx, ly - (half_w - r)) - r
    d2 = np.hypot(lx, ly + (half_w - r)) - r
    return np.maximum(d1, d2)


def _segment_sdf(x, y, ax, ay, bx, by, radius):
    px, py = x - ax, y - ay
    dx, dy = bx - ax, by - ay
    t = np.clip((px * dx + py * dy) / (dx * dx + dy * dy), 0, 1)
    return np.hypot(px - t * dx, py - t * dy) - radius


def leaves(rng, w=256, h=256):
    x, y = _grid(w, h)
    d = np.full(x.shape, np.inf)
    for _ in range(14):
        cx, cy = rng.uniform(0.15, 0.85) * w, rng.uniform(0.15, 0.85) * h
        ang = rng.uniform(0, np.pi)
        ln = rng.uniform(0.22, 0.38) * w
        d = np.minimum(d, _leaf_sdf(x, y, cx, cy, ln, ln * rng.uniform(0.35, 0.5), ang))
    stem = _segment_sdf(x, y, 0.5 * w, h - 2, 0.5 * w, 0.55 * h, 1.5)
    return _coverage(np.minimum(d, stem))


def big_leaf(rng, w=256, h=256):
    x, y = _grid(w, h)
    d = _leaf_sdf(x, y, w / 2, h / 2, 0.9 * w, 0.45 * w, np.pi / 2 + rng.uniform(-0.2, 0.2))
    # serrated edge: modulate the distance with angle around the centre
    ang = np.arctan2(y - h / 2, x - w / 2)
    d = d + 2.5 * np.abs(np.sin(ang * 24))
    # insect bites: a few holes
    for _ in range(4):
        hx, hy, hr = rng.uniform(0.35, 0.65) * w, rng.uniform(0.25, 0.75) * h, rng.uniform(4, 11)
        d = np.maximum(d, -(np.hypot(x - hx, y - hy) - hr))
    return _coverage(d)


def chainlink(rng, w=256, h=256, pitch=32.0, wire=2.2):
    x, y = _grid(w, h)
    a = np.abs(((x + y) % pitch) - pitch / 2) - (pitch / 2 - wire)
    b = np.abs(((x - y) % pitch) - pitch / 2) - (pitch / 2 - wire)
    d = -np.maximum(a, b)  # inside a wire where either family is within ``wire`` of its line
    return _coverage(d, edge=1.2)


def grate(rng, w=256, h=256, bars=7, bar=6.0, frame=10.0):
    x, y = _grid(w, h)
    dx = np.abs((x % (w / bars)) - w / bars / 2) - bar / 2
    dy = np.abs((y % (h / 4)) - h / 8) - bar
    inner = np.minimum(dx, dy)
    border = np.minimum.reduce([x, w - x, y, h - y]) - frame
    return _coverage(np.minimum(inner, border), edge=1.0)


def grass(rng, w=256, h=256, blades=26):
    x, y = _grid(w, h)
    d = np.full(x.shape, np.inf)
    for _ in range(blades):
        base = rng.uniform(0.05, 0.95) * w
        height = rng.uniform(0.45, 0.95) * h
        bend = rng.uniform(-0.25, 0.25) * w
        t = np.clip((h - y) / height, 0, 1)  # 0 at the bottom, 1 at the tip
        centre = base + bend * t * t
        half = (1 - t) * rng.uniform(3, 6) + 0.3
        blade = np.abs(x - centre) - half
        blade = np.where((h - y) > height, np.inf, blade)
        d = np.minimum(d, blade)
    return _coverage(d)


def fern(rng, w=256, h=256):
    x, y = _grid(w, h)
    d = _segment_sdf(x, y, w / 2, h - 2, w / 2, 6, 2.0)
    tilt = 0.45  # leaflets rise from the stem at this angle (radians)
    for k in range(15):
        py = h - 16 - k * (h - 30) / 15
        ln = (1 - k / 16) * 0.42 * w + 6
        for side in (-1, 1):
            cx = w / 2 + side * ln / 2 * np.cos(tilt)
            cy = py - ln / 2 * np.sin(tilt)
            d = np.minimum(d, _leaf_sdf(x, y, cx, cy, ln, 9 + rng.uniform(0, 3), -side * tilt))
    return _coverage(d)


GENERATORS = {
    "leaves": leaves,
    "big_leaf": big_leaf,
    "chainlink": chainlink,
    "grate": grate,
    "grass": grass,
    "fern": fern,
}


def default_corpus() -> list[AlphaTexture]:
    """The default corpus, identical on every run (one seeded generator per texture)."""
    out = []
    for i, (name, gen) in enumerate(GENERATORS.items()):
        rng = np.random.default_rng([SEED, i])
        out.append(AlphaTexture(f"{name}.png", gen(rng), 255))
    return out
