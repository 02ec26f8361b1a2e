"""``omaps omm SCENE -o OUT.glb|OUT.gltf``: the baked micromaps written into the scene itself
(``EXT_mesh_opacity_micromap``, and ``OMAPS_pair_opacity_maps`` for ``--from SCHEME``), and
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
    if spec.get("kind") != "gltf":
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
    prim_omm, prim_pairs = {}, {}
    for mesh, prim, first, n in _ranges(summary):
        prim_omm[(mesh, prim)] = (0, result.index[first:first + n].astype(np.int64))
        if result.pair_records is not None:
            prim_pairs[(mesh, prim)] = (0, result.pair_records[first:first + n])
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
               prim_omm, pair_maps, prim_pairs, said.append, **assets)
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
    summary["input"] = {"kind": "gltf", "path": os.path.abspath(path), **rules}
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
    stats = summary.get("statistics")
    if isinstance(stats, dict):
        for key, got in (("triangles", len(index)), ("micromaps", len(triangles)), ("data_bytes", len(data))):
            if stats.get(key) != got:
                raise InputError(f"extras.omaps.statistics.{key} is {stats.get(key)!r}, the file holds {got}", path)
    return OmmResult(np.asarray(data, np.uint8).copy(), np.asarray(triangles).astype(omm_format.TRIANGLE_RECORD),
                     index, usage, summary, blocks, records)
