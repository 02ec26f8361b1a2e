"""``omaps omm``: standard opacity micromaps from a glTF scene or a texture plus UV triangles,
and ``omaps omm --verify DIR``. ``add_parser`` registers the subcommand on omaps' CLI."""

from __future__ import annotations

import sys
import time

from ..atomic import Outputs
from ..errors import InputError
from ..names import BUDGET_WEIGHTS, OMM_FORMATS, PROMOTIONS
from .common import (add_codec_options, add_material_options, check_jobs, material_rules, parse_size, plural,
                     show_progress)


def add_parser(sub) -> None:
    o = sub.add_parser(
        "omm", help="standard opacity micromaps (Vulkan / DirectX 12) from a glTF scene or a texture + UVs",
        description="Bake VK_EXT_opacity_micromap / DXR 1.2 opacity micromaps: from a glTF scene (every "
                    "alpha-tested primitive) or from a texture and a .npy array of UV triangles (T, 3, 2). "
                    "Writes omm_data.bin, omm_triangles.bin, omm_index.bin, omm_usage.json and omm.json "
                    "into DIR (all or nothing). With --verify DIR: check a written folder.")
    o.add_argument("inputs", nargs="*", metavar="INPUT", help="SCENE.gltf|.glb, or TEXTURE UVS.npy")
    o.add_argument("-o", "--output", metavar="DIR|OUT.glb|OUT.gltf",
                   help="output folder (replaced whole if it is empty or holds an earlier omm.json; any other "
                        "folder is left alone: error), or, for a glTF input, a .glb / .gltf file: the scene with "
                        "the EXT_mesh_opacity_micromap extension (and OMAPS_pair_opacity_maps with --from)")
    o.add_argument("--verify", metavar="DIR|FILE.glb",
                   help="check an OMM folder or glTF file: layout (the extension's rules), usage counts, pair "
                        "blocks, and a re-bake from its recorded inputs (a glTF file: its own textures)")
    o.add_argument("--expand", action="store_true",
                   help="with one baked .glb/.gltf input holding OMAPS_pair_opacity_maps and -o OUT.glb|.gltf: "
                        "decode the pair blocks into standard micromaps (EXT_mesh_opacity_micromap only)")
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
                   help="texture (default), or a square scheme: sqN (the pair's N x N map, expanded to level "
                        "log2 N) or a codec (vq2, vq4, vq4x64, vq4-synth, wavelet3, also -paper, -fast, -medium, "
                        "-thorough): square maps "
                        "stored, decoded, expanded. Pairs: the tracer's (shared edges) in a glTF scene, triangles "
                        "2k and 2k+1 with a UV array")
    o.add_argument("--threads", type=int, default=None, help="baking threads (default: all cores)")
    o.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="worker processes encoding the --from codec's maps (default 1)")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    add_material_options(o)
    add_codec_options(o, "--from codecs named without a variant")
    o.set_defaults(func=cmd_omm)


def _spec(a) -> dict:
    from ..omm import inputs
    from ..scene.files import SCENE_RULE, is_scene_file  # the scene loader's rule (omaps trace's too)

    if len(a.inputs) == 1 and is_scene_file(a.inputs[0]):
        if a.channel:
            raise InputError("--channel applies to a texture input, not to glTF")
        return inputs.gltf_spec(a.inputs[0], material_rules(a))
    if len(a.inputs) == 2:
        return inputs.texture_spec(a.inputs[0], a.inputs[1], a.cutoff, a.filter, a.wrap, a.channel)
    if len(a.inputs) == 1:
        raise InputError(f"a texture needs a .npy array of UV triangles (T, 3, 2) after it; {SCENE_RULE}",
                         a.inputs[0])
    raise InputError("give SCENE.gltf|.glb, or TEXTURE UVS.npy (and -o DIR), or --verify DIR")


def _settings(a):
    from ..omm.pipeline import OmmSettings

    if sum(x is not None for x in (a.level, a.dynamic, a.budget)) > 1:
        raise InputError("--level, --dynamic and --budget exclude each other")
    budget = None
    if a.budget is not None:
        from ..budget import parse_bytes

        budget = parse_bytes(a.budget)
    check_jobs(a.jobs)
    if a.level is not None and a.source != "texture":
        raise InputError("--from fixes the level to log2 N of the square map; drop --level")
    return OmmSettings(format=a.format, level=4 if a.level is None else a.level, dynamic_scale=a.dynamic,
                       max_level=a.max_level, promotion=a.promote, special=not a.no_special, dedup=not a.no_dedup,
                       source=a.source, encoder=a.encoder, effort=a.effort, seed=a.seed, jobs=a.jobs,
                       budget=budget)


