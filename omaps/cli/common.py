"""Options and output shared by the commands: texel-state rules, scene material rules, codec
choices, tables, and how library warnings are shown."""

from __future__ import annotations

import argparse
import os
import sys

from ..errors import InputError
from ..text import format_table, plural  # noqa: F401 - plural: the commands' one helper
from ..names import BLEND_RULES, EFFORTS, ENCODERS, FILTERS, MODES, WRAP_MODES  # numba-free: parsing loads no kernel


# Help texts name the registry's codecs through these markers, filled in when help is shown
# (``main.Parser.format_help``): building a parser imports no codec module, and every codec of the
# registry, plug-ins' included, is named.
CODECS = "{codecs}"  # the compressed codecs (``codec_names()``), comma-separated
CODECS_OR = "{codecs or}"  # the same, the last two joined by "or"
BUDGET_DEFAULTS = "{budget defaults}"  # a budget:BYTES scheme's options: "sqN up to 64, " and its codecs


def codec_help(text):
    """``text`` (a help text, or None) with the codec markers replaced by the registry's names."""
    if not isinstance(text, str) or not any(m in text for m in (CODECS, CODECS_OR, BUDGET_DEFAULTS)):
        return text
    import re

    from ..codecs.registry import budget_options, codec_list, codec_names

    default = budget_options(default=True)
    raw = [int(n[2:]) for n in default if re.fullmatch(r"sq\d+", n)]
    coded = [n for n in default if n in codec_names()]
    budget = codec_list("or", ([f"sqN up to {max(raw)}"] if raw else []) + coded)
    return (text.replace(CODECS, codec_list("")).replace(CODECS_OR, codec_list("or"))
            .replace(BUDGET_DEFAULTS, budget))


class _Default(float):
    """A state option's default value: the same number, but told apart from one given on the
    command line (so an option of the other mode is an error, not silently unused)."""


class _DefaultMode(str):
    """``--mode``'s default, told apart from ``--mode`` given (``--cutoff`` alone selects cutoff)."""


def add_state_options(p: argparse.ArgumentParser, default_mode: str) -> None:
    """The corpus rules of a texture (``alpha_test.StateRule``), filter, wrap and channel."""
    g = p.add_argument_group("texel states")
    g.add_argument("--mode", choices=MODES, default=_DefaultMode(default_mode),
                   help="levels: T if alpha <= t-max, O if alpha >= o-min (the deck's corpus rule); "
                        f"cutoff: opaque iff alpha > cutoff (default: {default_mode}, or cutoff when --cutoff is "
                        "given)")
    g.add_argument("--t-max", type=float, default=_Default(30.0), help="levels: T at or below this 8-bit alpha (30)")
    g.add_argument("--o-min", type=float, default=_Default(225.0),
                   help="levels: O at or above this 8-bit alpha (225)")
    g.add_argument("--cutoff", type=float, default=_Default(0.5),
                   help="cutoff: opaque iff alpha > cutoff, in [0, 1] (0.5); selects --mode cutoff")
    g.add_argument("--filter", choices=FILTERS, default="nearest", help="texture filter of the alpha test")
    g.add_argument("--wrap", choices=WRAP_MODES, default="clamp", help="texture addressing (clamp)")
    g.add_argument("--channel", default=None,
                   help="read coverage from this channel (R, G, B, A, L or an index) instead of alpha")


def state_mode(a) -> str:
    """The texel-state mode of the options: ``--mode``, else cutoff when ``--cutoff`` is given,
    else the command's default; an option of the other mode is an error (it would do nothing).
    The mode is set in ``a`` (``omaps batch`` records it with the other options)."""
    given = {opt for opt, name in (("--t-max", "t_max"), ("--o-min", "o_min"), ("--cutoff", "cutoff"))
             if not isinstance(getattr(a, name), _Default)}
    levels_only = [o for o in ("--t-max", "--o-min") if o in given]
    mode = a.mode
    if isinstance(mode, _DefaultMode):
        if "--cutoff" in given and levels_only:
            raise InputError(f"--cutoff (mode cutoff) and {levels_only[0]} (mode levels) belong to different modes: "
                             "give the options of one")
        mode = "cutoff" if "--cutoff" in given else mode
    if mode == "levels" and "--cutoff" in given:
        raise InputError("--cutoff applies only to --mode cutoff, and the mode is levels (give --mode cutoff, or "
                         "--t-max / --o-min for levels)")
    if mode == "cutoff" and levels_only:
        raise InputError(f"{levels_only[0]} applies only to --mode levels, and the mode is cutoff (give --cutoff "
                         "for cutoff)")
    if mode != a.mode:
        a.mode = mode
    return mode


