"""``EXT_meshopt_compression``: the extension's three bitstreams and three filters, decoded as its
specification (Appendix A and B) states them.

A compressed bufferView names, in its extension object, a byte range of another buffer, a
``mode`` (``ATTRIBUTES``, ``TRIANGLES`` or ``INDICES``), a ``filter`` (``NONE``, ``OCTAHEDRAL``,
``QUATERNION``, ``EXPONENTIAL``), the element size ``byteStride`` and the element ``count``.
``decode_view`` turns that range into the ``count * byteStride`` bytes of the bufferView, which
accessors then read as any other view's. The kernels read only inside the bytes they are given,
and a stream that does not decode exactly as the specification says (a wrong header byte, data
that ends early or holds bytes no element used, a vertex FIFO entry read before anything was
written there, an index wider than its element) is a ``MeshoptError`` naming what is wrong: the
scene reader turns it into an ``InputError`` naming the file and the bufferView. Nothing here is
a guess: a stream omaps cannot read exactly is refused.

Only the extension's own bitstream versions are read: attributes ``0xa0``, triangles ``0xe1``,
indices ``0xd1`` (the later attribute codec ``0xa1`` belongs to ``KHR_meshopt_compression``).

Example::

    >>> import numpy as np
    >>> from omaps.scene.meshopt import decode_indices
    >>> stream = bytes([0xd1, 0x00, 0x04, 0x04]) + bytes(4)  # 0, then +1, then +1 from baseline 0
    >>> decode_indices(stream, 3, 4).tolist()
    [0, 1, 2]
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["MeshoptError", "MODES", "FILTERS", "decode_attributes", "decode_triangles", "decode_indices",
           "apply_filter", "decode_view"]

MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL")
_ATTRIBUTES_HEADER, _TRIANGLES_HEADER, _INDICES_HEADER = 0xA0, 0xE1, 0xD1
_TAIL_MIN = 32  # an attribute stream's tail: its baseline element, padded to 32 bytes
_GROUP = 16  # elements per delta group

# kernel status codes -> what is wrong with the stream
_OK, _SHORT, _EXTRA, _FIFO, _WIDE, _AUX = 0, 1, 2, 3, 4, 5
_PROBLEMS = {
    _SHORT: "its data ends before its last element",
    _EXTRA: "it holds bytes after its last element that no element used",
    _FIFO: "it reads a FIFO entry that no earlier triangle wrote",
    _WIDE: "it decodes an index that does not fit its {size}-byte elements",
    _AUX: "its 16-byte code table is malformed (its last two bytes must be 0)",
}


class MeshoptError(ValueError):
    """A meshopt stream that does not decode as the specification says (the message says why)."""


# -- attributes (mode 0) --------------------------------------------------------------------------

@njit(cache=True)
def _unzigzag8(v):
    return (v >> 1) ^ (-(v & 1) & 0xFF)


@njit(cache=True)
def _attributes_kernel(data, count, stride, out):
    """Decode an attribute stream (header checked by the caller) into ``out`` (count * stride
    bytes). Returns a status code."""
    end = len(data)
    tail = stride if stride > _TAIL_MIN else _TAIL_MIN
    if end - 1 < tail:
        return _SHORT
    last = np.empty(stride, np.uint8)
    for k in range(stride):
        last[k] = data[end - stride + k]
    limit = end - tail  # the blocks end where the tail begins
    block_max = (8192 // stride) & ~15
    if block_max > 256:
        block_max = 256
    deltas = np.empty(256, np.uint8)
    pos = 1
    first = 0
    while first < count:
        n = count - first
        if n > block_max:
            n = block_max
        groups = (n + _GROUP - 1) // _GROUP
        header_bytes = (groups + 3) // 4
        for k in range(stride):
            if pos + header_bytes > limit:
                return _SHORT
            head = pos
            pos += header_bytes
            for g in range(groups):
                mode = (data[head + g // 4] >> ((g % 4) * 2)) & 3
                base = g * _GROUP
                if mode == 0:
                    for j in range(_GROUP):
                        deltas[base + j] = 0
                elif mode == 3:
                    if pos + _GROUP > limit:
                        return _SHORT
                    for j in range(_GROUP):
                        deltas[base + j] = data[pos + j]
                    pos += _GROUP
                else:
                    bits = 2 if mode == 1 else 4
                    packed = _GROUP * bits // 8
                    sentinel = (1 << bits) - 1
                    if pos + packed > limit:
                        return _SHORT
                    extra = pos + packed
                    per_byte = 8 // bits
                    for j in range(_GROUP):
                        shift = 8 - bits * (j % per_byte + 1)
                        v = (data[pos + j // per_byte] >> shift) & sentinel
                        if v == sentinel:
                            if extra >= limit:
                                return _SHORT
                            v = data[extra]
                            extra += 1
                        deltas[base + j] = v
                    pos = extra
            p = last[k]
            for i in range(n):
                p = (p + _unzigzag8(deltas[i])) & 0xFF
                out[(first + i) * stride + k] = p
            last[k] = p
        first += n
    if pos != limit:
        return _EXTRA
    return _OK


# -- triangles (mode 1) and indices (mode 2) ------------------------------------------------------

@njit(cache=True)
def _varint(data, pos, limit):
    """(value, next position), or (0, -1) when the bytes end first or it runs past 32 bits."""
    v = np.int64(0)
    shift = 0
    while True:
        if pos >= limit or shift > 28:
            return np.int64(0), -1
        b = data[pos]
        pos += 1
        v |= np.int64(b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            break
    if v > 0xFFFFFFFF:
        return np.int64(0), -1
    return v, pos


@njit(cache=True)
def _unzigzag32(v):
    return (v >> 1) ^ (-(v & 1) & 0xFFFFFFFF)


@njit(cache=True, inline="always")
def _push(edges, at, x, y):
    """Push the edge (x, y) on the edge FIFO at ``at``; returns the next position."""
    edges[at, 0] = x
    edges[at, 1] = y
    return (at + 1) & 15


@njit(cache=True, inline="always")
def _corner(f, explicit, data, pos, limit, nxt, last, verts, vert_at):
    """The index a 4-bit code ``f`` gives a triangle's corner: ``nxt`` (0: a new vertex), vertex
    FIFO entry f - 1 (1..14), or, where ``explicit``, a varint delta from ``last`` (15).
    Returns (index, pos, nxt, last, status)."""
    if f == 0:
        return nxt, pos, nxt + 1, last, _OK
    if f < 15:
        v = verts[(vert_at - f) & 15]
        return v, pos, nxt, last, (_FIFO if v < 0 else _OK)
    if not explicit:
        return np.int64(0), pos, nxt, last, _AUX
    d, pos = _varint(data, pos, limit)
    if pos < 0:
        return np.int64(0), pos, nxt, last, _SHORT
    v = (last + _unzigzag32(d)) & 0xFFFFFFFF
    return v, pos, nxt, v, _OK


@njit(cache=True)
def _triangles_kernel(data, count, wide_max, out):
    """Decode a triangle stream (header checked by the caller) into ``out`` (count uint32).
    ``wide_max``: the largest index an element can hold. Returns a status code."""
    end = len(data)
    ntri = count // 3
    if end < 1 + ntri + 16:
        return _SHORT
    aux = end - 16
    if data[aux + 14] != 0 or data[aux + 15] != 0:
        return _AUX
    edges = np.full((16, 2), -1, np.int64)
    verts = np.full(16, -1, np.int64)
    edge_at = 0
    vert_at = 0
    nxt = np.int64(0)
    last = np.int64(0)
    codes = 1
    pos = 1 + ntri  # the extra data follows the codes
    for t in range(ntri):
        code = data[codes + t]
        hi = code >> 4
        lo = code & 15
        if hi < 15:
            e = (edge_at - 1 - hi) & 15
            a = edges[e, 0]
            b = edges[e, 1]
            if a < 0:
                return _FIFO
            if lo == 0:
                c = nxt
                nxt += 1
                verts[vert_at] = c
                vert_at = (vert_at + 1) & 15
            elif lo < 13:
                c = verts[(vert_at - 1 - lo) & 15]
                if c < 0:
                    return _FIFO
            elif lo < 15:
                c = (last + (-1 if lo == 13 else 1)) & 0xFFFFFFFF
                last = c
                verts[vert_at] = c
                vert_at = (vert_at + 1) & 15
            else:
                c, pos, nxt, last, status = _corner(15, True, data, pos, aux, nxt, last, verts, vert_at)
                if status != _OK:
                    return status
                verts[vert_at] = c
                vert_at = (vert_at + 1) & 15
            edge_at = _push(edges, edge_at, c, b)
            edge_at = _push(edges, edge_at, a, c)
        else:  # three indices: from the code table (0xfY) or from a data byte (0xfe, 0xff)
            explicit = lo >= 14
            b = c = np.int64(0)
            if explicit:
                if pos >= aux:
                    return _SHORT
                zw = data[pos]
                pos += 1
                if zw == 0:
                    nxt = 0
            else:
                zw = data[aux + lo]
            z = zw >> 4
            w = zw & 15
            a, pos, nxt, last, status = _corner(15 if lo == 15 else 0, True, data, pos, aux, nxt, last, verts, vert_at)
            if status == _OK:
                b, pos, nxt, last, status = _corner(z, explicit, data, pos, aux, nxt, last, verts, vert_at)
            if status == _OK:
                c, pos, nxt, last, status = _corner(w, explicit, data, pos, aux, nxt, last, verts, vert_at)
            if status != _OK:
                return status
            push_b = z == 0 or z == 15
            push_c = w == 0 or w == 15
            # the FIFO reads above use the state before this triangle's pushes
            edge_at = _push(edges, edge_at, b, a)
            edge_at = _push(edges, edge_at, c, b)
            edge_at = _push(edges, edge_at, a, c)
            verts[vert_at] = a
            vert_at = (vert_at + 1) & 15
            if push_b:
                verts[vert_at] = b
                vert_at = (vert_at + 1) & 15
            if push_c:
                verts[vert_at] = c
                vert_at = (vert_at + 1) & 15
        nxt &= 0xFFFFFFFF
        if a > wide_max or b > wide_max or c > wide_max:
            return _WIDE
        out[3 * t] = a
        out[3 * t + 1] = b
        out[3 * t + 2] = c
    if pos != aux:
        return _EXTRA
    return _OK


@njit(cache=True)
def _indices_kernel(data, count, wide_max, out):
    """Decode an index sequence (header checked by the caller) into ``out`` (count uint32)."""
    end = len(data)
    if end < 1 + count + 4:
        return _SHORT
    limit = end - 4
    last = np.zeros(2, np.int64)
    pos = 1
    for i in range(count):
        v, pos = _varint(data, pos, limit)
        if pos < 0:
            return _SHORT
        k = v & 1
        d = v >> 1
        if d & 1:
            delta = -(d >> 1) - 1
        else:
            delta = d >> 1
        last[k] = (last[k] + delta) & 0xFFFFFFFF
        if last[k] > wide_max:
            return _WIDE
        out[i] = last[k]
    if pos != limit:
        return _EXTRA
    return _OK


def _stream(data) -> np.ndarray:
    return np.frombuffer(bytes(data), np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8)


def _fail(status: int, **fmt) -> None:
    if status != _OK:
        raise MeshoptError(_PROBLEMS[status].format(**fmt))


def _header(raw: np.ndarray, expected: int, what: str) -> None:
    if len(raw) == 0:
        raise MeshoptError(f"its {what} stream is empty")
    if raw[0] != expected:
        if what == "attribute" and raw[0] == 0xA1:
            raise MeshoptError("its attribute stream is version 1 (header 0xa1, KHR_meshopt_compression's codec); "
                               "EXT_meshopt_compression streams are version 0 (0xa0)")
        raise MeshoptError(f"its {what} stream starts with 0x{int(raw[0]):02x}, not 0x{expected:02x}")


def decode_attributes(data, count: int, stride: int) -> np.ndarray:
    """Decode a mode 0 (``ATTRIBUTES``) stream: ``count`` elements of ``stride`` bytes.

    Parameters
    ----------
    data : bytes or uint8 array
        The stream: header byte ``0xa0``, its blocks, then its tail (the baseline element,
        padded to 32 bytes), exactly.
    count : int
        The number of elements.
    stride : int
        Bytes per element: a multiple of 4, at most 256.

    Returns
    -------
    numpy.ndarray
        uint8, shape ``(count * stride,)``.

    Raises
    ------
    MeshoptError
        When the stream does not decode exactly (the message says why).
    """
    if stride <= 0 or stride % 4 or stride > 256:
        raise MeshoptError(f"byteStride {stride} is not a multiple of 4 up to 256, as ATTRIBUTES needs")
    raw = _stream(data)
    _header(raw, _ATTRIBUTES_HEADER, "attribute")
    out = np.zeros(count * stride, np.uint8)
    _fail(_attributes_kernel(raw, count, stride, out))
    return out


def decode_triangles(data, count: int, size: int) -> np.ndarray:
    """Decode a mode 1 (``TRIANGLES``) stream: ``count`` indices (a multiple of 3) of ``size``
    bytes (2 or 4), as uint32 ``(count,)``. Raises ``MeshoptError`` when it does not decode
    exactly."""
    if count % 3:
        raise MeshoptError(f"count {count} is not a multiple of 3, as TRIANGLES needs")
    return _decode_index_stream(_triangles_kernel, data, count, size, "TRIANGLES", _TRIANGLES_HEADER, "triangle")


def decode_indices(data, count: int, size: int) -> np.ndarray:
    """Decode a mode 2 (``INDICES``) stream: ``count`` indices of ``size`` bytes (2 or 4), as
    uint32 ``(count,)``. Raises ``MeshoptError`` when it does not decode exactly."""
    return _decode_index_stream(_indices_kernel, data, count, size, "INDICES", _INDICES_HEADER, "index")


def _decode_index_stream(kernel, data, count: int, size: int, mode: str, header: int, what: str) -> np.ndarray:
    """An index stream of ``mode`` decoded by ``kernel`` into ``count`` uint32, each at most
    ``size`` bytes wide."""
    if size not in (2, 4):
        raise MeshoptError(f"byteStride {size} is not 2 or 4, as {mode} needs")
    raw = _stream(data)
    _header(raw, header, what)
    out = np.zeros(count, np.uint32)
    _fail(kernel(raw, count, (1 << (8 * size)) - 1, out), size=size)
    return out


# -- filters (Appendix B) -------------------------------------------------------------------------

def _round(x: np.ndarray) -> np.ndarray:
    """C's ``round``: halves away from zero."""
    return np.trunc(x + np.copysign(np.float32(0.5), x))


