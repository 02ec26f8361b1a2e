"""``omaps eval``, ``omaps bake``, ``omaps encode`` and ``omaps decode``: the corpus evaluation
and single maps of one texture."""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from ..atomic import atomic_path, write_bytes
from ..bake import GROW_TEXEL, bake_micromap_rows, bake_square, known_fraction
from ..codecs import get_codec
from ..corpus import default_corpus, evaluate_many, mean_results, report
from ..corpus.evaluate import scheme_map
from ..errors import InputError
from ..omm.inputs import load_uvs
from ..schemes import DEFAULT_SCHEMES, EVAL_KINDS, get_scheme, parse_schemes
from ..texture import find_images, load_alpha
from .common import add_codec_options, add_state_options, eval_config, print_table


def add_parsers(sub) -> None:
    e = sub.add_parser("eval", help="savings of map schemes over a corpus of alpha textures",
                       description="Savings (fraction of hits needing no any-hit shader) of each scheme "
                                   "on each texture mapped to a triangle pair. With no PATH: the embedded "
                                   "procedural corpus.")
    e.add_argument("paths", nargs="*", metavar="PATH", help="image files or folders (searched recursively)")
    e.add_argument("--schemes", default=",".join(DEFAULT_SCHEMES),
                   help="comma-separated: sqN (N = 1..128, power of two), triL (L = 0..12), texel, vq2, vq4, "
                        "vq4x64, each codec also with -paper, -fast, -medium or -thorough (default: %(default)s)")
    e.add_argument("--min-size", type=int, default=0, metavar="PX",
                   help="skip textures whose smaller side is below PX")
    e.add_argument("--json", metavar="FILE", help="write per-texture and mean results as JSON")
    e.add_argument("--csv", metavar="FILE", help="write results as CSV (one row per texture and scheme)")
    e.add_argument("--plot", metavar="FILE.png", help="chart of mean savings against bits per pair")
    e.add_argument("--show", metavar="DIR", help="write one PNG per texture with its maps")
    e.add_argument("--jobs", type=int, default=None, metavar="N", help="worker processes (default: all cores)")
    e.add_argument("--quiet", action="store_true", help="no progress bar, only the mean table")
    add_state_options(e, "levels")
    add_codec_options(e)
    e.set_defaults(func=cmd_eval)

    b = sub.add_parser("bake", help="bake one uncompressed map and save its states as .npy",
                       description="Bake a square map (sqN, corpus convention) or per-triangle micromaps "
                                   "(triL) for a texture; with --uvs, micromaps of the given UV triangles.")
    b.add_argument("texture")
    b.add_argument("--scheme", required=True, help="sqN or triL")
    b.add_argument("--uvs", metavar="UVS.npy", help="UV triangles, array of shape (T, 3, 2), for triL")
    b.add_argument("-o", "--output", required=True, metavar="OUT.npy", help="states (0 T, 1 O, 2 C), uint8")
    add_state_options(b, "levels")
    b.set_defaults(func=cmd_bake)

    en = sub.add_parser("encode", help="store a texture's square map in a codec block",
                        description="Bake the codec's square map of a texture (corpus convention) and "
                                    "write the block.")
    en.add_argument("texture")
    en.add_argument("--codec", required=True, help="sqN, vq2, vq4 or vq4x64")
    en.add_argument("-o", "--output", required=True, metavar="FILE", help="block bytes")
    add_state_options(en, "levels")
    add_codec_options(en, "the codec")
    en.set_defaults(func=cmd_encode)

    de = sub.add_parser("decode", help="decode a codec block and print or draw its map")
    de.add_argument("block", metavar="FILE")
    de.add_argument("--codec", required=True, help="sqN, vq2, vq4 or vq4x64")
    de.add_argument("--show", metavar="OUT.png", help="draw the map in the deck's colours")
    de.add_argument("--json", action="store_true", help="print the map as JSON")
    de.set_defaults(func=cmd_decode)


def _print_table(results, names, per_texture: bool) -> None:
    means = mean_results(results, names)
    rows = []
    if per_texture:
        rows += [[r.name[:40]] + [f"{r.savings[n]:.3f}" for n in names] for r in results]
    rows.append([f"MEAN savings ({len(results)})"] + [f"{means[n]['savings']:.3f}" for n in names])
    rows.append(["mean bits/pair"] + [f"{means[n]['bits']:.0f}" for n in names])
    print_table(["texture"] + names, rows)


def cmd_eval(a) -> int:
    config = eval_config(a)
    schemes = parse_schemes(a.schemes, EVAL_KINDS, config.encoder, config.effort, "omaps eval")
    names = [s.name for s in schemes]
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
        report.write_json(a.json, results, names, {"source": source, **config.settings(), "min_size": a.min_size,
                                                    "schemes": {s.name: s.settings() for s in schemes}})
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
    config = eval_config(a)
    scheme = get_scheme(a.scheme)
    if scheme.kind not in ("micromap", "square") or (scheme.codec is not None and scheme.codec.compressed):
        raise InputError(f"bake makes sqN or triL maps, not {scheme.name}")
    test = config.test(load_alpha(a.texture, config.channel))
    grid = test.grid()
    if a.uvs:
        if scheme.kind != "micromap":
            raise InputError("--uvs needs a triL scheme", a.uvs)
        uvs = load_uvs(a.uvs)
        out = bake_micromap_rows(grid, uvs, scheme.level, GROW_TEXEL)
    else:
        out = scheme_map(scheme, grid)
    with atomic_path(a.output, suffix=".npy") as tmp:
        np.save(tmp, out)
    print(f"{a.output}: {scheme.name} map {out.shape}, {known_fraction(out):.1%} of regions known")
    return 0


def cmd_encode(a) -> int:
    codec = get_codec(a.codec)
    config = eval_config(a)
    grid = config.grid(load_alpha(a.texture, config.channel))
    original = bake_square(grid, codec.map_size)
    block = codec.encode(original, a.encoder, a.effort)  # checked: only O->C and T->C
    decoded = codec.decode(block)
    write_bytes(a.output, block)
    print(f"{a.output}: {codec.name} block, {len(block)} bytes; savings {known_fraction(decoded):.3f} "
          f"(uncompressed sq{codec.map_size}: {known_fraction(original):.3f})")
    return 0


def cmd_decode(a) -> int:
    import json

    from ..states import NAMES

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
        print(json.dumps({"codec": codec.name, "size": int(m.shape[0]), "savings": known_fraction(m),
                          "states": m.tolist()}))
    else:
        print(f"{a.block}: {codec.name} {m.shape[1]}x{m.shape[0]} map, savings {known_fraction(m):.3f} "
              f"(rows are v, T transparent, O opaque, C check)")
        for row in m:
            print("".join(NAMES[s] for s in row))
    if a.show:
        from PIL import Image

        from ..drawing import square_image
        with atomic_path(a.show, suffix=".png") as tmp:
            Image.fromarray(square_image(m, 16 * m.shape[0])).save(tmp, format="PNG")
    return 0


