"""Scheme names: the one grammar of ``omaps eval``, ``omaps trace`` and ``omaps omm --from``.

    none                 no map: every candidate hit runs the any-hit shader (trace)
    texel                the per-texel limit of an infinitely fine map (eval)
    triL                 two per-triangle micromaps of 4^L micro-triangles, L = 0..12
    succinctL            the same micromaps, each its pruned 4-way tree with rank support (lossless)
    csmL                 the same micromaps, identical subtrees of the whole set stored once (lossless)
    sqN                  the raw N x N square map over a pair, N a power of two up to 128
    CODEC[-VARIANT]      a compressed codec of the registry (``codecs.codec_names()``: omaps'
                         own and the plug-ins'); VARIANT: paper (the deck's encoder, for the
                         codecs that have it) or an effort of the codec's encoder (fast, medium,
                         thorough); none: the command's --encoder / --effort where the codec has
                         them (else its defaults, and the scheme's ``notes`` say so)
    omm                  (trace) the EXT_mesh_opacity_micromap micromaps stored in the traced file
    file:CODEC           (trace) the OMAPS_pair_opacity_maps pair blocks stored in the traced file,
                         CODEC the codec they were stored with (sqN or a codec of the registry)
    file:csm             (trace) the OMAPS_merged_micromaps stored in the traced file (omm --from csmL)
    budget:BYTES         (trace) per pair the default option (none, sqN up to 64 and the codecs
                         that opt in: ``budget.PAIR_OPTIONS``) that saves the most alpha tests per
                         byte, all pairs within BYTES (1263936, 1.2MiB, 800KiB)
    budget:BYTES:OPTS    the same with the options OPTS, '+'-separated: budget options (every
                         codec the registry marks as one: ``codecs.budget_options(variable=True)``;
                         succinctL: the pair's two level-L micromaps as succinct trees, bytes per
                         pair) or ``default`` (the default options): budget:120KiB:default+succinct6

A ``Scheme`` says what is stored (its ``kind``: none, texel, micromap -- with its
``representation``: raw, succinct or csm -- or square with its ``codec``) and what it costs
(``bits_for``: storage bits per pair; None where the size depends on the map, as for the
hierarchical micromaps). The bakers make the maps.

Example::

    >>> from omaps.schemes import parse_schemes
    >>> [(s.name, s.kind, s.encoder, s.effort) for s in parse_schemes("sq16,vq4-paper,tri3")]
    [('sq16', 'square', None, None), ('vq4-paper', 'square', 'paper', 'medium'), ('tri3', 'micromap', None, None)]
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from .codecs.registry import EFFORTS, Codec, budget_options, check_choice, codec_names, get_codec
from . import checks
from .errors import InputError, InputTypeError

__all__ = ["Scheme", "get_scheme", "parse_schemes", "square_scheme_choices", "notes_lines", "DEFAULT_SCHEMES", "KINDS", "EVAL_KINDS",
           "TRACE_KINDS", "VARIANTS"]

KINDS = ("none", "texel", "micromap", "square", "stored", "budget")
EVAL_KINDS = ("texel", "micromap", "square")  # omaps eval
TRACE_KINDS = ("none", "micromap", "square", "stored", "budget")  # omaps trace ("stored": read from the traced file)
VARIANTS = ("paper",) + tuple(EFFORTS)
DEFAULT_SCHEMES = ("sq4", "sq8", "sq16", "sq32", "sq64", "tri2", "tri3", "tri4", "tri5", "texel")
_TRI = re.compile(r"(tri|succinct|csm)(\d+)")
MICROMAP_REPRESENTATIONS = {"tri": "raw", "succinct": "succinct", "csm": "csm"}  # name prefix -> representation
_SQ = re.compile(r"sq(\d+)")


@dataclass(frozen=True)
class Scheme:
    name: str
    kind: str  # none | texel | micromap | square | stored (omm, file:CODEC: maps the traced file holds) | budget
    level: int | None = None  # micromap
    codec: Codec | None = None  # square: raw sqN or a compressed codec
    encoder: str | None = None
    effort: str | None = None
    budget: int | None = None  # budget: the scene's map bytes
    options: tuple[str, ...] | None = None  # budget: the pair options (none first); None: the default
    representation: str = "raw"  # micromap: raw (2 bits per micro-triangle), succinct or csm (lossless trees)
    # what the command's encoder or effort could not be for a codec of this scheme, and what was
    # used instead (``Codec.fallback``); commands print them with their results
    notes: tuple[str, ...] = ()

    @property
    def family(self) -> str:
        """Lines of a plot connect schemes of one family: sq, tri, a codec (vq4 and vq4x64 share
        one) with its variant."""
        if self.kind == "micromap":
            return "tri" if self.representation == "raw" else self.representation
        if self.kind == "square" and self.codec is not None and not self.codec.compressed:
            return "sq"
        if self.kind == "square" and self.codec is not None:
            base = "vq4" if self.codec.name == "vq4x64" else self.codec.name
            return base + self.name[len(self.codec.name):]
        return self.name

    @property
    def map_size(self) -> int | None:
        return self.codec.map_size if self.codec is not None else None

    def bits_for(self, width: int, height: int) -> int | None:
        """Storage bits per pair for a width x height texture; None for a hierarchical micromap,
        whose size depends on its states (``omaps.corpus.evaluate.scheme_bits``)."""
        if self.kind == "micromap":
            if self.representation != "raw" or self.level is None:
                return None
            return 2 * 4 ** self.level * 2  # two triangles, 2 bits per micro-triangle
        if self.kind == "square" and self.codec is not None:
            return self.codec.bits
        if self.kind == "texel":
            return 2 * width * height
        return 0

    def settings(self) -> dict:
        out: dict[str, object] = {"kind": self.kind}
        if self.level is not None:
            out["level"] = self.level
        if self.kind == "micromap" and self.representation != "raw":
            out["representation"] = self.representation
        if self.budget is not None:
            out.update(budget_bytes=self.budget, encoder=self.encoder, effort=self.effort)
            from .budget import PAIR_OPTIONS

            out["options"] = list(self.options or PAIR_OPTIONS)  # (the default options too: a run says which)
        if self.notes:
            out["notes"] = list(self.notes)
        if self.codec is not None:
            out.update(codec=self.codec.name, map_size=self.codec.map_size, bits=self.codec.bits)
            if self.codec.compressed:
                out.update(encoder=self.encoder, effort=self.effort)
        return out


def notes_lines(settings: dict) -> list[str]:
    """The lines a command prints under its results for the schemes' notes (``Scheme.notes``),
    from a run's settings (``{"schemes": {name: Scheme.settings()}}``): one per note, each naming
    its scheme."""
    return [f"note: {name}: {n}" for name, s in (settings.get("schemes") or {}).items() for n in s.get("notes", ())]


def codec_variants(codec_name: str) -> tuple[str, ...]:
    """The variants a codec accepts after its name (``vq4-paper``, ``vq4-fast``): ``paper`` where
    the codec has the deck's encoder, then its efforts; from the codec registry."""
    codec = get_codec(codec_name)
    return tuple(v for v in VARIANTS if (v == "paper" and v in codec.encoders) or v in codec.efforts)


