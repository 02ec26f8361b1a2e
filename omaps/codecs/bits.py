"""Bit fields in a block: bit k is bit (k mod 8) of byte k div 8 (little-endian), and a field of
n bits at position p holds its least significant bit at p. docs/FORMAT.md uses the same rule."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def get_bits(block, pos, n):
    """Unsigned value of the ``n``-bit field (n <= 56) at bit ``pos`` of a uint8 array, read a
    byte at a time."""
    byte = pos >> 3
    shift = pos & 7
    v = np.int64(block[byte]) >> shift
    got = 8 - shift
    while got < n:
        byte += 1
        v |= np.int64(block[byte]) << got
        got += 8
    return v & ((np.int64(1) << n) - 1)


def put_bits(block: np.ndarray, pos: int, n: int, value: int) -> None:
    if not 0 <= value < (1 << n):
        raise ValueError(f"value {value} does not fit in {n} bits")
    for i in range(n):
        k = pos + i
        if (value >> i) & 1:
            block[k >> 3] |= np.uint8(1 << (k & 7))
        else:
            block[k >> 3] &= np.uint8(~(1 << (k & 7)) & 0xFF)


def as_block(data, nbytes: int, name: str = "block") -> np.ndarray:
    """A physical block as a uint8 array of exactly ``nbytes``."""
    b = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) \
        else np.asarray(data, dtype=np.uint8)
    if b.shape != (nbytes,):
        raise ValueError(f"{name} must be {nbytes} bytes, got {b.size}")
    return b
