"""Argument checks every encoder shares: encoder and effort names, and the maps it is given."""

from __future__ import annotations

import numpy as np

from .. import states

from ..names import EFFORTS, ENCODERS  # noqa: E402,F401 (the deck's compressor and our search; efforts)


def check_options(codec: str, encoder: str, effort: str) -> tuple[int, int]:
    """(encoder number, effort number) for the numba entry points."""
    if encoder not in ENCODERS:
        raise ValueError(f"unknown {codec} encoder {encoder!r} (choose from {', '.join(ENCODERS)})")
    if effort not in EFFORTS:
        raise ValueError(f"unknown effort {effort!r} (choose from {', '.join(EFFORTS)})")
    return ENCODERS.index(encoder), EFFORTS[effort]


def check_maps(m, size: int, codec: str) -> np.ndarray:
    """One or many size x size maps of states, as contiguous uint8."""
    m = np.ascontiguousarray(m, dtype=np.uint8)
    if m.ndim < 2 or m.shape[-2:] != (size, size) or m.max(initial=0) > states.C:
        raise ValueError(f"{codec} encodes {size}x{size} maps of states 0..2, got shape {m.shape}")
    return m
