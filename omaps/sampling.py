"""What a hit can read: texture addressing and the "footprint grid" of filtered lookups.

A region of a map is known (T or O) only if every texel value a hit inside it can read agrees.
We turn each (filter, addressing) pair into one grid of flag cells in texel space so that a
single rasteriser serves every case:

* ``nearest``: cell (x, y) is texel (x, y), covering [x, x+1] x [y, y+1] in texel units.
* ``linear``: a hit at texel coordinate p reads the taps floor(p - 0.5) and floor(p - 0.5) + 1
  in each axis, i.e. the hit lies in a *dual* cell [c - 0.5, c + 0.5] whose flag is the OR of
  its four taps. The grid is shifted by +0.5 (``offset``). The OR is exact for a whole cell (a
  bilinear function takes its extremes over the cell at its corners, the taps) and for every
  cell whose taps agree. A cell whose taps disagree is *mixed*: part of it may still be known.
  A grid made from an alpha test (``AlphaTest.grid``) keeps the tap values and the test's
  bounds, and the bakers then decide each region's part of a mixed cell exactly from the
  extremes of the bilinear alpha over it (``omaps.bilinear``); a grid made from texel states
  alone counts a mixed cell as C wherever a region touches it (conservative, not exact).

Out-of-range cells are handled by the grid's per-axis ``period`` (wrap, mirror: the grid repeats)
or by clamping (period 0: indices clamp to the grid's edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from . import states
from .errors import InputError

from .names import FILTERS, WRAP_MODES  # noqa: E402,F401 (defined there, numba-free, for the command line)


@njit(cache=True, inline="always")
def address(i, n, mode):
    """Texel index ``i`` (any integer, negative too) to [0, n) under mode 0 wrap, 1 clamp, 2 mirror."""
    if mode == 0:
        r = i % n
        return r + n if r < 0 else r
    if mode == 1:
        return 0 if i < 0 else (n - 1 if i >= n else i)
    p = 2 * n
    r = i % p
    if r < 0:
        r += p
    return r if r < n else p - 1 - r


@njit(cache=True, inline="always")
def taps(filt, mode_u, mode_v, w, h, x, y):
    """The texels a shader's fetch at texel coordinate (x, y) of a ``w`` x ``h`` texture reads,
    addressed: (column a, column b, row a, row b, fraction x, fraction y). Filter 0 (nearest)
    reads texel floor(p) (b = a, fractions 0); filter 1 (linear) the taps floor(p - 0.5) and
    + 1 on each axis, at the fractions of p - 0.5 past the first. The fetch
    (``sample_texture``) and the texture traffic of ``trace --memory`` both read them here."""
    if filt == 0:
        xa = address(int(math.floor(x)), w, mode_u)
        ya = address(int(math.floor(y)), h, mode_v)
        return xa, xa, ya, ya, 0.0, 0.0
    fx = x - 0.5
    fy = y - 0.5
    x0 = int(math.floor(fx))
    y0 = int(math.floor(fy))
    return (address(x0, w, mode_u), address(x0 + 1, w, mode_u), address(y0, h, mode_v), address(y0 + 1, h, mode_v),
            fx - x0, fy - y0)


@njit(cache=True)
def sample_texture(value, filt, mode_u, mode_v, x, y):
    """What a shader's texture fetch returns at texel coordinate (x, y) of ``value`` (H, W): the
    texel ``taps`` names (nearest), or the blend of its four taps (linear), clamped into the
    range of its taps (where exact arithmetic puts it), so rounding cannot flip a comparison
    every tap agrees on -- which the conservative maps rely on."""
    h, w = value.shape
    xa, xb, ya, yb, ax, ay = taps(filt, mode_u, mode_v, w, h, x, y)
    if filt == 0:
        return np.float64(value[ya, xa])
    return blend(np.float64(value[ya, xa]), np.float64(value[ya, xb]), np.float64(value[yb, xa]),
                 np.float64(value[yb, xb]), ax, ay)


@njit(cache=True, inline="always")
def blend(a00, a01, a10, a11, ax, ay):
    """The linear filter's blend of taps a00 (row y0, column x0), a01, a10, a11 at fractions
    (ax, ay) from the first: two lerps along x, one along y, clamped into the taps' range. Every
    evaluation of the shader's fetch calls it (``sample_texture``, the sampled opaque fractions);
    the exact bilinear extremes use the same function in its coefficient form
    (``bilinear``)."""
    top = a00 + ax * (a01 - a00)
    bot = a10 + ax * (a11 - a10)
    a = top + ay * (bot - top)
    lo = min(min(a00, a01), min(a10, a11))
    hi = max(max(a00, a01), max(a10, a11))
    return min(max(a, lo), hi)


@njit(cache=True, inline="always")
def cell_index(c, size, period):
    """Stored index of footprint cell ``c`` (any integer) of an axis of ``size`` stored cells:
    periodic with ``period``, or clamped when it is 0."""
    if period:
        r = c % period
        return r + period if r < 0 else r
    return 0 if c < 0 else (size - 1 if c >= size else c)


def filter_code(filter: str, path=None) -> int:
    """0 nearest, 1 linear (the numba kernels' code); InputError naming ``path`` otherwise."""
    try:
        return FILTERS.index(filter)
    except ValueError:
        raise InputError(f"unknown filter {filter!r} (choose from {', '.join(FILTERS)})", path) from None


def wrap_code(wrap: str) -> int:
    try:
        return WRAP_MODES.index(wrap)
    except ValueError:
        raise InputError(f"unknown wrap mode {wrap!r} (choose from {', '.join(WRAP_MODES)})") from None


@dataclass(frozen=True)
class FootprintGrid:
    """Flag cells a hit can read. Texel coordinate p lies in cell floor(p + offset); that cell is
    ``flags[addr_y(cy), addr_x(cx)]`` with the period (or clamp when 0) of each axis."""

    flags: np.ndarray  # uint8 (Hc, Wc), values FLAG_T / FLAG_O / FLAG_C
    offset: float
    period_x: int
    period_y: int
    width: int  # texture size in texels
    height: int
    # exact bilinear (empty when absent): 1 where a cell's taps disagree, the texel values the
    # cells' taps read (extended like the flags: mirror doubled), and the alpha test's bounds
    # (O iff min > bounds[0], or >= when bounds[1]; T iff max < bounds[2], or <= when bounds[3])
    mixed: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float64))
    bounds: np.ndarray = field(default_factory=lambda: np.zeros(4, np.float64))

    @property
    def exact(self) -> bool:
        """Whether mixed cells are decided exactly (a linear grid of an alpha test)."""
        return self.values.size > 0

    def kernel_args(self) -> tuple:
        """(flags, mixed, values, bounds, period_x, period_y): what the numba rasterisers read."""
        return self.flags, self.mixed, self.values, self.bounds, self.period_x, self.period_y

    def cells_within_texture(self) -> tuple[np.ndarray, np.ndarray]:
        """Flags and area weights of the cells that cover the texture [0,W]x[0,H] (for the
        texel-resolution limit)."""
        cx, wx = _axis_cover(self.width, self.offset)
        cy, wy = _axis_cover(self.height, self.offset)
        ix = _addr_cells(cx, self.flags.shape[1], self.period_x)
        iy = _addr_cells(cy, self.flags.shape[0], self.period_y)
        return self.flags[np.ix_(iy, ix)], np.outer(wy, wx)


