"""``omaps eval``, ``omaps bake``, ``omaps encode`` and ``omaps decode``: the corpus evaluation
and single maps of one texture."""

from __future__ import annotations

import sys

import numpy as np

from ..atomic import Outputs
from ..bake import GROW_TEXEL, bake_micromap_rows, bake_square, known_fraction
from ..codecs import get_codec
from ..corpus import evaluate_corpus, report
from ..corpus.evaluate import scheme_map
from ..errors import InputError
from ..omm.inputs import load_uvs
from ..schemes import DEFAULT_SCHEMES, EVAL_KINDS, get_scheme, parse_schemes
from ..texture import load_alpha
from .common import CODECS, CODECS_OR, add_codec_options, add_state_options, eval_config, plural, show_progress


def add_parsers(sub) -> None:
    add_eval_parser(sub)
    _add_map_parsers(sub)


def add_eval_parser(sub) -> None:
    e = sub.add_parser("eval", help="savings of map schemes over a corpus of alpha textures",
                       description="Savings (fraction of hits needing no any-hit shader) of each scheme "
                                   "on each texture mapped to a triangle pair. With no PATH: the embedded "
                                   "procedural corpus.")
    e.add_argument("paths", nargs="*", metavar="PATH", help="image files or folders (searched recursively)")
    e.add_argument("--schemes", default=",".join(DEFAULT_SCHEMES),
                   help="comma-separated: sqN (N = 1..128, power of two), triL (L = 0..12; succinctL and csmL: the same "
                        f"micromaps as lossless trees, their bits per texture), texel, or a codec ({CODECS}), "
                        "each codec also with -fast, -medium or -thorough where it has efforts, and -paper where "
                        "it has the deck's encoder (default: %(default)s)")
    e.add_argument("--min-size", type=int, default=0, metavar="PX",
                   help="skip textures whose smaller side is below PX")
    e.add_argument("--json", metavar="FILE", help="write settings, per-texture and mean results, and unreadable "
                                                  "files as JSON")
    e.add_argument("--csv", metavar="FILE", help="write results as CSV (one row per texture and scheme)")
    e.add_argument("--plot", metavar="FILE.png", help="chart of mean savings against bits per pair (the suffix "
                                                      "picks the format: .png, .svg, .pdf, ...)")
    e.add_argument("--show", metavar="DIR", help="write one PNG per texture with its maps, and show.json (the folder "
                                                 "is replaced whole if it is empty or an earlier --show folder)")
    e.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")
    e.add_argument("--per-texture", action="store_true",
                   help="print every texture's row (by default only up to 20 textures; --json and --csv always "
                        "hold them all)")
    e.add_argument("--quiet", action="store_true", help="no progress bar, only the mean table")
    add_state_options(e, "levels")
    add_codec_options(e)
    e.set_defaults(func=cmd_eval)


def _add_map_parsers(sub) -> None:
    b = sub.add_parser("bake", help="bake one uncompressed map and save its states as .npy",
                       description="Bake a square map (sqN, corpus convention) or per-triangle micromaps "
                                   "(triL) for a texture; with --uvs, micromaps of the given UV triangles.")
    b.add_argument("texture")
    b.add_argument("--scheme", required=True, help="sqN or triL")
    b.add_argument("--uvs", metavar="UVS.npy", help="UV triangles, array of shape (T, 3, 2), for triL")
    b.add_argument("-o", "--output", required=True, metavar="OUT.npy", help="states (0 T, 1 O, 2 C), uint8 "
                                                                           "(replaced if it exists)")
    add_state_options(b, "levels")
    b.set_defaults(func=cmd_bake)

    en = sub.add_parser("encode", help="store a texture's square map in a codec block",
                        description="Bake the codec's square map of a texture (corpus convention) and "
                                    "write the block.")
    en.add_argument("texture")
    en.add_argument("--codec", required=True, help=f"sqN, {CODECS_OR}")
    en.add_argument("-o", "--output", required=True, metavar="FILE",
                    help="block bytes (replaced if it exists; any name but one of another format, such as .png)")
    add_state_options(en, "levels")
    add_codec_options(en, "the codec")
    en.set_defaults(func=cmd_encode)

    de = sub.add_parser("decode", help="decode a codec block and print or draw its map")
    de.add_argument("block", metavar="FILE")
    de.add_argument("--codec", required=True, help=f"sqN, {CODECS_OR}")
    de.add_argument("--show", metavar="OUT.png", help="draw the map in the deck's colours")
    de.add_argument("--json", action="store_true", help="print the map (and its settings) as JSON")
    de.set_defaults(func=cmd_decode)


