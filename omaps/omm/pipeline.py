"""The OMM pipeline: geometries in, the buffers an engine uploads out (data, triangle records,
index buffer, usage histograms), with special indices and reuse of identical micromaps.

A ``Geometry`` is a set of UV triangles with one alpha test (a glTF primitive, or a texture and
a UV array). Each triangle's micromap comes either straight from the texture (``source``
``texture``: the fast baker, at one level or a level per triangle from its texel area) or from
the deck's square pair maps (``sqN``: uncompressed; a codec name such as ``vq2``: compressed,
decoded, then expanded by ``pairs.expand``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from .. import __version__, states
from ..errors import InputError
from ..maps import check_square_size, check_uv_triangles
from . import bake, pairs, resolve
from . import format as omm_format
from .alpha_test import AlphaTest

CHUNK_MICRO_TRIANGLES = 1 << 24  # bake this many micro-triangles at a time (bounded memory)


@dataclass(frozen=True)
class Geometry:
    name: str
    test: AlphaTest
    tris_uv: np.ndarray  # (T, 3, 2) UV triangles
    area: np.ndarray | None = None  # (T,) weights of the known-area fraction (default: texel area)
    unknown: np.ndarray | None = None  # (T,) bool: triangles forced fully unknown (e.g. zero UV area)
    info: dict = field(default_factory=dict)  # recorded in omm.json


@dataclass(frozen=True)
class OmmSettings:
    format: str = "4state"
    level: int = 4
    dynamic_scale: float | None = None  # texels per micro-triangle edge; None: ``level`` for all
    max_level: int = 8
    promotion: str = "nearest"
    special: bool = True
    dedup: bool = True
    source: str = "texture"  # texture | sqN | a codec name (vq2, vq4, vq4x64)
    encoder: str | None = None  # codec encoder and effort (None: the codec's first / "medium")
    effort: str | None = None
    seed: int = 0  # of the hashed promotion

    def __post_init__(self):
        if self.format not in omm_format.FORMAT_NAMES:
            raise InputError(f"unknown OMM format {self.format!r} (choose from {', '.join(omm_format.FORMAT_NAMES)})")
        if self.promotion not in resolve.PROMOTIONS:
            raise InputError(f"unknown promotion {self.promotion!r} (choose from {', '.join(resolve.PROMOTIONS)})")
        bake.check_level(self.level)
        bake.check_level(self.max_level, "max level")
        if self.dynamic_scale is not None and self.source != "texture":
            raise InputError("--dynamic needs the texture source: square pair maps fix the level to log2 N")

    @property
    def format_code(self) -> int:
        return omm_format.FORMAT_NAMES[self.format]


@dataclass
class OmmResult:
    """The buffers, as written to disk: ``data`` (uint8), ``triangles`` (TRIANGLE_RECORD),
    ``index`` (int32 per input triangle), ``usage`` and ``summary`` (the two JSON files) and,
    for a codec source, the compressed pair maps ``pair_blocks``."""

    data: np.ndarray
    triangles: np.ndarray
    index: np.ndarray
    usage: dict
    summary: dict
    pair_blocks: bytes | None = None

    def micromap_states(self, i: int) -> np.ndarray:
        """States of micromap ``i`` (0..3), decoded from ``data``."""
        rec = self.triangles[i]
        nbytes = omm_format.micromap_bytes(rec["level"], rec["format"])
        raw = self.data[rec["data_offset"]:rec["data_offset"] + nbytes]
        return omm_format.unpack(raw[None], int(rec["level"]), int(rec["format"]))[0]

    def triangle_states(self, t: int) -> np.ndarray:
        """States of input triangle ``t``: its micromap's, or one state for a special index."""
        i = int(self.index[t])
        if i >= 0:
            return self.micromap_states(i)
        return np.array([-1 - i], dtype=np.uint8)


_SQUARE = re.compile(r"sq(\d+)$")


def source_map_size(source: str) -> tuple[int | None, object]:
    """(N, codec) of a source: (None, None) for ``texture``, (N, None) for ``sqN``."""
    if source == "texture":
        return None, None
    m = _SQUARE.match(source)
    if m:
        return check_square_size(int(m.group(1))), None
    from ..codecs.registry import get_codec

    codec = get_codec(source)
    return codec.map_size, codec


