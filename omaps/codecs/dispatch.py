"""A pair's stored block read by its format code: one numba kernel built from the registry.

``block_state(fmt, data, s, t)`` reads the state of the cell holding (s, t) (the hit's position in
its pair's square, in [0, 1]^2) from the block of format ``fmt`` (``CodecEntry.code``; 0: no map,
always C) whose bytes start at ``data`` (a uint8 array view). It is a chain of inlined tests, one
per ``registry.ENTRIES`` entry, each calling that codec's own random-access lookup on the cell
``pair.uv_to_cell(s, t, N)``; the tracer's any-hit filter calls it, so a new codec is traced as soon
as it has its registry entry.

``pair_block_state(fmt, data, s, t, second, b1, b2)`` reads every entry's format, those of
variable bytes too (``CodecEntry.level``: a pair's two triangles' level-L micromaps, read at the
micro-triangle of the hit's barycentrics (b1, b2) on the pair's first or ``second`` triangle).

Example::

    >>> import numpy as np
    >>> from omaps.codecs import block_state, get_codec
    >>> m = np.zeros((16, 16), np.uint8); m[:, 8:] = 1          # T left, O right
    >>> block = np.frombuffer(get_codec("vq2").encode(m), np.uint8)
    >>> code = get_codec("vq2").code
    >>> int(block_state(code, block, 0.2, 0.5)), int(block_state(code, block, 0.9, 0.5)), int(block_state(0, block, 0.9, 0.5))
    (0, 1, 2)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import states
from ..birdcurve import bary_to_index
from ..pair import uv_to_cell
from .registry import ENTRIES

__all__ = ["block_state", "pair_block_state", "MAX_BLOCK_BYTES"]

MAX_BLOCK_BYTES = max(e.block_bytes for e in ENTRIES)  # a view of this many bytes holds any fixed-size block


def _chain(entries):
    """The test of the first entry, falling through to the rest (no map at the end: C)."""
    if not entries:
        @njit(inline="always")
        def no_map(fmt, data, s, t):
            return np.uint8(states.C)

        return no_map
    e = entries[0]
    code, n, nbytes, lookup = e.code, e.map_size, e.block_bytes, e.lookup()
    rest = _chain(entries[1:])

    @njit(inline="always")
    def state(fmt, data, s, t):
        if fmt == code:
            i, j = uv_to_cell(s, t, n)
            return np.uint8(lookup(data[:nbytes], i, j))
        return rest(fmt, data, s, t)

    return state


block_state = _chain([e for e in ENTRIES if not e.variable])


def _pair_chain(entries):
    """``_chain`` with the hit's triangle (first or second of its pair) and barycentrics, for the
    entries whose blocks hold the pair's micromaps."""
    if not entries:
        @njit(inline="always")
        def no_map(fmt, data, s, t, second, b1, b2):
            return np.uint8(states.C)

        return no_map
    e = entries[0]
    rest = _pair_chain(entries[1:])
    code, lookup = e.code, e.lookup()
    if e.variable:
        level = e.level

        @njit(inline="always")
        def tree(fmt, data, s, t, second, b1, b2):
            if fmt == code:
                return np.uint8(lookup(data, level, second, bary_to_index(b1, b2, level)))
            return rest(fmt, data, s, t, second, b1, b2)

        return tree
    n, nbytes = e.map_size, e.block_bytes

    @njit(inline="always")
    def square(fmt, data, s, t, second, b1, b2):
        if fmt == code:
            i, j = uv_to_cell(s, t, n)
            return np.uint8(lookup(data[:nbytes], i, j))
        return rest(fmt, data, s, t, second, b1, b2)

    return square


pair_block_state = _pair_chain(ENTRIES)
