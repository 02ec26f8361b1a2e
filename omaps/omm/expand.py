"""Stored maps of a baked glTF expanded into standard micromaps: pair blocks
(``OMAPS_pair_opacity_maps``) decoded by their codec, each pair's square map split into its
triangles' level-log2 N micromaps (``pairs.expand``), or merged micromaps
(``OMAPS_merged_micromaps``, a ``csmL`` source) decoded from their DAG; then unknown regions
resolved by the recorded promotion with the scene's own alpha tests (``resolve.resolve``), given
special indices and shared as ``pipeline.build`` does (its ``Packer``): the micromaps equal those
``omm --from`` wrote beside the stored maps."""

from __future__ import annotations

import warnings

import numpy as np

from .. import omm_format, states
from ..codecs import get_codec
from ..omm_format import Packer
from . import pairs, resolve
from .files import settings_from_summary
from .inputs import load_geometries
from .pipeline import OmmResult

__all__ = ["decoded_blocks", "stored_states", "expand_result"]


def decoded_blocks(res: OmmResult) -> np.ndarray:
    """Every stored pair block decoded: (P, N, N) states."""
    codec = get_codec(res.summary["pair_blocks"]["codec"])
    raw = np.frombuffer(res.pair_blocks, np.uint8).reshape(-1, codec.block_bytes)
    if len(raw) == 0:
        return np.zeros((0, codec.map_size, codec.map_size), np.uint8)
    return codec.decode_many(raw)


def stored_states(res: OmmResult) -> tuple[np.ndarray, int, str]:
    """Every triangle's T/O/C micromap (T, 4^L) from the stored maps of a result read with pair
    blocks or merged micromaps, their level, and the summary key that describes them."""
    if res.merged_micromaps is not None:
        from ..codecs import csm_decode

        info = res.summary["merged_micromaps"]
        level = int(info["level"])
        return csm_decode(res.merged_micromaps, level, len(res.index)), level, "merged_micromaps"
    maps = decoded_blocks(res)
    rec = res.pair_records
    return (pairs.expand(maps, rec["pair"].astype(np.int64), rec["corners"]), pairs.level_of_size(maps.shape[1]),
            "pair_blocks")


def expand_result(res: OmmResult, **assets) -> OmmResult:
    """Standard micromaps only (no stored pair blocks or merged micromaps) from a result read
    with them."""
    settings = settings_from_summary(res.summary)
    fmt = settings.format_code
    three, level, key = stored_states(res)  # (T, 4**L)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geoms, _, _ = load_geometries(res.summary["input"], **assets)  # (root, allow_outside: load_scene's)
    packer = Packer(settings.format_code, settings.special, settings.dedup)
    parts, first = [], 0
    for g in geoms:
        n = len(g.tris_uv)
        s3 = three[first:first + n].copy()
        if g.unknown is not None:
            s3[np.asarray(g.unknown, bool)] = states.C
        starts = np.arange(n + 1, dtype=np.int64) << (2 * level)
        omm = resolve.resolve(s3.ravel(), starts, np.full(n, level, np.int64), g.test, g.tris_uv, fmt,
                              settings.promotion, settings.seed)
        parts.append(packer.add(omm.reshape(n, -1), level) if n else np.zeros(0, np.int32))
        first += n
    if first != len(three):
        raise RuntimeError(f"internal error: {first} triangles in the scene, {len(three)} pair records")
    index = np.concatenate(parts) if parts else np.zeros(0, np.int32)
    triangles = packer.record_array()
    data = packer.data()
    usage = omm_format.usage_histograms(triangles["level"], triangles["format"], index)
    summary = {k: v for k, v in res.summary.items() if k != key}
    summary["expanded_from"] = res.summary[key]
    summary["statistics"] = dict(summary.get("statistics") or {}, triangles=int(len(index)),
                                 micromaps=int(len(triangles)), data_bytes=int(len(data)))
    return OmmResult(data, triangles, index, usage, summary)
