"""Equal rows found fast: a 64-bit hash per row, then a byte-for-byte check of the rows that
share a hash.

Maps and micromaps repeat a lot (a scene's pairs of one texture, uniform regions), and sorting
whole rows to find the repeats (``np.unique(..., axis=0)``) compares them byte by byte: 2.1 s
for the 6,431 64 x 64 pair maps of forest.glb. Hashing reads each row once.

Example::

    >>> import numpy as np
    >>> from omaps.rows import unique_rows
    >>> uniq, inverse = unique_rows(np.array([[1, 2], [0, 5], [1, 2]], np.uint8))
    >>> uniq.tolist(), inverse.tolist()
    ([[0, 5], [1, 2]], [1, 0, 1])
"""

from __future__ import annotations

import numpy as np

__all__ = ["row_hashes", "unique_rows", "first_occurrences"]

_CHUNK_BYTES = 1 << 24  # rows hashed this many bytes at a time (bounded temporaries)
_MIX = np.uint64(0xBF58476D1CE4E5B9)  # splitmix64's finaliser multipliers
_MIX2 = np.uint64(0x94D049BB133111EB)


def _keys(n: int) -> np.ndarray:
    # a fixed random 64-bit key per 8-byte word of a row: a word's position changes its hash
    return np.random.default_rng(0x0A3F).integers(0, 2**63, size=n, dtype=np.uint64) * np.uint64(2) + np.uint64(1)


def row_hashes(rows: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row's bytes (M, ...) -> (M,) uint64: equal rows, equal hashes (rows
    with equal hashes may still differ: callers compare them)."""
    a = np.ascontiguousarray(rows)
    a = a.reshape(len(a), int(np.prod(a.shape[1:]))).view(np.uint8)
    m, k = a.shape
    pad = -k % 8
    if pad:
        a = np.concatenate([a, np.zeros((m, pad), np.uint8)], axis=1)
    words = a.view("<u8")
    keys = _keys(words.shape[1])
    out = np.empty(m, dtype=np.uint64)
    step = max(1, _CHUNK_BYTES // max(1, words.shape[1] * 8))
    with np.errstate(over="ignore"):
        for s in range(0, m, step):
            # each word mixed on its own (splitmix64's finaliser) before the sum: a plain weighted
            # sum is linear, and rows that differ only in the top bit of two words (2**63 + 2**63
            # = 0 modulo 2**64) always collided -- 4 of the oak leaf's 36,715 micromaps did
            x = words[s:s + step] ^ keys
            x ^= x >> np.uint64(30)
            x *= _MIX
            x ^= x >> np.uint64(27)
            x *= _MIX2
            x ^= x >> np.uint64(31)
            out[s:s + step] = x.sum(axis=1, dtype=np.uint64)  # wraps modulo 2**64
    return out


def unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(rows, axis=0, return_inverse=True)`` of an integer array (M, ...), the same
    result (the distinct rows in their sorted order, and each row's index among them), found by
    hashing: only the distinct rows are sorted."""
    a = np.ascontiguousarray(rows)
    if a.dtype.kind not in "biu":
        raise TypeError(f"unique_rows compares bytes: integer or bool rows only, not {a.dtype}")
    flat = a.reshape(len(a), int(np.prod(a.shape[1:])))
    if len(flat) == 0:
        return a[:0].copy(), np.zeros(0, dtype=np.int64)
    first, inverse = first_occurrences(flat)
    uniq, order = np.unique(flat[first], axis=0, return_inverse=True)
    return uniq.reshape((len(uniq),) + a.shape[1:]), order.ravel()[inverse].astype(np.int64)


def first_occurrences(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse) of rows (M, ...): the index of each distinct row's first occurrence, in
    the order of first use, and each row's index among them (``rows[first][inverse]`` equals
    ``rows``). Found by hashing, checked byte for byte."""
    a = np.ascontiguousarray(rows)
    flat = a.reshape(len(a), int(np.prod(a.shape[1:]))).view(np.uint8)
    if len(flat) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    _, first, inverse = np.unique(row_hashes(flat), return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if not all(np.array_equal(flat[s:s + 4096], flat[first[inverse[s:s + 4096]]]) for s in range(0, len(flat), 4096)):
        _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)  # a hash collision
        inverse = inverse.ravel()
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    return first[order].astype(np.int64), rank[inverse]
