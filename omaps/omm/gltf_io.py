"""``omaps omm SCENE -o OUT.glb|OUT.gltf``: the baked micromaps written into the scene itself
(``EXT_mesh_opacity_micromap``, and ``OMAPS_pair_opacity_maps`` or ``OMAPS_merged_micromaps`` for
``--from SCHEME``), and
read back as an ``OmmResult`` for ``--verify`` and ``--expand``. The glTF side (JSON, buffers,
the extension's rules) is ``omaps.scene.micromaps``; this module maps geometries to primitives.

One root micromap array holds every micromap (identical micromaps are shared across
primitives); each alpha-tested TRIANGLES primitive gets its ``micromapIndices`` accessor
(base triangle 0). omaps' record of the bake (format, settings, material rules, statistics,
per-geometry ranges) is the array's ``extras.omaps``.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..errors import InputError
from ..scene.files import GLTF_SUFFIXES as SCENE_GLTF_SUFFIXES
from .. import omm_format
from .pipeline import OmmResult

__all__ = ["GLTF_SUFFIXES", "is_gltf", "write_gltf_result", "read_gltf", "OMAPS_KEY"]

GLTF_SUFFIXES = SCENE_GLTF_SUFFIXES  # (a USD stage is a scene input, never a glTF output)
OMAPS_KEY = "omaps"


def is_gltf(path) -> bool:
    return str(path).lower().endswith(GLTF_SUFFIXES)


def _ranges(summary: dict):
    """(mesh, primitive, first triangle, triangles) of every geometry omm.json lists."""
    for g in summary.get("geometries", []):
        yield int(g["mesh"]), int(g["primitive"]), int(g["first_triangle"]), int(g["triangles"])


def write_gltf_result(src, out_tmp, out_final, result: OmmResult, extra_summary: dict | None = None,
                      **assets) -> list[str]:
    """Write scene ``src`` with ``result``'s micromaps (geometries from a glTF input: each
    ``summary['geometries'][k]`` names its mesh and primitive). Returns warnings. ``assets``:
    ``root``, ``allow_outside``, ``max_bytes``, the URI policy of ``load_scene``."""
    from ..scene.micromaps import write_gltf

    summary = dict(result.summary, **(extra_summary or {}))
    spec = summary.get("input") or {}
    if spec.get("kind") != "scene":
        raise InputError("a glTF output needs a glTF input (a texture and UVs have no scene to write into)", out_final)
    summary["input"] = {k: v for k, v in spec.items() if k not in ("kind", "path")}  # the material rules
    summary["source"] = os.path.basename(spec["path"])
    triangles, data = result.triangles, result.data
    if len(triangles) == 0:  # the extension needs at least one record: an unreferenced one-byte micromap
        triangles = np.array([(0, 0, result.summary["format_code"])], omm_format.TRIANGLE_RECORD)
        data = np.zeros(1, np.uint8)
        summary["placeholder_record"] = True
    usage = [(u["count"], u["subdivisionLevel"], u["format"])
             for u in omm_format.usage_histograms(triangles["level"], triangles["format"],
                                                  np.zeros(0, np.int32))["micromap_array"]]
    prim_omm, prim_pairs, prim_merged = {}, {}, {}
    for mesh, prim, first, n in _ranges(summary):
        prim_omm[(mesh, prim)] = (0, result.index[first:first + n].astype(np.int64))
        if result.pair_records is not None:
            prim_pairs[(mesh, prim)] = (0, result.pair_records[first:first + n])
        prim_merged[(mesh, prim)] = first
    merged = None
    if result.merged_micromaps is not None:
        info = summary["merged_micromaps"]
        merged = {"level": info["level"], "micromaps": info["micromaps"], "dag": result.merged_micromaps,
                  "extras": {OMAPS_KEY: {"scheme": info["scheme"]}}}
    pair_maps = []
    if result.pair_blocks is not None:
        info = summary["pair_blocks"]
        pair_maps.append({"codec": info["codec"], "blockBytes": info["block_bytes"], "mapSize": info["map_size"],
                          "blocks": result.pair_blocks, "extras": {OMAPS_KEY: {"scheme": info.get("scheme"),
                                                                               "encoder": info.get("encoder"),
                                                                               "effort": info.get("effort")}}})
    said = []
    write_gltf(src, out_tmp, out_final,
               [{"data": data.tobytes(), "triangles": triangles, "usage": usage, "extras": {OMAPS_KEY: summary}}],
               prim_omm, pair_maps, prim_pairs, said.append, merged=merged,
               prim_merged=prim_merged if merged is not None else None, **assets)
    return said


def read_gltf(path, scene=None, **assets) -> OmmResult:
    """The micromaps of a glTF file omaps wrote, as the buffers of ``omm.files.read``: index in
    the order of the recorded geometries, and the summary with ``input`` pointing at the file
    itself (its own textures, for a re-bake). Every rule of the extension is checked by the
    reader (an InputError naming the file). ``assets``: ``root``, ``allow_outside``,
    ``max_bytes``, the URI policy of ``load_scene``."""
    from ..scene import load_scene

    path = os.fspath(path)
    if scene is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(path, **assets)
    stored = scene.micromaps
    if stored is None or not stored.micromaps:
        raise InputError("holds no EXT_mesh_opacity_micromap micromaps", path)
    if len(stored.micromaps) != 1 or not isinstance(stored.micromaps[0].extras.get(OMAPS_KEY), dict):
        raise InputError("its micromaps were not written by omaps (one micromap array with extras.omaps expected)",
                         path)
    arr = stored.micromaps[0]
    summary = dict(arr.extras[OMAPS_KEY])
    rules = summary.get("input")
    if not isinstance(rules, dict) or not isinstance(summary.get("geometries"), list):
        raise InputError("extras.omaps lacks input (material rules) or geometries", path)
    summary["input"] = {"kind": "scene", "path": os.path.abspath(path), **rules}
    parts, pair_parts = [], []
    try:
        ranges = list(_ranges(summary))
    except (KeyError, TypeError, ValueError):
        raise InputError("extras.omaps.geometries: each needs mesh, primitive, first_triangle, triangles", path) from None
    first = 0
    for mesh, prim, start, n in ranges:
        p = stored.primitives.get((mesh, prim))
        if p is None or p.micromap != 0 or len(p.values) != n or start != first:
            raise InputError(f"mesh {mesh} primitive {prim}: its micromap indices are not the {n} triangles "
                             "extras.omaps records", path)
        parts.append(p.records)
        if stored.pair_maps:
            q = stored.pair_primitives.get((mesh, prim))
            if q is None:
                raise InputError(f"mesh {mesh} primitive {prim} has no OMAPS_pair_opacity_maps pairs", path)
            rec = q.records.copy()
            pair_parts.append(rec)
        if stored.merged is not None and stored.merged_primitives.get((mesh, prim)) != start:
            raise InputError(f"mesh {mesh} primitive {prim}: its OMAPS_merged_micromaps first is "
                             f"{stored.merged_primitives.get((mesh, prim))!r}, not its first triangle {start}", path)
        first += n
    index = np.concatenate(parts).astype(np.int32) if parts else np.zeros(0, np.int32)
    triangles, data = arr.triangles, arr.data
    if summary.pop("placeholder_record", False):
        triangles = triangles[:0]
        data = data[:0]
    usage = omm_format.usage_histograms(triangles["level"], triangles["format"], index)
    blocks = records = None
    if stored.pair_maps:
        pm = stored.pair_maps[0]
        blocks = pm.blocks
        records = np.concatenate(pair_parts).astype(omm_format.PAIR_RECORD) if pair_parts else np.zeros(
            0, omm_format.PAIR_RECORD)
        summary["pair_blocks"] = dict(summary.get("pair_blocks") or {}, codec=pm.codec, block_bytes=pm.block_bytes,
                                      blocks=len(pm.blocks) // pm.block_bytes, map_size=pm.map_size)
    merged = None
    if stored.merged is not None:
        mm = stored.merged
        if mm.micromaps != len(index):
            raise InputError(f"OMAPS_merged_micromaps holds {mm.micromaps} micromaps for {len(index)} triangles", path)
        from ..codecs import get_bits

        merged = mm.dag
        nodes = int(get_bits(np.frombuffer(mm.dag, np.uint8), 0, 32))  # the blob's header (checked when read)
        summary["merged_micromaps"] = dict(summary.get("merged_micromaps") or {}, level=mm.level,
                                           micromaps=mm.micromaps, nodes=nodes, bytes=len(mm.dag),
                                           scheme=f"csm{mm.level}")
    elif summary.get("merged_micromaps") is not None:
        raise InputError("extras.omaps describes merged_micromaps, the file has no OMAPS_merged_micromaps", path)
    stats = summary.get("statistics")
    if isinstance(stats, dict):
        for key, got in (("triangles", len(index)), ("micromaps", len(triangles)), ("data_bytes", len(data))):
            if stats.get(key) != got:
                raise InputError(f"extras.omaps.statistics.{key} is {stats.get(key)!r}, the file holds {got}", path)
    return OmmResult(np.asarray(data, np.uint8).copy(), np.asarray(triangles).astype(omm_format.TRIANGLE_RECORD),
                     index, usage, summary, blocks, records, merged)
