"""Where a camera's view of a scene falls on its alpha-tested triangles: the ``view`` weights of
the byte budgets (``omaps trace --schemes budget:BYTES --weights view`` and ``omaps omm --budget
BYTES --weights view``), one computation for both.

A counting trace of the view (the tracer's ray loop with a filter that counts every candidate
hit and records its micro-triangle, ``trace.lookups.counting_state``) gives each alpha triangle
its expected candidate hits; ``VIEW_PRIOR`` of them is spread by world area so a triangle the
coarse view misses still counts (``budget.triangle_weights``).
"""

from __future__ import annotations

import numpy as np

from ..budget import HIT_LEVEL, triangle_weights

__all__ = ["view_samples", "view_prior", "view_weights", "scene_view_samples", "VIEW_PRIOR", "HITS_PER_RAY"]

VIEW_PRIOR = 0.05  # share of the view weights spread by area: pairs the coarse view misses still count
HITS_PER_RAY = 16  # candidate hits per ray recorded by view_samples (beyond that, counts only)


def view_samples(prep, cam: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Per alpha triangle its candidate hits in a trace of the camera's view at half the
    resolution (one thread, every candidate counted, no map), and where they fell: (H, 2) int64
    rows (alpha triangle, micro-triangle index at ``budget.HIT_LEVEL``), or None when there were
    more than ``HITS_PER_RAY`` per ray."""
    import numba

    from .maps import SchemeMaps
    from .prepare import trace_scheme
    from .tables import T_COUNT

    at = prep.alpha
    n = at.count
    hw, hh = max(1, w // 2), max(1, h // 2)
    cap = HITS_PER_RAY * hw * hh
    words = np.zeros(3 + n + cap, np.int64)
    words[0], words[1] = n, cap
    sm = SchemeMaps("count", "count", 0, np.zeros(n, np.int32), np.zeros(1, np.uint8), 1, 0, 0, 0.0,
                    extra={T_COUNT: words})
    key = "\0count"
    prep.maps[key] = sm
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        trace_scheme(prep, key, cam, hw, hh)
    finally:
        numba.set_num_threads(threads)
        del prep.maps[key]
    counts = words[3:3 + n].copy()
    k = int(words[2])
    if k > cap:
        return counts, None
    keys = words[3 + n:3 + n + k]
    return counts, np.stack([keys >> (2 * HIT_LEVEL), keys & ((1 << (2 * HIT_LEVEL)) - 1)], axis=1)


def view_prior(counts: np.ndarray, area: np.ndarray) -> np.ndarray:
    """``VIEW_PRIOR`` of the view's candidate hits spread by world area (per alpha triangle), so
    that a triangle the coarse view misses is not left without value."""
    total = float(counts.sum())
    if total == 0 or area.sum() == 0:
        return area if total == 0 else np.zeros(len(area))
    return VIEW_PRIOR * total * area / area.sum()


def view_weights(prep, cam: np.ndarray, w: int, h: int) -> np.ndarray:
    """Per alpha triangle, its candidate hits in a trace of the camera's view at half the
    resolution (``view_samples``) plus ``view_prior``."""
    counts, _ = view_samples(prep, cam, w, h)
    return counts + view_prior(counts.astype(np.float64), triangle_weights(prep.scene, prep.alpha))


def scene_view_samples(scene, rules, w: int, h: int, camera=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """A scene's view weights for ``omaps omm --budget --weights view``: per alpha triangle the
    weight spread by area (``view_prior``; all of the counts when the hits were too many to
    record), the recorded hits (``view_samples``) and the camera's description. ``camera``: a
    ``trace.Camera``; default: the tracer's default camera for a ``w`` x ``h`` image."""
    from ..schemes import parse_schemes
    from .camera import choose_default_camera
    from .prepare import prepare

    prep = prepare(scene, parse_schemes("none"), rules)
    if camera is None:
        camera, info = choose_default_camera(prep, w, h)
    else:
        info = {"chosen": "given"}
    counts, hits = view_samples(prep, camera.basis(w, h), w, h)
    prior = view_prior(counts.astype(np.float64), triangle_weights(scene, prep.alpha))
    if hits is None:
        return counts + prior, np.zeros((0, 2), np.int64), info
    return prior, hits, info
