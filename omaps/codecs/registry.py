"""Codecs by name: block size, map size, encode (map -> bytes) and decode (bytes -> map)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import InputError


@dataclass(frozen=True)
class Codec:
    name: str
    map_size: int  # the codec stores an N x N square map
    block_bytes: int
    encoders: tuple[str, ...]
    efforts: tuple[str, ...]
    encode: Callable[..., bytes]  # (map, encoder, effort) -> physical block(s)
    decode: Callable[[bytes], np.ndarray]  # physical block(s) -> map
    # numba @njit (data: uint8[block_bytes], x, y) -> state of cell (x, y), reading only the bits it
    # needs; callable from other numba code (the tracer's any-hit filter)
    lookup: Callable


def _vq2() -> Codec:
    from . import vq2_block, vq2_encode

    def enc(m, encoder="best", effort="medium"):
        return vq2_encode.encode(m, encoder, effort).pack()

    return Codec("vq2", vq2_block.SIZE, vq2_block.BLOCK_BYTES, vq2_encode.ENCODERS, tuple(vq2_encode.EFFORTS),
                 enc, vq2_block.decode, vq2_block.lookup)


def _vq4() -> Codec:
    from . import vq4_block, vq4_encode

    def enc(m, encoder="best", effort="medium"):
        return vq4_encode.encode(m, encoder, effort).pack()

    return Codec("vq4", vq4_block.SIZE, vq4_block.BLOCK_BYTES, vq4_encode.ENCODERS, tuple(vq4_encode.EFFORTS),
                 enc, vq4_block.decode, vq4_block.lookup)


def _vq4x64() -> Codec:
    from . import vq4_block, vq4_encode

    return Codec("vq4x64", vq4_block.X64_SIZE, vq4_block.X64_BYTES, vq4_encode.ENCODERS,
                 tuple(vq4_encode.EFFORTS), vq4_encode.encode_x64, vq4_block.decode_x64, vq4_block.lookup_x64)


_FACTORIES: dict[str, Callable[[], Codec]] = {"vq2": _vq2, "vq4": _vq4, "vq4x64": _vq4x64}


def codec_names() -> list[str]:
    return list(_FACTORIES)


def get_codec(name: str) -> Codec:
    try:
        return _FACTORIES[name]()
    except KeyError:
        raise InputError(f"unknown codec {name!r} (choose from {', '.join(_FACTORIES)})") from None
