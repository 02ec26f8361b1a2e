"""The OMM output folder: written whole or not at all, read back with every layout check.

``write`` fills a temporary folder beside the target and renames it into place (an existing
OMM folder is swapped out and removed only after that; ``omaps.atomic`` holds the rule), so a
failed run leaves no partial output. ``read`` checks sizes, record fields, offsets, index
entries and the usage histograms against the files, and raises ``InputError`` naming the file
and the problem.
"""

from __future__ import annotations

import json
import os

import numpy as np

from .. import atomic
from ..checks import typed
from ..errors import InputError
from .. import omm_format
from .inputs import check_spec
from .pipeline import OmmResult, OmmSettings


def check_target(folder) -> str:
    """The absolute output folder, when it may be written: absent, empty, or an earlier output
    (holding omm.json); the one rule of ``omaps.atomic``."""
    return atomic.check_folder(folder, omm_format.SUMMARY_FILE)


@typed
def write(folder: str | os.PathLike[str], result: OmmResult, extra_summary: dict | None = None) -> None:
    """Write the folder whole or not at all (an earlier OMM folder there is replaced)."""
    with atomic.atomic_folder(folder, omm_format.SUMMARY_FILE) as tmp:
        write_into(tmp, result, extra_summary)


def write_into(folder, result: OmmResult, extra_summary: dict | None = None) -> None:
    """Write the OMM files into an existing (empty) folder."""
    summary = dict(result.summary, **(extra_summary or {}))
    files = {
        omm_format.DATA_FILE: _raw(result.data, np.uint8),
        omm_format.TRIANGLES_FILE: _raw(result.triangles, omm_format.TRIANGLE_RECORD),
        omm_format.INDEX_FILE: _raw(result.index, omm_format.INDEX_DTYPE),
        omm_format.USAGE_FILE: (json.dumps(result.usage, indent=1) + "\n").encode(),
        omm_format.SUMMARY_FILE: (json.dumps(summary, indent=1) + "\n").encode(),
    }
    if result.pair_blocks is not None:
        files[omm_format.PAIR_BLOCKS_FILE] = result.pair_blocks
        files[omm_format.PAIRS_FILE] = _raw(result.pair_records, omm_format.PAIR_RECORD)
    if result.merged_micromaps is not None:
        files[omm_format.MERGED_FILE] = result.merged_micromaps
    for name, raw in files.items():
        with open(os.path.join(folder, name), "wb") as f:
            f.write(raw)


def _raw(a: np.ndarray, dtype) -> memoryview:
    """The bytes of an array as ``dtype``, without a copy where it is already that (the micromap
    data can be gigabytes: written from where it lies)."""
    return memoryview(np.ascontiguousarray(a, dtype=dtype)).cast("B")


def _read(folder, name) -> bytes:
    path = os.path.join(folder, name)
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise InputError("missing", path) from None


def _json(folder, name) -> dict:
    path = os.path.join(folder, name)
    try:
        doc = json.loads(_read(folder, name))
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not valid JSON ({exc})", path) from None
    if not isinstance(doc, dict):
        raise InputError(f"holds {type(doc).__name__}, not a JSON object", path)
    return doc


# omm.json's settings: the Python types each may have (None: may be null)
_SETTING_TYPES = {"source": (str,), "level": (int, None), "dynamic_scale": (float, None), "max_level": (int,),
                  "promotion": (str,), "special": (bool,), "dedup": (bool,), "seed": (int,), "encoder": (str, None),
                  "effort": (str, None), "budget": (int, None)}


def _is(value, kind) -> bool:
    if kind is None:
        return value is None
    if kind is bool or kind is str:
        return isinstance(value, kind)
    if isinstance(value, bool) or not isinstance(value, (int, float) if kind is float else int):
        return False
    return -1e300 < value < 1e300 if kind is float else -(2 ** 63) <= value < 2 ** 63  # finite; int64


