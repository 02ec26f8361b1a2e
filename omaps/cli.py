"""The ``omaps`` command line: a thin layer over the Python API."""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from . import __version__, maps, report
from .codecs.registry import codec_names
from .errors import InputError
from .evaluate import EvalConfig, evaluate_many, mean_results
from .procedural import default_corpus
from .sampling import FILTERS, WRAP_MODES
from .schemes import DEFAULT_SCHEMES, parse_schemes
from .texel_states import MODES, StateRule
from .texture import find_images, load_alpha


def _add_state_options(p: argparse.ArgumentParser, default_mode: str) -> None:
    g = p.add_argument_group("texel states")
    g.add_argument("--mode", choices=MODES, default=default_mode,
                   help="levels: T if alpha <= t-max, O if alpha >= o-min (the deck's corpus rule); "
                        "cutoff: opaque iff alpha > cutoff (default: %(default)s)")
    g.add_argument("--t-max", type=float, default=30.0, help="levels: T at or below this 8-bit alpha (30)")
    g.add_argument("--o-min", type=float, default=225.0, help="levels: O at or above this 8-bit alpha (225)")
    g.add_argument("--cutoff", type=float, default=0.5, help="cutoff: opaque iff alpha > cutoff, in [0, 1] (0.5)")
    g.add_argument("--filter", choices=FILTERS, default="nearest", help="texture filter of the alpha test")
    g.add_argument("--wrap", choices=WRAP_MODES, default="clamp", help="texture addressing (clamp)")
    g.add_argument("--channel", default=None,
                   help="read coverage from this channel (R, G, B, A, L or an index) instead of alpha")


def _config(a) -> EvalConfig:
    rule = StateRule(a.mode, a.t_max, a.o_min, a.cutoff)
    return EvalConfig(rule, a.filter, a.wrap, a.channel)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="omaps", description="Bake, compress and evaluate opacity maps "
                                "for ray tracing alpha-tested geometry.")
    p.add_argument("--version", action="version", version=f"omaps {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    e = sub.add_parser("eval", help="savings of map schemes over a corpus of alpha textures",
                       description="Savings (fraction of hits needing no any-hit shader) of each scheme "
                                   "on each texture mapped to a triangle pair. With no PATH: the embedded "
                                   "procedural corpus.")
    e.add_argument("paths", nargs="*", metavar="PATH", help="image files or folders (searched recursively)")
    e.add_argument("--schemes", default=",".join(DEFAULT_SCHEMES),
                   help="comma-separated: sqN (N = 1..128, power of two), triL (L = 0..8), texel "
                        "(default: %(default)s)")
    e.add_argument("--min-size", type=int, default=0, metavar="PX",
                   help="skip textures whose smaller side is below PX")
    e.add_argument("--json", metavar="FILE", help="write per-texture and mean results as JSON")
    e.add_argument("--csv", metavar="FILE", help="write results as CSV (one row per texture and scheme)")
    e.add_argument("--plot", metavar="FILE.png", help="chart of mean savings against bits per pair")
    e.add_argument("--show", metavar="DIR", help="write one PNG per texture with its maps")
    e.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")
    e.add_argument("--quiet", action="store_true", help="no progress bar, only the mean table")
    _add_state_options(e, "levels")
    e.set_defaults(func=cmd_eval)

    b = sub.add_parser("bake", help="bake one uncompressed map and save its states as .npy",
                       description="Bake a square map (sqN, corpus convention) or per-triangle micromaps "
                                   "(triL) for a texture; with --uvs, micromaps of the given UV triangles.")
    b.add_argument("texture")
    b.add_argument("--scheme", required=True, help="sqN or triL")
    b.add_argument("--uvs", metavar="UVS.npy", help="UV triangles, array of shape (T, 3, 2), for triL")
    b.add_argument("-o", "--output", required=True, metavar="OUT.npy", help="states (0 T, 1 O, 2 C), uint8")
    _add_state_options(b, "levels")
    b.set_defaults(func=cmd_bake)

    en = sub.add_parser("encode", help="compress a texture's square map into a codec block",
                        description="Bake the codec's square map of a texture (corpus convention) and "
                                    "write the raw block.")
    en.add_argument("texture")
    en.add_argument("--codec", required=True, help=", ".join(codec_names()))
    en.add_argument("--encoder", default="best", help="paper or best (default)")
    en.add_argument("--effort", default="medium", help="best encoder's search: fast, medium (default), thorough")
    en.add_argument("-o", "--output", required=True, metavar="FILE", help="raw block bytes")
    _add_state_options(en, "levels")
    en.set_defaults(func=cmd_encode)

    de = sub.add_parser("decode", help="decode a codec block and print or draw its map")
    de.add_argument("block", metavar="FILE")
    de.add_argument("--codec", required=True, help=", ".join(codec_names()))
    de.add_argument("--show", metavar="OUT.png", help="draw the map in the deck's colours")
    de.add_argument("--json", action="store_true", help="print the map as JSON")
    de.set_defaults(func=cmd_decode)

    from .trace_cli import add_parser as add_trace_parser
    add_trace_parser(sub)
    from .omm.command import add_parser as add_omm_parser
    add_omm_parser(sub)
    return p


def _fmt_row(cells, widths):
    return "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths)))


