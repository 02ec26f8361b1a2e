"""``omaps trace SCENE``: alpha tests per ray on a glTF scene, per scheme, with pictures.

A thin layer over ``omaps.trace``: parse options, prepare (pair, bake, store, build the
Embree scene), trace ``none`` (always: it is the reference every scheme must match) and each
scheme, then print a table and write the JSON, heat map and render asked for.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from ..atomic import Outputs, write_text
from ..errors import InputError
from ..names import BUDGET_WEIGHTS
from ..schemes import TRACE_KINDS, parse_schemes
from ..trace.camera import DEFAULT_LIGHT
from ..trace.timing import TIMING_ROUNDS, time_side_by_side
from .common import (add_codec_options, add_material_options, check_jobs, material_rules, parse_size, plural,
                     print_table, show_progress)

DEFAULT_SCHEMES = "none,tri3,sq16,vq2,vq4,vq4x64"

TABLE_HELP = """\
the printed table, one row per scheme (every figure is also in --json):
  scheme        the scheme's name; 'none' is no map (every candidate runs the any-hit shader)
  tests/ray     alpha tests (any-hit shader invocations) per primary ray: what the maps save
  cand/ray      distinct candidate hits on alpha-tested triangles per primary ray, any map or none
  none/x        tests/ray of 'none' divided by this scheme's: how many times fewer shader calls
  differ        pixels (and shadow rays) whose result differs from 'none'; must be 0 (exit 1 otherwise)
  shadow tests  with --shadows: alpha tests per shadow ray
  deferred      with --shadows: the same with deferred C (O hits first, C candidates tested only
                if no O hit exists)
  saved         with --shadows: the share of shadow-ray alpha tests that deferring C saves
  Mrays/s       millions of rays per second (primary and shadow) traced on this CPU with the map: the
                best of {rounds} rounds, every scheme and the opaque-only traversal timed side by side
  x opaque      Mrays/s relative to an opaque-only traversal of the same scene (no any-hit filter);
                above 1 (marked *) is timing noise, as every scheme does more work
  map KiB       storage of the scheme's maps over every prototype pair (or triangle), in KiB