def square_scheme_choices() -> str:
    """The square schemes ``get_scheme`` accepts, for a message: every raw size and every codec of
    the registry with its variants (``vq2[-paper|-fast|...]``)."""
    from .bake.square import MAX_SQUARE

    sizes = [str(1 << k) for k in range(MAX_SQUARE.bit_length())]
    codecs = [c + "[" + "|".join("-" + v for v in codec_variants(c)) + "]" for c in codec_names()]
    return f"sqN, N = {', '.join(sizes[:-1])} or {sizes[-1]}; " + ", ".join(codecs)


def _budget_options(name: str, text: str) -> tuple[str, ...]:
    """The pair options of ``budget:BYTES:OPTS``: ``none`` then the named ones, in the order
    given, without repeats; ``default`` stands for the default options (``budget.PAIR_OPTIONS``)."""
    from .budget import PAIR_OPTIONS

    known = ("none",) + budget_options(variable=True)
    out = ["none"]
    for o in text.split("+"):
        o = o.strip()
        for x in (PAIR_OPTIONS if o == "default" else (o,)):
            if x not in known:
                why = (": csmL shares subtrees across the whole scene, so its bytes are not a pair's"
                       if _TRI.fullmatch(x) and x.startswith("csm") else "")
                raise InputError(f"unknown budget option {x!r} in scheme {name!r}{why} (choose from default, "
                                 f"{', '.join(k for k in known if not k.startswith('succinct'))}, "
                                 f"succinctL with L = 0..12)")
            if x not in out:
                out.append(x)
    return tuple(out)