def _print_table(results, names, per_texture: bool) -> None:
    means = mean_results(results, names)
    header = ["texture"] + names
    rows = []
    if per_texture:
        rows += [[r.name[:40]] + [f"{r.savings[n]:.3f}" for n in names] for r in results]
    rows.append([f"MEAN savings ({len(results)})"] + [f"{means[n]['savings']:.3f}" for n in names])
    rows.append(["mean bits/pair"] + [f"{means[n]['bits']:.0f}" for n in names])
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    print(_fmt_row(header, widths))
    for r in rows:
        print(_fmt_row(r, widths))


def cmd_eval(a) -> int:
    schemes = parse_schemes(a.schemes)
    names = [s.name for s in schemes]
    config = _config(a)
    if a.min_size < 0:
        raise InputError(f"--min-size must be >= 0, got {a.min_size}")
    if a.jobs is not None and a.jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {a.jobs}")
    if a.paths:
        items, skipped_other = find_images(a.paths)
        if skipped_other:
            print(f"omaps: skipping {len(skipped_other)} files without an image extension "
                  f"(e.g. {skipped_other[0]})", file=sys.stderr)
        if not items:
            raise InputError("no image files found", ", ".join(a.paths))
        source = f"{len(items)} files"
    else:
        items = default_corpus()
        source = "the embedded procedural corpus"
    t0 = time.perf_counter()
    results, small = evaluate_many(items, schemes, config, a.jobs, keep_maps=bool(a.show),
                                   min_size=a.min_size, progress=not a.quiet and sys.stderr.isatty())
    dt = time.perf_counter() - t0
    if small:
        print(f"omaps: skipped {len(small)} textures smaller than {a.min_size} px", file=sys.stderr)
    if not results:
        raise InputError(f"no texture is at least {a.min_size} px")
    print(f"omaps eval: {len(results)} textures from {source}, mode {config.rule.mode}, "
          f"filter {config.filter}, {dt:.2f} s")
    _print_table(results, names, per_texture=not a.quiet and len(results) <= 20)
    # everything is computed; now write, each file atomically
    if a.json:
        report.write_json(a.json, results, names)
    if a.csv:
        report.write_csv(a.csv, results, names)
    if a.plot:
        report.plot_savings(a.plot, results, names)
    if a.show:
        os.makedirs(a.show, exist_ok=True)
        for i, r in enumerate(results):
            report.show_texture(os.path.join(a.show, report.show_file_name(r, i)), r)
    return 0


def cmd_bake(a) -> int:
    from .schemes import get_scheme

    config = _config(a)
    scheme = get_scheme(a.scheme)
    grid = config.grid(load_alpha(a.texture, config.channel))
    if a.uvs:
        if scheme.family != "tri":
            raise InputError("--uvs needs a triL scheme", a.uvs)
        try:
            uvs = np.load(a.uvs, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot read UV array ({exc})", a.uvs) from None
        try:
            out = maps.bake_triangles(grid, uvs, int(scheme.name[3:]))
        except InputError as exc:
            raise InputError(exc.problem, a.uvs) from None
    elif scheme.family in ("sq", "tri"):
        out = scheme.bake(grid)
    else:
        raise InputError(f"bake makes sqN or triL maps, not {scheme.name}")
    from .atomic import atomic_path
    with atomic_path(a.output, suffix=".npy") as tmp:
        np.save(tmp, out)
    known = float(np.mean(out != 2))
    print(f"{a.output}: {scheme.name} map {out.shape}, {known:.1%} of regions known")
    return 0


def cmd_encode(a) -> int:
    from .codecs.registry import get_codec
    from .states import is_conservative

    codec = get_codec(a.codec)
    if a.encoder not in codec.encoders:
        raise InputError(f"unknown encoder {a.encoder!r} for {codec.name} (choose from {', '.join(codec.encoders)})")
    if a.effort not in codec.efforts:
        raise InputError(f"unknown effort {a.effort!r} (choose from {', '.join(codec.efforts)})")
    config = _config(a)
    grid = config.grid(load_alpha(a.texture, config.channel))
    original = maps.bake_square(grid, codec.map_size)
    block = codec.encode(original, a.encoder, a.effort)
    decoded = codec.decode(block)
    if len(block) != codec.block_bytes or not is_conservative(original, decoded):
        raise RuntimeError("internal error: the encoder produced a bad block")  # never expected
    from .atomic import write_bytes
    write_bytes(a.output, block)
    print(f"{a.output}: {codec.name} block, {len(block)} bytes; savings {maps.known_fraction(decoded):.3f} "
          f"(uncompressed sq{codec.map_size}: {maps.known_fraction(original):.3f})")
    return 0


def cmd_decode(a) -> int:
    import json

    from .codecs.registry import get_codec
    from .states import NAMES

    codec = get_codec(a.codec)
    try:
        with open(a.block, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise InputError("no such file", a.block) from None
    if len(data) != codec.block_bytes:
        raise InputError(f"a {codec.name} block is {codec.block_bytes} bytes, this file has {len(data)}", a.block)
    m = codec.decode(data)
    if a.json:
        print(json.dumps({"codec": codec.name, "size": int(m.shape[0]), "savings": maps.known_fraction(m),
                          "states": m.tolist()}))
    else:
        print(f"{a.block}: {codec.name} {m.shape[1]}x{m.shape[0]} map, savings {maps.known_fraction(m):.3f} "
              f"(rows are v, T transparent, O opaque, C check)")
        for row in m:
            print("".join(NAMES[s] for s in row))
    if a.show:
        from PIL import Image

        from .atomic import atomic_path
        from .render import square_image
        with atomic_path(a.show, suffix=".png") as tmp:
            Image.fromarray(square_image(m, 16 * m.shape[0])).save(tmp, format="PNG")
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as exc:
        print(f"omaps: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"omaps: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