def cmd_eval(a) -> int:
    from ..corpus.experiment import PER_TEXTURE_ROWS

    config = eval_config(a)
    parse_schemes(a.schemes, EVAL_KINDS, config.encoder, config.effort, "omaps eval")  # before the outputs
    outputs = Outputs(inputs=a.paths)
    outputs.file(a.json, "--json")
    outputs.file(a.csv, "--csv")
    outputs.file(a.plot, "--plot", report.plot_suffixes() if a.plot else None)
    outputs.folder(a.show, "--show", report.SHOW_MANIFEST)
    progress = show_progress(a.quiet)
    try:
        res = evaluate_corpus(a.paths, **eval_options(a), keep_maps=bool(a.show), progress=progress)
    except InputError as exc:
        if getattr(exc, "unreadable", None):
            _print_unreadable(exc.unreadable)
        raise
    if res.skipped_other:
        print(f"omaps: skipping {plural(len(res.skipped_other), 'file')} without an image extension "
              f"(e.g. {res.skipped_other[0]})", file=sys.stderr)
    if res.no_alpha:
        print(f"omaps: skipped {plural(len(res.no_alpha), 'image')} without alpha, not alpha masks (--channel "
              f"reads one of their bands instead): e.g. {res.no_alpha[0][0]} ({res.no_alpha[0][1]})", file=sys.stderr)
    if res.small:
        print(f"omaps: skipped {plural(len(res.small), 'texture')} smaller than {a.min_size} px", file=sys.stderr)
    print(res.heading())
    per_texture = a.per_texture or (not a.quiet and len(res.results) <= PER_TEXTURE_ROWS)
    print(res.table(per_texture))
    if not per_texture and not a.quiet:
        print(f"({plural(len(res.results), 'per-texture row')} not shown: --per-texture prints them)")
    # everything is computed; now write: all outputs are renamed into place together at the end
    with outputs.writing():
        if a.json:
            res.write_json(outputs.path(a.json))
        if a.csv:
            res.write_csv(outputs.path(a.csv))
        if a.plot:
            res.plot(outputs.path(a.plot))
        if a.show:
            res.write_show(outputs.path(a.show), progress)
    if res.unreadable:
        _print_unreadable(res.unreadable)
        return 1
    return 0


def eval_options(a) -> dict:
    """``evaluate_corpus``' keyword arguments from the command line (``omaps batch eval`` too)."""
    return dict(schemes=a.schemes, config=eval_config(a), jobs=a.jobs, min_size=a.min_size)


def _print_unreadable(unreadable) -> None:
    print(f"omaps: {plural(len(unreadable), 'file')} could not be read (skipped):", file=sys.stderr)
    for path, problem in unreadable:
        print(f"  {path}: {problem}", file=sys.stderr)


def cmd_bake(a) -> int:
    config = eval_config(a)
    scheme = get_scheme(a.scheme)
    if scheme.kind not in ("micromap", "square") or (scheme.codec is not None and scheme.codec.compressed):
        raise InputError(f"bake makes sqN or triL maps, not {scheme.name}")
    outputs = Outputs(inputs=[a.texture, a.uvs])
    outputs.file(a.output, "-o", (".npy",))
    test = config.test(load_alpha(a.texture, config.channel))
    grid = test.grid()
    if a.uvs:
        if scheme.kind != "micromap":
            raise InputError("--uvs needs a triL scheme", a.uvs)
        uvs = load_uvs(a.uvs)
        out = bake_micromap_rows(grid, uvs, scheme.level, GROW_TEXEL)
    else:
        out = scheme_map(scheme, grid)
    with outputs.writing(), open(outputs.path(a.output), "wb") as f:
        np.save(f, out)
    print(f"{a.output}: {scheme.name} map {out.shape}, {known_fraction(out):.1%} of regions known")
    return 0


def cmd_encode(a) -> int:
    codec = get_codec(a.codec)
    config = eval_config(a)
    outputs = Outputs(inputs=[a.texture])
    outputs.file(a.output, "-o", raw=True)
    grid = config.grid(load_alpha(a.texture, config.channel))
    original = bake_square(grid, codec.map_size)
    block = codec.encode(original, a.encoder, a.effort)  # checked: only O->C and T->C
    decoded = codec.decode(block)
    with outputs.writing(), open(outputs.path(a.output), "wb") as f:
        f.write(block)
    print(f"{a.output}: {codec.name} block, {plural(len(block), 'byte')}; savings {known_fraction(decoded):.3f} "
          f"(uncompressed sq{codec.map_size}: {known_fraction(original):.3f})")
    return 0


def cmd_decode(a) -> int:
    import json

    from ..states import NAMES

    codec = get_codec(a.codec)
    outputs = Outputs(inputs=[a.block])
    outputs.file(a.show, "--show", (".png",))
    try:
        with open(a.block, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise InputError("no such file", a.block) from None
    except IsADirectoryError:
        raise InputError("is a folder; decode reads one block file", a.block) from None
    except OSError as exc:  # an input that cannot be read is bad input (exit 2), not a failed write
        raise InputError(f"cannot read the file ({exc.strerror or exc})", a.block) from None
    if len(data) != codec.block_bytes:
        raise InputError(f"a {codec.name} block is {codec.block_bytes} bytes, this file has {len(data)}", a.block)
    try:
        m = codec.decode(data)
    except InputError as exc:  # a block no map decodes from (a raw map holding code 3)
        raise InputError(exc.problem, a.block) from None
    if a.json:
        print(json.dumps({"settings": {"codec": codec.name, "block": a.block}, "codec": codec.name,
                          "size": int(m.shape[0]), "savings": known_fraction(m), "states": m.tolist()}))
    else:
        print(f"{a.block}: {codec.name} {m.shape[1]}x{m.shape[0]} map, savings {known_fraction(m):.3f} "
              f"(rows are v, T transparent, O opaque, C check)")
        for row in m:
            print("".join(NAMES[s] for s in row))
    if a.show:
        from ..drawing import map_picture
        with outputs.writing():
            map_picture(outputs.path(a.show), m, a.block, codec.name)
    return 0