def eval_config(a):
    """The ``corpus.evaluate.EvalConfig`` of eval's options."""
    from ..alpha_test import StateRule
    from ..corpus.evaluate import EvalConfig

    rule = StateRule(state_mode(a), float(a.t_max), float(a.o_min), float(a.cutoff))
    return EvalConfig(rule, a.filter, a.wrap, a.channel, getattr(a, "encoder", None), getattr(a, "effort", None))


def add_codec_options(p: argparse.ArgumentParser, what: str = "codec schemes named without a variant") -> None:
    g = p.add_argument_group("codecs")
    g.add_argument("--encoder", choices=ENCODERS, default=None, help=f"encoder of {what} (default: best)")
    g.add_argument("--effort", choices=list(EFFORTS), default=None,
                   help=f"our encoder's search effort for {what} (default: the codec's, medium)")


def add_material_options(p: argparse.ArgumentParser) -> None:
    """A scene's material rules (``alpha_test.MaterialRules``), the same for trace and omm."""
    g = p.add_argument_group("materials (the same rules in omaps trace and omaps omm)")
    g.add_argument("--cutoff", type=float, default=None,
                   help="replace every MASK material's alphaCutoff (opaque iff alpha x factor >= cutoff)")
    g.add_argument("--filter", choices=FILTERS, default=None, help="replace every sampler's filter")
    g.add_argument("--wrap", choices=WRAP_MODES, default=None, help="replace every sampler's wrap modes")
    g.add_argument("--blend", choices=BLEND_RULES, default="levels",
                   help="BLEND materials: levels (T only at alpha 0, O only at 1; the shader decides the rest at "
                        "--blend-cutoff), cutoff (alpha-tested at --blend-cutoff), skip (opaque) (default levels)")
    g.add_argument("--blend-cutoff", type=float, default=0.5, metavar="A",
                   help="the any-hit shader's cut-off for BLEND materials (default: %(default)s)")


def material_rules(a):
    """The ``alpha_test.MaterialRules`` of a scene command's options."""
    from ..alpha_test import MaterialRules

    return MaterialRules(a.cutoff, a.filter, a.wrap, a.blend, a.blend_cutoff)


def show_progress(quiet: bool = False) -> bool:
    """Progress bars (on stderr): off with --quiet; else on when stderr is a terminal, or as the
    environment variable OMAPS_PROGRESS says (1 on, 0 off), so logs and pipes stay clean."""
    if quiet:
        return False
    forced = os.environ.get("OMAPS_PROGRESS", "").strip()
    if forced in ("0", "1"):
        return forced == "1"
    return sys.stderr.isatty()


def parse_size(text: str) -> tuple[int, int]:
    parts = str(text).lower().split("x")
    try:
        w = int(parts[0])
        h = int(parts[1]) if len(parts) == 2 else w
    except (ValueError, IndexError):
        raise InputError(f"--size must be W or WxH, got {text!r}") from None
    if len(parts) > 2 or not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise InputError(f"--size must be W or WxH with sides 1..8192, got {text!r}")
    return w, h


def print_table(header: list, rows: list) -> None:
    print(format_table(header, rows))


def add_asset_options(p: argparse.ArgumentParser) -> None:
    """``--root DIR`` and ``--allow-outside``: where the files a glTF scene names may lie (the URI
    policy of ``omaps.scene.container``), for every command that reads a scene."""
    g = p.add_argument_group("untrusted assets")
    g.add_argument("--root", metavar="DIR", default=None,
                   help="read the files a scene names (buffers, images) only under DIR, symbolic links followed "
                        "(default: the scene's own folder; omaps batch: the folder given as input)")
    g.add_argument("--allow-outside", action="store_true",
                   help="read the files a scene names wherever they are (a scene you trust); URIs with a scheme "
                        "(http:, ...) are never fetched")


def asset_options(a) -> dict:
    """The keyword arguments of the library's scene readers (``root``, ``allow_outside``) from the
    options ``add_asset_options`` added (absent ones: the defaults)."""
    return {"root": getattr(a, "root", None), "allow_outside": bool(getattr(a, "allow_outside", False))}


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Library warnings as one line each: ``omaps: warning: ...``."""
    print(f"omaps: warning: {message}", file=sys.stderr)