def _axis_cover(n: int, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell indices meeting [offset, n + offset] on one axis and the length each covers."""
    if offset == 0:
        return np.arange(n), np.ones(n)
    w = np.ones(n + 1)
    w[0] = w[-1] = 0.5
    return np.arange(n + 1), w


def _addr_cells(c: np.ndarray, size: int, period: int) -> np.ndarray:
    return c % period if period else np.clip(c, 0, size - 1)


def _extend(arr: np.ndarray, axis: int, mode: str) -> tuple[np.ndarray, int]:
    """The array the cell index runs over along ``axis`` and its period (0 = clamp)."""
    n = arr.shape[axis]
    if mode == "wrap":
        return arr, n
    if mode == "mirror":
        return np.concatenate([arr, np.flip(arr, axis=axis)], axis=axis), 2 * n
    return arr, 0


def footprint_grid(texel_states: np.ndarray, filter: str = "nearest", wrap: str = "clamp",
                   wrap_v: str | None = None, values: np.ndarray | None = None,
                   bounds=None) -> FootprintGrid:
    """Build the grid for texel states (H, W) under a filter and addressing (``wrap`` for u,
    ``wrap_v`` for v, default the same). ``values`` (H, W) and ``bounds`` (the alpha test's, see
    ``FootprintGrid``) make a linear grid exact; ``AlphaTest.grid`` passes them."""
    filter_code(filter)
    wrap_code(wrap)
    wrap_v = wrap if wrap_v is None else wrap_v
    wrap_code(wrap_v)
    from .checks import array

    s = array(texel_states, "texel_states", kinds="biuf")
    if s.ndim != 2 or s.size == 0:
        raise InputError(f"texel states must be a non-empty 2-D array, got shape {s.shape}", param="texel_states")
    if not np.isin(s, (states.T, states.O, states.C)).all():
        raise InputError("texel_states must hold the states 0 (T), 1 (O) and 2 (C) only", param="texel_states")
    s = s.astype(np.intp)
    h, w = s.shape
    f = states.STATE_TO_FLAG[s]
    f, px = _extend(f, 1, wrap)
    f, py = _extend(f, 0, wrap_v)
    if filter == "nearest":
        return FootprintGrid(np.ascontiguousarray(f), 0.0, px, py, w, h)
    # linear: dual cell c reads taps c-1 and c (addressed); OR them along each axis.
    known = (f != states.FLAG_C).astype(np.uint8)
    f = _dual(_dual(f, 1, px), 0, py)
    if values is None:
        return FootprintGrid(np.ascontiguousarray(f), 0.5, px, py, w, h)
    v = np.asarray(values, dtype=np.float64)
    if v.shape != s.shape:
        raise InputError(f"values have shape {v.shape}, texel states {s.shape}")
    v, _ = _extend(v, 1, wrap)
    v, _ = _extend(v, 0, wrap_v)
    # a C cell can be narrowed only when some tap is known (all taps C: every point is C)
    mixed = ((f == states.FLAG_C) & (_dual(_dual(known, 1, px), 0, py) > 0)).astype(np.uint8)
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (4,):
        raise ValueError("bounds must be (o_bound, o_inclusive, t_bound, t_inclusive)")
    return FootprintGrid(np.ascontiguousarray(f), 0.5, px, py, w, h, np.ascontiguousarray(mixed),
                         np.ascontiguousarray(v), b)


def _dual(f: np.ndarray, axis: int, period: int) -> np.ndarray:
    if period:  # periodic: dual cell c = taps (c-1) mod P and c
        return f | np.roll(f, 1, axis=axis)
    # clamp: cells 0..n, where cell 0 = tap 0 and cell n = tap n-1
    first = np.take(f, [0], axis=axis)
    last = np.take(f, [-1], axis=axis)
    lo = np.concatenate([first, f], axis=axis)
    hi = np.concatenate([f, last], axis=axis)
    return lo | hi