def settings_from_summary(summary: dict, path=None) -> OmmSettings:
    """The ``OmmSettings`` omm.json records (``summary``), every field checked: an InputError
    naming ``path`` and the field otherwise."""
    s = summary.get("settings")
    if not isinstance(s, dict):
        raise InputError(f"settings is {s!r}, not an object", path)
    s = {key: s.get(key) for key in _SETTING_TYPES}  # an absent key reads as null
    for key, kinds in _SETTING_TYPES.items():
        if not any(_is(s[key], k) for k in kinds):
            raise InputError(f"settings.{key} is {s[key]!r}", path)
    if s["dynamic_scale"] is not None and s["dynamic_scale"] <= 0:
        raise InputError(f"settings.dynamic_scale is {s['dynamic_scale']}, not positive", path)
    fmt = summary.get("format")
    if not isinstance(fmt, str) or summary.get("format_code") != omm_format.FORMAT_NAMES.get(fmt):
        raise InputError(f"format {fmt!r} and format_code {summary.get('format_code')!r} do not match "
                         f"({', '.join(f'{k} = {v}' for k, v in omm_format.FORMAT_NAMES.items())})", path)
    try:
        return OmmSettings(format=fmt, level=s["level"] if s["level"] is not None else 4,
                           dynamic_scale=s["dynamic_scale"], max_level=s["max_level"], promotion=s["promotion"],
                           special=s["special"], dedup=s["dedup"], source=s["source"], encoder=s["encoder"],
                           effort=s["effort"], seed=s["seed"], budget=s["budget"])
    except InputError as exc:
        raise InputError(f"settings: {exc.problem}", path) from None


def _pair_blocks_info(summary: dict, path) -> int:
    """omm.json's ``pair_blocks`` (a square source's codec and block count), checked against the
    codec; the number of blocks."""
    from ..codecs import get_codec

    info = summary.get("pair_blocks")
    if not isinstance(info, dict):
        raise InputError(f"pair_blocks is {info!r}: {omm_format.PAIR_BLOCKS_FILE} is present but not described",
                         path)
    name = info.get("codec")
    try:
        codec = get_codec(name) if isinstance(name, str) else None
    except InputError:
        codec = None
    if codec is None:
        raise InputError(f"pair_blocks.codec is {name!r}, not a codec", path)
    if info.get("block_bytes") != codec.block_bytes or isinstance(info.get("block_bytes"), bool):
        raise InputError(f"pair_blocks.block_bytes is {info.get('block_bytes')!r}, a {codec.name} block has "
                         f"{codec.block_bytes}", path)
    n = info.get("blocks")
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise InputError(f"pair_blocks.blocks is {n!r}, not a count", path)
    return n


def merged_info(summary: dict, blob: bytes, n_triangles: int, path) -> dict:
    """omm.json's ``merged_micromaps`` (a csmL source's scheme, level and micromaps), checked
    against the blob ``blob`` (``codecs.csm.check``: every reference in range, every descent ending
    within the level) and the ``n_triangles`` triangles; InputError naming ``path`` otherwise."""
    from ..codecs import csm_check

    info = summary.get("merged_micromaps")
    if not isinstance(info, dict):
        raise InputError(f"merged_micromaps is {info!r}: the merged DAG is present but not described", path)
    level, n = info.get("level"), info.get("micromaps")
    if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level <= omm_format.MAX_LEVEL:
        raise InputError(f"merged_micromaps.level is {level!r}, not a level 0..{omm_format.MAX_LEVEL}", path)
    if n != n_triangles or isinstance(n, bool):
        raise InputError(f"merged_micromaps.micromaps is {n!r}, the index holds {n_triangles} triangles", path)
    if info.get("scheme") != f"csm{level}":
        raise InputError(f"merged_micromaps.scheme is {info.get('scheme')!r}, its level is {level}", path)
    try:
        csm_check(np.frombuffer(blob, np.uint8), level, n)
    except InputError as exc:
        raise InputError(exc.problem, path) from None
    return info


