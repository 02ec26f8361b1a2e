"""``build_report``: one self-contained HTML page for a glTF scene or a texture corpus."""

from __future__ import annotations

import base64
import os
import tempfile
import time
from dataclasses import dataclass, field

from ..errors import InputError
from . import page as pg

__all__ = ["build_report", "ReportResult", "SCENE_SUFFIXES"]

from ..scene.files import SCENE_SUFFIXES  # (glTF and OpenUSD)


@dataclass
class ReportResult:
    """What ``build_report`` wrote.

    Attributes
    ----------
    path : str
        The HTML file.
    kind : {"scene", "corpus"}
        What the input was.
    bytes : int
        The file's size.
    timings : dict
        Seconds per step (``trace_s`` or ``eval_s``, ``view_s``, ``pictures_s``, ``total_s``).
    numbers : dict
        The numbers shown, as the library returned them: for a scene the report of
        ``omaps.trace.trace_scene`` (what ``omaps trace --json`` writes); for a corpus what
        ``omaps eval --json`` writes (``omaps.corpus.report.to_json``).
    view : dict
        For a scene, per scheme drawn on the mesh: its atlas size and distinct triangle images.
    """

    path: str
    kind: str
    bytes: int
    timings: dict
    numbers: dict
    view: dict = field(default_factory=dict)


def _png_uri(path: str) -> str:
    with open(path, "rb") as f:
        return "data:image/png;base64," + base64.b64encode(f.read()).decode()


def _check_output(output) -> str:
    from ..atomic import check_file

    return check_file(output, "-o", (".html",))


def build_report(input, output, schemes: str | None = None, *, size=512, shadows: bool = False, camera=None,
                 jobs: int | None = None, rules=None, min_size: int = 0, config=None, view: bool = True,
                 progress: bool = False, root=None, allow_outside: bool = False) -> ReportResult:
    """Write one self-contained HTML report (no network: scripts, styles and images inside) of a
    glTF scene or of a texture corpus.

    Parameters
    ----------
    input : str or path
        A ``.gltf`` / ``.glb`` scene (its stored micromaps and pair blocks are drawn as stored
        with the schemes ``omm`` and ``file:CODEC``), or a folder of textures (a corpus).
    output : str or path
        The ``.html`` file, written whole or not at all.
    schemes : str, optional
        Comma-separated schemes: for a scene those of ``omaps trace`` (default
        ``omaps.trace.DEFAULT_SCHEMES``; ``none`` is always traced), for a corpus those of
        ``omaps eval`` (default ``omaps.schemes.DEFAULT_SCHEMES``).
    size : int or (int, int)
        A scene's traced image size (as ``omaps trace --size``).
    shadows : bool
        Also trace shadow rays (``omaps trace --shadows``).
    camera : str, Camera or int, optional
        The traced view (``omaps trace --camera``); the 3D view starts there.
    jobs : int, optional
        Processes for baking, encoding and evaluating (default: all cores).
    rules : omaps.alpha_test.MaterialRules, optional
        How a scene's materials are alpha-tested (as ``omaps trace``'s material options).
    min_size : int
        A corpus's smallest texture side evaluated (``omaps eval --min-size``).
    config : omaps.corpus.EvalConfig, optional
        A corpus's state rule, filter and wrap.
    view : bool
        Draw a scene's 3D view (False: tables and pictures only).
    progress : bool
        Progress bars on stderr.
    root, allow_outside : optional
        Where the files a scene names may lie (``omaps.load_scene``'s URI policy).

    Returns
    -------
    ReportResult

    Raises
    ------
    InputError
        For an input that is neither a scene nor a folder of textures, or a bad option; nothing
        is written.

    Examples
    --------
    >>> from omaps.report import build_report                                   # doctest: +SKIP
    >>> r = build_report("palm.glb", "palm.html", "none,tri3,vq4", size=128)    # doctest: +SKIP
    >>> r.numbers["schemes"]["vq4"]["alpha_tests_per_primary_ray"]             # doctest: +SKIP
    """
    t0 = time.perf_counter()
    src = os.fspath(input)
    out = _check_output(output)
    if os.path.isdir(src):
        kind = "corpus"
    elif src.lower().endswith(SCENE_SUFFIXES):
        if not os.path.isfile(src):
            raise InputError("no such file", src)
        kind = "scene"
    elif os.path.exists(src):
        raise InputError("is neither a scene (.gltf, .glb, .usd, .usda, .usdc, .usdz) nor a folder of textures", src)
    else:
        raise InputError("no such file or folder", src)
    if os.path.exists(out) and os.path.exists(src) and os.path.samefile(out, src):
        raise InputError("is also the input", os.fspath(output))
    if kind == "scene":
        text, numbers, timings, info = _scene_page(src, schemes, size, shadows, camera, jobs, rules, view, progress,
                                                   {"root": root, "allow_outside": allow_outside})
    else:
        from .corpus import corpus_page

        text, numbers, timings = corpus_page(src, schemes, min_size, config, jobs, progress)
        info = {}
    from ..atomic import write_text

    write_text(out, text)
    timings["total_s"] = time.perf_counter() - t0
    return ReportResult(out, kind, os.path.getsize(out), timings, numbers, info)


