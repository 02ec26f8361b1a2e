"""``omaps omm``: standard opacity micromaps from a glTF scene or a texture plus UV triangles,
and ``omaps omm --verify DIR``. ``add_parser`` registers the subcommand on omaps' CLI."""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from ..errors import InputError
from ..sampling import FILTERS, WRAP_MODES
from . import files, inputs, pairs, resolve
from . import format as omm_format
from .pipeline import OmmResult, OmmSettings, build

GLTF_EXTENSIONS = (".gltf", ".glb")


def add_parser(sub) -> None:
    o = sub.add_parser(
        "omm", help="standard opacity micromaps (Vulkan / DirectX 12) from a glTF scene or a texture + UVs",
        description="Bake VK_EXT_opacity_micromap / DXR 1.2 opacity micromaps: from a glTF scene (every "
                    "alpha-tested primitive) or from a texture and a .npy array of UV triangles (T, 3, 2). "
                    "Writes omm_data.bin, omm_triangles.bin, omm_index.bin, omm_usage.json and omm.json "
                    "into DIR (all or nothing). With --verify DIR: check a written folder.")
    o.add_argument("inputs", nargs="*", metavar="INPUT", help="SCENE.gltf|.glb, or TEXTURE UVS.npy")
    o.add_argument("-o", "--output", metavar="DIR", help="output folder (replaced if it holds an earlier omm.json)")
    o.add_argument("--verify", metavar="DIR", help="check an OMM folder: layout, usage counts, pair blocks, "
                                                   "and a re-bake from its recorded inputs when they are present")
    lv = o.add_argument_group("subdivision")
    lv.add_argument("--level", type=int, default=None, help="one subdivision level for all, 0..12 (default 4)")
    lv.add_argument("--dynamic", type=float, default=None, metavar="SCALE",
                    help="per-triangle level: the smallest whose micro-triangles cover at most SCALE^2 texels")
    lv.add_argument("--max-level", type=int, default=8, help="cap of --dynamic (default 8)")
    f = o.add_argument_group("states")
    f.add_argument("--format", choices=list(omm_format.FORMAT_NAMES), default="4state",
                   help="4state (conservative, unknown runs the any-hit shader) or 2state (default 4state)")
    f.add_argument("--promote", choices=resolve.PROMOTIONS, default="nearest",
                   help="what unknown regions become: nearest (the majority of their area), opaque, transparent, "
                        "hashed (opaque with probability = opaque fraction); in 4state it picks unknown-opaque "
                        "or unknown-transparent (default nearest)")
    f.add_argument("--seed", type=int, default=0, help="seed of the hashed promotion (0)")
    f.add_argument("--cutoff", type=float, default=None,
                   help="alpha cut-off in [0, 1]: texture input opaque iff alpha > cutoff (0.5); glTF: replaces "
                        "every material's alphaCutoff (opaque iff alpha >= cutoff)")
    f.add_argument("--filter", choices=FILTERS, default=None,
                   help="texture filter of the alpha test (texture: nearest; glTF: each sampler's magFilter)")
    f.add_argument("--wrap", choices=WRAP_MODES, default=None,
                   help="addressing (texture: clamp; glTF: each sampler's wrapS / wrapT)")
    f.add_argument("--channel", default=None, help="texture input: read coverage from this channel")
    f.add_argument("--blend", choices=inputs.BLEND_RULES, default="levels",
                   help="glTF BLEND materials: levels (T only at alpha 0, O only at alpha 1), cutoff "
                        "(alpha-test them), skip (default levels)")
    r = o.add_argument_group("reuse and source")
    r.add_argument("--no-special", action="store_true", help="no special indices for uniform triangles")
    r.add_argument("--no-dedup", action="store_true", help="no sharing of identical micromaps")
    r.add_argument("--from", dest="source", default="texture", metavar="SOURCE",
                   help="texture (default), sqN (the pair's N x N square map, expanded to level log2 N), or a codec "
                        "(vq2, vq4, vq4x64): square maps compressed, decoded, expanded; pairs are triangles "
                        "2k and 2k+1")
    r.add_argument("--encoder", default=None, help="codec encoder (default best)")
    r.add_argument("--effort", default=None, help="codec encoder effort (default medium)")
    o.add_argument("--threads", type=int, default=None, help="baking threads (default: all cores)")
    o.set_defaults(func=cmd_omm)


def _spec(a) -> dict:
    if len(a.inputs) == 1 and a.inputs[0].lower().endswith(GLTF_EXTENSIONS):
        if a.channel:
            raise InputError("--channel applies to a texture input, not to glTF")
        return inputs.gltf_spec(a.inputs[0], a.cutoff, a.filter, a.wrap, a.blend)
    if len(a.inputs) == 2:
        return inputs.texture_spec(a.inputs[0], a.inputs[1], a.cutoff, a.filter, a.wrap, a.channel)
    if len(a.inputs) == 1:
        raise InputError("a texture needs a .npy array of UV triangles (T, 3, 2) after it; "
                         "a scene must end in .gltf or .glb", a.inputs[0])
    raise InputError("give SCENE.gltf|.glb, or TEXTURE UVS.npy (and -o DIR), or --verify DIR")


def _settings(a) -> OmmSettings:
    if a.level is not None and a.dynamic is not None:
        raise InputError("--level and --dynamic exclude each other")
    if a.level is not None and a.source != "texture":
        raise InputError("--from fixes the level to log2 N of the square map; drop --level")
    return OmmSettings(format=a.format, level=4 if a.level is None else a.level, dynamic_scale=a.dynamic,
                       max_level=a.max_level, promotion=a.promote, special=not a.no_special, dedup=not a.no_dedup,
                       source=a.source, encoder=a.encoder, effort=a.effort, seed=a.seed)


