"""Uncompressed stored maps: states packed 2 bits (or 1 bit) each, and the raw ``sqN`` codec.

One layout for every uncompressed map omaps stores -- the raw square maps (``sqN``), the
tracer's per-triangle micromaps (``triL``) and the standard OMM data (4-state 2 bits, 2-state
1 bit): region k of a row at bits ``bits * (k mod (8 / bits))`` of byte ``k div (8 / bits)``,
little-endian, every row starting on a byte. docs/FORMAT.md "Stored maps" states the same.

A raw N x N square map is cell (i, j) = region k = j * N + i of one row of ``ceil(N*N / 4)``
bytes.

Example::

    >>> import numpy as np
    >>> from omaps.codecs.raw import pack_states, unpack_states
    >>> packed = pack_states(np.array([[0, 1, 2, 2, 1]]))
    >>> packed.tolist(), unpack_states(packed, 5).tolist()
    ([[164, 1]], [[0, 1, 2, 2, 1]])
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from ..checks import typed

__all__ = ["pack_states", "unpack_states", "row_bytes", "read_state", "square_lookup"]


@typed
def row_bytes(regions: int, bits: int = 2) -> int:
    """Bytes of one packed row (at least one); ``bits`` per state: 1, 2, 4 or 8."""
    from ..checks import integer

    regions = integer(regions, "regions", 0)
    _check_bits(bits)
    return max(1, (regions * bits + 7) // 8)


def _check_bits(bits: int) -> None:
    from ..errors import InputError

    if bits not in (1, 2, 4, 8):
        raise InputError(f"bits must be 1, 2, 4 or 8, got {bits}", param="bits")


@typed
def pack_states(rows: ArrayLike, bits: int = 2) -> np.ndarray:
    """Rows of states (R, K) -> packed (R, row_bytes(K, bits)) uint8."""
    from ..checks import array
    from ..errors import InputError

    _check_bits(bits)
    s = array(rows, "rows", ndim=(1, 2), kinds="biu")
    if s.size and (s.min() < 0 or s.max() >= 1 << bits):
        raise InputError(f"rows must hold states 0..{(1 << bits) - 1}", param="rows")
    s = s.astype(np.uint8, copy=False)
    if s.ndim == 1:
        s = s[None]
    r, k = s.shape
    per_byte = 8 // bits
    nbytes = row_bytes(k, bits)
    if k != nbytes * per_byte:
        padded = np.zeros((r, nbytes * per_byte), dtype=np.uint8)
        padded[:, :k] = s
        s = padded
    s = s.reshape(r, nbytes, per_byte)
    out = s[:, :, 0].copy()
    for i in range(1, per_byte):  # one shifted OR per slot (3-7x faster than a reduce over a broadcast)
        out |= s[:, :, i] << np.uint8(i * bits)
    return out


@typed
def unpack_states(packed: ArrayLike, regions: int, bits: int = 2) -> np.ndarray:
    """Inverse of ``pack_states``: (R, bytes) -> (R, regions) states."""
    from ..checks import array, integer
    from ..errors import InputError

    _check_bits(bits)
    regions = integer(regions, "regions", 0)
    p = array(packed, "packed", ndim=(1, 2), kinds="iu")
    if p.size and (p.min() < 0 or p.max() > 255):
        raise InputError("packed must hold bytes 0..255", param="packed")
    p = p.astype(np.uint8, copy=False)
    if p.ndim == 1:
        p = p[None]
    per_byte = 8 // bits
    shifts = np.arange(per_byte, dtype=np.uint8) * bits
    s = (p[:, :, None] >> shifts) & ((1 << bits) - 1)
    return s.reshape(p.shape[0], -1)[:, :int(regions)].astype(np.uint8)


@njit(cache=True, inline="always")
def read_state(data, start, k):
    """2-bit state of region k of the row at byte ``start`` of ``data``."""
    return (data[start + (k >> 2)] >> (2 * (k & 3))) & 3


_LOOKUPS: dict = {}


def square_lookup(n: int):
    """The random-access lookup ``(block, x, y) -> state`` of a raw N x N map (numba)."""
    if n not in _LOOKUPS:
        @njit
        def lookup(block, x, y):
            return read_state(block, 0, y * n + x)
        _LOOKUPS[n] = lookup
    return _LOOKUPS[n]