def _names(names: list, most: int = 4) -> str:
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


def _materials_text(report: dict, prep) -> str:
    """How the alpha-tested materials were tested: which settings the options replaced, then per
    group of materials alike the mode, cutoff, filter and wrap in effect."""
    import numpy as np

    from ..alpha_test import MaterialRules

    rules = MaterialRules(**report["settings"]["materials"])
    set_ = [f"{k} {v}" for k, v in (("cutoff", rules.cutoff), ("filter", rules.filter), ("wrap", rules.wrap))
            if v is not None]
    head = ("the scene's own per-material settings (none overridden)" if not set_ else
            f"{', '.join(set_)} for every material (overridden), the rest each material's own")
    scene = prep.scene
    used = sorted({int(m) for m in np.unique(prep.alpha.material)}) if len(prep.alpha.material) else []
    groups: dict = {}
    for m in used:
        mat = scene.materials[m]
        if mat.alpha_mode == "BLEND":
            mode = f"BLEND, blend rule {rules.blend}, blend cutoff {rules.blend_cutoff:g}"
        else:
            mode = f"MASK, cutoff {rules.cutoff if rules.cutoff is not None else mat.cutoff:g}"
        wrap_u, wrap_v = rules.wrap or mat.wrap_u, rules.wrap or mat.wrap_v
        wrap = wrap_u if wrap_u == wrap_v else f"{wrap_u} (u), {wrap_v} (v)"
        groups.setdefault(f"{mode}, filter {rules.filter or mat.filter}, wrap mode {wrap}", []).append(
            mat.name or f"#{m}")
    parts = [f"{pg.esc(_names(names))}: {pg.esc(what)}" for what, names in groups.items()]
    skipped = [mat.name or f"#{k}" for k, mat in enumerate(scene.materials)
               if mat.alpha_mode == "BLEND" and rules.blend == "skip"]
    if skipped:
        parts.append(f"{pg.esc(_names(skipped))}: BLEND, treated as opaque (blend skip)")
    return f"materials: {pg.esc(head)} ({'; '.join(parts) if parts else 'no alpha-tested material'})"


def _settings_text(report: dict, prep) -> str:
    st, cam = report["settings"], report["camera"]
    view = cam.get("view") or {}
    parts = [f"schemes <code>{pg.esc(','.join(st['schemes']))}</code>",
             f"image {cam['width']}x{cam['height']}",
             f"camera <code>{pg.esc(','.join(f'{x:g}' for x in cam['eye']))}:"
             f"{pg.esc(','.join(f'{x:g}' for x in cam['target']))}:{cam['fov']:g}</code>"
             + (f" ({pg.esc(view.get('chosen', ''))})" if view.get("chosen") else ""),
             f"shadows {'on' if st['shadows'] else 'off'}",
             _materials_text(report, prep),
             f"Embree {pg.esc(report['embree'])}"]
    return "; ".join(parts)


