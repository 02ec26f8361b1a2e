"""What a ray reads (``omaps trace --memory``): the map data each alpha-test lookup of the primary
pass reads, modelled as hardware would read it, per scheme and per layout of its stored data.

Every lookup the tracer's any-hit filter performs (one per filter call, the same rays and
candidates as the traced run: the filter is run again with a recording hook,
``filter.make_recording_filter``) is replayed against a byte layout of the scheme's data in one
address space. Each layout places its regions (index buffer, records, data) one after another,
each starting on a 64-byte line. A lookup is a chain of *dependent reads*: a read's address needs
the value of the read before it; the bytes one read fetches together (whose addresses are known
at once) count as one read, whatever lines they span. docs/FORMAT.md, "What a lookup reads",
states every layout; per scheme two of them:

``own``
    Each triangle (pair) its own copy, found from its index as ``map_bytes`` counts it: a raw
    micromap row per triangle (``triL``); a block per prototype pair stored with the pair
    (``sqN``, the deck's codecs); a succinct tree per triangle through a 32-bit byte offset
    (``succinctL``); the merged DAG (``csmL``, shared by construction).
``shared``
    Identical maps stored once and reached through a 32-bit index per triangle (pair), the index
    read counted: for ``triL`` the standard OMM layout as ``omaps omm`` writes it (index buffer,
    8-byte triangle records, data; uniform micromaps are special indices that read no record or
    data; reuse of identical micromaps); a block per distinct map behind a per-pair index; the
    distinct succinct trees; the DAG again.

Per layout: ``map_reads_per_lookup`` (dependent reads, mean over lookups), ``map_lines_per_ray``
(distinct 64-byte lines a primary ray touches, mean over pixels) and, given a cache size, the
misses per ray of a fully associative LRU cache of that many KiB shared by an 8 x 8 tile of
pixels: it starts empty at each tile, whose 64 rays run one after another in row-major order,
each ray's lookups in the order the filter made them.

Beside the map data, the alpha texture each alpha test the map did not spare fetches: every
lookup that ends in C runs the any-hit shader, which reads the taps of the material's filter
(``sampling.taps``: one texel nearest, 2 x 2 linear, addressed by the material's wrap modes) at
the hit's texel coordinate (``lookups.hit_texel``) on mip level 0. ``TextureLayout`` places the
textures (``TEXEL_BYTES``-byte texels in ``TEX_TILE`` x ``TEX_TILE`` tiles, one 64-byte line
each); ``texture_lines_per_ray`` is the distinct texture lines per primary ray (mean over
pixels), the same for every layout of a scheme's maps, and each layout's ``total_lines_per_ray``
its map lines plus them.

The walks compile ``pair.hit_st``, ``pair.uv_to_cell``, ``birdcurve.bary_to_index``,
``lookups.hit_texel`` and ``sampling.taps`` into themselves; their cached kernels are keyed on
those modules too (``omaps.kernel_cache``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import birdcurve, omm_format, pair, states
from ..codecs import bit_length, get_bits
from ..sampling import taps
from .lookups import hit_texel

__all__ = ["LINE_BYTES", "TILE", "TEXEL_BYTES", "TEX_TILE", "Lookups", "Layout", "TextureLayout", "record_lookups",
           "layouts", "touches", "measure", "texture_layout", "texture_touches", "texture_lines_per_ray",
           "scheme_memory", "lines_per_ray", "lru_misses"]

LINE_BYTES = 64
TILE = 8  # pixels per side of the tile of rays that shares a cache
INDEX_BYTES = 4  # an index buffer entry or a byte offset
RECORD_BYTES = omm_format.TRIANGLE_RECORD.itemsize  # a standard OMM triangle record
TEXEL_BYTES = 4  # an alpha texture's texel: RGBA8, the base colour texture the alpha is read from
TEX_TILE = 4  # texels per side of a texture tile: 4 x 4 texels of 4 bytes, one 64-byte line
assert TEX_TILE * TEX_TILE * TEXEL_BYTES == LINE_BYTES

# layout kinds (the walks below)
K_NONE, K_ROWS, K_OMM, K_BLOCK, K_SUCCINCT, K_CSM = 0, 1, 2, 3, 4, 5
# what part of a pair's block a lookup reads
SPAN_BLOCK, SPAN_CELL_BYTE, SPAN_QUADRANT = 0, 1, 2


@dataclass
class Lookups:
    """Every lookup of a primary pass: pixel ``p``'s are ``start[p]:start[p + 1]``, in the order
    the filter made them; per lookup the alpha triangle, clamped barycentrics and state read."""

    start: np.ndarray
    tri: np.ndarray
    b1: np.ndarray
    b2: np.ndarray
    state: np.ndarray
    width: int
    height: int

    @property
    def count(self) -> int:
        return int(self.start[-1])


def record_lookups(prep, name: str, cam: np.ndarray, w: int, h: int, calls: np.ndarray) -> tuple[Lookups, object]:
    """Trace scheme ``name``'s primary pass again with the recording filter and return its
    lookups and the recording run (``PrimaryResult``). ``calls``: the traced run's filter calls
    per pixel (h, w), the slots each pixel gets; RuntimeError if the recording run's calls differ
    (then it did not see the traced run's lookups)."""
    from .filter import make_recording_filter
    from .lookups import state_function
    from .rays import run_primary
    from .tables import T_REC_BARY, T_REC_COUNT, T_REC_START, T_REC_STATE, T_REC_TRI, scheme_tables

    sm = prep.maps[name]
    tables = scheme_tables(prep.base, sm)
    n = w * h
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.asarray(calls, np.int64).ravel(), out=start[1:])
    total = max(int(start[-1]), 1)
    count = np.zeros(n, np.int64)
    tri = np.zeros(total, np.int64)
    bary = np.zeros(2 * total, np.float64)
    st = np.zeros(total, np.uint8)
    for word, a in ((T_REC_START, start), (T_REC_COUNT, count), (T_REC_TRI, tri), (T_REC_BARY, bary),
                    (T_REC_STATE, st)):
        tables.arrays[word] = a
        tables.table[word] = a.ctypes.data
    primary = run_primary(prep.bvh, tables, make_recording_filter(state_function(sm)).address, cam, w, h)
    if not np.array_equal(count, start[1:] - start[:-1]):
        raise RuntimeError(f"memory model: scheme {name}'s recording run made other lookups than its traced run")
    m = int(start[-1])
    return Lookups(start, tri[:m], bary[0:2 * m:2].copy(), bary[1:2 * m:2].copy(), st[:m], w, h), primary


