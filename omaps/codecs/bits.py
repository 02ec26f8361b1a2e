"""Bit fields in a block: bit k is bit (k mod 8) of byte k div 8 (little-endian), and a field of
n bits at position p holds its least significant bit at p. docs/FORMAT.md uses the same rule.

A codec describes its block as a field table (each field's bit position and width); ``pack_many``
and ``unpack_many`` turn many blocks' fields into bytes and back in compiled code, a block's
fields being one row of an int64 array in the table's order.

Example::

    >>> import numpy as np
    >>> pos, width = np.array([0, 3]), np.array([3, 5])  # a 3-bit field at bit 0, a 5-bit one at bit 3
    >>> data = pack_many(np.array([[5, 17]]), pos, width, 1)
    >>> data.tolist(), unpack_many(data, pos, width).tolist()
    ([[141]], [[5, 17]])
"""

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


@njit(cache=True, inline="always")
def bit_length(n):
    """Bits needed to write the non-negative integer ``n`` (0 for 0), as Python's ``int.bit_length``."""
    w = 0
    while n > 0:
        w += 1
        n >>= 1
    return w


def check_fields(values, width) -> np.ndarray:
    """``values`` (n, F) as int64, ValueError unless every field fits its width (0 <= v < 2**w)."""
    v = np.ascontiguousarray(values, dtype=np.int64)
    w = np.asarray(width, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != w.shape[0]:
        raise ValueError(f"fields: expected (n, {w.shape[0]}) values, got shape {v.shape}")
    bad = (v < 0) | (v >> w != 0)
    if bad.any():
        i, f = np.argwhere(bad)[0]
        raise ValueError(f"value {v[i, f]} does not fit in {w[f]} bits (field {f} of block {i})")
    return v


@njit(cache=True)
def _pack_many(values, pos, width, nbytes):
    out = np.zeros((values.shape[0], nbytes), dtype=np.uint8)
    for i in range(values.shape[0]):
        for f in range(pos.shape[0]):
            byte = pos[f] >> 3
            v = values[i, f] << (pos[f] & 7)
            while v != 0:  # fields do not overlap: OR into zeroed bytes
                out[i, byte] |= np.uint8(v & 255)
                v >>= 8
                byte += 1
    return out


@njit(cache=True)
def _unpack_many(blocks, pos, width):
    out = np.empty((blocks.shape[0], pos.shape[0]), dtype=np.int64)
    for i in range(blocks.shape[0]):
        for f in range(pos.shape[0]):
            out[i, f] = get_bits(blocks[i], pos[f], width[f])
    return out


def pack_many(values, pos, width, nbytes: int) -> np.ndarray:
    """Fields (n, F) -> blocks (n, nbytes) uint8: field f of each row at bit ``pos[f]``, ``width[f]``
    bits (at most 56), every other bit 0. ValueError if a value does not fit its field."""
    v = check_fields(values, width)
    return _pack_many(v, np.asarray(pos, dtype=np.int64), np.asarray(width, dtype=np.int64), int(nbytes))


def kernel_bytes(data) -> np.ndarray:
    """Bytes (bytes, bytearray, memoryview or an array) as a contiguous, writable uint8 array:
    numba compiles a kernel once per argument layout, and a read-only buffer (``np.frombuffer``
    of bytes) would cost a second compile of every decoder and lookup it reaches."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(bytearray(data), dtype=np.uint8)
    if isinstance(data, np.ndarray) and data.dtype == np.uint8:
        b = np.ascontiguousarray(data)
        return b if b.flags.writeable else b.copy()
    from ..checks import array
    from ..errors import InputError

    a = array(data, "data", kinds="iu")
    if a.size and (a.min() < 0 or a.max() > 255):
        raise InputError("data must hold bytes 0..255", param="data")
    return np.ascontiguousarray(a, dtype=np.uint8)


def unpack_many(blocks, pos, width) -> np.ndarray:
    """Blocks (n, nbytes) uint8 -> their fields (n, F) int64, the inverse of ``pack_many``."""
    b = kernel_bytes(blocks)
    return _unpack_many(b.reshape(len(b), -1), np.asarray(pos, dtype=np.int64), np.asarray(width, dtype=np.int64))


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
    b = kernel_bytes(data)
    if b.shape != (nbytes,):
        raise ValueError(f"{name} must be {nbytes} bytes, got {b.size}")
    return b


def pack_block_fields(indices, entries, transforms, pos, width, nbytes: int) -> np.ndarray:
    """A VQ codec's symbolic fields of n blocks -> physical blocks (n, nbytes) uint8: ``indices``
    (n, 64), ``entries`` (n, E), ``transforms`` (n, 4) with column 0 all 0, or (n, 3) for quadrants
    1..3, in that order at the codec's field positions ``pos`` and widths ``width`` (64 + E + 3
    fields). ValueError for a field out of range or a wrong shape."""
    tr = np.asarray(transforms, dtype=np.int64)
    if tr.ndim == 2 and tr.shape[1] == 4:
        if np.any(tr[:, 0] != 0):
            raise ValueError("transforms: the top-left quadrant's (column 0) must be 0")
        tr = tr[:, 1:]
    idx, ent = np.asarray(indices, dtype=np.int64), np.asarray(entries, dtype=np.int64)
    if idx.ndim != 2 or ent.ndim != 2 or tr.ndim != 2 or not len(idx) == len(ent) == len(tr):
        raise ValueError(f"fields of n blocks: indices (n, 64), entries (n, {len(pos) - 67}), transforms (n, 4); "
                         f"got shapes {idx.shape}, {ent.shape}, {tr.shape}")
    return pack_many(np.concatenate([idx, ent, tr], axis=1), pos, width, nbytes)


def unpack_block_fields(blocks, pos, width):
    """Physical blocks -> (indices (n, 64), entries (n, E), transforms (n, 4)), int64,
    transforms[:, 0] = 0: the inverse of ``pack_block_fields``."""
    f = unpack_many(blocks, pos, width)
    tr = np.zeros((len(f), 4), dtype=np.int64)
    tr[:, 1:] = f[:, len(pos) - 3:]
    return f[:, :64], f[:, 64:len(pos) - 3], tr

