"""Equal rows found fast: a 64-bit hash per row, an open-addressing table of the distinct rows
(``RowIndex``), and a word-by-word check of the rows that share a hash.

Maps and micromaps repeat a lot (a scene's pairs of one texture, uniform regions, instanced
foliage), and sorting whole rows to find the repeats (``np.unique(..., axis=0)``) compares them
byte by byte: 2.1 s for the 6,431 64 x 64 pair maps of forest.glb. Hashing reads each row once,
and the table finds each row's equal in one probe or a few, with no sort.

Example::

    >>> import numpy as np
    >>> from omaps.rows import unique_rows
    >>> uniq, inverse = unique_rows(np.array([[1, 2], [0, 5], [1, 2]], np.uint8))
    >>> uniq.tolist(), inverse.tolist()
    ([[0, 5], [1, 2]], [1, 0, 1])
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["row_hashes", "unique_rows", "first_occurrences", "first_uses", "RowIndex"]

_MIX = np.uint64(0xBF58476D1CE4E5B9)  # splitmix64's finaliser multipliers
_MIX2 = np.uint64(0x94D049BB133111EB)


def _keys(n: int) -> np.ndarray:
    # a fixed random 64-bit key per 8-byte word of a row: a word's position changes its hash
    return np.random.default_rng(0x0A3F).integers(0, 2**63, size=n, dtype=np.uint64) * np.uint64(2) + np.uint64(1)


def _as_bytes(rows: np.ndarray) -> np.ndarray:
    """Rows (M, ...) as a contiguous uint8 array (M, K) of their bytes."""
    a = np.ascontiguousarray(rows)
    return a.reshape(len(a), int(np.prod(a.shape[1:]))).view(np.uint8)


def _words(a: np.ndarray) -> np.ndarray:
    """uint8 rows (M, K) as little-endian 64-bit words (M, ceil(K / 8)), zero-padded."""
    pad = -a.shape[1] % 8
    if pad:
        a = np.concatenate([a, np.zeros((len(a), pad), np.uint8)], axis=1)
    return np.ascontiguousarray(a).view("<u8")


def row_hashes(rows: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row's bytes (M, ...) -> (M,) uint64: equal rows, equal hashes (rows
    with equal hashes may still differ: callers compare them)."""
    words = _words(_as_bytes(rows))
    out = np.empty(len(words), dtype=np.uint64)
    _hash_rows(words, _keys(words.shape[1]), out)
    return out


@njit(cache=True)
def _hash_rows(words, keys, out):
    # each word mixed on its own (splitmix64's finaliser) before the sum: a plain weighted sum is
    # linear, and rows that differ only in the top bit of two words (2**63 + 2**63 = 0 modulo
    # 2**64) always collided -- 4 of the oak leaf's 36,715 micromaps did. One pass over the rows
    # (numpy's one operation at a time read the words seven times).
    for i in range(words.shape[0]):
        h = np.uint64(0)
        for w in range(words.shape[1]):
            x = words[i, w] ^ keys[w]
            x ^= x >> np.uint64(30)
            x *= _MIX
            x ^= x >> np.uint64(27)
            x *= _MIX2
            x ^= x >> np.uint64(31)
            h += x  # wraps modulo 2**64
        out[i] = h


OWN, IN_PLACE, EXTERNAL = 0, 1, 2  # where ``_insert`` finds the rows it compares


@njit(cache=True, inline="always")
def _same_words(store, j, words, i):
    for w in range(words.shape[1]):
        if store[j, w] != words[i, w]:
            return False
    return True


@njit(cache=True, inline="always")
def _same_bytes(data, at, rows, i):
    """Whether ``data[at:at + K]`` holds row ``i`` of ``rows`` (M, K): compared a block of bytes
    at a time, with no branch inside a block (the compiler vectorises it)."""
    width = rows.shape[1]
    k = 0
    while k < width:
        end = min(k + 256, width)
        d = np.uint8(0)
        for q in range(k, end):
            d |= data[at + q] ^ rows[i, q]
        if d:
            return False
        k = end
    return True


