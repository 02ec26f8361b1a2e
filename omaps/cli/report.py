"""``omaps report INPUT -o REPORT.html``: one self-contained HTML page of a glTF scene (the trace
table, pictures, a 3D view of each scheme's map states on the mesh) or of a texture corpus (the
savings chart and a sortable table of every texture's maps). A thin layer over
``omaps.report.build_report``."""

from __future__ import annotations

import argparse
import os

from ..atomic import check_file
from ..errors import InputError, check_count
from .common import (add_asset_options, add_material_options, asset_options, material_rules, parse_size,
                     show_progress)


def add_parser(sub) -> None:
    r = sub.add_parser("report", help="one self-contained HTML page of a scene or a texture corpus",
                       description="Write one HTML file that opens from disk without a network: for a glTF "
                                   "scene, omaps trace's table of alpha tests per ray, its heat map, render and "
                                   "bytes chart, each alpha material's texture with the map states over its UVs, "
                                   "and a 3D view (orbit, zoom) of the mesh with every alpha triangle's map states "
                                   "(T cyan, O magenta, C green) per scheme, or its alpha texture; for a folder of "
                                   "textures, omaps eval's savings chart and a sortable table of every texture "
                                   "with its maps.",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("input", metavar="INPUT", help="a scene: .gltf / .glb (baked or not: omm and file:CODEC "
                   "show what it stores) or .usd / .usda / .usdc / .usdz; or a folder of textures")
    r.add_argument("-o", "--output", required=True, metavar="REPORT.html", help="the HTML file to write")
    r.add_argument("--schemes", default=None,
                   help="comma-separated schemes: those of omaps trace for a scene (default: its default), "
                        "of omaps eval for a folder (default: its default)")
    r.add_argument("--size", default="512", metavar="W[xH]",
                   help="a scene's traced image size, as omaps trace --size (default: %(default)s)")
    r.add_argument("--shadows", action="store_true", help="a scene: also trace shadow rays (omaps trace --shadows)")
    r.add_argument("--camera", metavar="X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ] | gltf[:N]",
                   help="a scene's traced view, as omaps trace --camera (write --camera=VALUE for a value "
                        "starting with '-'); the 3D view starts there. Default: omaps trace's")
    r.add_argument("--no-3d", action="store_true", help="a scene: no 3D view (tables and pictures only)")
    r.add_argument("--min-size", type=int, default=0, metavar="PX",
                   help="a folder: skip textures with a side below PX (default: %(default)s)")
    r.add_argument("--jobs", type=int, default=None, metavar="N", help="processes (default: all cores)")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    add_material_options(r)
    add_asset_options(r)
    r.set_defaults(func=cmd_report)


def cmd_report(a) -> int:
    from ..report import build_report

    check_count(a.jobs)
    check_file(a.output, "-o", (".html",), inputs=[a.input])
    if not os.path.exists(a.input):
        raise InputError("no such file or folder", a.input)
    size = parse_size(a.size)
    rules = material_rules(a)
    config = None
    if os.path.isdir(a.input):  # a corpus: the material options as omaps eval's
        from ..alpha_test import StateRule
        from ..corpus import EvalConfig

        config = EvalConfig(rule=StateRule("cutoff", cutoff=a.cutoff) if a.cutoff is not None else StateRule(),
                            filter=a.filter or "nearest", wrap=a.wrap or "clamp")
    res = build_report(a.input, a.output, a.schemes, size=size, shadows=a.shadows, camera=a.camera, jobs=a.jobs,
                       rules=rules, min_size=a.min_size, config=config, view=not a.no_3d,
                       progress=show_progress(a.quiet), **asset_options(a))
    t = res.timings
    steps = ", ".join(f"{k[:-2]} {v:.1f} s" for k, v in t.items() if k != "total_s")
    print(f"omaps report: {a.output}: {res.kind} report, {res.bytes / 2**20:.2f} MiB, {t['total_s']:.1f} s ({steps})")
    if res.kind == "scene":
        for name, r in res.numbers["schemes"].items():
            print(f"  {name:12s} {r['alpha_tests_per_primary_ray']:.4f} alpha tests per primary ray, "
                  f"{r.get('map_bytes', 0):,} map bytes")
        if not res.numbers["passed"]:
            print("omaps: a scheme changed the visible result: " + ", ".join(res.numbers["changed_visible_result"]))
            return 1
    else:
        for name, m in res.numbers["mean"].items():
            print(f"  {name:12s} mean savings {m['savings']:.4f}, {m['bits']:g} bits per pair")
    return 0
