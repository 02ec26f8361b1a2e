"""A whole run: pair the scene's alpha triangles, bake and store every scheme's maps, build the
Embree scene once; then trace any scheme (``trace_scheme``)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..alpha_test import MaterialRules
from ..scene.alpha import alpha_triangles
from .filter import make_filter
from .lookups import state_function
from .maps import build_scheme_maps
from .rays import PrimaryResult, ShadowResult, run_primary, run_shadow
from .tables import base_tables, scheme_tables
from ..checks import typed

__all__ = ["Prepared", "prepare", "SchemeRun", "trace_scheme"]


@dataclass
class Prepared:
    scene: object
    rules: MaterialRules
    tests: dict  # material -> AlphaTest
    alpha: object  # scene.alpha.AlphaTriangles
    maps: dict  # name -> trace.maps.SchemeMaps
    bvh: object  # embree.InstancedScene
    base: dict
    proto_of_instance: np.ndarray
    opaque_tris: list  # per mesh: merged triangle indices of geometry 0, in primID order
    timings: dict
    device: object = None
    cache: dict = field(default_factory=dict)  # pair flags and encoded maps, for budget schemes (trace.budget)


@typed
def prepare(scene: Scene, schemes: list[Scheme], rules: MaterialRules = MaterialRules(), jobs: int = 1,
            progress: bool = False,
            embree_config: str = "") -> Prepared:
    """Pair, bake and store every scheme's maps (``schemes``: ``omaps.schemes.Scheme`` objects),
    and build the Embree scene.

    Example::

        >>> from omaps.scene import load_scene                                        # doctest: +SKIP
        >>> from omaps.schemes import parse_schemes                                   # doctest: +SKIP
        >>> from omaps.trace import choose_default_camera, prepare, trace_scheme      # doctest: +SKIP
        >>> scene = load_scene("palm.glb")                                             # doctest: +SKIP
        >>> prep = prepare(scene, parse_schemes("none,vq4"))                          # doctest: +SKIP
        >>> cam = choose_default_camera(prep, 256, 256)[0].basis(256, 256)            # doctest: +SKIP
        >>> run = trace_scheme(prep, "vq4", cam, 256, 256)                            # doctest: +SKIP
        >>> run.primary.tests.mean()                                                   # doctest: +SKIP
    """
    from . import embree

    timings = {}
    t0 = time.perf_counter()
    at = alpha_triangles(scene, rules)
    timings["pair_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    tests = {int(m): scene.alpha_test(int(m), rules) for m in np.unique(at.material)}
    cache: dict = {}
    maps_ = build_scheme_maps(at, tests, schemes, jobs, progress, scene, cache)
    timings["bake_encode_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    device = embree.Device(embree_config)
    alpha = scene.alpha_tested(rules)
    protos, opaque_tris = [], []
    for k, mesh in enumerate(scene.meshes):
        mg = mesh.merged
        op = np.flatnonzero(~alpha[mg["material"]])
        opaque_tris.append(op)
        protos.append((mg["positions"], mg["triangles"][op], mg["triangles"][at.mesh_tri[at.base[k]:at.base[k + 1]]]))
    bvh = embree.InstancedScene(device, protos, scene.instances)
    timings["bvh_s"] = time.perf_counter() - t0
    proto_of = np.array([mi for mi, _ in scene.instances], np.int32)
    return Prepared(scene, rules, tests, at, maps_, bvh, base_tables(tests, len(scene.materials), at, proto_of),
                    proto_of, opaque_tris, timings, device, cache)


@dataclass
class SchemeRun:
    name: str
    primary: PrimaryResult
    shadow: ShadowResult | None = None
    deferred: ShadowResult | None = None


@typed
def trace_scheme(prep: Prepared, name: str | None, cam: np.ndarray, w: int, h: int, light=None, tnear: float = 0.0,
                 deferred: bool = False) -> SchemeRun:
    """Trace one scheme (``None``: opaque-only traversal, no filter at all)."""
    if name is None:
        tables, filt = None, 0
    else:
        sm = prep.maps[name]
        tables = scheme_tables(prep.base, sm)
        filt = make_filter(state_function(sm)).address
    primary = run_primary(prep.bvh, tables, filt, cam, w, h)
    run = SchemeRun(name or "opaque", primary)
    if light is not None:
        run.shadow = run_shadow(prep.bvh, tables, filt, cam, light, tnear, False, primary.dist)
        if deferred:
            run.deferred = run_shadow(prep.bvh, tables, filt, cam, light, tnear, True, primary.dist)
    return run
