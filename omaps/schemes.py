"""Map schemes by name (``sq16``, ``tri3``, ``texel``): what they bake and what they cost.

Every scheme evaluated by ``omaps eval`` is a ``Scheme``; codecs add theirs with ``register``.
Savings = fraction of hits, uniform over the pair's area, that land in a T or O region.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import maps, states
from .errors import InputError
from .sampling import FootprintGrid

DEFAULT_SCHEMES = ("sq4", "sq8", "sq16", "sq32", "sq64", "tri2", "tri3", "tri4", "tri5", "texel")


@dataclass(frozen=True)
class Scheme:
    name: str
    family: str  # lines of a plot connect schemes of one family
    bake: Callable[[FootprintGrid], np.ndarray]  # symbolic map (states) of the corpus pair
    bits_for: Callable[[int, int], int]  # storage bits per pair for a W x H texture

    def savings(self, grid: FootprintGrid) -> float:
        return self.savings_of(grid, self.bake(grid))

    def savings_of(self, grid: FootprintGrid, map_states: np.ndarray) -> float:
        """Savings of a map this scheme baked (regions of equal area)."""
        return maps.known_fraction(map_states)


def _square(n: int) -> Scheme:
    n = maps.check_square_size(n)
    return Scheme(f"sq{n}", "sq", lambda g: maps.bake_square(g, n), lambda w, h: 2 * n * n)


def _tri(level: int) -> Scheme:
    level = maps.check_tri_level(level)
    # two triangles, 4**L micro-triangles each, 2 bits per micro-triangle
    return Scheme(f"tri{level}", "tri", lambda g: maps.bake_pair_triangles(g, level),
                  lambda w, h: 2 * 4 ** level * 2)


class _Texel(Scheme):
    def savings_of(self, grid: FootprintGrid, map_states: np.ndarray) -> float:
        return maps.texel_limit(grid)  # border cells of a linear footprint have half area


TEXEL = _Texel("texel", "texel", lambda g: states.FLAG_TO_STATE[g.cells_within_texture()[0]],
               lambda w, h: 2 * w * h)

_FIXED: dict[str, Callable[[], Scheme]] = {"texel": lambda: TEXEL}
_PATTERNS: list[tuple[re.Pattern, Callable[[int], Scheme]]] = [
    (re.compile(r"sq(\d+)"), _square),
    (re.compile(r"tri(\d+)"), _tri),
]


def register(name: str, factory: Callable[[], Scheme]) -> None:
    """Add a fixed-name scheme (a codec) to the registry."""
    _FIXED[name] = factory


def _codec_scheme(name: str, codec_name: str, encoder: str, effort: str, family: str) -> Scheme:
    """A compressed square map: bake the codec's N x N map, encode, decode what was stored."""
    from .codecs.registry import get_codec

    codec = get_codec(codec_name)

    def bake(g: FootprintGrid) -> np.ndarray:
        return codec.decode(codec.encode(maps.bake_square(g, codec.map_size), encoder, effort))

    return Scheme(name, family, bake, lambda w, h: 8 * codec.block_bytes)


# "vq2" is the best encoder at medium effort (thorough gains little there); "vq4" and "vq4x64" at
# thorough effort, which the corpus affords (about 60 blocks/s). Suffixes name the others.
for _codec, _main in (("vq2", "medium"), ("vq4", "thorough"), ("vq4x64", "thorough")):
    for _suffix, _enc, _eff in [("", "best", _main), ("-paper", "paper", "medium"), ("-fast", "best", "fast"),
                                ("-medium", "best", "medium"), ("-thorough", "best", "thorough")]:
        _name = _codec + _suffix
        if _suffix != "-" + _main:  # the main effort has the plain name
            register(_name, lambda n=_name, c=_codec, e=_enc, f=_eff: _codec_scheme(n, c, e, f, n))


def get_scheme(name: str) -> Scheme:
    key = name.strip().lower()
    if key in _FIXED:
        return _FIXED[key]()
    for pattern, factory in _PATTERNS:
        m = pattern.fullmatch(key)
        if m:
            return factory(int(m.group(1)))
    known = ", ".join(sorted(_FIXED)) + ", sq<N>, tri<L>"
    raise InputError(f"unknown scheme {name!r} (known: {known})")


def parse_schemes(text) -> list[Scheme]:
    """Schemes from a comma-separated string or a list of names, in order, without repeats."""
    names = text.split(",") if isinstance(text, str) else list(text)
    names = [n.strip() for n in names if n.strip()]
    if not names:
        raise InputError("no schemes given")
    out, seen = [], set()
    for n in names:
        s = get_scheme(n)
        if s.name not in seen:
            seen.add(s.name)
            out.append(s)
    return out
