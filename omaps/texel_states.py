"""Texel states: which texels are T, O or C before any map is made.

``levels`` is the deck's corpus rule (T if alpha <= 30, O if alpha >= 225, in 8-bit units).
``cutoff`` is the bakers' rule for alpha-tested materials: opaque iff alpha > cutoff, so every
texel is T or O and uncertainty only comes from regions straddling the cut (or from filtering).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import states
from .errors import InputError
from .texture import AlphaTexture

MODES = ("levels", "cutoff")


@dataclass(frozen=True)
class StateRule:
    """How alpha becomes a texel state. Thresholds of ``levels`` are in 8-bit units (0..255);
    ``cutoff`` is in [0, 1] like glTF's alphaCutoff."""

    mode: str = "levels"
    t_max: float = 30.0
    o_min: float = 225.0
    cutoff: float = 0.5

    def __post_init__(self):
        if self.mode not in MODES:
            raise InputError(f"unknown state mode {self.mode!r} (choose from {', '.join(MODES)})")
        for name in ("t_max", "o_min", "cutoff"):
            if not np.isfinite(getattr(self, name)):
                raise InputError(f"{name} must be finite")
        if self.mode == "levels" and not (0 <= self.t_max < self.o_min <= 255):
            raise InputError(f"levels need 0 <= t_max < o_min <= 255, got {self.t_max}, {self.o_min}")
        if self.mode == "cutoff" and not (0 <= self.cutoff <= 1):
            raise InputError(f"cutoff must be in [0, 1], got {self.cutoff}")

    def classify(self, texture: AlphaTexture) -> np.ndarray:
        """Texel states (uint8 codes of ``omaps.states``), shape (H, W)."""
        a8 = texture.alpha8
        out = np.full(a8.shape, states.C, dtype=np.uint8)
        if self.mode == "levels":
            out[a8 <= self.t_max] = states.T
            out[a8 >= self.o_min] = states.O
        else:
            opaque = a8 > self.cutoff * 255.0
            out[opaque] = states.O
            out[~opaque] = states.T
        return out
