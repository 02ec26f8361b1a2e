"""``omaps omm``: standard opacity micromaps from a glTF scene or a texture plus UV triangles,
and ``omaps omm --verify DIR``. ``add_parser`` registers the subcommand on omaps' CLI."""

from __future__ import annotations

import sys

from ..errors import InputError, check_count
from ..names import BUDGET_WEIGHTS, OMM_FORMATS, PROMOTIONS
from .common import (CODECS, add_asset_options, add_codec_options, add_material_options, asset_options, material_rules,
                     parse_size, plural, show_progress)


def add_parser(sub) -> None:
    o = sub.add_parser(
        "omm", help="standard opacity micromaps (Vulkan / DirectX 12) from a scene (glTF, OpenUSD) or a texture "
                    "+ UVs",
        description="Bake VK_EXT_opacity_micromap / DXR 1.2 opacity micromaps: from a glTF or OpenUSD scene (every "
                    "alpha-tested primitive) or from a texture and a .npy array of UV triangles (T, 3, 2). "
                    "Writes omm_data.bin, omm_triangles.bin, omm_index.bin, omm_usage.json and omm.json "
                    "into DIR (all or nothing). With --verify DIR: check a written folder.")
    o.add_argument("inputs", nargs="*", metavar="INPUT",
                   help="SCENE (.gltf, .glb, .usd, .usda, .usdc, .usdz), or TEXTURE UVS.npy")
    o.add_argument("-o", "--output", metavar="DIR|OUT.glb|OUT.gltf",
                   help="output folder (replaced whole if it is empty or holds an earlier omm.json; any other "
                        "folder is left alone: error), or, for a glTF input, a .glb / .gltf file: the scene with "
                        "the EXT_mesh_opacity_micromap extension (and OMAPS_pair_opacity_maps or OMAPS_merged_micromaps with --from)")
    o.add_argument("--verify", metavar="DIR|FILE.glb",
                   help="check an OMM folder or glTF file: layout (the extension's rules), usage counts, pair "
                        "blocks or merged micromaps, and a re-bake from its recorded inputs (a glTF file: its own textures)")
    o.add_argument("--expand", action="store_true",
                   help="with one baked .glb/.gltf input holding OMAPS_pair_opacity_maps or OMAPS_merged_micromaps "
                        "and -o OUT.glb|.gltf: decode them into standard micromaps (EXT_mesh_opacity_micromap only)")
    lv = o.add_argument_group("subdivision")
    lv.add_argument("--level", type=int, default=None, help="one subdivision level for all, 0..12 (default 4)")
    lv.add_argument("--dynamic", type=float, default=None, metavar="SCALE",
                    help="per-triangle level: the smallest whose micro-triangles cover at most SCALE^2 texels")
    lv.add_argument("--max-level", type=int, default=8, help="cap of --dynamic and --budget (default 8)")
    lv.add_argument("--budget", metavar="BYTES", default=None,
                    help="per triangle the level (and 2-state where its micromap has no unknown, else 4-state) "
                         "that saves the most expected any-hit calls per byte of micromap data + records, every "
                         "triangle within BYTES (1263936, 1.2MiB, 800KiB); weights: world area x instances "
                         "(a scene), texel area (a texture); see --weights")
    lv.add_argument("--weights", choices=BUDGET_WEIGHTS, default=BUDGET_WEIGHTS[0],
                    help="--budget's weights: area (world area x instances, the default) or view: where the "
                         "candidate hits of a one-thread trace of the scene's default camera (as omaps trace "
                         "chooses it for --size) at half the resolution fall, plus 5%% of them spread by area")
    lv.add_argument("--size", default="512", metavar="W[xH]", help="--weights view: the view's image size (512)")
    f = o.add_argument_group("states")
    f.add_argument("--format", choices=list(OMM_FORMATS), default="4state",
                   help="4state (conservative, unknown runs the any-hit shader) or 2state (default 4state)")
    f.add_argument("--promote", choices=PROMOTIONS, default="nearest",
                   help="what unknown regions become: nearest (the majority of their area), opaque, transparent, "
                        "hashed (opaque with probability = opaque fraction); in 4state it picks unknown-opaque "
                        "or unknown-transparent (default nearest)")
    f.add_argument("--seed", type=int, default=0, help="seed of the hashed promotion (0)")
    f.add_argument("--channel", default=None, help="texture input: read coverage from this channel")
    r = o.add_argument_group("reuse and source")
    r.add_argument("--no-special", action="store_true", help="no special indices for uniform triangles")
    r.add_argument("--no-dedup", action="store_true", help="no sharing of identical micromaps")
    r.add_argument("--from", dest="source", default="texture", metavar="SCHEME",
                   help="texture (default); csmL: the texture's micromaps at level L, also stored as one merged "
                        "DAG of identical subtrees (merged_micromaps.bin, or OMAPS_merged_micromaps in a glTF "
                        "output); or a square scheme: sqN (the pair's N x N map, expanded to level "
                        f"log2 N) or a codec ({CODECS}; also with -fast, -medium or -thorough where it has "
                        "efforts, and -paper where it has the deck's encoder): square maps "
                        "stored, decoded, expanded. Pairs: the tracer's (shared edges) in a glTF scene, triangles "
                        "2k and 2k+1 with a UV array")
    o.add_argument("--threads", type=int, default=None, help="baking threads (default: all cores)")
    o.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="worker processes encoding the --from codec's maps (default 1)")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    add_material_options(o)
    add_codec_options(o, "--from codecs named without a variant")
    add_asset_options(o)
    o.set_defaults(func=cmd_omm)