@njit(cache=True)
def _insert(words, hashes, table, store, n, mode, rows, data, offsets, before):
    """Each row of ``words`` (M, W) looked up in the open-addressing ``table`` (S, 2), S a power
    of two at least twice the entries it will hold: per slot an entry (-1: empty) and its row's
    hash (int64 bits). A row not found gets the id n, n + 1, ... Returns (ids, new n). A probe
    reads one slot (entry and hash together); a row's words are compared only when the hashes
    agree.

    ``mode`` OWN: an entry is an id, whose row is copied to ``store`` (at least n + M rows; a
    ``RowIndex``, rows added over many calls). IN_PLACE (``first_occurrences``: every row at
    once, from an empty table, ``store`` is ``words``): an entry is the position of its row's first
    occurrence in ``words``, nothing is copied. EXTERNAL (a ``RowIndex`` over its caller's
    bytes): an entry is an id; a row of an id below ``before`` is read from ``data`` at
    ``offsets[id]`` and compared with the row's bytes ``rows`` (M, K), a newer one from ``words``
    itself; nothing is copied."""
    mask = table.shape[0] - 1
    ids = np.empty(words.shape[0], dtype=np.int64)
    first = np.empty(words.shape[0] if mode == EXTERNAL else 0, dtype=np.int64)  # the row of each new id
    for i in range(words.shape[0]):
        h = hashes[i]
        s = h & mask
        while True:
            j = table[s, 0]
            if j < 0:  # not there: a new row
                table[s, 0] = i if mode == IN_PLACE else n
                table[s, 1] = h
                if mode == OWN:
                    store[n] = words[i]
                elif mode == EXTERNAL:
                    first[n - before] = i
                ids[i] = n
                n += 1
                break
            if table[s, 1] == h:
                if mode == OWN:
                    same = _same_words(store, j, words, i)
                elif mode == IN_PLACE:
                    same = _same_words(words, j, words, i)
                elif j >= before:
                    same = _same_words(words, first[j - before], words, i)
                else:
                    same = _same_bytes(data, offsets[j], rows, i)
                if same:
                    ids[i] = ids[j] if mode == IN_PLACE else j
                    break
            s = (s + 1) & mask
    return ids, n


@njit(cache=True)
def _rehash(old, table):
    mask = table.shape[0] - 1
    for t in range(old.shape[0]):
        if old[t, 0] < 0:
            continue
        s = old[t, 1] & mask
        while table[s, 0] >= 0:
            s = (s + 1) & mask
        table[s, 0] = old[t, 0]
        table[s, 1] = old[t, 1]


