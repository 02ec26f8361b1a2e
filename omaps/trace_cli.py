"""``omaps trace SCENE``: alpha tests per ray on a glTF scene, per scheme, with pictures.

A thin layer over ``omaps.trace``: parse options, prepare (pair, bake, encode, build the
Embree scene), trace ``none`` (always: it is the reference every scheme must match) and each
scheme, then print a table and write the JSON, heat map and render asked for.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings

import numpy as np

from .errors import InputError

DEFAULT_SCHEMES = "none,tri3,sq16,vq2,vq4,vq4x64"
DEFAULT_LIGHT = (0.45, 0.8, 0.4)  # towards the sun: high enough to light the ground, low enough to cross crowns
SHADOW_TNEAR = 1e-5  # shadow ray start, as a fraction of the scene's diagonal


def add_parser(sub) -> None:
    t = sub.add_parser("trace", help="ray trace a glTF scene: alpha tests per ray with each scheme's maps",
                       description="Trace primary (and shadow) rays through a glTF 2.0 scene with Embree; "
                                   "each scheme's maps are read in the any-hit filter, and every scheme's "
                                   "visible result is checked against 'none' (every candidate alpha-tested).")
    t.add_argument("scene", metavar="SCENE", help=".gltf or .glb file")
    t.add_argument("--schemes", default=None,
                   help="comma-separated: none, sqN, triL, or a codec (vq2, vq4, vq4x64) (default: "
                        f"{DEFAULT_SCHEMES}, those of its codecs that this installation has)")
    t.add_argument("--camera", metavar="X,Y,Z:TX,TY,TZ:FOV",
                   help="eye, target and vertical field of view in degrees (default: a low grazing view "
                        "across the scene bounds)")
    t.add_argument("--size", default="512", metavar="W[xH]", help="image size (default: %(default)s)")
    t.add_argument("--shadows", action="store_true",
                   help="also trace shadow rays to a directional light, normally and with deferred C tests")
    t.add_argument("--light", metavar="X,Y,Z", help=f"direction towards the light (default: {DEFAULT_LIGHT})")
    t.add_argument("--blend-cutoff", type=float, default=0.5, metavar="A",
                   help="alpha cut-off for BLEND materials, treated as alpha-tested (default: %(default)s)")
    t.add_argument("--effort", default="medium", help="codec encoder effort (default: %(default)s)")
    t.add_argument("--jobs", type=int, default=None, metavar="N", help="processes for baking and encoding "
                   "(default: all cores)")
    t.add_argument("--two-state", metavar="MODES", default=None,
                   help="also trace each square or codec scheme with its C cells resolved to O or T (no "
                        "alpha tests; not exact) by these comma-separated rules: nearest, opaque, "
                        "transparent, hashed, or 'all'; reports the per-pixel coverage error")
    t.add_argument("--json", metavar="FILE", help="write the results as JSON")
    t.add_argument("--heatmap", metavar="FILE.png", help="alpha tests per pixel, 'none' beside each scheme")
    t.add_argument("--render", metavar="FILE.png", help="the alpha-tested albedo image")
    t.add_argument("--quiet", action="store_true", help="no progress bars")
    t.set_defaults(func=cmd_trace)


def default_schemes() -> str:
    from .codecs.registry import codec_names

    known = set(codec_names())
    return ",".join(n for n in DEFAULT_SCHEMES.split(",") if not n.startswith("vq") or n in known)


def parse_size(text: str) -> tuple[int, int]:
    parts = str(text).lower().split("x")
    try:
        w = int(parts[0])
        h = int(parts[1]) if len(parts) == 2 else w
    except (ValueError, IndexError):
        raise InputError(f"--size must be W or WxH, got {text!r}") from None
    if len(parts) > 2 or not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise InputError(f"--size must be W or WxH with sides 1..8192, got {text!r}")
    return w, h


def _floats(text: str, n: int, what: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")], dtype=np.float64)
    except ValueError:
        raise InputError(f"{what}: expected {n} comma-separated numbers, got {text!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what}: expected {n} finite comma-separated numbers, got {text!r}")
    return v


def parse_camera(text: str):
    from .trace import Camera

    parts = text.split(":")
    if len(parts) != 3:
        raise InputError(f"--camera must be X,Y,Z:TX,TY,TZ:FOV, got {text!r}")
    eye = _floats(parts[0], 3, "--camera eye")
    target = _floats(parts[1], 3, "--camera target")
    fov = _floats(parts[2], 1, "--camera fov")[0]
    if not 0 < fov < 180:
        raise InputError(f"--camera field of view must be in (0, 180) degrees, got {fov}")
    if np.allclose(eye, target):
        raise InputError("--camera eye and target must differ")
    return Camera(eye, target, float(fov))


def parse_light(text: str | None) -> np.ndarray:
    v = np.asarray(DEFAULT_LIGHT, np.float64) if text is None else _floats(text, 3, "--light")
    n = np.linalg.norm(v)
    if n == 0:
        raise InputError("--light must not be the zero vector")
    return v / n


def cmd_trace(a) -> int:
    from . import scene_maps, trace
    from .scene import SceneWarning, load_scene

    names = scene_maps.parse_trace_schemes(a.schemes or default_schemes())
    modes = parse_two_state(a.two_state)
    w, h = parse_size(a.size)
    if a.jobs is not None and a.jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {a.jobs}")
    light = parse_light(a.light) if a.shadows else None
    cam_given = parse_camera(a.camera) if a.camera else None
    progress = not a.quiet and sys.stderr.isatty()
    t_start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)  # printed below, once each
        scene = load_scene(a.scene, a.blend_cutoff)
    for msg in scene.warnings:
        print(f"omaps: warning: {a.scene}: {msg}", file=sys.stderr)
    t_load = time.perf_counter() - t_start
    traced = ["none"] + [n for n in names if n != "none"]
    prep = trace.prepare(scene, traced, scene_maps.default_jobs(a.jobs), a.effort, progress)
    bounds = scene.bounds()
    camera = cam_given or trace.default_camera(bounds)
    cam = camera.basis(w, h)
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    tnear = SHADOW_TNEAR * diag
    trace.trace_scheme(prep, None, cam, 2, 2, light, tnear, deferred=a.shadows)  # compile the ray loops
    from tqdm import tqdm

    runs = {}
    for n in tqdm(traced, desc="trace", unit="scheme", disable=not progress, leave=False):
        runs[n] = trace.trace_scheme(prep, n, cam, w, h, light, tnear, deferred=a.shadows)
    opaque = trace.trace_scheme(prep, None, cam, w, h, light, tnear)
    ref = runs["none"]
    two_state = _trace_two_state(prep, names, modes, cam, w, h, ref) if modes else {}
    total = time.perf_counter() - t_start
    report = {
        "scene": {"file": a.scene, **scene.counts(), "paired_fraction": prep.alpha.paired_fraction,
                  "pairs": int(len(prep.alpha.pair_first)), "bounds": bounds.tolist(),
                  "warnings": list(scene.warnings)},
        "camera": {**camera.to_json(), "width": w, "height": h},
        "light": None if light is None else light.tolist(),
        "embree": prep.device.version_text,
        "schemes": {n: trace.summary(runs[n], ref, prep.maps[n], w, h) for n in names},
        "opaque_only": trace.summary(opaque, ref, None, w, h),
        "two_state": two_state,
        "timings": {"load_s": t_load, **prep.timings, "total_s": total},
    }
    none_tests = report["schemes"]["none"]["alpha_tests_per_primary_ray"] if "none" in names else \
        trace.summary(ref, ref, prep.maps["none"], w, h)["alpha_tests_per_primary_ray"]
    for n, r in report["schemes"].items():
        t = r["alpha_tests_per_primary_ray"]
        r["none_over_scheme_alpha_tests"] = none_tests / t if t else None
        r["rays_per_second_over_opaque"] = (r["rays_per_second"] / report["opaque_only"]["rays_per_second"]
                                            if r["rays_per_second"] else None)
    bad = {n: r["differing_pixels"] + r.get("differing_shadow_rays", 0) + r.get("deferred_differing_shadow_rays", 0)
           for n, r in report["schemes"].items()}
    _print_report(report, names, a.shadows)
    if two_state:
        _print_two_state(two_state)
    if a.json:
        from .atomic import write_text
        write_text(a.json, json.dumps(report, indent=1))
    if a.heatmap:
        heatmap(a.heatmap, runs, names, a.shadows)
    if a.render:
        render(a.render, prep, runs["none"], cam, light)
    if any(bad.values()):
        print("omaps: error: a scheme changed the visible result: " +
              ", ".join(f"{n} ({v})" for n, v in bad.items() if v), file=sys.stderr)
        return 1
    return 0


def parse_two_state(text: str | None) -> list[str]:
    from .two_state import MODES

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
    from . import trace
    from .two_state import coverage_error, two_state_maps

    out: dict = {}
    cache: dict = {}
    for n in names:
        sm = prep.maps[n]
        if sm.kind not in ("square", "codec"):
            continue
        out[n] = {}
        for mode in modes:
            sm2 = two_state_maps(prep.scene, prep.alpha, sm, mode, cache=cache)
            prep.maps[sm2.name] = sm2
            run = trace.trace_scheme(prep, sm2.name, cam, w, h)
            out[n][mode] = coverage_error(run, ref)
            del prep.maps[sm2.name]
    return out


def _print_two_state(two_state: dict) -> None:
    print("2-state (C cells resolved, no alpha tests): pixels whose visible hit differs from 'none' "
          "(stopped early / passed through)")
    for n, by_mode in two_state.items():
        cells = [f"{m} {r['differing_fraction']:.2%} ({r['stopped_early_fraction']:.2%}/"
                 f"{r['passed_through_fraction']:.2%})" for m, r in by_mode.items()]
        print(f"  {n:8} " + "   ".join(cells))


def _print_report(report: dict, names: list[str], shadows: bool) -> None:
    s = report["scene"]
    c = report["camera"]
    print(f"omaps trace: {s['file']}: {s['instances']} instances of {s['prototypes']} meshes, {s['triangles']:,} "
          f"triangles ({s['alpha_triangles']:,} alpha-tested); {s['pairs']:,} prototype pairs, "
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
               f"{r['rays_per_second'] / 1e6:.2f}", f"{r['rays_per_second_over_opaque']:.2f}",
               f"{r.get('map_bytes', 0) / 1024:.0f}"]
        if shadows:
            row[5:5] = [f"{r['alpha_tests_per_shadow_ray']:.3f}", f"{r['deferred_alpha_tests_per_shadow_ray']:.3f}",
                        f"{r['deferred_tests_saved_fraction']:.1%}"]
        rows.append(row)
    widths = [max(len(x[i]) for x in rows + [cols]) for i in range(len(cols))]
    for r in [cols] + rows:
        print("  ".join(v.rjust(wd) if i else v.ljust(wd) for i, (v, wd) in enumerate(zip(r, widths))))
    o = report["opaque_only"]
    t = report["timings"]
    print(f"opaque-only traversal: {o['rays_per_second'] / 1e6:.2f} Mrays/s; total {t['total_s']:.1f} s "
          f"(load {t['load_s']:.1f}, pair {t['pair_s']:.1f}, bake+encode {t['bake_encode_s']:.1f}, "
          f"BVH {t['bvh_s']:.1f})")


def _tests_image(run, shadows: bool) -> np.ndarray:
    img = run.primary.tests.astype(np.float64)
    if shadows and run.shadow is not None:
        img = img + run.shadow.tests
    return img


def heatmap(path: str, runs: dict, names: list[str], shadows: bool) -> None:
    """Alpha tests per pixel, 'none' first then each scheme, one colour scale and a colour bar."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .atomic import atomic_path

    shown = ["none"] + [n for n in names if n != "none"]
    imgs = [_tests_image(runs[n], shadows) for n in shown]
    vmax = max(1.0, float(np.percentile(imgs[0], 99.5)))
    cols = min(len(shown), 4)
    rows = math.ceil(len(shown) / cols)
    h, w = imgs[0].shape
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols * w / h + 1.0, 3.4 * rows), squeeze=False,
                             constrained_layout=True)
    what = "primary + shadow" if shadows else "primary"
    for ax, n, img in zip(axes.flat, shown, imgs):
        im = ax.imshow(img, cmap="inferno", vmin=0, vmax=vmax, interpolation="nearest")
        ax.set_title(f"{n}: {img.mean():.2f} tests/pixel", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(shown):]:
        ax.axis("off")
    fig.colorbar(im, ax=axes, shrink=0.8, label=f"alpha tests per pixel ({what} rays)")
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def render(path: str, prep, run, cam: np.ndarray, light) -> None:
    """The alpha-tested albedo image (base colour, nearest texel), lit by |N.L| and the shadow
    rays when traced, over a sky colour."""
    from PIL import Image

    from .atomic import atomic_path

    scene = prep.scene
    p = run.primary
    h, w = p.inst.shape
    img = np.empty((h, w, 3), np.float64)
    img[:] = (0.62, 0.74, 0.90)
    hit = p.inst >= 0
    ys, xs = np.nonzero(hit)
    mesh = prep.proto_of_instance[p.inst[hit]]
    is_alpha = p.geom[hit] == 1
    prim = p.prim[hit].astype(np.int64)
    tri = np.empty(len(prim), np.int64)
    at = prep.alpha
    tri[is_alpha] = at.mesh_tri[at.base[mesh[is_alpha]] + prim[is_alpha]]
    op = ~is_alpha
    for k in np.unique(mesh[op]):
        sel = op & (mesh == k)
        tri[sel] = prep.opaque_tris[k][prim[sel]]
    b1 = p.u[hit].astype(np.float64)
    b2 = p.v[hit].astype(np.float64)
    colour = np.empty((len(tri), 3))
    shade = np.ones(len(tri))
    for k in np.unique(mesh):
        sel = mesh == k
        m = scene.meshes[k]
        vi = m.triangles[tri[sel]]
        uv = ((1 - b1[sel] - b2[sel])[:, None] * m.uvs[vi[:, 0]] + b1[sel][:, None] * m.uvs[vi[:, 1]]
              + b2[sel][:, None] * m.uvs[vi[:, 2]])
        mats = m.material[tri[sel]]
        col = np.empty((len(vi), 3))
        for mi in np.unique(mats):
            s2 = mats == mi
            mat = scene.materials[mi]
            c = np.asarray(mat.base_colour[:3], np.float64)
            if mat.texture >= 0:
                rgba = scene.textures[mat.texture].rgba
                th, tw = rgba.shape[:2]
                x = np.floor(uv[s2, 0] * tw).astype(np.int64) % tw
                y = np.floor(uv[s2, 1] * th).astype(np.int64) % th
                c = c * rgba[y, x, :3] / 255.0
            col[s2] = c
        colour[sel] = col
        if light is not None:
            pos = m.positions[vi].astype(np.float64)
            inst_m = np.stack([scene.instances[i][1] for i in p.inst[hit][sel]])
            n_obj = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
            n_world = np.einsum("nij,nj->ni", np.linalg.inv(inst_m[:, :3, :3]).transpose(0, 2, 1), n_obj)
            n_world /= np.maximum(np.linalg.norm(n_world, axis=1, keepdims=True), 1e-30)
            shade[sel] = np.abs(n_world @ light)
    if light is not None and run.shadow is not None:
        lit = run.shadow.occluded[hit] == 0
        shade = 0.3 + 0.7 * shade * lit
    img[ys, xs] = colour * shade[:, None]
    out = (np.clip(img, 0, 1) ** (1 / 1.6) * 255 + 0.5).astype(np.uint8)
    with atomic_path(path, suffix=".png") as tmp:
        Image.fromarray(out).save(tmp, format="PNG")