class _Packer:
    """Collects micromaps, turning uniform ones into special indices and sharing duplicates."""

    def __init__(self, settings: OmmSettings):
        self.s = settings
        self.chunks: list[bytes] = []
        self.size = 0
        self.records: list[tuple[int, int, int]] = []
        self.seen: dict[tuple[int, bytes], int] = {}
        self.needing = 0  # micromaps before reuse of identical ones

    def add(self, omm_states: np.ndarray, level: int) -> np.ndarray:
        """Index buffer entries for micromaps (n, 4**level) of one level."""
        fmt = self.s.format_code
        idx = np.empty(len(omm_states), dtype=np.int32)
        need = np.ones(len(omm_states), dtype=bool)
        if self.s.special:
            uniform = (omm_states == omm_states[:, :1]).all(axis=1)
            idx[uniform] = omm_format.SPECIAL_INDEX[omm_states[uniform, 0]]
            need = ~uniform
        rows = np.flatnonzero(need)
        self.needing += len(rows)
        if len(rows) == 0:
            return idx
        packed = omm_format.pack(omm_states[rows], fmt)
        if self.s.dedup:
            void = np.ascontiguousarray(packed).view(np.dtype((np.void, packed.shape[1]))).ravel()
            _, first, inverse = np.unique(void, return_index=True, return_inverse=True)
            ids = np.empty(len(first), dtype=np.int32)
            for u in np.argsort(first):  # in order of first use
                key = (level, packed[first[u]].tobytes())
                got = self.seen.get(key)
                if got is None:
                    got = self._new(key[1], level, fmt)
                    self.seen[key] = got
                ids[u] = got
            idx[rows] = ids[inverse.ravel()]
        else:
            for r, row in zip(rows, packed):
                idx[r] = self._new(row.tobytes(), level, fmt)
        return idx

    def _new(self, raw: bytes, level: int, fmt: int) -> int:
        self.records.append((self.size, level, fmt))
        self.chunks.append(raw)
        self.size += len(raw)
        if self.size > 0xFFFFFFFF:
            raise InputError("micromap data exceeds the 4 GiB a 32-bit data offset can address; lower the level")
        return len(self.records) - 1


def _chunks(levels: np.ndarray, even: bool):
    """Triangle ranges [a, b) of at most CHUNK_MICRO_TRIANGLES micro-triangles (at least one
    triangle, or pair when ``even``)."""
    sizes = np.left_shift(np.int64(1), 2 * levels)
    n = len(levels)
    a = 0
    while a < n:
        total = np.cumsum(sizes[a:])
        b = a + max(int(np.searchsorted(total, CHUNK_MICRO_TRIANGLES, side="right")), 1)
        if even and b < n and (b - a) % 2:
            b = b + 1 if b - a == 1 else b - 1
        b = min(b, n)
        yield a, b
        a = b


