"""Stored square maps by name: the raw ``sqN`` map and the compressed codecs, one interface.

This module is the one list of codecs: each declares itself once in ``ENTRIES`` (a
``CodecEntry``: its name, the tracer's format code, map size, block bytes, random-access lookup,
whether a byte budget may choose it, and the compile families of its kernels). The tracer's
dispatch (``codecs.dispatch``), the budget's options (``budget_options``), ``omm --from``, the
scheme grammar's messages and the compile-ahead families are derived from it; adding a codec is
its own modules plus one entry. Besides the square codecs, the entries ``succinct0`` ..
``succinct12`` are byte-budget options of variable size: a pair's two triangles' level-L
micromaps as succinct trees (``PairMicromaps``), their bytes those of the pair's trees.

A ``Codec`` stores one N x N map in a fixed number of bytes: ``encode`` (map -> bytes, the same
kind of object for every codec), ``decode`` (bytes -> map) and a numba ``lookup(block, x, y)``
that reads one cell by random access (the tracer's any-hit filter calls it). The codec owns its
encoder and effort choices, their defaults and their validation (``options``: an unknown value is
an error in every command), and the post-encode check that a decoded map only ever turned O or T
into C (``encode_many``), so every command gets the same blocks and the same guarantee.

Example::

    >>> import numpy as np
    >>> from omaps.codecs import get_codec
    >>> codec = get_codec("vq2")
    >>> m = np.zeros((16, 16), np.uint8); m[:, 8:] = 1
    >>> block = codec.encode(m)
    >>> len(block), bool((codec.decode(block) == m).all()), int(codec.lookup(np.frombuffer(block, np.uint8), 9, 0))
    (32, True, 1)
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from .. import states
from ..birdcurve import MAX_LEVEL
from ..errors import InputError
from .options import EFFORTS, ENCODERS
from ..checks import typed

__all__ = ["Codec", "CodecEntry", "PairMicromaps", "ENTRIES", "get_codec", "codec_names", "entry", "budget_options", "format_names",
           "COMPILE_FAMILIES", "ENCODERS", "EFFORTS", "check_choice"]


def check_choice(kind: str, value, allowed) -> None:
    """InputError unless ``value`` (an encoder or effort name; None means the default) is known."""
    from ..checks import choice

    choice(value, kind, allowed, optional=True)


@dataclass(frozen=True)
class Codec:
    name: str
    map_size: int  # the codec stores an N x N square map
    bits: int  # storage bits of one map
    block_bytes: int
    encoders: tuple[str, ...]  # () when there is nothing to choose (raw maps)
    efforts: tuple[str, ...]
    default_encoder: str | None
    default_effort: str | None
    _encode_many: Callable[[np.ndarray, str, str], np.ndarray]  # (P, N, N) -> (P, block_bytes) uint8
    _decode: Callable[[bytes], np.ndarray]
    # numba @njit (data: uint8[block_bytes], x, y) -> state of cell (x, y), reading only the bits it
    # needs; callable from other numba code (the tracer's any-hit filter)
    lookup: Callable
    # (P, block_bytes) uint8 -> (P, N, N) maps in compiled code; None: ``_decode`` block by block
    _decode_many: Callable[[np.ndarray], np.ndarray] | None = None
    code: int = 0  # the tracer's format code of this codec's blocks (``CodecEntry.code``)

    @property
    def compressed(self) -> bool:
        return bool(self.encoders)

    def options(self, encoder: str | None = None, effort: str | None = None) -> tuple[str | None, str | None]:
        """(encoder, effort) with defaults filled in; InputError for a name no codec knows. A raw
        map has no choices and ignores valid ones (a command's ``--effort`` applies to its
        codecs)."""
        check_choice("encoder", encoder, ENCODERS)
        check_choice("effort", effort, tuple(EFFORTS))
        if not self.compressed:
            return None, None
        if encoder is not None and encoder not in self.encoders:
            raise InputError(f"{self.name} has no encoder {encoder!r} (choose from {', '.join(self.encoders)})")
        return encoder or self.default_encoder, effort or self.default_effort

    def _maps(self, maps: object, param: str, one: bool) -> np.ndarray:
        """``maps`` (N, N) when ``one``, else (P, N, N): states 0..2 as uint8 (integers, bools, or
        floats of those values), checked; an InputError naming ``param`` and the shape given."""
        from ..checks import array

        n = self.map_size
        a = array(maps, param, kinds="biuf")
        want = (n, n) if one else (None, n, n)
        bad_shape = a.ndim != len(want) or any(w is not None and w != s for w, s in zip(want, a.shape))
        if bad_shape or (a.size and (a.min() < 0 or a.max() > states.C)) or (
                a.dtype.kind == "f" and not np.array_equal(a, np.floor(a))):
            what = f"a {n}x{n} map" if one else f"{n}x{n} maps (P, {n}, {n})"
            raise InputError(f"{param}: {self.name} stores {what} of states 0..2, got shape {a.shape}"
                             + ("" if bad_shape else " with other values"), param=param)
        return np.ascontiguousarray(a, dtype=np.uint8)

    def encode(self, m: ArrayLike, encoder: str | None = None, effort: str | None = None) -> bytes:
        """One N x N map of states -> its block (``block_bytes`` bytes). A map of another shape or
        other values raises an ``InputError`` naming ``m`` and the shape given."""
        blocks, _ = self.encode_many(self._maps(m, "m", True)[None], encoder, effort)
        return blocks[0].tobytes()

    def encode_many(self, maps: ArrayLike, encoder: str | None = None,
                    effort: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Maps (P, N, N) -> (blocks (P, block_bytes) uint8, decoded maps (P, N, N)). Every block is
        decoded again and must be conservative (only O->C or T->C): a RuntimeError otherwise."""
        enc, eff = self.options(encoder, effort)
        m = self._maps(maps, "maps", False)
        if len(m) == 0:
            return np.zeros((0, self.block_bytes), np.uint8), m.copy()
        blocks = np.ascontiguousarray(self._encode_many(m, enc, eff), dtype=np.uint8)
        decoded = self.decode_many(blocks)
        if blocks.shape != (len(m), self.block_bytes) or not states.is_conservative(m, decoded):
            raise RuntimeError(f"internal error: the {self.name} encoder changed a known state")
        return blocks, decoded

    def decode(self, data: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
        """A block (bytes or uint8 array) -> its N x N map."""
        b = _block_bytes(data, "data").tobytes()
        if len(b) != self.block_bytes:
            raise InputError(f"a {self.name} block is {self.block_bytes} bytes, got {len(b)}", param="data")
        return self._decode(b)

    def decode_many(self, blocks: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
        """Blocks (P, block_bytes) (or their bytes, concatenated) -> their maps (P, N, N)."""
        raw = _block_bytes(blocks, "blocks")
        if self.block_bytes == 0 or raw.size % self.block_bytes:
            raise InputError(f"blocks: {self.name} blocks are {self.block_bytes} bytes each, got {raw.size} bytes",
                             param="blocks")
        b = raw.reshape(-1, self.block_bytes)
        if self._decode_many is not None:
            return self._decode_many(b)
        out = np.empty((len(b), self.map_size, self.map_size), np.uint8)
        for i, row in enumerate(b):
            out[i] = self._decode(row.tobytes())
        return out


def _block_bytes(data: object, param: str) -> np.ndarray:
    """Blocks given as bytes, bytearray, memoryview or a uint8 array, as a contiguous uint8 array."""
    if isinstance(data, np.ndarray) and data.dtype == np.uint8:
        return np.ascontiguousarray(data)
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(bytes(data), np.uint8).copy()  # (writable: the kernels' one array type)
    from ..errors import InputTypeError

    raise InputTypeError(f"{param} must be bytes or a uint8 array, got "
                         f"{type(data).__name__}{'' if not hasattr(data, 'dtype') else ' of ' + str(data.dtype)}",
                         param=param)


def _raw(n: int) -> Codec:
    from ..bake.square import check_square_size
    from .raw import pack_states, row_bytes, square_lookup, unpack_states

    n = check_square_size(n)

    def enc(maps, encoder, effort):
        return pack_states(maps.reshape(len(maps), -1))

    def dec_many(blocks):
        m = unpack_states(blocks, n * n).reshape(-1, n, n)
        if m.max(initial=0) > states.C:  # the one 2-bit code that is no state: a corrupt map, not a guess
            k, j, i = np.argwhere(m > states.C)[0]
            where = f" (map {k})" if len(m) > 1 else ""
            raise InputError(f"cell ({i}, {j}) of the sq{n} map{where} holds code {m[k, j, i]}, which is no state "
                             "(0 T, 1 O, 2 C)")
        return m

    def dec(data):
        return dec_many(np.frombuffer(data, np.uint8)[None])[0]

    return Codec(f"sq{n}", n, 2 * n * n, row_bytes(n * n), (), (), None, None, enc, dec, square_lookup(n), dec_many)


def _vq(name: str) -> Codec:
    if name == "vq2":
        from . import vq2_block as block, vq2_encode as encoder
    else:
        from . import vq4_block as block, vq4_encode as encoder
    x64 = name == "vq4x64"
    # maps -> bytes in bulk: the encoder's fields packed by the block module in compiled code,
    # decoded again (the conservativeness check) the same way, with no block objects in between
    enc = encoder.encode_blocks_x64 if x64 else encoder.encode_blocks
    size = block.X64_SIZE if x64 else block.SIZE
    nbytes = block.X64_BYTES if x64 else block.BLOCK_BYTES
    return Codec(name, size, 8 * nbytes, nbytes, ENCODERS, tuple(EFFORTS), "best", "medium", enc,
                 block.decode_x64 if x64 else block.decode, block.lookup_x64 if x64 else block.lookup,
                 block.decode_many_x64 if x64 else block.decode_many)


def _synth(name: str) -> Codec:
    """vq4-synth (32x32, synthesised vectors) and wavelet3 (64x64, three levels): 512 bits each."""
    if name == "vq4-synth":
        from . import vq4_synth_block as block, vq4_synth_encode as encoder
    else:
        from . import wavelet3_block as block, wavelet3_encode as encoder

    def enc(maps, e, f):
        return np.stack([np.frombuffer(b.pack(), np.uint8) for b in encoder.encode_many(maps, e, f)])

    return Codec(name, block.SIZE, 8 * block.BLOCK_BYTES, block.BLOCK_BYTES, encoder.ENCODERS, tuple(EFFORTS),
                 "best", "medium", enc, block.decode, block.lookup)


@dataclass(frozen=True)
class CodecEntry:
    """One codec's declaration: what every part of omaps derives from the registry.

    ``code`` is the tracer's format code of a pair's block (0 is no map); ``lookup()`` imports the
    codec's block module only and returns its numba ``(block, x, y) -> state``; ``make()`` builds the
    full ``Codec`` (encoders, decoders) on first use; ``families`` are the compile-ahead families
    (``COMPILE_FAMILIES`` and ``omaps.cli.precompile``) that baking and encoding its maps compile;
    ``budget``: a byte budget may choose it for a pair.

    ``level``: None for a square codec (a fixed ``block_bytes`` block over the pair's ``map_size``
    square, read by cell); a micromap level L for an entry that stores the pair's two triangles'
    level-L micromaps in a representation whose bytes depend on the maps (``map_size`` and
    ``block_bytes`` 0; ``make()`` gives a ``PairMicromaps``): its ``lookup()`` is a numba
    ``(block, level, second, k) -> state`` of micro-triangle k of the pair's first or second
    triangle."""

    name: str
    code: int
    map_size: int
    block_bytes: int
    lookup: Callable[[], Callable]
    make: Callable[[], "Codec | PairMicromaps"]
    families: tuple[str, ...]
    budget: bool = False
    level: int | None = None

    @property
    def variable(self) -> bool:
        """Its bytes depend on the pair's maps (a budget option priced per pair)."""
        return self.level is not None


@dataclass(frozen=True)
class PairMicromaps:
    """A pair's two triangles' level-``level`` micromaps stored as one block of variable bytes:
    the first triangle's tree, then the second's from the next byte (``codecs.succinct``'s
    ``pair_encode``; a pair without a second triangle stores the first's alone).

    Example::

        >>> import numpy as np
        >>> pm = entry("succinct1").make()
        >>> data, starts = pm.encode_pairs(np.array([[0, 0, 0, 0], [0, 1, 2, 1]]), np.array([[1, 1, 1, 1], [0, 0, 0, 0]]),
        ...                                np.array([True, False]))
        >>> np.diff(starts).tolist()          # a uniform tree is 4 bits (1 byte), a mixed level-1 tree 10 (2)
        [2, 2]
    """

    name: str
    level: int
    code: int
    _encode: Callable

    def encode_pairs(self, first, second, has_second) -> tuple[np.ndarray, np.ndarray]:
        """Micromaps (P, 4^L) of each pair's first and second triangle (``second``'s row ignored
        where ``has_second`` is False) -> (data uint8, byte offsets (P + 1,)): pair i's block is
        ``data[starts[i]:starts[i + 1]]``, its bytes the option's cost."""
        return self._encode(first, second, has_second, self.level)


def _raw_lookup(n: int):
    def get():
        from .raw import square_lookup

        return square_lookup(n)
    return get


def _block_lookup(module: str, attr: str = "lookup"):
    def get():
        import importlib

        return getattr(importlib.import_module(f"{__package__}.{module}"), attr)
    return get


_RAW_SIZES = tuple(1 << k for k in range(8))  # sq1 .. sq128 (``bake.square.MAX_SQUARE``)
_RAW_BUDGET = 64  # a budget chooses raw maps up to sq64
_FIRST_TREE_CODE = 14  # succinct0 .. succinct12: codes 14 .. 26


def _pair_micromaps(level: int) -> PairMicromaps:
    from .succinct import pair_encode

    return PairMicromaps(f"succinct{level}", level, _FIRST_TREE_CODE + level, pair_encode)


ENTRIES: tuple[CodecEntry, ...] = tuple(
    CodecEntry(f"sq{n}", 1 + k, n, max(1, n * n // 4), _raw_lookup(n), lambda n=n: _raw(n), ("square",),
               n <= _RAW_BUDGET) for k, n in enumerate(_RAW_SIZES)) + (
    CodecEntry("vq2", 9, 16, 32, _block_lookup("vq2_block"), lambda: _vq("vq2"), ("square", "vq2"), True),
    CodecEntry("vq4", 10, 32, 64, _block_lookup("vq4_block"), lambda: _vq("vq4"), ("square", "vq4"), True),
    CodecEntry("vq4x64", 11, 64, 256, _block_lookup("vq4_block", "lookup_x64"), lambda: _vq("vq4x64"),
               ("square", "vq4"), True),
    CodecEntry("vq4-synth", 12, 32, 64, _block_lookup("vq4_synth_block"), lambda: _synth("vq4-synth"),
               ("square", "vq4", "synth")),
    CodecEntry("wavelet3", 13, 64, 64, _block_lookup("wavelet3_block"), lambda: _synth("wavelet3"),
               ("square", "wavelet")),
) + tuple(  # a pair's two succinct micromaps (per-triangle trees); csmL shares subtrees across the scene: no pair cost
    CodecEntry(f"succinct{lv}", _FIRST_TREE_CODE + lv, 0, 0, _block_lookup("succinct", "pair_lookup"),
               lambda lv=lv: _pair_micromaps(lv), ("hierarchical",), True, lv) for lv in range(MAX_LEVEL + 1))
_BY_NAME = {e.name: e for e in ENTRIES}
_COMPRESSED = tuple(e.name for e in ENTRIES if not e.name.startswith("sq") and not e.variable)

# the compile-ahead families of the codecs' own kernels: (modules whose numba kernels they compile,
# seconds their compile process took with an empty cache on the 2-core reference machine, as
# ``omaps.cli.precompile``'s figures)
COMPILE_FAMILIES = {
    "vq2": (("omaps.codecs.vq2_encode",), 47),
    "vq4": (("omaps.codecs.vq4_encode",), 51),
    "synth": (("omaps.codecs.vq4_synth_encode", "omaps.codecs.vq4_synth_block"), 68),
    "wavelet": (("omaps.codecs.wavelet3_encode", "omaps.codecs.wavelet3_block", "omaps.codecs.vec4_search",
                 "omaps.allocate"), 36),
    # the micromaps' lossless tree representations (``succinctL``, ``csmL``; not square codecs)
    "hierarchical": (("omaps.codecs.succinct", "omaps.codecs.csm"), 70),
}


def entry(name: str) -> CodecEntry:
    """A codec's declaration by name (``sqN`` or a compressed codec); InputError if unknown."""
    from ..checks import text

    key = text(name, "name").strip().lower()
    if key not in _BY_NAME:
        raise InputError(f"unknown codec {name!r} (choose from sqN, {', '.join(_COMPRESSED)})", param="name")
    return _BY_NAME[key]


@typed
def budget_options(variable: bool = False) -> tuple[str, ...]:
    """The codecs a byte budget may choose for a pair, in registry order: those of fixed bytes (a
    budget's default options) and, with ``variable``, also those whose bytes depend on the
    pair's maps (``succinctL``)."""
    return tuple(e.name for e in ENTRIES if e.budget and (variable or not e.variable))


@typed
def format_names() -> tuple[str, ...]:
    """Every format code's codec name, indexed by code (0: ``none``, no map)."""
    names = ["none"] * (1 + max(e.code for e in ENTRIES))
    for e in ENTRIES:
        names[e.code] = e.name
    return tuple(names)


_CACHE: dict[str, Codec] = {}


@typed
def codec_names() -> list[str]:
    """The compressed codecs (raw maps are ``sqN``, N a power of two up to 128)."""
    return list(_COMPRESSED)


def get_codec(name: str) -> Codec:
    """A codec by name: ``sqN`` (raw 2-bit map), ``vq2``, ``vq4``, ``vq4x64``, ``vq4-synth`` or
    ``wavelet3``."""
    from ..checks import text

    key = text(name, "name").strip().lower()
    if key not in _CACHE:
        m = re.fullmatch(r"sq(\d+)", key)
        if m and key not in _BY_NAME:  # its own message for a size that is no codec
            from ..bake.square import MAX_SQUARE

            n = int(m.group(1))
            if not 1 <= n <= MAX_SQUARE or n & (n - 1):
                raise InputError(f"unknown codec {name!r}: the N of sqN is a power of two from 1 to {MAX_SQUARE}, "
                                 f"got {n}", param="name")
            key = f"sq{n}"
        e = entry(key)
        if e.variable:
            raise InputError(f"{e.name} stores a pair's micromaps as trees of variable bytes (a byte budget's "
                             "option), not a square map")
        codec = e.make()
        _CACHE[key] = replace(codec, code=e.code)
    return _CACHE[key]
