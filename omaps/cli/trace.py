"""``omaps trace SCENE``: alpha tests per ray on a glTF scene, per scheme, with pictures.

A thin layer over ``omaps.trace``: parse options, prepare (pair, bake, store, build the
Embree scene), trace ``none`` (always: it is the reference every scheme must match) and each
scheme, then print a table and write the JSON, heat map and render asked for.
"""

from __future__ import annotations

import argparse
import sys

from ..atomic import Outputs
from ..names import BUDGET_WEIGHTS
from .common import (BUDGET_DEFAULTS, CODECS, add_asset_options, add_codec_options, add_material_options, asset_options,
                     material_rules, parse_size, show_progress)

from ..trace.camera import DEFAULT_LIGHT
from ..trace.experiment import DEFAULT_SCHEMES
from ..trace.timing import TIMING_ROUNDS

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
with --memory, a second table says what each lookup of the primary pass reads (docs/FORMAT.md, "What a
lookup reads"): lookups/ray (filter calls per primary ray), tex lines (distinct 64-byte lines of alpha
texture per primary ray that the alpha tests the map leaves fetch: the filter's taps on mip level 0,
RGBA8 texels in 4x4 tiles, one line per tile), then per layout -- own (each pair's or triangle's map
stored with it, as map KiB counts it) and shared (identical maps once, behind a 32-bit index per pair
or triangle; for triL the standard OMMs omaps omm writes: index buffer, record, data, special
indices) -- KiB (its map bytes), reads (dependent reads per lookup), lines (distinct 64-byte lines of
map data per primary ray), total (lines plus tex lines) and, with --cache-kib K, misses (per primary
ray, of a K KiB LRU cache shared by each 8x8 tile of pixels).
"""


def add_parser(sub) -> None:
    t = sub.add_parser("trace", help="ray trace a scene (glTF, OpenUSD): alpha tests per ray with each scheme's "
                       "maps",
                       description="Trace primary (and shadow) rays through a glTF 2.0 scene or an OpenUSD stage "
                                   "with Embree; "
                                   "each scheme's maps are read in the any-hit filter, and every scheme's "
                                   "visible result is checked against 'none' (every candidate alpha-tested).",
                       epilog=TABLE_HELP.format(rounds=TIMING_ROUNDS),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    t.add_argument("scene", metavar="SCENE", help=".gltf, .glb, .usd, .usda, .usdc or .usdz file")
    t.add_argument("--schemes", default=DEFAULT_SCHEMES,
                   help="comma-separated: none, triL (or succinctL, csmL: the same micromaps as lossless trees), sqN, "
                        f"or a codec ({CODECS}; also with -fast, -medium or -thorough where it has efforts, "
                        "and -paper where it has the deck's encoder), omm, file:CODEC or file:csm (the maps the traced file stores), or "
                        f"budget:BYTES (per pair the map -- none, {BUDGET_DEFAULTS} -- that saves the "
                        "most alpha tests per byte, every pair together within BYTES: 1263936, 1.2MiB, 800KiB) "
                        "(default: %(default)s)")
    t.add_argument("--weights", choices=BUDGET_WEIGHTS, default=BUDGET_WEIGHTS[0],
                   help="budget schemes: a pair's expected candidate hits are its triangles' world area times "
                        "instances (area: rays uniform over the scene), or their candidate hits in a trace of "
                        "this view at half the resolution (view) (default: %(default)s)")
    t.add_argument("--plot-budget", metavar="FILE.png",
                   help="alpha tests per primary ray against map bytes, every traced scheme on one chart")
    t.add_argument("--memory", action="store_true",
                   help="also model the map data each lookup reads: dependent reads per lookup and 64-byte lines "
                        "per primary ray, per scheme in its own and its shared (indexed) layout, and the lines of "
                        "alpha texture its alpha tests read, alone and added to the map lines")
    t.add_argument("--cache-kib", type=float, default=None, metavar="K",
                   help="with --memory: also the misses per primary ray of a K KiB LRU cache (64-byte lines) "
                        "shared by each 8x8 tile of pixels, empty at each tile")
    t.add_argument("--plot-frontier", metavar="FILE.png",
                   help="alpha tests per primary ray against map bytes (and, with --memory, against map lines "
                        "and map + texture lines read per ray), every traced scheme, the Pareto front marked")
    t.add_argument("--camera", metavar="X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ] | gltf[:N]",
                   help="eye, target, vertical field of view in degrees and optionally the up direction "
                        "(default +Y); or 'gltf:N', the file's camera N (default 0) placed by its node (a USD stage: its "
                        "Nth camera prim), with "
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
    add_asset_options(t)
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


def cmd_trace(a) -> int:
    from ..trace import trace_scene

    options = trace_options(a)  # the library checks them all before any work
    outputs = Outputs(inputs=[a.scene])
    outputs.file(a.json, "--json")
    outputs.file(a.heatmap, "--heatmap", (".png",))
    outputs.file(a.render, "--render", (".png",))
    outputs.file(a.plot_budget, "--plot-budget", (".png",))
    outputs.file(a.plot_frontier, "--plot-frontier", (".png",))
    res = trace_scene(a.scene, **options, progress=show_progress(a.quiet))
    print(res.table())
    # a failed check still writes every output asked for, complete, and says so (then exit 1)
    with outputs.writing():  # all renamed into place together at the end
        if a.json:
            res.write_json(outputs.path(a.json))
        if a.heatmap:
            res.heatmap(outputs.path(a.heatmap))
        if a.render:
            res.render(outputs.path(a.render))
        if a.plot_budget:
            res.plot_budget(outputs.path(a.plot_budget))
        if a.plot_frontier:
            res.plot_frontier(outputs.path(a.plot_frontier))
    for m in res.messages():
        print(m, file=sys.stderr)
    return 0 if res.passed else 1


def trace_options(a) -> dict:
    """``trace_scene``'s keyword arguments from the command line (``omaps batch trace`` too)."""
    return dict(schemes=a.schemes, size=parse_size(a.size), camera=a.camera, shadows=a.shadows, light=a.light,
                weights=a.weights, two_state=a.two_state, rules=material_rules(a), jobs=a.jobs, encoder=a.encoder,
                effort=a.effort, memory=a.memory, cache_kib=a.cache_kib, **asset_options(a))