"""


def add_parser(sub) -> None:
    t = sub.add_parser("trace", help="ray trace a glTF scene: alpha tests per ray with each scheme's maps",
                       description="Trace primary (and shadow) rays through a glTF 2.0 scene with Embree; "
                                   "each scheme's maps are read in the any-hit filter, and every scheme's "
                                   "visible result is checked against 'none' (every candidate alpha-tested).",
                       epilog=TABLE_HELP.format(rounds=TIMING_ROUNDS),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    t.add_argument("scene", metavar="SCENE", help=".gltf or .glb file")
    t.add_argument("--schemes", default=DEFAULT_SCHEMES,
                   help="comma-separated: none, triL, sqN, or a codec (vq2, vq4, vq4x64, vq4-synth, wavelet3, "
                        "also with -paper, -fast, -medium or -thorough), omm or file:CODEC (the maps the traced file stores), or "
                        "budget:BYTES (per pair the map -- none, sqN up to 64, vq2, vq4 or vq4x64 -- that saves the "
                        "most alpha tests per byte, every pair together within BYTES: 1263936, 1.2MiB, 800KiB) "
                        "(default: %(default)s)")
    t.add_argument("--weights", choices=BUDGET_WEIGHTS, default=BUDGET_WEIGHTS[0],
                   help="budget schemes: a pair's expected candidate hits are its triangles' world area times "
                        "instances (area: rays uniform over the scene), or their candidate hits in a trace of "
                        "this view at half the resolution (view) (default: %(default)s)")
    t.add_argument("--plot-budget", metavar="FILE.png",
                   help="alpha tests per primary ray against map bytes, every traced scheme on one chart")
    t.add_argument("--camera", metavar="X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ] | gltf[:N]",
                   help="eye, target, vertical field of view in degrees and optionally the up direction "
                        "(default +Y); or 'gltf:N', the file's camera N (default 0) placed by its node, with "
                        "this image's aspect ratio. Default: a view that frames the alpha-tested geometry "
                        "(a low grazing view across a wide scene), checked to show it")
    t.add_argument("--size", default="512", metavar="W[xH]", help="image size (default: %(default)s)")
    t.add_argument("--shadows", action="store_true",
                   help="also trace shadow rays to a directional light, normally and with deferred C tests")
    t.add_argument("--light", metavar="X,Y,Z", help=f"direction towards the light (default: {DEFAULT_LIGHT})")
    t.add_argument("--jobs", type=int, default=None, metavar="N", help="processes for baking and encoding "
                   "(default: all cores)")
    t.add_argument("--two-state", metavar="MODES", default=None,
                   help="also trace each square or codec scheme with its C cells resolved to O or T (no "
                        "alpha tests; not exact) by these comma-separated rules: nearest, opaque, "
                        "transparent, hashed, or 'all'; reports the per-pixel coverage error")
    t.add_argument("--json", metavar="FILE", help="write the settings and results as JSON")
    t.add_argument("--heatmap", metavar="FILE.png", help="alpha tests per pixel, 'none' beside each scheme (PNG)")
    t.add_argument("--render", metavar="FILE.png", help="the alpha-tested albedo image (PNG)")
    t.add_argument("--quiet", action="store_true", help="no progress bars")
    add_material_options(t)
    add_codec_options(t)
    t.set_defaults(func=cmd_trace)


def bind_camera_value(argv: list[str]) -> list[str]:
    """``--camera -70,130,-70:0,175,0:70`` as the README writes it: argparse takes a value that
    starts with '-' (and is no plain negative number) for an option, so the token after
    ``--camera`` (or an abbreviation of it) in an ``omaps trace`` command line is bound to it
    (``--camera=VALUE``) before parsing. Nothing after ``--`` is touched."""
    argv = list(argv)
    words = [k for k, a in enumerate(argv) if not a.startswith("-")]  # omaps' own options take no values
    if words[:1] and argv[words[0]] == "batch" and len(words) > 1:
        words = words[1:]  # omaps batch trace: the same options
    if not words or argv[words[0]] != "trace":
        return argv
    start = words[0] + 1
    out = argv[:start]
    i = start
    while i < len(argv):
        a = argv[i]
        if a == "--":
            out.extend(argv[i:])
            break
        if (len(a) > 4 and "--camera".startswith(a) and i + 1 < len(argv) and argv[i + 1].startswith("-")
                and argv[i + 1][1:2] in tuple("0123456789.")):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def _numbers(n: int, kind: str = "") -> str:
    return f"a {kind}number" if n == 1 else f"{n} {kind}comma-separated numbers"


def _floats(text: str, n: int, what: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")], dtype=np.float64)
    except ValueError:
        raise InputError(f"{what}: expected {_numbers(n)}, got {text!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what}: expected {_numbers(n, 'finite ')}, got {text!r}")
    return v


def parse_camera(text: str):
    """A ``Camera``, or the index N of ``gltf[:N]`` (the file's camera, resolved once it is read)."""
    from ..trace import Camera

    parts = text.split(":")
    if parts[0].strip().lower() == "gltf":
        if len(parts) == 1:
            return 0
        if len(parts) == 2 and parts[1].strip().isdigit():
            return int(parts[1])
        raise InputError(f"--camera gltf[:N] takes a camera index N >= 0, got {text!r}")
    if len(parts) not in (3, 4):
        raise InputError(f"--camera must be X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ] or gltf[:N], got {text!r}")
    eye = _floats(parts[0], 3, "--camera eye")
    target = _floats(parts[1], 3, "--camera target")
    fov = _floats(parts[2], 1, "--camera fov")[0]
    up = _floats(parts[3], 3, "--camera up") if len(parts) == 4 else None
    if not 0 < fov < 180:
        raise InputError(f"--camera field of view must be in (0, 180) degrees, got {fov}")
    if np.allclose(eye, target):
        raise InputError("--camera eye and target must differ")
    cam = Camera(eye, target, float(fov), up)
    try:
        cam.basis(1, 1)
    except ValueError:
        raise InputError("--camera up must not be zero or parallel to the view direction") from None
    return cam


def parse_light(text: str | None) -> np.ndarray:
    from ..trace import light_direction

    try:
        return light_direction(None if text is None else _floats(text, 3, "--light"))
    except ValueError:
        raise InputError("--light must not be the zero vector") from None


def cmd_trace(a) -> int:
    from .. import trace
    from ..scene import load_scene
    from ..trace.maps import default_jobs
    from ..trace.pictures import budget_plot, heatmap, render

    schemes = parse_schemes(a.schemes, TRACE_KINDS, a.encoder, a.effort, "omaps trace")
    names = [s.name for s in schemes]
    modes = parse_two_state(a.two_state)
    w, h = parse_size(a.size)
    check_jobs(a.jobs)
    rules = material_rules(a)
    light = parse_light(a.light) if a.shadows else None
    cam_given = parse_camera(a.camera) if a.camera else None  # a Camera, or a glTF camera's index
    outputs = Outputs(inputs=[a.scene])
    outputs.file(a.json, "--json")
    outputs.file(a.heatmap, "--heatmap", (".png",))
    outputs.file(a.render, "--render", (".png",))
    outputs.file(a.plot_budget, "--plot-budget", (".png",))
    progress = show_progress(a.quiet)
    t_start = time.perf_counter()
    scene = load_scene(a.scene)
    if not any(len(scene.meshes[mi].merged["triangles"]) for mi, _ in scene.instances):
        raise InputError("the scene has no triangles", a.scene)
    if isinstance(cam_given, int):
        cam_info = {"chosen": f"gltf:{cam_given}"}
        cam_given = trace.gltf_camera(scene, cam_given)  # before any work: a bad index is an input error
    else:
        cam_info = {"chosen": "--camera"} if cam_given is not None else None
    t_load = time.perf_counter() - t_start
    if "none" not in names:
        schemes = parse_schemes("none", TRACE_KINDS) + schemes
    traced = [s.name for s in schemes]
    prep = trace.prepare(scene, schemes, rules, default_jobs(a.jobs), progress)
    bounds = scene.bounds()
    if cam_given is None:
        camera, cam_info = trace.choose_default_camera(prep, w, h)
    else:
        camera = cam_given
    cam = camera.basis(w, h)
    budgets = [s for s in schemes if s.kind == "budget"]
    if budgets:
        from ..budget import triangle_weights
        from ..trace.budget import budget_maps
        from ..view import view_weights

        t0 = time.perf_counter()
        weights = view_weights(prep, cam, w, h) if a.weights == "view" else triangle_weights(scene, prep.alpha)
        for s in budgets:
            prep.maps[s.name] = budget_maps(prep.alpha, prep.tests, s, weights, default_jobs(a.jobs), progress,
                                            cache=prep.cache)
        prep.cache.clear()  # the uniform schemes' flags and blocks: only the budgets re-use them
        prep.timings["budget_s"] = time.perf_counter() - t0
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    tnear = trace.SHADOW_TNEAR * diag
    trace.trace_scheme(prep, None, cam, 2, 2, light, tnear, deferred=a.shadows)  # compile the ray loops
    from tqdm import tqdm

    runs = {}
    for n in tqdm(traced, desc="trace", unit="scheme", disable=not progress, leave=False):
        runs[n] = trace.trace_scheme(prep, n, cam, w, h, light, tnear, deferred=a.shadows)
    opaque = trace.trace_scheme(prep, None, cam, w, h, light, tnear)
    # the speeds: every scheme and the opaque traversal timed again, side by side, each its best round
    timed = {**runs, None: opaque}
    with tqdm(total=(TIMING_ROUNDS - 1) * len(timed), desc="timing", unit="run", disable=not progress,
              leave=False) as bar:
        def trace_once(n):
            bar.update()
            return trace.trace_scheme(prep, n, cam, w, h, light, tnear)

        samples = time_side_by_side(timed, trace_once, TIMING_ROUNDS)
    ref = runs["none"]
    two_state = _trace_two_state(prep, names, modes, cam, w, h, ref) if modes else {}
    total = time.perf_counter() - t_start
    report = {
        "scene": {"file": a.scene, **scene.counts(rules), "paired_fraction": prep.alpha.paired_fraction,
                  "pairs": int(len(prep.alpha.pair_first)), "bounds": bounds.tolist(),
                  "warnings": list(scene.warnings), "skipped_primitives": scene.skipped},
        "settings": {"materials": rules.settings(), "schemes": {s.name: s.settings() for s in schemes},
                     "two_state": modes, "shadows": bool(a.shadows), "encoder": a.encoder, "effort": a.effort,
                     "jobs": a.jobs, "weights": a.weights if budgets else None},
        "camera": {**camera.to_json(), "width": w, "height": h, "view": cam_info},
        "light": None if light is None else light.tolist(),
        "embree": prep.device.version_text,
        "schemes": {n: trace.summary(runs[n], ref, prep.maps[n], w, h) for n in names},
        "opaque_only": {**trace.summary(opaque, ref, None, w, h), "timing": _timing(opaque, samples[None])},
        "two_state": two_state,
        "timings": {"load_s": t_load, **prep.timings, "total_s": total},
    }
    none_tests = trace.summary(ref, ref, prep.maps["none"], w, h)["alpha_tests_per_primary_ray"]
    for n, r in report["schemes"].items():
        r["timing"] = _timing(runs[n], samples[n])
        t = r["alpha_tests_per_primary_ray"]
        r["none_over_scheme_alpha_tests"] = none_tests / t if t else None
        r["rays_per_second_over_opaque"] = (r["rays_per_second"] / report["opaque_only"]["rays_per_second"]
                                            if r["rays_per_second"] else None)
    bad = {n: r["differing_pixels"] + r.get("differing_shadow_rays", 0) + r.get("deferred_differing_shadow_rays", 0)
           for n, r in report["schemes"].items()}
    # a failed check still writes every output asked for, complete, and says so (then exit 1)
    report["passed"] = not any(bad.values())
    report["changed_visible_result"] = {n: v for n, v in bad.items() if v}
    _print_report(report, names, a.shadows)
    if two_state:
        _print_two_state(two_state)
    with outputs.writing():  # all renamed into place together at the end
        if a.json:
            write_text(outputs.path(a.json), json.dumps(report, indent=1))
        if a.heatmap:
            heatmap(outputs.path(a.heatmap), runs, names, a.shadows, scene=a.scene)
        if a.render:
            render(outputs.path(a.render), prep, runs["none"], cam, light)
        if a.plot_budget:
            budget_plot(outputs.path(a.plot_budget), report)
    if any(bad.values()):
        print("omaps: error: a scheme changed the visible result: " +
              ", ".join(f"{n} ({v})" for n, v in bad.items() if v), file=sys.stderr)
        return 1
    return 0


def _timing(run, seconds: list[float]) -> dict:
    """How a run's rays per second were measured: the rays of one round (primary and shadow) and
    every round's seconds; the rate is the rays over the best (least) seconds."""
    rays = run.primary.tests.size + (run.shadow.rays if run.shadow is not None else 0)
    return {"rounds": len(seconds), "statistic": "best", "rays": int(rays), "seconds": [float(t) for t in seconds]}


def parse_two_state(text: str | None) -> list[str]:
    from ..trace.two_state import MODES

    if not text:
        return []
    modes = list(MODES) if text.strip().lower() == "all" else [m.strip().lower() for m in text.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        raise InputError(f"--two-state: unknown rule {bad[0] if bad else text!r} (choose from {', '.join(MODES)} "
                         "or all)")
    return list(dict.fromkeys(modes))


def _trace_two_state(prep, names, modes, cam, w, h, ref) -> dict:
    """Each square / codec scheme traced again with its C cells resolved by each rule."""
    from .. import trace
    from ..trace.two_state import two_state_maps

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
            run = trace.trace_scheme(prep, sm2.name, cam, w, h)
            out[n][mode] = trace.coverage_error(run, ref)
            del prep.maps[sm2.name]
    return out


def _print_two_state(two_state: dict) -> None:
    print("2-state (C cells resolved, no alpha tests): pixels whose visible hit differs from 'none' "
          "(stopped early / passed through)")
    for n, by_mode in two_state.items():
        cells = [f"{m} {r['differing_fraction']:.2%} ({r['stopped_early_fraction']:.2%}/"
                 f"{r['passed_through_fraction']:.2%})" for m, r in by_mode.items()]
        print(f"  {n:8} " + "   ".join(cells))


def _count(n: int, noun: str) -> str:
    """``plural`` with thousands separators: 1 triangle, 4,152 triangles."""
    return f"{n:,}" + plural(n, noun)[len(str(n)):]


def _over_opaque(ratio) -> str:
    """The x opaque cell; a scheme faster than the opaque traversal (it does more work) is marked:
    the difference is timing noise."""
    if ratio is None:
        return "-"
    return f"{ratio:.2f}" + ("*" if ratio > 1 else "")


def _print_report(report: dict, names: list[str], shadows: bool) -> None:
    s = report["scene"]
    c = report["camera"]
    print(f"omaps trace: {s['file']}: {plural(s['instances'], 'instance')} of "
          f"{plural(s['prototypes'], 'mesh', 'meshes')}, "
          f"{_count(s['triangles'], 'triangle')} ({s['alpha_triangles']:,} alpha-tested); "
          f"{_count(s['pairs'], 'prototype pair')}, "
          f"{s['paired_fraction']:.1%} of alpha triangles paired; {c['width']}x{c['height']}, Embree {report['embree']}")
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
    print_table(cols, rows)
    if any(r[cols.index("x opaque")].endswith("*") for r in rows):
        print("* faster than the opaque-only traversal, which does less work: within this machine's timing noise")
    o = report["opaque_only"]
    t = report["timings"]
    print(f"opaque-only traversal: {o['rays_per_second'] / 1e6:.2f} Mrays/s; total {t['total_s']:.1f} s "
          f"(load {t['load_s']:.1f}, pair {t['pair_s']:.1f}, bake+encode {t['bake_encode_s']:.1f}, "
          f"BVH {t['bvh_s']:.1f})")
