"""A byte budget for a whole scene: the options a pair may store under a budget (``PAIR_OPTIONS``,
from the codec registry) and their bytes, byte counts as users write them, the weights of
triangles (expected candidate hits), and the known fraction of each half of a pair's map. The
allocation itself is ``omaps.allocate``.

Example::

    >>> from omaps.budget import PAIR_OPTIONS, parse_bytes
    >>> PAIR_OPTIONS[:3], parse_bytes("1.5KiB")
    (('none', 'sq1', 'sq2'), 1536)
"""

from __future__ import annotations

import re

import numpy as np

from . import states
from .errors import InputError

from .allocate import allocate, allocate_arrays, upper_hull  # noqa: F401 - the budget's allocator, re-exported
from .codecs.registry import budget_options

__all__ = ["HIT_LEVEL", "parse_bytes", "triangle_weights", "half_known", "PAIR_OPTIONS", "pair_option_bytes",
           "allocate"]

# What a pair may store under a budget by default: no map (all C), a raw N x N square up to 64, or a
# block of a codec the registry marks as a default budget option (``CodecEntry.budget_default``);
# the tracer reads each by its codec's format code. ``budget:BYTES:OPTS`` names others.
PAIR_OPTIONS = ("none",) + budget_options(default=True)

# Where a view's candidate hits are recorded (``view.view_samples``): the micro-triangle
# at this subdivision level, so that a budget can value any coarser level by the hits it knows.
HIT_LEVEL = 8

_UNITS = {"": 1, "b": 1, "kib": 1024, "mib": 1024 ** 2, "gib": 1024 ** 3, "kb": 1000, "mb": 1000 ** 2,
          "gb": 1000 ** 3}


def parse_bytes(text: str) -> int:
    """A byte count as written by a user: 1263936, 1.2MiB, 800KiB, 2MB (binary and decimal units)."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([a-zA-Z]*)\s*", str(text))
    unit = m.group(2).lower() if m else None
    if m is None or unit not in _UNITS:
        raise InputError(f"a byte budget must be a number with an optional unit (B, KiB, MiB, GiB, KB, MB, GB), "
                         f"got {text!r}")
    return int(float(m.group(1)) * _UNITS[unit])


def pair_option_bytes(options=PAIR_OPTIONS) -> np.ndarray:
    """Bytes each pair option stores (int64 (K,)): 0 for none, the codec's block otherwise."""
    from .codecs import get_codec

    return np.array([0 if o == "none" else get_codec(o).block_bytes for o in options], np.int64)


def triangle_weights(scene, at) -> np.ndarray:
    """Expected candidate hits of every alpha triangle (rows of ``scene.alpha.AlphaTriangles``)
    for rays spread uniformly over the scene: its world-space area summed over the instances of
    its prototype. A triangle with non-finite positions weighs 0."""
    w = np.zeros(at.count)
    for mi, m in scene.instances:
        a, b = int(at.base[mi]), int(at.base[mi + 1])
        if b == a:
            continue
        mg = scene.meshes[mi].merged
        tri = mg["triangles"][at.mesh_tri[a:b]]
        p = np.asarray(mg["positions"], np.float64) @ np.asarray(m, np.float64)[:3, :3].T  # translation: no area
        area = 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1)
        w[a:b] += np.nan_to_num(area, nan=0.0, posinf=0.0)
    return w


def half_known(maps) -> np.ndarray:
    """Known (T or O) fraction of each half of square maps (P, N, N): column 0 triangle A (v <=
    u, cells below the diagonal), column 1 triangle B; a diagonal cell counts half to each, so
    each half's cells weigh N*N/2 in all -- the share of its triangle's area they cover."""
    m = np.asarray(maps)
    n = m.shape[-1]
    i = np.arange(n)
    wa = (i[None, :] > i[:, None]) + 0.5 * (i[None, :] == i[:, None])  # [j, i]: cell (i, j) in A's half
    known = (m != states.C).reshape(len(m), n * n).astype(np.float64)
    return np.stack([known @ wa.ravel(), known @ wa.T.ravel()], axis=1) / (0.5 * n * n)