@dataclass
class Layout:
    """One layout of a scheme's stored data, as ``touches`` walks it: ``kind`` (``K_*``), its
    map bytes and the integer / byte arrays and parameters of its walk."""

    name: str
    description: str
    map_bytes: int
    kind: int
    ints: tuple = ()  # int64 arrays of the walk
    data: np.ndarray = None  # the bytes the walk reads values from (succinct, csm)
    params: tuple = ()


def _align(n: int) -> int:
    return -(-int(n) // LINE_BYTES) * LINE_BYTES


def _standard_omm(sm) -> tuple[np.ndarray, np.ndarray, int]:
    """Per triangle its index buffer entry, per record its data offset, and the data bytes of the
    triL maps as ``omaps omm`` packs them (``omm_format.Packer``; docs/FORMAT.md, "Standard
    opacity micromaps"): 4-state data (C as unknown-transparent), a uniform micromap a special
    index with no record or data, identical micromaps once (``sm``'s rows are already distinct)."""
    from ..codecs import unpack_states

    n_rows = len(sm.data) // sm.row_bytes
    packer = omm_format.Packer(omm_format.FORMAT_4_STATE)
    entry = packer.add(unpack_states(sm.data.reshape(n_rows, sm.row_bytes), 4 ** sm.param), sm.param)
    offs = packer.record_array()["data_offset"].astype(np.int64)
    return entry[sm.rows].astype(np.int64), offs, packer.size


def layouts(sm, at) -> dict[str, Layout]:
    """The ``own`` and ``shared`` layouts of a scheme's maps (``trace.maps.SchemeMaps``) over the
    alpha triangles ``at``; {} for a kind not modelled (a budget's mixed maps, a file's maps)."""
    t_count = len(sm.rows)
    if sm.kind == "none":
        none = Layout("own", "no map data", 0, K_NONE)
        return {"own": none, "shared": Layout("shared", "no map data", 0, K_NONE)}
    if sm.kind == "micromap":
        rb = sm.row_bytes
        own = Layout("own", "a raw 2-bit micromap row per triangle, at triangle x row bytes", t_count * rb, K_ROWS,
                     (), None, (rb, sm.param))
        idx, offs, nbytes = _standard_omm(sm)
        rec_base = _align(INDEX_BYTES * t_count)
        data_base = rec_base + _align(RECORD_BYTES * len(offs))
        shared = Layout("shared", "standard OMMs: index buffer -> triangle record -> data (special indices, reuse)",
                        INDEX_BYTES * t_count + RECORD_BYTES * len(offs) + nbytes, K_OMM, (idx, offs), None,
                        (rec_base, data_base, sm.param))
        return {"own": own, "shared": shared}
    if sm.kind == "square" and (sm.scheme is None or sm.scheme.kind != "stored") and sm.codec is not None:
        from .tables import T_TRI_CORNER

        codec = sm.codec
        bb = codec.block_bytes
        if codec.name.startswith("sq"):
            span = SPAN_CELL_BYTE
        elif codec.name == "vq4x64":
            span = SPAN_QUADRANT
        else:
            span = SPAN_BLOCK
        corners = np.ascontiguousarray(sm.extra.get(T_TRI_CORNER, at.corners), dtype=np.int64).ravel()
        n_pairs = len(at.pair_first)
        pair_of = np.ascontiguousarray(at.pair, dtype=np.int64)
        own = Layout("own", "a block per prototype pair, stored with the pair (one read)", n_pairs * bb, K_BLOCK,
                     (pair_of, corners), None, (bb, codec.map_size, span, 0, -1))
        rows = np.ascontiguousarray(sm.rows, dtype=np.int64)
        n_distinct = len(sm.data) // bb
        blk_base = _align(INDEX_BYTES * n_pairs)
        # the pair's index entry: a pair's distinct block is its triangles' row
        shared = Layout("shared", "a 32-bit index per pair -> the distinct block", INDEX_BYTES * n_pairs + n_distinct * bb,
                        K_BLOCK, (pair_of, corners, rows), None, (bb, codec.map_size, span, blk_base, 1))
        return {"own": own, "shared": shared}
    if sm.kind == "succinct":
        from .tables import T_MAP_OFFSET

        starts = np.ascontiguousarray(sm.extra[T_MAP_OFFSET], dtype=np.int64)  # per distinct map its byte offset
        sizes = np.diff(np.append(starts, len(sm.data) - 1))
        rows = np.ascontiguousarray(sm.rows, dtype=np.int64)
        own_at = np.concatenate([[0], np.cumsum(sizes[rows])[:-1]]).astype(np.int64)  # each triangle's own copy
        base = _align(INDEX_BYTES * t_count)
        own = Layout("own", "a 32-bit byte offset per triangle -> its own succinct tree", int(sizes[rows].sum())
                     + INDEX_BYTES * t_count, K_SUCCINCT, (rows, starts, own_at), sm.data, (sm.param, base))
        shared = Layout("shared", "a 32-bit byte offset per triangle -> the distinct succinct tree",
                        int(sizes.sum()) + INDEX_BYTES * t_count, K_SUCCINCT, (rows, starts, starts[rows]), sm.data,
                        (sm.param, base))
        return {"own": own, "shared": shared}
    if sm.kind == "csm":
        rows = np.ascontiguousarray(sm.rows, dtype=np.int64)  # each triangle's root
        lay = Layout("own", "the merged DAG: the triangle's root reference, then one reference per mixed node",
                     int(sm.map_bytes), K_CSM, (rows,), sm.data, (sm.param,))
        return {"own": lay, "shared": Layout("shared", lay.description, lay.map_bytes, K_CSM, lay.ints, sm.data,
                                             (sm.param,))}
    return {}


# ---- the walks: per lookup its dependent reads and the lines they touch ------------------------

@njit(cache=True, inline="always")
def _span(out, p, a, b):
    """Append the lines of bytes [a, b) to ``out`` from ``p`` (only counted past its end)."""
    if b <= a:
        return p
    for line in range(a >> 6, ((b - 1) >> 6) + 1):
        if p < out.shape[0]:
            out[p] = line
        p += 1
    return p


@njit(cache=True, inline="always")
def _bits(out, p, base, a, b):
    """``_span`` of the bytes holding bits [a, b) of a region at byte ``base``."""
    if b <= a:
        return p
    return _span(out, p, base + (a >> 3), base + ((b - 1) >> 3) + 1)


@njit(cache=True)
def _walk_rows(out, p, tri, k, rb):
    return 1, _span(out, p, tri * rb + (k >> 2), tri * rb + (k >> 2) + 1), -1


@njit(cache=True)
def _walk_omm(out, p, tri, k, idx, offs, rec_base, data_base):
    p = _span(out, p, 4 * tri, 4 * tri + 4)
    r = idx[tri]
    if r < 0:
        return 1, p, -1
    p = _span(out, p, rec_base + 8 * r, rec_base + 8 * r + 8)
    a = data_base + offs[r] + (k >> 2)
    return 3, _span(out, p, a, a + 1), -1


@njit(cache=True)
def _walk_block(out, p, tri, b1, b2, pair_of, corners, rows, bb, n, span, blk_base, indexed):
    pr = pair_of[tri]
    reads = 1
    if indexed:
        p = _span(out, p, 4 * pr, 4 * pr + 4)
        reads = 2
        a = blk_base + bb * rows[tri]
    else:
        a = bb * pr
    if span == SPAN_BLOCK:
        return reads, _span(out, p, a, a + bb), -1
    s, t = pair.hit_st(corners, tri, b1, b2)
    i, j = pair.uv_to_cell(s, t, n)
    if span == SPAN_CELL_BYTE:
        c = a + ((j * n + i) >> 2)
        return reads, _span(out, p, c, c + 1), -1
    q = a + 64 * (2 * (j >> 5) + (i >> 5))
    return reads, _span(out, p, q, q + 64), -1


@njit(cache=True)
def _walk_succinct(out, p, tri, k, data, start_byte, at, level, base):
    """The descent of ``codecs.succinct.lookup`` on the blob at ``start_byte`` of ``data``,
    its reads placed at byte ``base + at`` (the blob's place in the layout); returns the state."""
    p = _span(out, p, 4 * tri, 4 * tri + 4)  # the triangle's byte offset
    reads = 1
    start = 8 * start_byte
    loc = base + at - start_byte  # layout byte of data byte x: loc + x
    w = bit_length((np.int64(1) << (2 * level)) // 3)
    n_t = get_bits(data, start, w) if w > 0 else np.int64(0)
    t0 = start + w
    d0 = t0 + n_t
    s0 = d0 + w * (n_t >> 6)
    if w > 0:  # the header, with the root's T bit
        p = _bits(out, p, loc, start, t0 + (1 if n_t > 0 else 0))
        reads += 1
    pos = np.int64(0)
    for d in range(level):
        if pos >= n_t or (data[(t0 + pos) >> 3] >> ((t0 + pos) & 7)) & 1 == 0:
            break
        pos = 1 + 4 * _rank(data, t0, d0, w, pos) + ((k >> (2 * (level - 1 - d))) & 3)
        # the node's read: its T word up to its bit (its rank's popcount) and the word's directory entry
        q = min(pos, n_t)
        word = q >> 6
        p = _bits(out, p, loc, t0 + (word << 6), t0 + min(pos + 1, n_t))
        if word > 0:
            p = _bits(out, p, loc, d0 + w * (word - 1), d0 + w * word)
        reads += 1
    leaf = pos - _rank(data, t0, d0, w, min(pos, n_t))
    p = _bits(out, p, loc, s0 + 2 * leaf, s0 + 2 * leaf + 2)
    return reads + 1, p, get_bits(data, s0 + 2 * leaf, 2)


@njit(cache=True)
def _rank(data, t0, d0, w, i):
    word = i >> 6
    c = np.int64(0)
    if word > 0:
        c = get_bits(data, d0 + w * (word - 1), w)
    for b in range(word << 6, i):
        c += (data[(t0 + b) >> 3] >> ((t0 + b) & 7)) & 1
    return c


@njit(cache=True)
def _walk_csm(out, p, root, k, data, level):
    """The descent of ``codecs.csm.lookup`` from root ``root`` (the header N is a constant of the
    scene, not a read)."""
    n = get_bits(data, 0, 32)
    w = bit_length(n + 2)
    pos = 32 + w * (4 * n + root)
    p = _bits(out, p, 0, pos, pos + w)
    ref = get_bits(data, pos, w)
    reads = 1
    for d in range(level):
        if ref < 3:
            break
        pos = 32 + w * (4 * (ref - 3) + ((k >> (2 * (level - 1 - d))) & 3))
        p = _bits(out, p, 0, pos, pos + w)
        ref = get_bits(data, pos, w)
        reads += 1
    return reads, p, ref


@njit(cache=True)
def _walk(kind, out, p, tri, b1, b2, i0, i1, i2, data, q0, q1, q2, q3, q4):
    if kind == K_ROWS:
        return _walk_rows(out, p, tri, birdcurve.bary_to_index(b1, b2, q1), q0)
    if kind == K_OMM:
        return _walk_omm(out, p, tri, birdcurve.bary_to_index(b1, b2, q2), i0, i1, q0, q1)
    if kind == K_BLOCK:
        return _walk_block(out, p, tri, b1, b2, i0, i1, i2, q0, q1, q2, q3, q4 > 0)
    if kind == K_SUCCINCT:
        return _walk_succinct(out, p, tri, birdcurve.bary_to_index(b1, b2, q0), data, i1[i0[tri]], i2[tri], q0, q1)
    if kind == K_CSM:
        return _walk_csm(out, p, i0[tri], birdcurve.bary_to_index(b1, b2, q0), data, q0)
    return 0, p, -1


@njit(cache=True)
def _touches(kind, tri, b1, b2, i0, i1, i2, data, q0, q1, q2, q3, q4, reads, starts, states, out):
    p = 0
    for j in range(tri.shape[0]):
        starts[j] = p
        r, p, s = _walk(kind, out, p, tri[j], b1[j], b2[j], i0, i1, i2, data, q0, q1, q2, q3, q4)
        reads[j] = r
        states[j] = s
    starts[tri.shape[0]] = p
    return p


def touches(lay: Layout, lk: Lookups) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per lookup its dependent reads and the lines they touch (lookup j's are
    ``lines[starts[j]:starts[j + 1]]``, in read order, a line once per read that touches it), and
    the state the walk read (-1 where the walk does not decode: raw rows, OMMs and blocks)."""
    empty = np.zeros(1, np.int64)
    ints = list(lay.ints) + [empty] * (3 - len(lay.ints))
    q = (tuple(int(v) for v in lay.params) + (0,) * 5)[:5]
    data = lay.data if lay.data is not None else np.zeros(8, np.uint8)
    data = np.concatenate([np.asarray(data, np.uint8), np.zeros(8, np.uint8)])
    n = len(lk.tri)
    reads = np.zeros(n, np.int64)
    starts = np.zeros(n + 1, np.int64)
    st = np.zeros(n, np.int64)
    args = (lay.kind, lk.tri, lk.b1, lk.b2, ints[0], ints[1], ints[2], data) + q
    total = _touches(*args, reads, starts, st, np.zeros(0, np.int64))
    lines = np.zeros(total, np.int64)
    _touches(*args, reads, starts, st, lines)
    return reads, starts, st, lines


@njit(cache=True)
def _lines_per_pixel(pix_start, starts, lines, out):
    for px in range(pix_start.shape[0] - 1):
        a = starts[pix_start[px]]
        b = starts[pix_start[px + 1]]
        if b > a:
            s = np.sort(lines[a:b])
            c = 1
            for i in range(1, s.shape[0]):
                if s[i] != s[i - 1]:
                    c += 1
            out[px] = c


def lines_per_ray(lk: Lookups, starts: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Distinct lines each pixel's primary ray touches, (h, w)."""
    out = np.zeros(lk.width * lk.height, np.int64)
    _lines_per_pixel(lk.start, starts, lines, out)
    return out.reshape(lk.height, lk.width)


@njit(cache=True)
def _lru(pix_start, starts, lines, w, h, tile, capacity):
    """Misses of an LRU cache of ``capacity`` lines that starts empty at each tile."""
    cache = np.full(max(capacity, 1), -1, np.int64)
    used = np.zeros(max(capacity, 1), np.int64)
    misses = np.int64(0)
    clock = np.int64(0)
    for ty in range(0, h, tile):
        for tx in range(0, w, tile):
            cache[:] = -1
            used[:] = 0
            for y in range(ty, min(ty + tile, h)):
                for x in range(tx, min(tx + tile, w)):
                    px = y * w + x
                    for i in range(starts[pix_start[px]], starts[pix_start[px + 1]]):
                        line = lines[i]
                        clock += 1
                        hit = -1
                        oldest = 0
                        for c in range(capacity):
                            if cache[c] == line:
                                hit = c
                                break
                            if used[c] < used[oldest]:
                                oldest = c
                        if hit < 0:
                            misses += 1
                            if capacity > 0:
                                cache[oldest] = line
                                used[oldest] = clock
                        else:
                            used[hit] = clock
    return misses


def lru_misses(lk: Lookups, starts: np.ndarray, lines: np.ndarray, cache_kib: float, tile: int = TILE) -> int:
    """Misses of a fully associative LRU cache of ``cache_kib`` KiB (64-byte lines) that an
    ``tile`` x ``tile`` tile of pixels shares: empty at each tile, the tile's rays in row-major
    order, each ray's lookups in order, every line each read touches accessed once per read."""
    capacity = int(cache_kib * 1024) // LINE_BYTES
    return int(_lru(lk.start, starts, lines, lk.width, lk.height, tile, capacity))


def measure(lay: Layout, lk: Lookups, cache_kib: float | None = None) -> dict:
    """One layout's figures over a pass's lookups: map bytes, dependent reads per lookup, lines
    per primary ray and (with ``cache_kib``) the tile cache's misses per primary ray."""
    reads, starts, st, lines = touches(lay, lk)
    ok = st >= 0
    if not np.array_equal(st[ok], lk.state[ok].astype(np.int64)):
        raise RuntimeError(f"memory model: the {lay.name} layout's walk read other states than the tracer")
    n_pix = lk.width * lk.height
    out = {"layout": lay.description, "map_bytes": int(lay.map_bytes),
           "map_reads_per_lookup": float(reads.mean()) if len(reads) else 0.0,
           "map_lines_per_ray": float(lines_per_ray(lk, starts, lines).sum()) / n_pix}
    if cache_kib is not None:
        out["cache_misses_per_ray"] = lru_misses(lk, starts, lines, cache_kib) / n_pix
    return out


# ---- the texture side: the lines the alpha tests fetch ----------------------------------------

TEXTURE_LAYOUT = (f"RGBA8 texels ({TEXEL_BYTES} bytes) in {TEX_TILE}x{TEX_TILE} tiles, one 64-byte line per tile, "
                  "tiles row-major, each texture from a line of its own; mip level 0")


@dataclass
class TextureLayout:
    """Where each alpha-tested material's texture lies (``TEXTURE_LAYOUT``): per material (the
    tracer's material index) its texture's first line, width in tiles, size in texels, filter
    code and wrap codes; ``texture_bytes`` the bytes of every distinct texture, tiles padded."""

    first_line: np.ndarray
    tiles_x: np.ndarray
    width: np.ndarray
    height: np.ndarray
    filt: np.ndarray
    wrap_u: np.ndarray
    wrap_v: np.ndarray
    texture_bytes: int
    description: str = TEXTURE_LAYOUT


def texture_layout(base: dict) -> TextureLayout:
    """The alpha textures of the tracer's shared tables (``tables.base_tables``) one after
    another in an address space of their own, in order of material, each distinct texture (its
    place in the texel table and its size) once and only those an alpha triangle's material
    reads: texel (x, y) of a ``w``-wide texture at line ``first + (y div TEX_TILE) * ceil(w /
    TEX_TILE) + x div TEX_TILE``."""
    from .tables import T_MAT_FILTER, T_MAT_H, T_MAT_TEX_START, T_MAT_W, T_MAT_WRAP_U, T_MAT_WRAP_V, T_TRI_MAT

    start, w, h = (np.asarray(base[k], np.int64) for k in (T_MAT_TEX_START, T_MAT_W, T_MAT_H))
    tiles_x = -(-w // TEX_TILE)
    tiles = tiles_x * -(-h // TEX_TILE)
    first = np.zeros(len(start), np.int64)
    seen: dict[tuple, int] = {}
    pos = 0
    for m in np.unique(np.asarray(base[T_TRI_MAT], np.int64)):
        key = (int(start[m]), int(w[m]), int(h[m]))
        if key not in seen:
            seen[key] = pos
            pos += int(tiles[m])
        first[m] = seen[key]
    return TextureLayout(first, tiles_x, w, h, *(np.ascontiguousarray(base[k], np.int64)
                                                  for k in (T_MAT_FILTER, T_MAT_WRAP_U, T_MAT_WRAP_V)),
                         pos * LINE_BYTES)


@njit(cache=True, inline="always")
def _tex_line(first, tiles_x, x, y):
    """The line of texel (x, y) of a texture from line ``first``, ``tiles_x`` tiles wide."""
    return first + (y // TEX_TILE) * tiles_x + x // TEX_TILE


@njit(cache=True)
def _texture_touches(tri, b1, b2, state, mat, uv, first, tiles_x, w, h, filt, wrap_u, wrap_v, starts, out):
    """Per lookup that ends in C (the shader runs) the lines of its taps, four for a linear
    filter (repeats kept), one for nearest; none for a decided lookup."""
    p = 0
    for j in range(tri.shape[0]):
        starts[j] = p
        if state[j] != states.C:
            continue
        t = tri[j]
        m = mat[t]
        x, y = hit_texel(uv, t, b1[j], b2[j], w[m], h[m])
        xa, xb, ya, yb, _, _ = taps(filt[m], wrap_u[m], wrap_v[m], w[m], h[m], x, y)
        out[p] = _tex_line(first[m], tiles_x[m], xa, ya)
        p += 1
        if filt[m] != 0:
            out[p] = _tex_line(first[m], tiles_x[m], xb, ya)
            out[p + 1] = _tex_line(first[m], tiles_x[m], xa, yb)
            out[p + 2] = _tex_line(first[m], tiles_x[m], xb, yb)
            p += 3
    starts[tri.shape[0]] = p
    return p


def texture_touches(tex: TextureLayout, base: dict, lk: Lookups) -> tuple[np.ndarray, np.ndarray]:
    """Per lookup the texture lines its alpha test fetches (lookup j's are
    ``lines[starts[j]:starts[j + 1]]``; none where the map decided the hit): (starts, lines)."""
    from .tables import T_TRI_MAT, T_TRI_UV

    n = len(lk.tri)
    starts = np.zeros(n + 1, np.int64)
    out = np.zeros(4 * n, np.int64)
    mat = np.ascontiguousarray(base[T_TRI_MAT], np.int64)
    uv = np.ascontiguousarray(base[T_TRI_UV], np.float64).ravel()
    k = _texture_touches(lk.tri, lk.b1, lk.b2, np.ascontiguousarray(lk.state, np.uint8), mat, uv, tex.first_line,
                         tex.tiles_x, tex.width, tex.height, tex.filt, tex.wrap_u, tex.wrap_v, starts, out)
    return starts, out[:k]


def texture_lines_per_ray(tex: TextureLayout, base: dict, lk: Lookups) -> float:
    """Distinct texture lines the alpha tests of a primary ray fetch, mean over every pixel of
    the pass (a ray without an alpha test counts 0)."""
    starts, lines = texture_touches(tex, base, lk)
    return float(lines_per_ray(lk, starts, lines).sum()) / (lk.width * lk.height)


def scheme_memory(prep, name: str, run, cam: np.ndarray, w: int, h: int, cache_kib: float | None = None,
                  tex: TextureLayout | None = None) -> dict | None:
    """``trace --memory``'s figures of one traced scheme (``run``: its ``SchemeRun``): lookups per
    primary ray, the texture lines its alpha tests fetch per primary ray and, per layout
    (``own``, ``shared``), ``measure``'s with ``total_lines_per_ray`` (map lines plus texture
    lines). None for a kind not modelled. RuntimeError if the recording run differs from the
    traced one. ``tex``: the scene's ``texture_layout`` (made here when not given; a caller
    measuring several schemes of one scene makes it once)."""
    sm = prep.maps[name]
    lays = layouts(sm, prep.alpha)
    if not lays:
        return None
    lk, rec = record_lookups(prep, name, cam, w, h, run.primary.calls)
    if not (np.array_equal(rec.tests, run.primary.tests) and np.array_equal(rec.prim, run.primary.prim)):
        raise RuntimeError(f"memory model: scheme {name}'s recording run differs from its traced run")
    tex = texture_layout(prep.base) if tex is None else tex
    tex_lines = texture_lines_per_ray(tex, prep.base, lk)
    out = {"lookups_per_primary_ray": lk.count / (w * h), "tile_pixels": TILE if cache_kib is not None else None,
           "cache_kib": cache_kib, "texture_layout": tex.description, "texture_bytes": tex.texture_bytes,
           "texture_lines_per_ray": tex_lines}
    for key, lay in lays.items():
        out[key] = measure(lay, lk, cache_kib)
        out[key]["total_lines_per_ray"] = out[key]["map_lines_per_ray"] + tex_lines
    return out
