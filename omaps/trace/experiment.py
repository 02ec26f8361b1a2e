"""One call traces a scene with every scheme: ``trace_scene`` returns a ``TraceResult`` holding
the report that ``omaps trace`` prints and writes as JSON, with the runs behind it and methods
that draw its pictures.

The reference scheme ``none`` (every candidate alpha-tested) is always traced; every scheme's
visible result (and, with shadows, every shadow ray's) is compared with it, and ``passed`` says
whether all of them matched. Speeds are measured side by side: every scheme and an opaque-only
traversal traced again for ``TIMING_ROUNDS`` rounds, each the best of its rounds.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..alpha_test import MaterialRules
from .. import checks
from ..errors import InputError, InputTypeError, check_count
from ..names import BUDGET_WEIGHTS
from ..schemes import TRACE_KINDS, Scheme, parse_schemes
from ..text import count, format_table, plural
from .camera import Camera, choose_default_camera, gltf_camera, light_direction, parse_camera, parse_light
from .timing import TIMING_ROUNDS, time_side_by_side
from .two_state import parse_modes
from ..checks import typed

if TYPE_CHECKING:
    from ..scene import Scene

__all__ = ["DEFAULT_SCHEMES", "trace_scene", "TraceResult", "format_report", "format_memory"]

DEFAULT_SCHEMES = "none,tri3,sq16,vq2,vq4,vq4x64"


def _size(size: object) -> tuple[int, int]:
    return checks.size(size, "size")


@dataclass
class TraceResult:
    """What ``trace_scene`` measured.

    Attributes
    ----------
    report : dict
        Everything ``omaps trace --json`` writes: scene, settings, camera, per-scheme results
        (alpha tests per primary and shadow ray, differing pixels, map bytes, speed), the
        opaque-only traversal, 2-state errors, timings, ``passed``.
    names : list of str
        The schemes asked for, in order (``none`` is traced and reported even when not asked for
        only as the reference: it is in ``runs``).
    runs : dict
        Scheme name -> ``SchemeRun`` (per-pixel tests, candidates, hits, shadow results).
    prep : Prepared
        The prepared scene: alpha triangles, each scheme's maps, the Embree scene.
    camera : Camera
        The camera traced (the default one when none was given).
    """

    report: dict
    names: list
    runs: dict
    prep: Any
    camera: Camera
    basis: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]
    light: np.ndarray | None = None
    shadows: bool = False

    @property
    def passed(self) -> bool:
        """True when no scheme changed a visible result (pixel or shadow ray)."""
        return bool(self.report["passed"])

    def messages(self) -> list[str]:
        """The error ``omaps trace`` prints on stderr when a scheme changed a visible result."""
        bad = self.report["changed_visible_result"]
        if not bad:
            return []
        return ["omaps: error: a scheme changed the visible result: " + ", ".join(f"{n} ({v})" for n, v in bad.items())]

    def table(self) -> str:
        """The report as ``omaps trace`` prints it (the schemes' notes under the table)."""
        from ..schemes import notes_lines

        return "\n".join([format_report(self.report, self.names, self.shadows),
                          *notes_lines(self.report.get("settings", {}))])

    def write_json(self, path) -> None:
        """The report as JSON."""
        from ..atomic import write_text

        write_text(path, json.dumps(self.report, indent=1))

    def heatmap(self, path) -> None:
        """Alpha tests per pixel, ``none`` beside each scheme (PNG)."""
        from .pictures import heatmap

        heatmap(path, self.runs, self.names, self.shadows, scene=self.report["scene"]["file"])

    def render(self, path) -> None:
        """The alpha-tested albedo image (PNG)."""
        from .pictures import render

        render(path, self.prep, self.runs["none"], self.basis, self.light)

    def plot_budget(self, path) -> None:
        """Alpha tests per primary ray against map bytes, every traced scheme on one chart."""
        from .pictures import budget_plot

        budget_plot(path, self.report)

    def plot_frontier(self, path) -> None:
        """Alpha tests per primary ray against map bytes and (with ``memory``) map lines and map +
        texture lines read per ray, every traced scheme, the Pareto front marked (PNG)."""
        from .pictures import frontier_plot

        frontier_plot(path, self.report)


def trace_scene(scene: str | os.PathLike[str] | Scene, schemes: str | Sequence[str | Scheme] = DEFAULT_SCHEMES, *,
                size: int | tuple[int, int] | str = 512, camera: Camera | str | int | None = None,
                shadows: bool = False, light: str | Sequence[float] | np.ndarray | None = None,
                weights: str = "area", two_state: str | Sequence[str] | None = None,
                rules: MaterialRules | None = None, jobs: int | None = None, encoder: str | None = None,
                effort: str | None = None, progress: bool = False, root: str | os.PathLike[str] | None = None,
                allow_outside: bool = False, memory: bool = False, cache_kib: float | None = None) -> TraceResult:
    """Trace primary (and shadow) rays through a scene with each scheme's maps read in the
    any-hit filter, and compare every scheme's visible result with ``none``'s.

    Parameters
    ----------
    scene : str, path or Scene
        A .gltf / .glb / .usd / .usda / .usdc / .usdz file, or a scene from ``omaps.load_scene``.
    schemes : str, or list of str or Scheme
        Comma-separated scheme names (``none``, ``triL``, ``sqN``, a codec, ``omm``, ``file:CODEC``,
        ``budget:BYTES``), or a list of names or parsed schemes.
    size : int, (int, int) or str
        Image width and height, 1..8192 (an int: a square image; or text "W" / "WxH").
    camera : Camera, str, int or None
        A ``Camera``, ``"X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ]"``, ``"gltf[:N]"`` or N (the file's
        camera N); None: a view that frames the alpha-tested geometry.
    shadows : bool
        Also trace shadow rays towards ``light``, normally and with deferred C tests.
    light : array_like or str, optional
        Direction towards the light (default ``DEFAULT_LIGHT``).
    weights : {"area", "view"}
        The budget schemes' weights.
    two_state : str or list of str, optional
        Also trace square and codec schemes with C resolved by these rules.
    rules : MaterialRules, optional
        How materials are alpha-tested (default ``MaterialRules()``).
    jobs : int, optional
        Processes for baking and encoding (default: all cores).
    encoder, effort : str, optional
        Codec choices for codec schemes named without a variant.
    progress : bool
        Progress bars on stderr.
    root : str, optional
        A scene's URI policy (``omaps.load_scene``): the folder the files it names must lie under
        (default: its own folder).
    allow_outside : bool
        Read the files a scene names wherever they are (a scene you trust).
    memory : bool
        Also model the map data each lookup of the primary pass reads (``trace.memory``): per
        scheme ``memory`` in the report, with dependent reads per lookup and 64-byte lines per
        primary ray in its ``own`` and ``shared`` layouts, and the 64-byte lines of alpha texture
        its alpha tests fetch per primary ray, alone and added to each layout's map lines
        (docs/FORMAT.md, "What a lookup reads").
    cache_kib : float, optional
        With ``memory``: also the misses per primary ray of an LRU cache of this many KiB shared
        by each 8 x 8 tile of pixels.

    Returns
    -------
    TraceResult

    Raises
    ------
    InputTypeError
        An argument of the wrong type (its message names the parameter).
    InputError
        For a bad scene (naming the file), scheme, camera, light or value (naming the parameter).

    Examples
    --------
    >>> import omaps                                                         # doctest: +SKIP
    >>> res = omaps.trace_scene("palm.glb", "none,tri3,vq4", size=128)       # doctest: +SKIP
    >>> res.passed, res.report["schemes"]["vq4"]["alpha_tests_per_primary_ray"]  # doctest: +SKIP
    (True, 0.253...)
    """
    from tqdm import tqdm

    from .camera import SHADOW_TNEAR
    from .maps import default_jobs
    from .metrics import summary
    from .prepare import prepare, trace_scheme

    from ..scene import Scene, load_scene

    if not isinstance(scene, Scene):
        scene = checks.path(scene, "scene")
    schemes = parse_schemes(schemes, TRACE_KINDS, encoder, effort, "trace_scene", param="schemes")
    names = [s.name for s in schemes]
    modes = parse_modes(two_state)
    w, h = _size(size)
    jobs = check_count(jobs, "jobs")
    shadows, memory = checks.boolean(shadows, "shadows"), checks.boolean(memory, "memory")
    progress = checks.boolean(progress, "progress")
    allow_outside = checks.boolean(allow_outside, "allow_outside")
    root = None if root is None else checks.path(root, "root")
    if cache_kib is not None:
        cache_kib = checks.number(cache_kib, "cache_kib", 1 / 16, 1 << 20)
        if not memory:
            raise InputError("a cache size (cache_kib) measures what a ray reads: it needs memory",
                             param=("cache_kib", "memory"))
    checks.choice(weights, "weights", BUDGET_WEIGHTS)
    if rules is not None and not isinstance(rules, MaterialRules):
        raise InputTypeError(f"rules must be an omaps.MaterialRules, got {type(rules).__name__}", param="rules")
    rules = MaterialRules() if rules is None else rules
    light = _light(light) if shadows else None
    if camera is not None and not isinstance(camera, (Camera, str, int, np.integer)) or isinstance(camera, bool):
        raise InputTypeError(f"camera must be a Camera, text or a glTF camera index, got {type(camera).__name__}",
                             param="camera")
    if isinstance(camera, (int, np.integer)) and camera < 0:
        raise InputError(f"camera index must be >= 0, got {camera}", param="camera")
    cam_given: Camera | int | np.integer | None = parse_camera(camera) if isinstance(camera, str) else camera
    t_start = time.perf_counter()
    if not isinstance(scene, Scene):
        scene = load_scene(scene, root=root, allow_outside=allow_outside)
    if not any(len(scene.meshes[mi].merged["triangles"]) for mi, _ in scene.instances):
        raise InputError("the scene has no triangles", scene.path)
    cam_info: dict[str, Any] | None
    if isinstance(cam_given, (int, np.integer)):
        cam_info = {"chosen": f"gltf:{cam_given}"}
        cam_given = gltf_camera(scene, int(cam_given))  # before any work: a bad index is an input error
    else:
        cam_info = {"chosen": "--camera"} if cam_given is not None else None
    t_load = time.perf_counter() - t_start
    if "none" not in names:
        schemes = parse_schemes("none", TRACE_KINDS) + list(schemes)
    traced = [s.name for s in schemes]
    prep: Any = prepare(scene, schemes, rules, default_jobs(jobs), progress)
    bounds = scene.bounds()
    if isinstance(cam_given, Camera):
        camera = cam_given
    else:
        camera, cam_info = choose_default_camera(prep, w, h)
    cam = camera.basis(w, h)
    budgets = [s for s in schemes if s.kind == "budget"]
    if budgets:
        _budget_maps(prep, budgets, weights, cam, w, h, default_jobs(jobs), progress)
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    tnear = SHADOW_TNEAR * diag
    trace_scheme(prep, None, cam, 2, 2, light, tnear, deferred=shadows)  # compile the ray loops
    runs = {}
    for n in tqdm(traced, desc="trace", unit="scheme", disable=not progress, leave=False):
        runs[n] = trace_scheme(prep, n, cam, w, h, light, tnear, deferred=shadows)
    opaque = trace_scheme(prep, None, cam, w, h, light, tnear)
    # the speeds: every scheme and the opaque traversal timed again, side by side, each its best round
    timed = {**runs, None: opaque}
    with tqdm(total=(TIMING_ROUNDS - 1) * len(timed), desc="timing", unit="run", disable=not progress,
              leave=False) as bar:
        def trace_once(n):
            bar.update()
            return trace_scheme(prep, n, cam, w, h, light, tnear)

        samples = time_side_by_side(timed, trace_once, TIMING_ROUNDS)
    ref = runs["none"]
    two = _trace_two_state(prep, names, modes, cam, w, h, ref) if modes else {}
    report = {
        "scene": {"file": scene.path, **scene.counts(rules), "paired_fraction": prep.alpha.paired_fraction,
                  "pairs": int(len(prep.alpha.pair_first)), "bounds": bounds.tolist(),
                  "warnings": list(scene.warnings), "skipped_primitives": scene.skipped},
        "settings": {"materials": rules.settings(), "schemes": {s.name: s.settings() for s in schemes},
                     "two_state": modes, "shadows": bool(shadows), "encoder": encoder, "effort": effort,
                     "jobs": jobs, "weights": weights if budgets else None},
        "camera": {**camera.to_json(), "width": w, "height": h, "view": cam_info},
        "light": None if light is None else light.tolist(),
        "embree": prep.device.version_text,
        "schemes": {n: summary(runs[n], ref, prep.maps[n], w, h) for n in names},
        "opaque_only": {**summary(opaque, ref, None, w, h), "timing": _timing(opaque, samples[None])},
        "two_state": two,
        "timings": {"load_s": t_load, **prep.timings, "total_s": time.perf_counter() - t_start},
    }
    none_tests = summary(ref, ref, prep.maps["none"], w, h)["alpha_tests_per_primary_ray"]
    for n, r in report["schemes"].items():
        r["timing"] = _timing(runs[n], samples[n])
        t = r["alpha_tests_per_primary_ray"]
        r["none_over_scheme_alpha_tests"] = none_tests / t if t else None
        r["rays_per_second_over_opaque"] = (r["rays_per_second"] / report["opaque_only"]["rays_per_second"]
                                            if r["rays_per_second"] else None)
    bad = {n: r["differing_pixels"] + r.get("differing_shadow_rays", 0) + r.get("deferred_differing_shadow_rays", 0)
           for n, r in report["schemes"].items()}
    if memory:
        from .memory import scheme_memory, texture_layout

        t0 = time.perf_counter()
        tex = texture_layout(prep.base)  # one layout of the scene's textures for every scheme
        for n in tqdm(names, desc="memory", unit="scheme", disable=not progress, leave=False):
            mem = scheme_memory(prep, n, runs[n], cam, w, h, cache_kib, tex)
            report["schemes"][n]["memory"] = mem
            if mem is not None:
                report["schemes"][n]["map_reads_per_lookup"] = mem["own"]["map_reads_per_lookup"]
                report["schemes"][n]["map_lines_per_ray"] = mem["own"]["map_lines_per_ray"]
                report["schemes"][n]["texture_lines_per_ray"] = mem["texture_lines_per_ray"]
                report["schemes"][n]["total_lines_per_ray"] = mem["own"]["total_lines_per_ray"]
        front_gaps(report)
        report["timings"]["memory_s"] = time.perf_counter() - t0
        report["timings"]["total_s"] = time.perf_counter() - t_start
    report["passed"] = not any(bad.values())
    report["changed_visible_result"] = {n: v for n, v in bad.items() if v}
    return TraceResult(report, names, runs, prep, camera, cam, light, bool(shadows))


def front_gaps(report: dict) -> None:
    """Add to each layout of each scheme's ``memory`` its ``bytes_gap``, ``lines_gap`` and
    ``both_fronts_gap`` (``omaps.frontier.gaps``) against every (scheme, layout) point of the
    report but ``none``: how many times more map bytes, and lines of map data per primary ray,
    it needs than the least of any point with no more alpha tests per primary ray."""
    from ..frontier import gaps

    points = [(r["memory"][lay], r["alpha_tests_per_primary_ray"]) for n, r in report["schemes"].items()
              if n != "none" and r.get("memory") for lay in ("own", "shared")]
    tests = [t for _, t in points]
    by_bytes = gaps(tests, [m["map_bytes"] for m, _ in points])
    by_lines = gaps(tests, [m["map_lines_per_ray"] for m, _ in points])
    for (m, _), b, li in zip(points, by_bytes, by_lines):
        m["bytes_gap"], m["lines_gap"] = b, li
        m["both_fronts_gap"] = None if b is None or li is None else max(b, li)


def _light(light) -> np.ndarray:
    if light is None or isinstance(light, str):
        return parse_light(light)
    try:
        return light_direction(light)
    except ValueError:
        raise InputError("light must not be the zero vector", param="light") from None


def _budget_maps(prep, budgets, weights: str, cam, w: int, h: int, jobs: int, progress: bool) -> None:
    """Each budget scheme's maps (``trace.budget``), weighted by area or by the view."""
    from ..budget import triangle_weights
    from .budget import budget_maps
    from .view import view_weights

    t0 = time.perf_counter()
    wt = view_weights(prep, cam, w, h) if weights == "view" else triangle_weights(prep.scene, prep.alpha)
    for s in budgets:
        prep.maps[s.name] = budget_maps(prep.alpha, prep.tests, s, wt, jobs, progress, cache=prep.cache)
    prep.cache.clear()  # the uniform schemes' flags and blocks: only the budgets re-use them
    prep.timings["budget_s"] = time.perf_counter() - t0


def _timing(run, seconds: list[float]) -> dict:
    """How a run's rays per second were measured: the rays of one round (primary and shadow) and
    every round's seconds; the rate is the rays over the best (least) seconds."""
    rays = run.primary.tests.size + (run.shadow.rays if run.shadow is not None else 0)
    return {"rounds": len(seconds), "statistic": "best", "rays": int(rays), "seconds": [float(t) for t in seconds]}


def _trace_two_state(prep, names, modes, cam, w, h, ref) -> dict:
    """Each square / codec scheme traced again with its C cells resolved by each rule."""
    from .metrics import coverage_error
    from .prepare import trace_scheme
    from .two_state import two_state_maps

    out: dict = {}
    cache: dict = {}
    for n in names:
        sm = prep.maps[n]
        if sm.kind != "square" or (sm.scheme is not None and sm.scheme.kind == "stored"):
            continue  # (a file's stored pair blocks are traced as stored)
        out[n] = {}
        for mode in modes:
            sm2 = two_state_maps(prep, sm, mode, cache=cache)
            prep.maps[sm2.name] = sm2
            run = trace_scheme(prep, sm2.name, cam, w, h)
            out[n][mode] = coverage_error(run, ref)
            del prep.maps[sm2.name]
    return out


def _over_opaque(ratio) -> str:
    """The x opaque cell; a scheme faster than the opaque traversal (it does more work) is marked:
    the difference is timing noise."""
    if ratio is None:
        return "-"
    return f"{ratio:.2f}" + ("*" if ratio > 1 else "")


def format_memory(report: dict, names: list) -> str:
    """``--memory``'s table: per scheme its lookups per primary ray, the 64-byte lines of alpha
    texture its alpha tests fetch per primary ray and, in its own and shared layouts, map KiB,
    dependent reads per lookup, 64-byte lines of map data per primary ray, map plus texture
    lines per primary ray (and cache misses per ray)."""
    mems = {n: report["schemes"][n].get("memory") for n in names}
    cache = next((m["cache_kib"] for m in mems.values() if m and m.get("cache_kib") is not None), None)
    fields = [("KiB", "map_bytes", lambda v: f"{v / 1024:.1f}"), ("reads", "map_reads_per_lookup", lambda v: f"{v:.2f}"),
              ("lines", "map_lines_per_ray", lambda v: f"{v:.3f}"), ("total", "total_lines_per_ray", lambda v: f"{v:.3f}")]
    if cache is not None:
        fields.append(("misses", "cache_misses_per_ray", lambda v: f"{v:.3f}"))
    cols = ["scheme", "lookups/ray", "tex lines"] + [f"{lay} {f[0]}" for lay in ("own", "shared") for f in fields]
    rows = []
    for n, m in mems.items():
        if not m:
            rows.append([n, "-", "-"] + ["-"] * (2 * len(fields)))
            continue
        rows.append([n, f"{m['lookups_per_primary_ray']:.3f}", f"{m['texture_lines_per_ray']:.3f}"]
                    + [fmt(m[lay][key]) for lay in ("own", "shared") for _, key, fmt in fields])
    head = ("what a lookup reads (primary rays; own: each pair's or triangle's map with it; shared: identical maps "
            "once, behind a 32-bit index; triL shared = standard OMMs; tex lines: alpha texture lines the alpha "
            "tests fetch; total: map lines + tex lines)")
    if cache is not None:
        head += f"; misses: a {cache:g} KiB LRU cache per 8x8 pixel tile"
    texture = next((m["texture_layout"] for m in mems.values() if m), None)
    if texture is not None:
        head += f"\ntexture layout: {texture}"
    return head + "\n" + format_table(cols, rows)


@typed
def format_report(report: dict, names: list, shadows: bool) -> str:
    """A trace report (``TraceResult.report``) as ``omaps trace`` prints it: a heading line, one
    row per scheme, the opaque traversal and timings, and the 2-state errors when traced. A dict
    that is no such report (a field missing or of another kind) is an ``InputError`` naming
    ``report``."""
    try:
        return _format_report(report, names, shadows)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        what = f"no field {exc}" if isinstance(exc, KeyError) else f"a field of another kind ({exc})"
        raise InputError(f"report is not a trace report of these schemes (TraceResult.report): {what}",
                         param="report") from None


def _format_report(report: dict, names: list, shadows: bool) -> str:
    s = report["scene"]
    c = report["camera"]
    lines = [f"omaps trace: {s['file']}: {plural(s['instances'], 'instance')} of "
             f"{plural(s['prototypes'], 'mesh', 'meshes')}, "
             f"{count(s['triangles'], 'triangle')} ({s['alpha_triangles']:,} alpha-tested); "
             f"{count(s['pairs'], 'prototype pair')}, "
             f"{s['paired_fraction']:.1%} of alpha triangles paired; {c['width']}x{c['height']}, "
             f"Embree {report['embree']}"]
    cols = ["scheme", "tests/ray", "cand/ray", "none/x", "differ", "Mrays/s", "x opaque", "map KiB"]
    if shadows:
        cols[5:5] = ["shadow tests", "deferred", "saved"]
    rows = []
    for n in names:
        r = report["schemes"][n]
        row = [n, f"{r['alpha_tests_per_primary_ray']:.3f}", f"{r['candidates_per_primary_ray']:.3f}",
               f"{r['none_over_scheme_alpha_tests']:.2f}" if r["none_over_scheme_alpha_tests"] else "-",
               str(r["differing_pixels"] + r.get("differing_shadow_rays", 0)),
               f"{r['rays_per_second'] / 1e6:.2f}", _over_opaque(r['rays_per_second_over_opaque']),
               f"{r.get('map_bytes', 0) / 1024:.0f}"]
        if shadows:
            row[5:5] = [f"{r['alpha_tests_per_shadow_ray']:.3f}", f"{r['deferred_alpha_tests_per_shadow_ray']:.3f}",
                        f"{r['deferred_tests_saved_fraction']:.1%}"]
        rows.append(row)
    lines.append(format_table(cols, rows))
    if any(r[cols.index("x opaque")].endswith("*") for r in rows):
        lines.append("* faster than the opaque-only traversal, which does less work: within this machine's timing "
                     "noise")
    o = report["opaque_only"]
    t = report["timings"]
    lines.append(f"opaque-only traversal: {o['rays_per_second'] / 1e6:.2f} Mrays/s; total {t['total_s']:.1f} s "
                 f"(load {t['load_s']:.1f}, pair {t['pair_s']:.1f}, bake+encode {t['bake_encode_s']:.1f}, "
                 f"BVH {t['bvh_s']:.1f})")
    if any(report["schemes"][n].get("memory") for n in names):
        lines.append(format_memory(report, names))
    if report.get("two_state"):
        lines.append("2-state (C cells resolved, no alpha tests): pixels whose visible hit differs from 'none' "
                     "(stopped early / passed through)")
        for n, by_mode in report["two_state"].items():
            cells = [f"{m} {r['differing_fraction']:.2%} ({r['stopped_early_fraction']:.2%}/"
                     f"{r['passed_through_fraction']:.2%})" for m, r in by_mode.items()]
            lines.append(f"  {n:8} " + "   ".join(cells))
    return "\n".join(lines)
