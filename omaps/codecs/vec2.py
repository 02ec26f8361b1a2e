"""The 5-bit code of a 2x2 vector (VQ2's codebook entries, VQ4's general sub-vectors).

By the deck's continuity assumption a 2x2 vector never holds O and T together, so it is a
palette ({T, C} or {O, C}) and, per element, "palette state or C":

    bit 0      palette: 0 = {T, C}, 1 = {O, C}
    bits 1..4  element e = 2*ey + ex is C when its bit (1 + e) is set

Codes 0 and 1 are uniform T and O, codes 30 and 31 uniform C (the palette does not matter).
Everything here is a small table, built once, so encoders and decoders share one definition.
"""

from __future__ import annotations

import numpy as np

from .. import states
from .symmetry import position_tables

N_CODES = 32
ALL_C = 30  # canonical code of the uniform C vector


def code_states(code: int) -> np.ndarray:
    """The 4 states (element order e = 2*ey + ex) of a code."""
    pal = states.O if code & 1 else states.T
    return np.array([states.C if (code >> (1 + e)) & 1 else pal for e in range(4)], dtype=np.uint8)


CODE_STATES = np.stack([code_states(c) for c in range(N_CODES)])  # (32, 4)


def vector_code(v) -> int:
    """Code of 4 states with no O and T together (all C gives ``ALL_C``)."""
    v = np.asarray(v).reshape(4)
    has_t, has_o = bool(np.any(v == states.T)), bool(np.any(v == states.O))
    if has_t and has_o:
        raise ValueError("a 2x2 vector cannot hold both O and T")
    mask = sum(1 << e for e in range(4) if v[e] == states.C)
    return (mask << 1) | (1 if has_o else 0) if mask != 15 else ALL_C


def _tables():
    fwd, inv = position_tables(2)
    trans = np.empty((8, N_CODES), dtype=np.int64)
    for t in range(8):
        for c in range(N_CODES):
            d = np.empty(4, dtype=np.uint8)
            d[fwd[t]] = CODE_STATES[c]
            trans[t, c] = vector_code(d)
    # inverse transform numbers: t_inv such that t_inv(t(p)) = p
    t_inv = np.array([next(u for u in range(8) if np.all(fwd[u][fwd[t]] == np.arange(4))) for t in range(8)])
    return fwd, inv, trans, t_inv


FWD2, INV2, TRANS_CODE, INVERSE_T = _tables()  # TRANS_CODE[t, c] = code of t(V)

POPCOUNT4 = np.array([bin(m).count("1") for m in range(16)], dtype=np.int64)


def _retained_table():
    """RETAINED[d, c]: known elements of vector d that entry c keeps when d is stored as c
    (0 when c does not cover d, i.e. would change a state other than to C)."""
    r = np.zeros((N_CODES, N_CODES), dtype=np.int64)
    for d in range(N_CODES):
        for c in range(N_CODES):
            sd, sc = CODE_STATES[d], CODE_STATES[c]
            if np.all((sc == sd) | (sc == states.C)):
                r[d, c] = int(np.sum(sc != states.C))
    return r


RETAINED = _retained_table()
KNOWN = np.array([4 - POPCOUNT4[(c >> 1) & 15] for c in range(N_CODES)], dtype=np.int64)
