"""The three region states and their one-byte codes: the single place they are defined.

T (transparent) and O (opaque) let traversal skip the any-hit shader; C (check) runs it.
The codes match the first three states of VK_EXT_opacity_micromap's 4-state format
(0 transparent, 1 opaque, 2 unknown-transparent), so a map can be written out as-is.
"""

import numpy as np

T = 0  # transparent: ignore the hit
O = 1  # opaque: accept the hit  # noqa: E741
C = 2  # check: run the any-hit shader

NAMES = "TOC"

# Aggregation works on bit flags: a region's flag is the OR of the flags of everything a hit
# in it can read. Only T -> T, only O -> O, anything else (a C, or T and O together) -> C.
FLAG_T = 1
FLAG_O = 2
FLAG_C = 3

STATE_TO_FLAG = np.array([FLAG_T, FLAG_O, FLAG_C], dtype=np.uint8)
# index by flag; flag 0 (nothing read) never occurs for a non-degenerate region
FLAG_TO_STATE = np.array([C, T, O, C], dtype=np.uint8)

# The deck's colours: T cyan, O magenta, C green (RGB, 8 bit).
COLOURS = np.array([[0, 255, 255], [255, 0, 255], [0, 200, 0]], dtype=np.uint8)


def is_conservative(original: np.ndarray, lossy: np.ndarray) -> bool:
    """True when every change from ``original`` to ``lossy`` is O->C or T->C."""
    original = np.asarray(original)
    lossy = np.asarray(lossy)
    if original.shape != lossy.shape:
        raise ValueError(f"shapes differ: {original.shape} vs {lossy.shape}")
    return bool(np.all((lossy == original) | (lossy == C)))
