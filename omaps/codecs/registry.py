"""Stored square maps by name: the raw ``sqN`` map and the compressed codecs, one interface.

This module is the one list of codecs: each declares itself once (a ``CodecEntry``: its name,
map size, block bytes, random-access lookup, whether a byte budget may choose it and whether it is
one of a budget's defaults, the compile families of its kernels, a one-line description), and
the registry gives each its format code (``ENTRIES``). The tracer's dispatch
(``codecs.dispatch``), the budget's options (``budget_options``), ``omm --from``, the scheme
grammar and its messages, the command line's help, the docs' codec tables and the compile-ahead
families and their warm-up runs are derived from it: adding a codec is its own modules plus one
entry in ``_BUILTIN``, or, outside omaps, a package whose entry point in the group
``omaps.codecs`` returns its entries (``omaps.plugins``; docs: "Adding a codec"). Besides the square codecs, the entries ``succinct0`` ..
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

__all__ = ["Codec", "CodecEntry", "CompileFamily", "PairMicromaps", "ENTRIES", "PLUGIN_GROUP", "get_codec",
           "codec_names", "codec_list", "entry", "budget_options", "format_names", "family_codecs", "square_codec",
           "COMPILE_FAMILIES",
           "ENCODERS", "EFFORTS", "check_choice"]


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
    # the block *is* the map (the raw sqN): decoding gives the map back unchanged, so commands use
    # the baked map as it is; every other codec's maps are encoded and decoded again
    raw: bool = False

    @property
    def compressed(self) -> bool:
        """Its maps are encoded (and decoded again, checked) before any figure is taken: every
        codec but the raw ``sqN`` (``raw``), whether or not it has encoders to choose from."""
        return not self.raw

    def options(self, encoder: str | None = None, effort: str | None = None) -> tuple[str | None, str | None]:
        """(encoder, effort) with defaults filled in; InputError for a name no codec knows, or
        for an encoder or effort this codec does not have (a scheme's variant: ``vq4-paper``). A
        raw map has no choices and ignores valid ones (a command's ``--effort`` applies to its
        codecs); a codec without choices (``encoders`` or ``efforts`` empty) gets None."""
        self._known(encoder, effort)
        if self.raw:
            return None, None
        for kind, value, have in (("encoder", encoder, self.encoders), ("effort", effort, self.efforts)):
            if value is not None and value not in have:
                raise InputError(f"{self.name} has no {kind} {value!r} "
                                 + (f"(choose from {', '.join(have)})" if have else f"(it has no {kind}s to choose)"))
        return encoder or self.default_encoder, effort or self.default_effort

    def _known(self, encoder: str | None, effort: str | None) -> None:
        """InputError for an encoder or effort name that neither omaps nor this codec knows."""
        check_choice("encoder", encoder, tuple(dict.fromkeys(ENCODERS + self.encoders)))
        check_choice("effort", effort, tuple(dict.fromkeys((*EFFORTS, *self.efforts))))

    def fallback(self, encoder: str | None = None, effort: str | None = None) -> tuple[str | None, str | None, str | None]:
        """``options`` for a choice made for many codecs at once (a command's ``--encoder`` /
        ``--effort``, a budget's): an encoder or effort this codec does not have gives its
        default instead. Returns (encoder, effort, note): the note, None when nothing fell back,
        says what was used instead (commands print it with their results).

        Example::

            >>> get_codec("wavelet3").fallback("paper")
            ('best', 'medium', "wavelet3 has no encoder 'paper': its default encoder 'best' was used")
        """
        self._known(encoder, effort)
        if self.raw:
            return None, None, None
        missing = []
        if encoder is not None and encoder not in self.encoders:
            missing.append(("encoder", encoder))
            encoder = None
        if effort is not None and effort not in self.efforts:
            missing.append(("effort", effort))
            effort = None
        enc, eff = self.options(encoder, effort)
        if not missing:
            return enc, eff, None
        used = {"encoder": enc, "effort": eff}
        what = " or ".join(f"{k} {v!r}" for k, v in missing)
        instead = ", ".join(f"its default {k} {used[k]!r}" if used[k] else f"no {k} (it has none to choose)"
                            for k, _ in missing)
        return enc, eff, f"{self.name} has no {what}: {instead} was used"

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


@typed
def square_codec(name: str, map_size: int, block_bytes: int, encode_many: Callable, decode: Callable,
                 lookup: Callable, *, encoders: tuple[str, ...] = (), efforts: tuple[str, ...] = (),
                 default_encoder: str | None = None, default_effort: str | None = None,
                 decode_many: Callable | None = None, bits: int | None = None) -> Codec:
    """A ``Codec`` from its parts: what a codec's ``CodecEntry.make`` returns.

    ``encode_many(maps, encoder, effort)``: maps (P, N, N) uint8 of states 0..2 -> blocks
    (P, block_bytes) uint8, conservative (a cell may only turn from T or O into C: ``encode_many``
    of the ``Codec`` checks every block); ``encoder`` / ``effort`` are one of ``encoders`` /
    ``efforts`` (their defaults when the caller names none), or None when the codec has none to
    choose. ``decode(data: bytes)`` -> (N, N) map; it must accept any ``block_bytes`` bytes
    (decoders are total: a block read from a file may hold anything). ``lookup``: a numba
    ``@njit`` ``(block: uint8[block_bytes], x, y) -> state`` reading only the bits it needs, the
    same state as ``decode`` gives for cell (x, y) (row y, column x); the tracer inlines it.
    ``decode_many(blocks (P, block_bytes)) -> (P, N, N)``: optional, a compiled bulk decoder.
    ``bits``: storage bits of one map (default 8 x ``block_bytes``)."""
    from ..checks import integer

    integer(map_size, "map_size", 1, _RAW_SIZES[-1])
    integer(block_bytes, "block_bytes", 1)
    for kind, choices, default in (("encoder", encoders, default_encoder), ("effort", efforts, default_effort)):
        if tuple(choices) and default not in choices or not tuple(choices) and default is not None:
            raise InputError(f"{name}: default_{kind} {default!r} must be one of its {kind}s ({', '.join(choices) or 'none'})",
                             param=f"default_{kind}")
    return Codec(name, map_size, 8 * block_bytes if bits is None else bits, block_bytes, tuple(encoders), tuple(efforts),
                 default_encoder, default_effort, encode_many, decode, lookup, decode_many)


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

    return Codec(f"sq{n}", n, 2 * n * n, row_bytes(n * n), (), (), None, None, enc, dec, square_lookup(n), dec_many,
                 raw=True)


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
class CompileFamily:
    """A compile-ahead family a codec declares (``omaps.cli.precompile``): the modules whose numba
    kernels encoding and decoding its maps compile, and about how many seconds one process took to
    compile them with an empty cache on the 2-core reference machine (imports and cache writes
    included; the compile's announced estimate). Its warm-up encodes a made-up map with every
    encoder and effort of each entry that declares it."""

    name: str
    modules: tuple[str, ...]
    seconds: int = 30


# the families of omaps' own kernels an entry may name by string (``omaps.cli.precompile``'s
# ``COMMAND_FAMILIES``): baking square maps, and the hierarchical micromaps' trees
SHARED_FAMILIES = ("square", "hierarchical")


@dataclass(frozen=True)
class CodecEntry:
    """One codec's declaration: what every part of omaps derives from the registry.

    ``lookup()`` imports the codec's block module only and returns its numba
    ``(block, x, y) -> state``; ``make()`` builds the full ``Codec`` (``square_codec``) on first
    use; ``families``: the compile-ahead families that baking and encoding its maps compile, a
    ``CompileFamily`` it declares or the name of one declared elsewhere (``"square"``: the square
    baker; another entry's family); ``budget``: a byte budget may choose it for a pair when a
    scheme names it (``budget:BYTES:default+NAME``); ``budget_default``: it is also one of the
    default options of every ``budget:BYTES`` (opt-in: a new codec changes no default budget);
    ``description``: one line for the docs' and the report's codec tables.

    ``code`` is the tracer's format code of a pair's block (0 is no map), assigned by the registry
    in declaration order: omaps' own entries first (their codes are those docs/FORMAT.md records),
    then the plug-ins' (``PLUGIN_GROUP``) in the order of their distributions' and entry points'
    names. An entry is declared without one. ``origin``: ``"omaps"`` or the plug-in it came from.

    ``level``: None for a square codec (a fixed ``block_bytes`` block over the pair's ``map_size``
    square, read by cell); a micromap level L for an entry that stores the pair's two triangles'
    level-L micromaps in a representation whose bytes depend on the maps (``map_size`` and
    ``block_bytes`` 0; ``make()`` gives a ``PairMicromaps``): its ``lookup()`` is a numba
    ``(block, level, second, k) -> state`` of micro-triangle k of the pair's first or second
    triangle.

    Example (a plug-in's entry point returns entries like this one)::

        >>> from omaps.codecs import CodecEntry, CompileFamily
        >>> e = CodecEntry("sq16copy", 16, 64, lookup=lambda: None, make=lambda: None,
        ...                families=("square", CompileFamily("sq16copy", ("mypkg.block",), 10)),
        ...                description="a raw 16x16 map again")
        >>> e.code, e.budget, e.budget_default
        (0, False, False)
    """

    name: str
    map_size: int
    block_bytes: int
    lookup: Callable[[], Callable]
    make: Callable[[], "Codec | PairMicromaps"]
    families: tuple["str | CompileFamily", ...] = ()
    budget: bool = False
    budget_default: bool = False
    level: int | None = None
    description: str = ""
    code: int = 0
    origin: str = "omaps"

    @property
    def variable(self) -> bool:
        """Its bytes depend on the pair's maps (a budget option priced per pair)."""
        return self.level is not None

    @property
    def family_names(self) -> tuple[str, ...]:
        """Its compile-ahead families' names, in order."""
        return tuple(f.name if isinstance(f, CompileFamily) else f for f in self.families)


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


def _pair_micromaps(level: int) -> PairMicromaps:
    from .succinct import pair_encode

    return PairMicromaps(f"succinct{level}", level, entry(f"succinct{level}").code, pair_encode)


_VQ2 = CompileFamily("vq2", ("omaps.codecs.vq2_encode",), 47)
_VQ4 = CompileFamily("vq4", ("omaps.codecs.vq4_encode",), 51)

# omaps' own codecs, in the order of their format codes (docs/FORMAT.md): append a new one at the end
_BUILTIN: tuple[CodecEntry, ...] = tuple(
    CodecEntry(f"sq{n}", n, max(1, n * n // 4), _raw_lookup(n), lambda n=n: _raw(n), ("square",),
               budget=n <= _RAW_BUDGET, budget_default=n <= _RAW_BUDGET,
               description=f"the raw {n}x{n} map, 2 bits per cell") for n in _RAW_SIZES) + (
    CodecEntry("vq2", 16, 32, _block_lookup("vq2_block"), lambda: _vq("vq2"), ("square", _VQ2), True, True,
               description="the deck's VQ2: 16x16 cells in 256 bits, vectors of 2x2 cells"),
    CodecEntry("vq4", 32, 64, _block_lookup("vq4_block"), lambda: _vq("vq4"), ("square", _VQ4), True, True,
               description="the deck's VQ4: 32x32 cells in 512 bits, vectors of 4x4 cells"),
    CodecEntry("vq4x64", 64, 256, _block_lookup("vq4_block", "lookup_x64"), lambda: _vq("vq4x64"),
               ("square", _VQ4), True, True, description="64x64 cells as four VQ4 blocks (2048 bits)"),
    CodecEntry("vq4-synth", 32, 64, _block_lookup("vq4_synth_block"), lambda: _synth("vq4-synth"),
               ("square", "vq4", CompileFamily("synth", ("omaps.codecs.vq4_synth_encode",
                                                         "omaps.codecs.vq4_synth_block"), 68)),
               description="a VQ4 block whose codebook order carries a synthesised 14th vector (512 bits)"),
    CodecEntry("wavelet3", 64, 64, _block_lookup("wavelet3_block"), lambda: _synth("wavelet3"),
               ("square", CompileFamily("wavelet", ("omaps.codecs.wavelet3_encode", "omaps.codecs.wavelet3_block",
                                                    "omaps.codecs.vec4_search", "omaps.allocate"), 36)),
               description="64x64 cells in 512 bits: a three-level hierarchy of uniform and refined blocks"),
) + tuple(  # a pair's two succinct micromaps (per-triangle trees); csmL shares subtrees across the scene: no pair cost
    CodecEntry(f"succinct{lv}", 0, 0, _block_lookup("succinct", "pair_lookup"), lambda lv=lv: _pair_micromaps(lv),
               ("hierarchical",), budget=True, level=lv,
               description=f"a pair's two level-{lv} micromaps as succinct trees (bytes per pair)")
    for lv in range(MAX_LEVEL + 1))

PLUGIN_GROUP = "omaps.codecs"  # the entry point group of codec plug-ins (``omaps.plugins``)

_RESERVED = re.compile(r"none|texel|omm|default|sq\d+|(tri|succinct|csm)\d+|(budget|file)(:.*)?")
_NAME = re.compile(r"[a-z][a-z0-9_]*(-[a-z0-9_]+)*")


def _check(e: object, where: str, seen: dict[str, str], families: dict[str, CompileFamily]) -> CodecEntry:
    """``e`` checked as a new entry (``where`` names its origin in messages); its families added."""
    from .. import checks

    MAX_SQUARE = _RAW_SIZES[-1]  # (``bake.square.MAX_SQUARE``; that module's import costs a bake's start)

    def bad(problem: str):
        return InputError(f"{where}: {problem}")

    if not isinstance(e, CodecEntry):
        raise bad(f"an entry must be a CodecEntry, got {type(e).__name__}")
    name = e.name
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise bad(f"codec name {name!r} must be lower-case letters, digits, '_' and inner '-'")
    if name in seen:
        raise bad(f"codec {name!r} is already declared by {seen[name]}")
    if name.rpartition("-")[2] in ("paper", *EFFORTS) or (_RESERVED.fullmatch(name) and where != "omaps"):
        raise bad(f"codec name {name!r} is a scheme name or ends in a variant (-paper, -fast, ...)")
    try:
        if e.variable:
            checks.integer(e.level, "level", 0, MAX_LEVEL)
        else:
            n = checks.integer(e.map_size, "map_size", 1, MAX_SQUARE)
            if n & (n - 1):
                raise InputError(f"map_size must be a power of two up to {MAX_SQUARE}, got {n}")
            checks.integer(e.block_bytes, "block_bytes", 1, 1 << 20)
    except InputError as exc:
        raise bad(f"codec {name!r}: {exc.problem}") from None
    if not callable(e.lookup) or not callable(e.make):
        raise bad(f"codec {name!r}: lookup and make must be callables (each returning what its entry states)")
    if e.budget_default and not e.budget:
        raise bad(f"codec {name!r}: budget_default needs budget")
    if not isinstance(e.description, str) or not e.description.strip() or "\n" in e.description:
        raise bad(f"codec {name!r}: description must be one line of text")
    if not isinstance(e.families, tuple):
        raise bad(f"codec {name!r}: families must be a tuple")
    for f in e.families:
        if isinstance(f, CompileFamily):
            if families.get(f.name, f) != f:
                raise bad(f"codec {name!r}: compile family {f.name!r} is declared otherwise by another entry")
            if not f.modules or not all(isinstance(m, str) for m in f.modules):
                raise bad(f"codec {name!r}: compile family {f.name!r} names no modules")
            families[f.name] = f
        elif not (isinstance(f, str) and (f in SHARED_FAMILIES or f in families)):
            raise bad(f"codec {name!r}: unknown compile family {f!r} (known: "
                      f"{', '.join([*SHARED_FAMILIES, *families])}, or a CompileFamily)")
    seen[name] = where
    return e


def _declare() -> tuple[tuple[CodecEntry, ...], dict[str, CompileFamily]]:
    """Every entry with its format code, omaps' own first, then each plug-in's (checked)."""
    from ..kernel_cache import watch
    from ..plugins import HINT, codec_entries

    seen: dict[str, str] = {}
    families: dict[str, CompileFamily] = {}
    out = [_check(e, "omaps", seen, families) for e in _BUILTIN]
    for where, got in codec_entries(prepare=watch):  # (each plug-in's kernels keyed on its content)
        try:
            out += [replace(_check(e, where, seen, families), origin=where) for e in got]
        except InputError as exc:
            raise InputError(f"{exc.problem}{HINT}") from None
    return tuple(replace(e, code=1 + i) for i, e in enumerate(out)), families


ENTRIES, _FAMILIES = _declare()
_BY_NAME = {e.name: e for e in ENTRIES}
_COMPRESSED = tuple(e.name for e in ENTRIES if not re.fullmatch(r"sq\d+", e.name) and not e.variable)

# the compile-ahead families the entries declare: name -> (modules whose numba kernels they
# compile, seconds their compile process took with an empty cache on the 2-core reference machine)
COMPILE_FAMILIES = {f.name: (f.modules, f.seconds) for f in _FAMILIES.values()}


@typed
def family_codecs(family: str) -> tuple[str, ...]:
    """The square codecs that declare the compile family ``family`` (its warm-up encodes with
    each of them)."""
    return tuple(e.name for e in ENTRIES if not e.variable
                 and any(isinstance(f, CompileFamily) and f.name == family for f in e.families))


def entry(name: str) -> CodecEntry:
    """A codec's declaration by name (``sqN`` or a compressed codec); InputError if unknown."""
    from ..checks import text

    key = text(name, "name").strip().lower()
    if key not in _BY_NAME:
        raise InputError(f"unknown codec {name!r} (choose from sqN, {', '.join(_COMPRESSED)})", param="name")
    return _BY_NAME[key]


@typed
def budget_options(variable: bool = False, default: bool = False) -> tuple[str, ...]:
    """The codecs a byte budget may choose for a pair, in registry order: those of fixed bytes
    and, with ``variable``, also those whose bytes depend on the pair's maps (``succinctL``);
    with ``default``, only the default options of ``budget:BYTES`` (``CodecEntry.budget_default``,
    ``omaps.budget.PAIR_OPTIONS``)."""
    return tuple(e.name for e in ENTRIES if e.budget and (variable or not e.variable)
                 and (e.budget_default or not default))


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


@typed
def codec_list(conjunction: str = "or", names: list[str] | tuple[str, ...] | None = None) -> str:
    """The compressed codecs (``codec_names()``, plug-ins' included), or ``names``, as a phrase for
    help texts and docs: the last two joined by ``conjunction`` (``""``: commas only).

    Example::

        >>> codec_list(names=["vq2", "vq4", "wavelet3"]), codec_list("and", ["vq2"]), codec_list("", ["a", "b"])
        ('vq2, vq4 or wavelet3', 'vq2', 'a, b')
    """
    items = list(codec_names() if names is None else names)
    if len(items) < 2 or not conjunction:
        return ", ".join(items)
    return f"{', '.join(items[:-1])} {conjunction} {items[-1]}"


def get_codec(name: str) -> Codec:
    """A codec by name: ``sqN`` (raw 2-bit map) or a compressed codec of the registry
    (``codec_names()``; plug-ins' included). A plug-in whose ``make()`` gives something other than
    its entry states is an ``InputError`` naming the plug-in."""
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
        if not (isinstance(codec, Codec) and (codec.name, codec.map_size, codec.block_bytes)
                == (e.name, e.map_size, e.block_bytes)):
            got = (f"{codec.name} ({codec.map_size}x{codec.map_size}, {codec.block_bytes} bytes)"
                   if isinstance(codec, Codec) else type(codec).__name__)
            raise InputError(f"{e.origin}: codec {e.name!r}: make() gave {got}, not the Codec its entry states "
                             f"({e.map_size}x{e.map_size}, {e.block_bytes} bytes)")
        _CACHE[key] = replace(codec, code=e.code)
    return _CACHE[key]