def settings_from_summary(summary: dict) -> OmmSettings:
    s = summary["settings"]
    return OmmSettings(format=summary["format"], level=s["level"] if s["level"] is not None else 4,
                       dynamic_scale=s["dynamic_scale"], max_level=s["max_level"], promotion=s["promotion"],
                       special=s["special"], dedup=s["dedup"], source=s["source"], encoder=s["encoder"],
                       effort=s["effort"], seed=s["seed"])


def cmd_omm(a) -> int:
    if a.threads is not None:
        import numba

        if a.threads < 1:
            raise InputError(f"--threads must be >= 1, got {a.threads}")
        numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))
    if a.verify:
        if a.inputs or a.output:
            raise InputError("--verify DIR takes no inputs and no -o")
        return _cmd_verify(a.verify)
    spec = _spec(a)
    if not a.output:
        raise InputError("give the output folder with -o DIR")
    files.check_target(a.output)  # before the work, not after
    settings = _settings(a)
    t0 = time.perf_counter()
    geoms, skipped = inputs.load_geometries(spec)
    result = build(geoms, settings)
    dt = time.perf_counter() - t0
    files.write(a.output, result, {"input": spec, "skipped_primitives": skipped})
    st = result.summary["statistics"]
    print(f"{a.output}: {st['triangles']} triangles, {st['micro_triangles']} micro-triangles "
          f"({st['transparent']} T, {st['opaque']} O, {st['unknown']} unknown; known area "
          f"{st['known_area_fraction']:.1%}); {st['micromaps']} micromaps after reuse "
          f"(of {st['micromaps_without_reuse']}), {st['data_bytes']} data bytes; {dt:.2f} s")
    for s in skipped:
        print(f"omaps: skipped mesh {s['mesh']} primitive {s['primitive']} ({s['name']}): {s['reason']}",
              file=sys.stderr)
    return 0


def verify(folder) -> tuple[OmmResult, list[str], list[str]]:
    """(the folder's buffers, problems, checks done). Layout problems raise InputError."""
    res = files.read(folder)
    problems, done = [], ["layout, records, offsets, index entries, usage counts"]
    fmt_code = res.summary.get("format_code")
    if len(res.triangles) and not np.all(res.triangles["format"] == fmt_code):
        problems.append(f"micromap formats differ from omm.json's format {fmt_code}")
    if res.pair_blocks is not None:
        problems += _check_pair_blocks(res)
        done.append("micromaps against the decoded pair blocks")
    spec = res.summary.get("input")
    if spec is not None:
        src = spec.get("path") or spec.get("texture")
        missing = [p for p in (spec.get("path"), spec.get("texture"), spec.get("uvs")) if p and not os.path.exists(p)]
        if missing:
            done.append(f"no re-bake: {missing[0]} is absent")
        else:
            geoms, _ = inputs.load_geometries(spec, warn=lambda m: None)
            again = build(geoms, settings_from_summary(res.summary))
            problems += _compare(res, again)
            done.append(f"every micro-triangle against a re-bake of {src}")
    return res, problems, done


def _compare(res: OmmResult, again: OmmResult) -> list[str]:
    if len(res.index) != len(again.index):
        return [f"{len(res.index)} triangles in the files, {len(again.index)} in the re-bake"]
    if (np.array_equal(res.index, again.index) and np.array_equal(res.triangles, again.triangles)
            and np.array_equal(res.data, again.data)):
        return []
    for t in range(len(res.index)):
        a, b = res.triangle_states(t), again.triangle_states(t)
        if not np.array_equal(np.broadcast_to(a, b.shape) if len(a) == 1 else a,
                              np.broadcast_to(b, a.shape) if len(b) == 1 else b):
            return [f"triangle {t}: its micro-triangle states differ from a re-bake"]
    return ["buffers differ from a re-bake (same states, different packing)"]


def _check_pair_blocks(res: OmmResult) -> list[str]:
    from ..codecs.registry import get_codec

    info = res.summary["pair_blocks"]
    codec = get_codec(info["codec"])
    raw = res.pair_blocks
    bb = codec.block_bytes
    if len(raw) != info["blocks"] * bb:
        return [f"{omm_format.PAIR_BLOCKS_FILE} has {len(raw)} bytes, {info['blocks']} blocks of {bb} expected"]
    problems = []
    two_state = res.summary["format_code"] == omm_format.FORMAT_2_STATE
    for g in res.summary["geometries"]:
        n_pairs, first_block, first_tri, n = g["pairs"], g["first_pair_block"], g["first_triangle"], g["triangles"]
        maps = np.stack([codec.decode(raw[(first_block + p) * bb:(first_block + p + 1) * bb]) for p in range(n_pairs)])
        expanded = pairs.unpair(pairs.expand(maps), n)
        for t in range(n):
            s = res.triangle_states(first_tri + t)
            want = expanded[t]
            s = np.broadcast_to(s, want.shape)
            known = want < 2
            ok = np.array_equal(s[known], want[known]) and (two_state or np.all(s[~known] >= 2))
            if not ok:
                problems.append(f"{g['name']}: triangle {t} disagrees with its decoded pair block")
                break
    return problems


def _cmd_verify(folder) -> int:
    res, problems, done = verify(folder)
    st = res.summary["statistics"]
    for d in done:
        print(f"checked: {d}")
    if problems:
        for p in problems:
            print(f"omaps: {folder}: {p}", file=sys.stderr)
        return 1
    print(f"{folder}: OK ({st['triangles']} triangles, {st['micromaps']} micromaps, {st['data_bytes']} data bytes)")
    return 0