def get_scheme(name: str, encoder: str | None = None, effort: str | None = None) -> Scheme:
    """A scheme by name; ``encoder`` / ``effort`` apply to a codec named without a variant.

    Raises an ``InputTypeError`` for a name that is no string, an ``InputError`` for an unknown
    scheme (its message lists the known ones)."""
    check_choice("encoder", encoder, ("paper", "best"))
    check_choice("effort", effort, tuple(EFFORTS))  # (a codec's own names go in its variant)
    key = checks.text(name, "name").strip().lower()
    if key in ("none", "texel"):
        return Scheme(key, key)
    if key == "omm":
        return Scheme(key, "stored")
    if key.startswith("budget:"):
        from .budget import parse_bytes

        size, _, opts = key[len("budget:"):].partition(":")
        nbytes = parse_bytes(size)
        enc: str | None = encoder or "best"  # our encoder's defaults; each option's codec falls back
        eff: str | None = effort or "medium"
        options = _budget_options(name, opts) if opts else None
        suffix = ":" + "+".join(t.strip() for t in opts.split("+")) if opts else ""  # as written
        from .budget import PAIR_OPTIONS
        from .codecs.registry import entry

        # a note where the encoder or effort the command asked for is one an option's codec lacks
        # (nothing asked: nothing to note, and no codec is made here)
        notes = tuple(n for o in (options or PAIR_OPTIONS)[1:] if (encoder or effort) and not entry(o).variable
                      for n in [get_codec(o).fallback(encoder, effort)[2]] if n)
        return Scheme(f"budget:{nbytes}{suffix}", "budget", encoder=enc, effort=eff, budget=nbytes, options=options,
                      notes=notes)
    if key == "file:csm":
        return Scheme(key, "stored", representation="csm")
    if key.startswith("file:"):
        codec_name = key[len("file:"):]
        if not (_SQ.fullmatch(codec_name) or codec_name in codec_names()):
            raise InputError(f"unknown scheme {name!r}: file:CODEC names a codec (sqN, {', '.join(codec_names())}), "
                             "or file:csm the merged micromaps")
        return Scheme(key, "stored", codec=get_codec(codec_name))
    m = _TRI.fullmatch(key)
    if m:
        from .bake.micromap import check_level

        rep = MICROMAP_REPRESENTATIONS[m.group(1)]
        return Scheme(key, "micromap", level=check_level(int(m.group(2)), f"{m.group(1)}L level"), representation=rep)
    if _SQ.fullmatch(key):
        return Scheme(key, "square", codec=get_codec(key))
    base, _, variant = (key, "", "") if key in codec_names() else key.rpartition("-")
    if base in codec_names():
        codec = get_codec(base)
        if variant:
            if variant not in codec_variants(base):
                raise InputError(f"unknown variant {variant!r} of {base} (choose from "
                                 f"{', '.join(codec_variants(base)) or 'none: it has no encoder choices'})")
            if variant == "paper":
                enc, eff = codec.options("paper", effort if effort in codec.efforts else None)
            else:
                enc, eff = codec.options(None, variant)
            return Scheme(key, "square", codec=codec, encoder=enc, effort=eff)
        enc, eff, note = codec.fallback(encoder, effort)
        return Scheme(key, "square", codec=codec, encoder=enc, effort=eff, notes=(note,) if note else ())
    raise InputError(f"unknown scheme {name!r} (known: none, texel, triL, succinctL, csmL, omm, file:CODEC, file:csm, budget:BYTES, "
                     f"{square_scheme_choices()})")


def parse_schemes(text: str | Scheme | Sequence[str | Scheme], kinds: Sequence[str] = KINDS,
                  encoder: str | None = None, effort: str | None = None, command: str = "this command", *,
                  param: str = "schemes") -> list[Scheme]:
    """Schemes from a comma-separated string, or a list / tuple of names (each may hold commas)
    and ``Scheme`` objects, in order, without repeats.

    Raises an ``InputTypeError`` naming ``param`` for anything else, an ``InputError`` for an
    unknown scheme, for none at all, or for a scheme whose kind (``kinds``) ``command`` cannot use.
    """
    param = checks.text(param, "param")
    command = checks.text(command, "command")
    if isinstance(kinds, str) or not isinstance(kinds, (list, tuple)) or not all(isinstance(k, str) for k in kinds):
        raise InputTypeError(f"kinds must be a tuple of scheme kinds ({', '.join(KINDS)}), got {kinds!r:.60}",
                             param="kinds")
    if isinstance(text, (str, Scheme)):
        items: list[object] = [text]
    elif isinstance(text, (list, tuple)):
        items = list(text)
    else:
        raise InputTypeError(f"{param} must be comma-separated scheme names or a list of names or Schemes, got "
                             f"{type(text).__name__}", param=param)
    given: list[str | Scheme] = []
    for item in items:
        if isinstance(item, Scheme):
            given.append(item)
        elif isinstance(item, str):
            given.extend(n.strip() for n in item.split(",") if n.strip())
        else:
            raise InputTypeError(f"{param} must hold scheme names or Schemes, got {type(item).__name__}", param=param)
    if not given:
        raise InputError(f"no schemes given in {param}", param=param)
    out, seen = [], set()
    for n in given:
        s = n if isinstance(n, Scheme) else get_scheme(n, encoder, effort)
        if s.kind not in kinds:
            raise InputError(f"scheme {s.name!r} ({s.kind}) is not available in {command}")
        if s.name not in seen:
            seen.add(s.name)
            out.append(s)
    return out