class RowIndex:
    """The distinct rows of one width seen so far, each with an id (0, 1, 2, ... in the order of
    first use), found by their 64-bit hashes (``row_hashes``) in an open-addressing table and
    confirmed word by word: equal rows get one id, different rows different ids, whatever their
    hashes. The pack stage's reuse of identical micromaps, and ``first_occurrences``.

    By default the index keeps a copy of each distinct row. With ``external``, it keeps none: the
    caller keeps the distinct rows in a byte buffer of its own, passes it to every ``add``
    (``data``) and stores the rows that call found new, in the order of their ids, at ``at``,
    ``at + width``, ... (the rows' first occurrences, ``first_uses``), before the next ``add``.
    The pack stage keeps its micromap data so: one copy of the output, not two.

    Example::

        >>> import numpy as np
        >>> from omaps.rows import RowIndex
        >>> index = RowIndex(2)
        >>> index.add(np.array([[1, 2], [0, 5], [1, 2]], np.uint8)).tolist()
        [0, 1, 0]
        >>> index.add(np.array([[0, 5], [7, 7]], np.uint8)).tolist()
        [1, 2]
        >>> ext, data = RowIndex(2, external=True), bytearray()
        >>> rows = np.array([[1, 2], [0, 5], [1, 2]], np.uint8)
        >>> ids = ext.add(rows, np.frombuffer(data, np.uint8), len(data))
        >>> data += rows[first_uses(ids)].tobytes()
        >>> ext.add(np.array([[0, 5], [7, 7]], np.uint8), np.frombuffer(data, np.uint8), len(data)).tolist()
        [1, 2]
    """

    def __init__(self, width: int, external: bool = False):
        self.width = int(width)  # bytes per row
        self.n = 0  # distinct rows so far
        self.external = bool(external)
        self._store = np.empty((0, -(-self.width // 8)), np.uint64)
        self._offsets = np.empty(0, np.int64)  # external: each id's row's byte offset in the caller's data
        self._end = 0  # external: the end of the furthest row stored, the bytes ``data`` must hold
        self._table = np.full((16, 2), -1, np.int64)

    def add(self, rows: np.ndarray, data: np.ndarray | None = None, at: int = 0) -> np.ndarray:
        """The id of each row (M, ...) of ``width`` bytes: an earlier equal row's, else a new one
        (ids from ``n`` on, in the order of the rows). ``external``: ``data`` (uint8) holds every
        earlier id's row where the caller stored it, and the new ones will be stored from byte
        ``at`` on (see the class)."""
        a = _as_bytes(rows)
        if a.shape[1] != self.width:
            raise ValueError(f"rows of {a.shape[1]} bytes in an index of {self.width}-byte rows")
        if self.external and data is None:
            raise ValueError("an external RowIndex compares with the caller's data: pass it")
        need = self.n + len(a)
        store, before = self._store, self.n
        if self.external:
            if need > len(self._offsets):
                offsets = np.empty(max(need, 2 * len(self._offsets)), np.int64)
                offsets[:self.n] = self._offsets[:self.n]
                self._offsets = offsets
            data = np.asarray(data, dtype=np.uint8).reshape(-1)
            if self._end > len(data):
                raise ValueError("data does not hold every row this index has seen")
        elif need > len(self._store):
            store = np.empty((max(need, 2 * len(self._store)), self._store.shape[1]), np.uint64)
            store[:self.n] = self._store[:self.n]
            self._store = store
        if 2 * need > len(self._table):
            size = len(self._table)
            while size < 2 * need:
                size *= 2
            old, self._table = self._table, np.full((size, 2), -1, np.int64)
            _rehash(old, self._table)
        mode = EXTERNAL if self.external else OWN
        ids, self.n = _insert(_words(a), row_hashes(a).view(np.int64), self._table, store, self.n, mode, a,
                              _NO_DATA if data is None else data, self._offsets, before)
        if self.external:
            self._offsets[before:self.n] = int(at) + self.width * np.arange(self.n - before, dtype=np.int64)
            if self.n > before:
                self._end = max(self._end, int(self._offsets[self.n - 1]) + self.width)
        return ids


_NO_DATA = np.empty(0, np.uint8)


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
    ``rows``). Found as a ``RowIndex`` finds them (hashed, confirmed word by word), with the
    rows compared in place: nothing is copied to a store."""
    flat = _as_bytes(rows)
    if len(flat) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    size = 16
    while size < 2 * len(flat):
        size *= 2
    words = _words(flat)
    ids, _ = _insert(words, row_hashes(flat).view(np.int64), np.full((size, 2), -1, np.int64), words, 0, IN_PLACE,
                     flat, _NO_DATA, np.empty(0, np.int64), 0)
    return first_uses(ids), ids


def first_uses(ids: np.ndarray, before: int = 0) -> np.ndarray:
    """The positions of the rows that ``RowIndex.add`` gave a new id (``before``: the index's
    ``n`` before the call), in order: new ids count up from ``before``, so a row is the first of
    its id exactly when its id exceeds every id before it."""
    seen = np.maximum.accumulate(np.concatenate([[before - 1], ids[:-1]]))  # the largest id before each row
    return np.flatnonzero(ids > seen).astype(np.int64)
