"""The 8 symmetries of the square used by the VQ codecs' per-quadrant transforms.

A 3-bit transform chains, in this order, reflect left/right (bit 2), reflect top/bottom (bit 1)
and rotate 90 (bit 0), acting on element positions with x to the right and y down:
LR (x, y) -> (-x, y); TB (x, y) -> (x, -y); R90 (x, y) -> (y, -x) (a quarter turn
anticlockwise as displayed). The deck's table follows: 000 identity, 001 rotate 90,
010 reflect top/bottom, 011 reflect X=-Y, 100 reflect left/right, 101 reflect X=Y,
110 rotate 180, 111 rotate 270.

A stored vector V shown through transform t is D = t(V): D[t(p)] = V[p]. A decoder reads
D[p] as V[inverse(t)(p)], i.e. the transform acts on the low coordinate bits.
"""

from __future__ import annotations

import numpy as np

def apply_position(t: int, ex: int, ey: int, n: int) -> tuple[int, int]:
    """Where element (ex, ey) of an n x n vector goes under transform t."""
    if t & 4:
        ex = n - 1 - ex
    if t & 2:
        ey = n - 1 - ey
    if t & 1:
        ex, ey = ey, n - 1 - ex
    return ex, ey


def position_tables(n: int) -> tuple[np.ndarray, np.ndarray]:
    """FWD[t, e] = t(e) and INV[t, e] = t^-1(e), elements numbered e = ey * n + ex."""
    fwd = np.empty((8, n * n), dtype=np.int64)
    for t in range(8):
        for ey in range(n):
            for ex in range(n):
                x, y = apply_position(t, ex, ey, n)
                fwd[t, ey * n + ex] = y * n + x
    inv = np.empty_like(fwd)
    for t in range(8):
        inv[t, fwd[t]] = np.arange(n * n)
    return fwd, inv
