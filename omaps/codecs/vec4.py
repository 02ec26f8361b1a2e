"""4x4 vectors of VQ4: element numbering, the four entry kinds and their codes, transforms.

A 4x4 vector can hold T, O and C together, so VQ4 stores explicit vectors in four *kinds* of
codebook entry, each a palette rule plus one C flag per element (docs/FORMAT.md, "VQ4"):

    kind 0  two-value   17 bits: bit 0 palette (0 {T,C}, 1 {O,C}), bits 1..16 C flags
    kind 1  vertical    18 bits: bit 0 palette of the left half (columns 0-1), bit 1 of the
                        right half (columns 2-3), bits 2..17 C flags
    kind 2  horizontal  18 bits: the same with the top half (rows 0-1) and bottom half
    kind 3  general     20 bits: four VQ2 2x2 codes (``vec2``), sub-vector s = 2*sy + sx at bit 5s

Element e = 4*ey + ex. Inside the encoders a vector is a *pattern*: two 16-bit masks, the
elements known T and the elements known O (the rest are C). Each kind splits the 16 elements into
palette groups (one, two halves or four 2x2 sub-vectors); a pattern fits a kind when no group
holds both T and O.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import states
from .symmetry import position_tables
from .vec2 import ALL_C

TWO_VALUE, VERTICAL, HORIZONTAL, GENERAL = 0, 1, 2, 3
KIND_NAMES = ("two-value", "vertical", "horizontal", "general")
KIND_BITS = np.array([17, 18, 18, 20], dtype=np.int64)
FULL = 0xFFFF

# palette groups of each kind, as element masks (unused groups 0)
GROUPS = np.array([
    [FULL, 0, 0, 0],
    [0x3333, 0xCCCC, 0, 0],  # left (ex < 2), right
    [0x00FF, 0xFF00, 0, 0],  # top (ey < 2), bottom
    [0x0033, 0x00CC, 0x3300, 0xCC00],  # 2x2 sub-vectors s = 2*sy + sx
], dtype=np.int64)


def _element_tables():
    e = np.arange(16)
    ex, ey = e & 3, e >> 2
    sub = 2 * (ey >> 1) + (ex >> 1)  # general: which 2x2 sub-vector
    e2 = 2 * (ey & 1) + (ex & 1)  # and which element of it
    # (palette bit, C-flag bit) offsets of element e inside an entry of each kind
    pal = np.stack([np.zeros(16, int), ex >> 1, ey >> 1, 5 * sub])
    cflag = np.stack([1 + e, 2 + e, 2 + e, 5 * sub + 1 + e2])
    return sub, e2, pal.astype(np.int64), cflag.astype(np.int64)


SUB_OF, E2_OF, PALETTE_BIT, CFLAG_BIT = _element_tables()

FWD4, INV4 = position_tables(4)  # FWD4[t, e] = t(e): where stored element e is shown


def _mask_perm_tables():
    """PERM[t, h, b]: the image under t of the elements in byte h (0 low, 1 high) of a mask."""
    perm = np.zeros((8, 2, 256), dtype=np.int64)
    for t in range(8):
        for h in range(2):
            for b in range(256):
                m = 0
                for k in range(8):
                    if (b >> k) & 1:
                        m |= 1 << FWD4[t, 8 * h + k]
                perm[t, h, b] = m
    return perm


_PERM = _mask_perm_tables()
INVERSE_T = np.array([next(u for u in range(8) if np.array_equal(FWD4[u][FWD4[t]], np.arange(16)))
                      for t in range(8)])
_PERM_INV = _PERM[INVERSE_T]


@njit(cache=True, inline="always")
def popcount16(m):
    m = m - ((m >> 1) & 0x5555)
    m = (m & 0x3333) + ((m >> 2) & 0x3333)
    m = (m + (m >> 4)) & 0x0F0F
    return (m + (m >> 8)) & 0x1F


@njit(cache=True, inline="always")
def transform_mask(m, t):
    """Mask of the shown elements of a stored mask under transform t."""
    return _PERM[t, 0, m & 255] | _PERM[t, 1, m >> 8]


@njit(cache=True, inline="always")
def untransform_mask(m, t):
    """Mask of the stored elements that transform t shows at the elements of ``m``."""
    return _PERM_INV[t, 0, m & 255] | _PERM_INV[t, 1, m >> 8]


@njit(cache=True)
def project(kind, kt, ko):
    """The pattern of ``kind`` closest below (kt, ko): in each palette group holding both T and
    O, the minority turns to C (O kept on a tie). Conservative for everything (kt, ko) covers."""
    for g in range(4):
        grp = GROUPS[kind, g]
        if grp == 0:
            break
        t = kt & grp
        o = ko & grp
        if t != 0 and o != 0:
            if popcount16(t) > popcount16(o):
                ko &= ~grp
            else:
                kt &= ~grp
    return kt, ko


@njit(cache=True)
def entry_code(kind, kt, ko):
    """Code of a pattern that fits ``kind`` (``project`` it first)."""
    cmask = FULL & ~(kt | ko)
    if kind == GENERAL:
        code = 0
        for s in range(4):
            sub = 0
            for e in range(16):
                if SUB_OF[e] == s and (cmask >> e) & 1:
                    sub |= 1 << E2_OF[e]
            c = ALL_C if sub == 15 else (sub << 1) | (1 if ko & GROUPS[GENERAL, s] else 0)
            code |= c << (5 * s)
        return code
    if kind == TWO_VALUE:
        return (cmask << 1) | (1 if ko else 0)
    p0 = 1 if ko & GROUPS[kind, 0] else 0
    p1 = 1 if ko & GROUPS[kind, 1] else 0
    return (cmask << 2) | (p1 << 1) | p0


@njit(cache=True)
def entry_pattern(kind, code):
    """(kt, ko) of any code of a kind: every bit pattern is a valid entry."""
    kt = 0
    ko = 0
    for e in range(16):
        if (code >> CFLAG_BIT[kind, e]) & 1:
            continue
        if (code >> PALETTE_BIT[kind, e]) & 1:
            ko |= 1 << e
        else:
            kt |= 1 << e
    return kt, ko


def pattern_states(kt: int, ko: int) -> np.ndarray:
    """The 4x4 states (``[ey, ex]``) of a pattern."""
    e = np.arange(16)
    s = np.where((kt >> e) & 1, states.T, np.where((ko >> e) & 1, states.O, states.C))
    return s.astype(np.uint8).reshape(4, 4)