def cmd_omm(a) -> int:
    # the library is imported here, not at the top: parsing (and --help) loads no numba kernel
    from ..jobs import bake_omms

    check_count(a.threads, "threads")
    if a.verify:
        if a.inputs or a.output:
            raise InputError("--verify DIR takes no inputs and no -o")
        return _cmd_verify(a.verify, a)
    if a.expand:
        return _cmd_expand(a)
    if len(a.inputs) > 2:
        raise InputError(f"give a SCENE (.gltf, .glb, .usd, .usda, .usdc, .usdz), or TEXTURE UVS.npy, not "
                         f"{len(a.inputs)} inputs")
    if a.inputs and not a.output:
        from ..jobs import omm_input_spec

        omm_input_spec(a.inputs, material_rules(a), a.channel)  # the inputs' own error first
    if not a.output:
        raise InputError("give the output folder with -o DIR" if a.inputs else
                         "give a SCENE, or TEXTURE UVS.npy (and -o DIR), or --verify DIR")
    bake = bake_omms(a.inputs, a.output, **bake_options(a), progress=show_progress(a.quiet))
    print(bake.line())
    for m in bake.messages():
        print(m, file=sys.stderr)
    return 0


def bake_options(a) -> dict:
    """``bake_omms``' keyword arguments from the command line (``omaps batch omm`` too)."""
    return dict(level=a.level, dynamic=a.dynamic, max_level=a.max_level, budget=a.budget, weights=a.weights,
                size=parse_size(a.size) if a.weights == "view" else (512, 512), format=a.format,
                promote=a.promote, seed=a.seed, special=not a.no_special, dedup=not a.no_dedup, source=a.source,
                encoder=a.encoder, effort=a.effort, jobs=a.jobs, threads=a.threads, rules=material_rules(a),
                channel=a.channel, **asset_options(a))


def _cmd_verify(folder, a=None) -> int:
    from ..jobs import verify_omms

    check = verify_omms(folder, **asset_options(a))
    st = check.result.summary["statistics"]
    for d in check.done:
        print(f"checked: {d}")
    if check.problems:
        for p in check.problems:
            print(f"omaps: {folder}: {p}", file=sys.stderr)
        return 1
    print(f"{folder}: OK ({plural(st['triangles'], 'triangle')}, {plural(st['micromaps'], 'micromap')}, "
          f"{plural(st['data_bytes'], 'data byte')})")
    return 0


def _cmd_expand(a) -> int:
    """``omaps omm BAKED.glb --expand -o STD.glb``: the stored pair blocks or merged micromaps
    decoded and expanded into standard micromaps, packed as a bake packs them."""
    from ..jobs import expand_omms

    if len(a.inputs) != 1 or not a.output:
        raise InputError("--expand takes one baked .glb/.gltf and -o OUT.glb|OUT.gltf")
    bake = expand_omms(a.inputs[0], a.output, **asset_options(a))
    for w in bake.warnings:
        print(f"omaps: warning: {w}", file=sys.stderr)
    st = bake.statistics
    blocks = bake.source_blocks
    source = (plural(blocks["blocks"], blocks["codec"] + " pair block") if "codec" in blocks else
              f"{blocks['scheme']} merged micromaps ({plural(blocks['nodes'], 'node')}, "
              f"{plural(blocks['bytes'], 'byte')})")
    print(f"{a.output}: {plural(st['triangles'], 'triangle')} from {source}; "
          f"{plural(st['micromaps'], 'micromap')}, {plural(st['data_bytes'], 'data byte')}")
    return 0
