"""What a traced scheme measured: alpha tests, candidates and rays per ray, and whether it saw
exactly what ``none`` saw (differing pixels and shadow rays)."""

from __future__ import annotations

import numpy as np
from ..checks import typed

__all__ = ["differing_pixels", "summary", "coverage_error"]


@typed
def differing_pixels(a: PrimaryResult, b: PrimaryResult) -> int:
    """Pixels whose visible result differs: hit instance, geometry, triangle or distance."""
    d = (a.inst != b.inst) | (a.geom != b.geom) | (a.prim != b.prim) | (a.dist != b.dist)
    return int(np.count_nonzero(d))


@typed
def summary(run: SchemeRun, ref: SchemeRun, sm, w: int, h: int) -> dict:
    n = w * h
    p = run.primary
    out = {
        "alpha_tests_per_primary_ray": float(p.tests.sum()) / n,
        "candidates_per_primary_ray": float(p.candidates.sum()) / n,
        "filter_calls_per_primary_ray": float(p.calls.sum()) / n,
        "differing_pixels": differing_pixels(p, ref.primary),
        "primary_rays_per_second": n / p.seconds if p.seconds > 0 else None,
        "candidate_set_overflows": p.set_full,  # candidates met with a full set (counted as new)
    }
    rays, secs = n, p.seconds
    if run.shadow is not None:
        s = run.shadow
        out["alpha_tests_per_shadow_ray"] = float(s.tests.sum()) / max(s.rays, 1)
        out["candidates_per_shadow_ray"] = float(s.candidates.sum()) / max(s.rays, 1)
        out["differing_shadow_rays"] = int(np.count_nonzero(s.occluded != ref.shadow.occluded))
        out["shadow_rays_per_second"] = s.rays / s.seconds if s.seconds > 0 else None
        rays += s.rays
        secs += s.seconds
    if run.deferred is not None:
        d = run.deferred
        normal = float(run.shadow.tests.sum())
        out["deferred_alpha_tests_per_shadow_ray"] = float(d.tests.sum()) / max(d.rays, 1)
        out["deferred_tests_saved"] = int(normal - d.tests.sum())
        out["deferred_tests_saved_fraction"] = (normal - float(d.tests.sum())) / normal if normal else 0.0
        out["deferred_differing_shadow_rays"] = int(np.count_nonzero(d.occluded != run.shadow.occluded))
        out["deferred_record_overflows"] = d.overflow
    out["rays_per_second"] = rays / secs if secs > 0 else None
    if sm is not None:
        out["map_bytes"] = int(sm.map_bytes)
        out["distinct_maps"] = int(sm.distinct_maps)
        out["known_fraction"] = sm.known_fraction
        out.update(sm.info)
    return out


@typed
def coverage_error(run: SchemeRun, ref: SchemeRun) -> dict:
    """Per-pixel visibility error of a 2-state run against the alpha-tested reference: pixels
    whose hit differs, split into those where the 2-state ray stopped earlier (a transparent
    region taken as opaque) and later (an opaque region taken as transparent)."""
    a, b = run.primary, ref.primary
    n = a.dist.size
    differ = (a.inst != b.inst) | (a.geom != b.geom) | (a.prim != b.prim) | (a.dist != b.dist)
    early = differ & (a.dist < b.dist)
    late = differ & (a.dist > b.dist)
    return {"differing_pixels": int(differ.sum()), "differing_fraction": float(differ.sum()) / n,
            "stopped_early_fraction": float(early.sum()) / n, "passed_through_fraction": float(late.sum()) / n,
            "alpha_tests_per_primary_ray": float(a.tests.sum()) / n}