def _check_filter(name: str, stride: int) -> None:
    need = {"OCTAHEDRAL": ((4, 8), "4 or 8"), "QUATERNION": ((8,), "8")}
    if name in need and stride not in need[name][0]:
        raise MeshoptError(f"byteStride {stride} is not {need[name][1]}, as {name} needs")
    if name == "EXPONENTIAL" and stride % 4:
        raise MeshoptError(f"byteStride {stride} is not a multiple of 4, as EXPONENTIAL needs")


def apply_filter(raw: np.ndarray, count: int, stride: int, name: str) -> np.ndarray:
    """The decoded bytes of ``count`` elements of ``stride`` bytes with filter ``name`` applied
    (a new uint8 array; ``NONE`` returns ``raw``). Raises ``MeshoptError`` when the stride does
    not fit the filter."""
    if name == "NONE":
        return raw
    if name not in FILTERS:
        raise MeshoptError(f"filter {name!r} is not one of {', '.join(FILTERS)}")
    _check_filter(name, stride)
    f32 = np.float32
    if name == "OCTAHEDRAL":
        it = np.int8 if stride == 4 else np.int16
        imax = f32(np.iinfo(it).max)
        v = raw.view(np.dtype(it).newbyteorder("<")).reshape(count, 4)
        one = v[:, 2].astype(f32)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = v[:, 0].astype(f32) / one
            y = v[:, 1].astype(f32) / one
            z = f32(1) - np.abs(x) - np.abs(y)
            t = np.minimum(z, f32(0))
            x = x - np.copysign(t, x)
            y = y - np.copysign(t, y)
            n = np.sqrt(x * x + y * y + z * z)
            xyz = np.stack([x / n, y / n, z / n], axis=1) * imax
        out = np.empty((count, 4), it)
        out[:, :3] = np.clip(np.nan_to_num(_round(xyz)), -imax, imax).astype(it)
        out[:, 3] = v[:, 3]
        return out.astype(np.dtype(it).newbyteorder("<")).view(np.uint8).ravel()
    if name == "QUATERNION":
        v = raw.view(np.dtype(np.int16).newbyteorder("<")).reshape(count, 4).astype(np.int32)
        one = (v[:, 3] | 3).astype(f32)
        scale = f32(1.0 / np.sqrt(2.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            xyz = v[:, :3].astype(f32) / one[:, None] * scale
        w = np.sqrt(np.maximum(f32(0), f32(1) - (xyz * xyz).sum(axis=1, dtype=f32)))
        comp = v[:, 3] & 3
        q = np.empty((count, 4), f32)
        rows = np.arange(count)
        for k in range(3):
            q[rows, (comp + 1 + k) % 4] = xyz[:, k]
        q[rows, comp] = w
        out = np.clip(np.nan_to_num(_round(q * f32(32767))), -32767, 32767).astype("<i2")
        return out.view(np.uint8).ravel()
    v = raw.view(np.dtype(np.int32).newbyteorder("<")).astype(np.int64)  # EXPONENTIAL
    e = v >> 24
    m = ((v & 0xFFFFFF) ^ 0x800000) - 0x800000
    with np.errstate(over="ignore"):
        out = np.ldexp(m.astype(np.float64), e).astype("<f4")
    return out.view(np.uint8).ravel()


def decode_view(data, ext: dict, parent_length: int, parent_stride: int | None) -> tuple[np.ndarray, int]:
    """A compressed bufferView's bytes: ``data`` is the byte range its extension object ``ext``
    names; ``parent_length`` and ``parent_stride`` are the bufferView's own ``byteLength`` and
    ``byteStride`` (None when absent). Returns (uint8 bytes of ``parent_length``, the element
    stride). Raises ``MeshoptError`` when the object breaks the extension's rules or its stream
    does not decode."""
    mode, filt = ext.get("mode"), ext.get("filter", "NONE")
    count, stride = ext.get("count"), ext.get("byteStride")
    for name, value in (("count", count), ("byteStride", stride)):
        if isinstance(value, bool) or not isinstance(value, int) or value < (0 if name == "count" else 1):
            raise MeshoptError(f"{name} is {value!r}, not a {'count' if name == 'count' else 'positive integer'}")
    if mode not in MODES:
        raise MeshoptError(f"mode is {mode!r}, not one of {', '.join(MODES)}")
    if filt not in FILTERS:
        raise MeshoptError(f"filter is {filt!r}, not one of {', '.join(FILTERS)}")
    if parent_stride is not None and parent_stride != stride:
        raise MeshoptError(f"its byteStride {stride} differs from the bufferView's {parent_stride}")
    if parent_length != stride * count:
        raise MeshoptError(f"the bufferView's byteLength {parent_length} is not byteStride {stride} x count {count}")
    if mode != "ATTRIBUTES" and filt != "NONE":
        raise MeshoptError(f"filter {filt} is only allowed with mode ATTRIBUTES")
    _check_filter(filt, stride)
    if mode == "ATTRIBUTES":
        out = decode_attributes(data, count, stride)
        return apply_filter(out, count, stride, filt), stride
    decode = decode_triangles if mode == "TRIANGLES" else decode_indices
    idx = decode(data, count, stride)
    return idx.astype("<u2" if stride == 2 else "<u4").view(np.uint8), stride