def _scene_table(report: dict, names: list) -> str:
    shadows = report["settings"]["shadows"]
    heads = [("scheme", "the scheme's maps"),
             ("alpha tests / primary ray", "any-hit shader calls per primary ray (alpha_tests_per_primary_ray)"),
             ("candidates / ray", "candidate hits on alpha-tested triangles per primary ray"),
             ("none / scheme", "alpha tests of none over this scheme's")]
    if shadows:
        heads += [("alpha tests / shadow ray", "any-hit calls per shadow ray, traced normally"),
                  ("deferred", "per shadow ray with deferred C: an O hit looked for first")]
    heads += [("map bytes", "every prototype pair's (or triangle's) map, as a BLAS stores them"),
              ("distinct maps", "maps stored once however many pairs use them"),
              ("known", "mean share of T or O regions (hits without an any-hit call)"),
              ("differing pixels", "pixels (and shadow rays) whose result differs from none: must be 0")]
    rows = []
    for n in names:
        r = report["schemes"][n]
        row = [pg.esc(n), (f"{r['alpha_tests_per_primary_ray']:.4f}", r["alpha_tests_per_primary_ray"]),
               (f"{r['candidates_per_primary_ray']:.4f}", r["candidates_per_primary_ray"]),
               (f"{r['none_over_scheme_alpha_tests']:.2f}" if r["none_over_scheme_alpha_tests"] else "-",
                r["none_over_scheme_alpha_tests"])]
        if shadows:
            row += [(f"{r['alpha_tests_per_shadow_ray']:.4f}", r["alpha_tests_per_shadow_ray"]),
                    (f"{r['deferred_alpha_tests_per_shadow_ray']:.4f}", r["deferred_alpha_tests_per_shadow_ray"])]
        differ = r["differing_pixels"] + r.get("differing_shadow_rays", 0) + r.get("deferred_differing_shadow_rays", 0)
        row += [(f"{r.get('map_bytes', 0):,}", r.get("map_bytes", 0)), (f"{r.get('distinct_maps', 0):,}",
                r.get("distinct_maps", 0)), (f"{r.get('known_fraction', 0):.1%}", r.get("known_fraction", 0)),
                (str(differ), differ)]
        rows.append(row)
    return pg.table(heads, rows, caption="Click a column to sort. Numbers as omaps.trace.trace_scene returns "
                    "them (omaps trace --json with the settings above).")