def cmd_omm(a) -> int:
    # the library is imported here, not at the top: parsing (and --help) loads no numba kernel
    from ..omm import files, gltf_io, inputs
    from ..omm import format as omm_format
    from ..omm.pipeline import build

    if a.threads is not None:
        import numba

        if a.threads < 1:
            raise InputError(f"--threads must be >= 1, got {a.threads}")
        numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))
    if a.verify:
        if a.inputs or a.output:
            raise InputError("--verify DIR takes no inputs and no -o")
        return _cmd_verify(a.verify)
    if a.expand:
        return _cmd_expand(a)
    spec = _spec(a)
    if not a.output:
        raise InputError("give the output folder with -o DIR")
    outputs = Outputs(inputs=a.inputs)
    to_gltf = gltf_io.is_gltf(a.output)
    if to_gltf:
        if spec["kind"] != "gltf":
            raise InputError("a .glb / .gltf output needs a glTF input (a texture and UVs have no scene)", a.output)
        outputs.file(a.output, "-o")
    else:
        outputs.folder(a.output, "-o", omm_format.SUMMARY_FILE, (".glb", ".gltf"))  # before the work, not after
    settings = _settings(a)
    t0 = time.perf_counter()
    view, view_info = None, None
    if a.weights == "view":  # where the view's hits fall: the same counting trace as trace's budget
        if settings.budget is None or spec["kind"] != "gltf":
            raise InputError("--weights view needs --budget and a glTF scene")
        from ..scene import load_scene
        from ..trace.view import scene_view_samples

        w, h = parse_size(a.size)
        weights, hits, cam = scene_view_samples(load_scene(spec["path"]), material_rules(a), w, h)
        view, view_info = (weights, hits), {"weights": "view", "size": [w, h], "camera": cam, "hits": int(len(hits))}
    geoms, skipped, warned = inputs.load_geometries(spec, view)
    if show_progress(a.quiet):
        bar = _Bar()
        try:
            result = build(geoms, settings, bar)
        finally:
            bar.close()
    else:
        result = build(geoms, settings)
    dt = time.perf_counter() - t0
    if "budget" in result.summary:
        result.summary["budget"].update(view_info or {"weights": "area"})
    extra = {"input": spec, "skipped_primitives": skipped, "warnings": warned}
    with outputs.writing():
        if to_gltf:
            for w in gltf_io.write_gltf_result(spec["path"], outputs.path(a.output), a.output, result, extra):
                print(f"omaps: warning: {w}", file=sys.stderr)
        else:
            files.write_into(outputs.path(a.output), result, extra)
    st = result.summary["statistics"]
    print(f"{a.output}: {plural(st['triangles'], 'triangle')}, {plural(st['micro_triangles'], 'micro-triangle')} "
          f"({_held_states(st, settings)}); {plural(st['micromaps'], 'micromap')} after reuse "
          f"(of {st['micromaps_without_reuse']}), {plural(st['data_bytes'], 'data byte')}; {dt:.2f} s")
    for s in skipped:
        print(f"omaps: skipped mesh {s['mesh']} primitive {s['primitive']} ({s['name']}): {s['reason']}",
              file=sys.stderr)
    return 0


class _Bar:
    """``omm.pipeline.Progress`` as a progress bar on stderr: one bar a stage (--budget's pricing,
    in micro-triangles; the baking, in geometries), its total known when it starts."""

    FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {unit} [{elapsed}<{remaining}]"

    def __init__(self):
        self.bar = None

    def stage(self, name: str, total: int, unit: str) -> None:
        from tqdm import tqdm  # only for the bar (its import costs 25 ms of the start)

        self.close()
        self.bar = tqdm(total=total, desc=f"omm {name}", unit=unit, unit_scale=unit == "micro-triangles",
                        bar_format=self.FORMAT, leave=False)

    def advance(self, n: int = 1) -> None:
        self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _held_states(st: dict, settings) -> str:
    """The micro-triangle states the output holds. The statistics count the bake's T, O and
    unknown (C); 4-state output keeps every unknown one (as unknown-transparent or
    unknown-opaque), 2-state output has none: each became T or O by the --promote rule."""
    known_area = f"known area {st['known_area_fraction']:.1%}"
    if settings.format != "2state":
        return f"{st['transparent']} T, {st['opaque']} O, {st['unknown']} unknown; {known_area}"
    to_t, to_o = st["unknown_resolved"]["transparent"], st["unknown_resolved"]["opaque"]
    return (f"{st['transparent'] + to_t} T, {st['opaque'] + to_o} O, 0 unknown: {st['unknown']} unknown resolved "
            f"to 2 states by {settings.promotion}, {to_t} to T and {to_o} to O; {known_area} before resolving")


def _cmd_verify(folder) -> int:
    from ..omm.verify import verify

    res, problems, done = verify(folder)
    st = res.summary["statistics"]
    for d in done:
        print(f"checked: {d}")
    if problems:
        for p in problems:
            print(f"omaps: {folder}: {p}", file=sys.stderr)
        return 1
    print(f"{folder}: OK ({plural(st['triangles'], 'triangle')}, {plural(st['micromaps'], 'micromap')}, "
          f"{plural(st['data_bytes'], 'data byte')})")
    return 0


def _cmd_expand(a) -> int:
    """``omaps omm BAKED.glb --expand -o STD.glb``: the stored pair blocks decoded and expanded
    into standard micromaps (``omm.pairs.expand``), packed as ``build`` packs them."""
    from ..omm import gltf_io
    from ..omm.expand import expand_result

    if len(a.inputs) != 1 or not gltf_io.is_gltf(a.inputs[0]) or not a.output or not gltf_io.is_gltf(a.output):
        raise InputError("--expand takes one baked .glb/.gltf and -o OUT.glb|OUT.gltf")
    outputs = Outputs(inputs=a.inputs)
    outputs.file(a.output, "-o")
    res = gltf_io.read_gltf(a.inputs[0])
    if res.pair_blocks is None:
        raise InputError("holds no OMAPS_pair_opacity_maps pair blocks to expand", a.inputs[0])
    out = expand_result(res)
    with outputs.writing():
        for w in gltf_io.write_gltf_result(a.inputs[0], outputs.path(a.output), a.output, out, None):
            print(f"omaps: warning: {w}", file=sys.stderr)
    st = out.summary["statistics"]
    blocks = res.summary["pair_blocks"]
    print(f"{a.output}: {plural(st['triangles'], 'triangle')} from "
          f"{plural(blocks['blocks'], blocks['codec'] + ' pair block')}; {plural(st['micromaps'], 'micromap')}, {plural(st['data_bytes'], 'data byte')}")
    return 0