def _texel_area(test: AlphaTest, tris: np.ndarray) -> np.ndarray:
    t = tris * np.array([test.width, test.height], dtype=np.float64)
    e1 = t[:, 1] - t[:, 0]
    e2 = t[:, 2] - t[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _pair_states(grid, tris, n, codec, settings, sat):
    """T/O/C micromaps at level log2 N of triangles from their pairs' square maps (codec: after
    a round trip through the codec), and the blocks."""
    squares, has_b = pairs.bake_squares(grid, tris, n, sat)
    blocks = []
    if codec is not None:
        encoder = settings.encoder or ("best" if "best" in codec.encoders else codec.encoders[0])
        effort = settings.effort or ("medium" if "medium" in codec.efforts else codec.efforts[0])
        if encoder not in codec.encoders:
            raise InputError(f"unknown encoder {encoder!r} for {codec.name} (choose from {', '.join(codec.encoders)})")
        if effort not in codec.efforts:
            raise InputError(f"unknown effort {effort!r} for {codec.name} (choose from {', '.join(codec.efforts)})")
        decoded = np.empty_like(squares)
        for p, m in enumerate(squares):
            blk = codec.encode(m, encoder, effort)
            d = codec.decode(blk)
            if len(blk) != codec.block_bytes or not states.is_conservative(m, d):
                raise RuntimeError(f"internal error: {codec.name} produced a bad block")  # never expected
            blocks.append(blk)
            decoded[p] = d
        squares = decoded
    return pairs.unpair(pairs.expand(squares), len(tris)).ravel(), blocks


def _triangle_levels(test: AlphaTest, tris: np.ndarray, settings: OmmSettings, n_map: int | None) -> np.ndarray:
    if n_map is not None:
        return np.full(len(tris), pairs.level_of_size(n_map), dtype=np.int64)
    if settings.dynamic_scale is not None:
        return bake.dynamic_levels(tris, test.width, test.height, settings.dynamic_scale, settings.max_level)
    return np.full(len(tris), settings.level, dtype=np.int64)


def build(geometries: list[Geometry], settings: OmmSettings = OmmSettings()) -> OmmResult:
    """Bake every geometry's micromaps and pack them into the standard buffers."""
    n_map, codec = source_map_size(settings.source)
    fmt = settings.format_code
    packer = _Packer(settings)
    index_parts, blocks_all, geo_info = [], [], []
    counts3 = np.zeros(3, dtype=np.int64)
    promoted = np.zeros(4, dtype=np.int64)
    known_area = total_area = 0.0
    micro_total = 0
    level_hist: dict[int, int] = {}
    first = 0
    for g in geometries:
        tris = check_uv_triangles(g.tris_uv) if len(g.tris_uv) else np.zeros((0, 3, 2))
        grid = g.test.grid()
        sat = bake.flag_table(grid)
        levels = _triangle_levels(g.test, tris, settings, n_map)
        area = _texel_area(g.test, tris) if g.area is None else np.asarray(g.area, dtype=np.float64)
        idx = np.empty(len(tris), dtype=np.int32)
        n_blocks = 0
        for a, b in _chunks(levels, even=n_map is not None):
            lv = levels[a:b]
            if n_map is None:
                s3, starts = bake.bake_levels(grid, tris[a:b], lv, sat)
            else:
                s3, blk = _pair_states(grid, tris[a:b], n_map, codec, settings, sat)
                starts = bake.micro_starts(lv)
                blocks_all += blk
                n_blocks += len(blk)
            if g.unknown is not None:
                for i in np.flatnonzero(g.unknown[a:b]):
                    s3[starts[i]:starts[i + 1]] = states.C
            omm = resolve.resolve(s3, starts, lv, g.test, tris[a:b], fmt, settings.promotion, settings.seed)
            counts3 += np.bincount(s3, minlength=3)[:3]
            promoted += np.bincount(omm[s3 == states.C], minlength=4)[:4]
            micro_total += len(s3)
            per_tri_known = np.add.reduceat((s3 != states.C).astype(np.int64), starts[:-1]) if len(s3) else np.zeros(0)
            known_area += float(np.sum(area[a:b] * per_tri_known / np.left_shift(1, 2 * lv)))
            total_area += float(np.sum(area[a:b]))
            for lvl in np.unique(lv):
                sel = np.flatnonzero(lv == lvl)
                if len(sel) == len(lv):
                    rows = omm.reshape(len(lv), -1)
                else:
                    rows = omm[starts[sel][:, None] + np.arange(1 << (2 * int(lvl)))]
                idx[a + sel] = packer.add(rows, int(lvl))
                level_hist[int(lvl)] = level_hist.get(int(lvl), 0) + len(sel)
        index_parts.append(idx)
        info = {"name": g.name, "first_triangle": first, "triangles": len(tris), "texture": g.test.name,
                "width": g.test.width, "height": g.test.height, "filter": g.test.filter,
                "wrap_u": g.test.wrap_u, "wrap_v": g.test.wrap_v, "threshold": g.test.threshold,
                "inclusive": g.test.inclusive, "state_rule": g.test.rule, **g.info}
        if n_map is not None:
            info["pairs"] = (len(tris) + 1) // 2
        if codec is not None:
            info["first_pair_block"] = len(blocks_all) - n_blocks
        geo_info.append(info)
        first += len(tris)
    index = np.concatenate(index_parts) if index_parts else np.zeros(0, dtype=np.int32)
    triangles = np.array(packer.records, dtype=omm_format.TRIANGLE_RECORD)
    data = np.frombuffer(b"".join(packer.chunks), dtype=np.uint8).copy()
    usage = omm_format.usage_histograms(triangles["level"], triangles["format"], index)
    special = {str(int(v)): int(np.count_nonzero(index == v)) for v in omm_format.SPECIAL_INDEX}
    bytes_no_reuse = int(sum(c * omm_format.micromap_bytes(lvl, fmt) for lvl, c in level_hist.items()))
    summary = {
        "omaps": __version__,
        "format": settings.format, "format_code": fmt,
        "settings": {"source": settings.source, "level": None if (settings.dynamic_scale or n_map) else settings.level,
                     "dynamic_scale": settings.dynamic_scale, "max_level": settings.max_level,
                     "promotion": settings.promotion, "special": settings.special, "dedup": settings.dedup,
                     "seed": settings.seed, "encoder": settings.encoder, "effort": settings.effort},
        "geometries": geo_info,
        "statistics": {
            "triangles": int(len(index)), "micro_triangles": int(micro_total),
            "levels": {str(k): v for k, v in sorted(level_hist.items())},
            "transparent": int(counts3[states.T]), "opaque": int(counts3[states.O]),
            "unknown": int(counts3[states.C]),
            "known_fraction": float((counts3[0] + counts3[1]) / micro_total) if micro_total else 0.0,
            "known_area_fraction": known_area / total_area if total_area > 0 else 0.0,
            "unknown_resolved": {"transparent": int(promoted[0]), "opaque": int(promoted[1]),
                                 "unknown_transparent": int(promoted[2]), "unknown_opaque": int(promoted[3])},
            "special_indices": special,
            "micromaps_without_reuse": int(len(index)),
            "micromaps_after_special_indices": int(packer.needing),
            "micromaps": int(len(triangles)),
            "data_bytes": int(len(data)), "data_bytes_without_reuse": bytes_no_reuse,
            "bytes": int(len(data) + triangles.nbytes + index.nbytes),
        },
    }
    if codec is not None:
        summary["pair_blocks"] = {"codec": codec.name, "block_bytes": codec.block_bytes, "blocks": len(blocks_all),
                                  "map_size": codec.map_size}
    return OmmResult(data, triangles, index, usage, summary, b"".join(blocks_all) if codec is not None else None)