def _scene_page(src, schemes, size, shadows, camera, jobs, rules, view, progress, assets):
    from .. import __version__
    from ..trace import DEFAULT_SCHEMES, trace_scene
    from .view3d import scene_view

    timings = {}
    t = time.perf_counter()
    res = trace_scene(src, schemes or DEFAULT_SCHEMES, size=size, shadows=shadows, camera=camera, jobs=jobs,
                      rules=rules, progress=progress, **assets)
    timings["trace_s"] = time.perf_counter() - t
    report = res.report
    names = list(res.names)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="omaps-report-") as tmp:
        pics = {}
        for what in ("heatmap", "render", "plot_budget"):
            p = os.path.join(tmp, what + ".png")
            getattr(res, what)(p)
            pics[what] = _png_uri(p)
    timings["pictures_s"] = time.perf_counter() - t
    t = time.perf_counter()
    drawn = ["none"] + [n for n in names if n != "none"]
    data, info, overlays = {}, {}, {}
    if view:
        data["view"], overlays = scene_view(res.prep, drawn, res.camera)
        data["view"]["initial"] = next((n for n in drawn if n != "none"), "none")
        info = {s["name"]: {"res": s["res"], "width": s["width"], "height": s["height"], "distinct": s["distinct"]}
                for s in data["view"]["schemes"]}
    timings["view_s"] = time.perf_counter() - t
    data["trace"] = report
    s = report["scene"]
    name = os.path.basename(src)
    body = [f"<h1>omaps report: {pg.esc(name)}</h1>",
            f"<p class=\"settings\">{pg.esc(src)}: {s['instances']:,} instances of {s['prototypes']:,} meshes, "
            f"{s['triangles']:,} triangles ({s['alpha_triangles']:,} alpha-tested); {s['pairs']:,} prototype pairs, "
            f"{s['paired_fraction']:.1%} of alpha triangles paired. omaps {pg.esc(__version__)}.</p>",
            f"<p class=\"settings\">Settings: {_settings_text(report, res.prep)}.</p>",
            "<p class=\"key\">States:<span style=\"background:#0ff\"></span>T transparent (hit ignored)"
            "<span style=\"background:#f0f\"></span>O opaque (hit accepted)"
            "<span style=\"background:#00c800\"></span>C check (any-hit shader runs)</p>",
            "<h2>Alpha tests per ray</h2>", _scene_table(report, names)]
    if not report["passed"]:
        body.append("<p><strong>A scheme changed the visible result</strong>: "
                    f"{pg.esc(report['changed_visible_result'])}</p>")
    if view:
        options = "".join(f"<option value=\"{pg.esc(n)}\">{pg.esc(n)}</option>" for n in drawn)
        body += ["<h2>3D view: map states on the mesh</h2>",
                 "<div class=\"controls\"><label>scheme <select id=\"scheme-select\">" + options + "</select></label>"
                 "<label><input type=\"radio\" name=\"mode\" value=\"states\" checked> map states</label>"
                 "<label><input type=\"radio\" name=\"mode\" value=\"alpha\"> alpha texture</label>"
                 "<label><input type=\"radio\" name=\"mode\" value=\"texture\"> alpha-tested texture</label>"
                 "<button id=\"reset-view\">traced view</button><span id=\"scheme-info\"></span></div>",
                 "<div id=\"viewer\"><canvas id=\"view3d\"></canvas></div>",
                 "<p class=\"settings\">Drag to orbit, scroll to zoom, right-drag to pan. Each alpha-tested "
                 "triangle shows the states the tracer's any-hit filter reads from the scheme's stored maps; "
                 "instances of a mesh are drawn from one copy.</p>"]
    body += ["<h2>Pictures</h2>",
             pg.figure(pics["heatmap"], "Alpha tests per pixel, none beside each scheme on one colour scale.",
                       "heat map", "wide"),
             pg.figure(pics["render"], "The alpha-tested render of the traced view.", "render"),
             pg.figure(pics["plot_budget"], "Alpha tests per primary ray against map bytes, every scheme.",
                       "alpha tests against bytes")]
    if overlays:
        body.append("<h2>Materials: map states over the UV layout</h2><div class=\"materials\">")
        first = data["view"]["initial"]
        import json

        for m, per in overlays.items():
            mat = data["view"]["materials"][m]
            body.append(f"<figure><img src=\"{per[first]}\" data-scheme-images=\"{pg.esc(json.dumps(per))}\" "
                        f"alt=\"material {pg.esc(mat['name'])}\"><figcaption>material {m} "
                        f"({pg.esc(mat['name'])}): its alpha texture in grey (white opaque, black "
                        "transparent); over its triangles' UVs, the states of the scheme chosen above "
                        "blended in: cyan T, magenta O, green C, lighter over opaque texels and darker "
                        "over transparent ones</figcaption></figure>")
        body.append("</div>")
    text = pg.page(f"omaps report: {name}", "\n".join(body), data, three=view)
    return text, report, timings, info
