"""``verify``: read an OMM folder back and check it -- layout, the decoded pair blocks, and, when
its recorded input is present, every micro-triangle against a re-bake and every known one
against the alpha test itself."""

from __future__ import annotations

import os

import numpy as np

from ..bake import micro_starts
from ..codecs import get_codec
from ..coverage import micro_fractions
from ..errors import InputError
from . import files, pairs
from .files import settings_from_summary
from .. import omm_format
from .inputs import load_geometries
from .pipeline import OmmResult, build

__all__ = ["verify", "settings_from_summary"]


def verify(folder, **assets) -> tuple[OmmResult, list[str], list[str]]:
    """(the folder's buffers, problems, checks done). Layout problems raise InputError.
    ``assets``: ``root``, ``allow_outside``, ``max_bytes``, the URI policy of the scenes read
    (``load_scene``).

    Example::

        >>> from omaps.omm import verify       # doctest: +SKIP
        >>> res, problems, done = verify("omm/")  # doctest: +SKIP
        >>> problems                           # doctest: +SKIP
        []
    """
    from . import gltf_io

    if gltf_io.is_gltf(folder):  # a scene with EXT_mesh_opacity_micromap: the reader checks the extension's rules
        res = gltf_io.read_gltf(folder, **assets)
        problems, done = [], ["EXT_mesh_opacity_micromap rules: usage counts = records, regions in range and "
                              "disjoint, one index per triangle, index values valid"]
    else:
        res = files.read(folder)
        problems, done = [], ["layout, records, offsets, index entries, usage counts"]
    fmt_code = res.summary.get("format_code")
    budgeted = (res.summary.get("settings") or {}).get("budget") is not None
    if len(res.triangles) and not np.all(res.triangles["format"] == fmt_code):
        two = res.triangles["format"] == omm_format.FORMAT_2_STATE
        if not budgeted or not np.all(two | (res.triangles["format"] == fmt_code)):
            problems.append(f"micromap formats differ from omm.json's format {fmt_code}")
    if res.pair_blocks is not None:
        problems += _check_pair_blocks(res, folder if gltf_io.is_gltf(folder) else
                                       os.path.join(folder, omm_format.PAIR_BLOCKS_FILE))
        done.append("micromaps against the decoded pair blocks")
    if res.merged_micromaps is not None:
        from .expand import stored_states

        problems += _against(res, stored_states(res)[0], "merged micromap")
        done.append("micromaps against the merged micromaps")
    spec = res.summary.get("input")
    if spec is not None:
        src = spec.get("path") or spec.get("texture")
        missing = [p for p in (spec.get("path"), spec.get("texture"), spec.get("uvs")) if p and not os.path.exists(p)]
        if missing:
            done.append(f"no re-bake: {missing[0]} is absent")
        else:
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                geoms, _, _ = load_geometries(spec, **assets)
            if (res.summary.get("budget") or {}).get("weights") == "view":  # the plan came from a trace
                problems += _compare_known(res, geoms)
                done.append(f"every known micro-triangle against a re-bake of {src} at its stored level")
            else:
                again = build(geoms, settings_from_summary(res.summary))
                problems += _compare(res, again)
                done.append(f"every micro-triangle against a re-bake of {src}")
            if fmt_code == omm_format.FORMAT_4_STATE:  # (a budget's 2-state micromaps hold no unknown: exact too)
                problems += _check_known_states(res, geoms)
                done.append("every known micro-triangle against the alpha test at up to 64 points")
    return res, problems, done


def _check_known_states(res: OmmResult, geoms) -> list[str]:
    """Each T or O micro-triangle (and special index) of a 4-state OMM against the alpha test
    itself -- the shader's fetch and comparison at points spread over it, not a baker: a known
    state that any point contradicts is a problem (independent of the re-bake)."""
    first = 0
    for g in geoms:
        n = len(g.tris_uv)
        if n == 0:
            continue
        idx = res.index[first:first + n]
        levels = np.zeros(n, np.int64)  # a special index (uniform triangle) has level 0
        has = idx >= 0
        levels[has] = res.triangles["level"][idx[has]]  # (no micromap at all: nothing to index)
        st = np.concatenate([res.triangle_states(first + t) for t in range(n)])
        frac = micro_fractions(g.test, g.tris_uv, levels)
        bad = ((st == 1) & (frac < 1.0)) | ((st == 0) & (frac > 0.0))
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            t = int(np.searchsorted(micro_starts(levels), k, side="right") - 1)
            return [f"triangle {first + t}: a micro-triangle stated {'TO'[int(st[k])]} is contradicted by the "
                    f"alpha test at {frac[k]:.0%} opaque points"]
        first += n
    return []


def _compare_known(res: OmmResult, geoms) -> list[str]:
    """A budget planned from a view (its weights are not in the files): each triangle re-baked at
    its stored level; every T or O micro-triangle stored must be the re-bake's state (a merged
    micromap may only have turned known ones unknown)."""
    from ..bake import GROW_TEXEL, bake_micromaps
    from ..bake.micromap import flag_table

    first = 0
    for g in geoms:
        n = len(g.tris_uv)
        idx = res.index[first:first + n]
        levels = np.zeros(n, np.int64)  # a special index (uniform triangle) has level 0
        has = idx >= 0
        levels[has] = res.triangles["level"][idx[has]]  # (no micromap at all: nothing to index)
        grid = g.test.grid()
        s3, starts = bake_micromaps(grid, np.asarray(g.tris_uv, np.float64), levels, GROW_TEXEL, flag_table(grid))
        for t in range(n):
            st = np.broadcast_to(res.triangle_states(first + t), (starts[t + 1] - starts[t],))
            ref = s3[starts[t]:starts[t + 1]] if g.unknown is None or not g.unknown[t] else np.full(len(st), 2)
            if np.any((st <= 1) & (st != ref)):
                return [f"triangle {first + t}: a known micro-triangle differs from a re-bake at its level"]
        first += n
    return []


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


def _check_pair_blocks(res: OmmResult, path) -> list[str]:
    info = res.summary["pair_blocks"]
    codec = get_codec(info["codec"])
    raw = res.pair_blocks
    bb = codec.block_bytes
    if len(raw) != info["blocks"] * bb:
        return [f"{omm_format.PAIR_BLOCKS_FILE} has {len(raw)} bytes, {info['blocks']} blocks of {bb} expected"]
    try:
        maps = codec.decode_many(np.frombuffer(raw, np.uint8).reshape(-1, bb)) if info["blocks"] else np.zeros(
            (0, codec.map_size, codec.map_size), np.uint8)
    except InputError as exc:  # a block that decodes to no map (a raw map holding code 3)
        raise InputError(exc.problem, path) from None
    rec = res.pair_records
    return _against(res, pairs.expand(maps, rec["pair"].astype(np.int64), rec["corners"]), "decoded pair block")


def _against(res: OmmResult, stored: np.ndarray, what: str) -> list[str]:
    """Each triangle's micromap against its stored T/O/C states (T, 4^L): T and O the same, C
    an unknown state (any state in 2-state output); the first triangle that differs."""
    two_state = res.summary["format_code"] == omm_format.FORMAT_2_STATE
    for t in range(len(res.index)):
        s = res.triangle_states(t)
        want = stored[t]
        if len(s) not in (1, len(want)):
            return [f"triangle {t} has {len(s)} micro-triangles, its {what} has {len(want)}"]
        s = np.broadcast_to(s, want.shape)
        known = want < 2
        if not (np.array_equal(s[known], want[known]) and (two_state or np.all(s[~known] >= 2))):
            return [f"triangle {t} disagrees with its {what}"]
    return []