@typed
def read(folder: str | os.PathLike[str]) -> OmmResult:
    """Load and check an OMM folder."""
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise InputError("no such folder", folder)
    data = np.frombuffer(_read(folder, omm_format.DATA_FILE), dtype=np.uint8)
    raw_tri = _read(folder, omm_format.TRIANGLES_FILE)
    raw_idx = _read(folder, omm_format.INDEX_FILE)
    tri_path = os.path.join(folder, omm_format.TRIANGLES_FILE)
    idx_path = os.path.join(folder, omm_format.INDEX_FILE)
    if len(raw_tri) % omm_format.TRIANGLE_RECORD.itemsize:
        raise InputError(f"size {len(raw_tri)} is not a multiple of the {omm_format.TRIANGLE_RECORD.itemsize}-byte record", tri_path)
    if len(raw_idx) % 4:
        raise InputError(f"size {len(raw_idx)} is not a multiple of 4 bytes", idx_path)
    tris = np.frombuffer(raw_tri, dtype=omm_format.TRIANGLE_RECORD)
    index = np.frombuffer(raw_idx, dtype=omm_format.INDEX_DTYPE)
    bad = np.flatnonzero(~np.isin(tris["format"], list(omm_format.BITS)))
    if len(bad):
        raise InputError(f"micromap {bad[0]} has format {tris['format'][bad[0]]} (1 or 2 expected)", tri_path)
    bad = np.flatnonzero(tris["level"] > omm_format.MAX_LEVEL)
    if len(bad):
        raise InputError(f"micromap {bad[0]} has level {tris['level'][bad[0]]} (at most {omm_format.MAX_LEVEL})", tri_path)
    sizes = np.array([omm_format.micromap_bytes(lv, f) for lv, f in zip(tris["level"], tris["format"])], dtype=np.int64)
    ends = tris["data_offset"].astype(np.int64) + sizes
    bad = np.flatnonzero(ends > len(data))
    if len(bad):
        raise InputError(f"micromap {bad[0]} reads bytes up to {ends[bad[0]]} of a {len(data)}-byte "
                         f"{omm_format.DATA_FILE}", tri_path)
    bad = np.flatnonzero((index < -4) | (index >= len(tris)))
    if len(bad):
        raise InputError(f"triangle {bad[0]} has index {index[bad[0]]} ({len(tris)} micromaps; specials -1..-4)", idx_path)
    usage = _json(folder, omm_format.USAGE_FILE)
    want = omm_format.usage_histograms(tris["level"], tris["format"], index)
    if usage != want:
        raise InputError("usage counts do not match the triangle records and the index buffer",
                         os.path.join(folder, omm_format.USAGE_FILE))
    summary = _json(folder, omm_format.SUMMARY_FILE)
    sum_path = os.path.join(folder, omm_format.SUMMARY_FILE)
    settings_from_summary(summary, sum_path)
    if summary.get("input") is not None:
        try:
            check_spec(summary["input"])
        except InputError as exc:
            raise InputError(exc.problem, sum_path) from None
    blocks = records = None
    if os.path.exists(os.path.join(folder, omm_format.PAIR_BLOCKS_FILE)):
        blocks = _read(folder, omm_format.PAIR_BLOCKS_FILE)
        n_blocks = _pair_blocks_info(summary, sum_path)
        block_bytes = summary["pair_blocks"]["block_bytes"]
        if len(blocks) != n_blocks * block_bytes:
            raise InputError(f"size {len(blocks)} is not {n_blocks} blocks of {block_bytes} bytes (omm.json)",
                             os.path.join(folder, omm_format.PAIR_BLOCKS_FILE))
        raw = _read(folder, omm_format.PAIRS_FILE)
        rec_path = os.path.join(folder, omm_format.PAIRS_FILE)
        if len(raw) != omm_format.PAIR_RECORD.itemsize * len(index):
            raise InputError(f"size {len(raw)} is not {omm_format.PAIR_RECORD.itemsize} bytes per triangle", rec_path)
        records = np.frombuffer(raw, dtype=omm_format.PAIR_RECORD)
        if np.any(records["pair"] < 0) or np.any(records["pair"] >= n_blocks) or np.any(records["corners"] > 3):
            raise InputError("a pair index or corner code is out of range", rec_path)
    merged = None
    if os.path.exists(os.path.join(folder, omm_format.MERGED_FILE)):
        merged = _read(folder, omm_format.MERGED_FILE)
        merged_info(summary, merged, len(index), os.path.join(folder, omm_format.MERGED_FILE))
    elif summary.get("merged_micromaps") is not None:
        raise InputError("missing: omm.json describes merged_micromaps", os.path.join(folder, omm_format.MERGED_FILE))
    stats = summary.get("statistics")
    if not isinstance(stats, dict):
        raise InputError(f"statistics is {stats!r}, not an object", sum_path)
    for key, got in (("triangles", len(index)), ("micromaps", len(tris)), ("data_bytes", len(data))):
        if stats.get(key) != got or isinstance(stats.get(key), bool):
            raise InputError(f"statistics.{key} is {stats.get(key)!r}, the files hold {got}", sum_path)
    return OmmResult(data.copy(), tris.copy(), index.copy(), usage, summary, blocks,
                     None if records is None else records.copy(), merged)
