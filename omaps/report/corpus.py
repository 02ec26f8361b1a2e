"""A corpus report: the savings chart, the mean table, and a sortable table of every texture with
its panels (the ``omaps eval --show`` picture), from ``omaps.corpus.evaluate_many``."""

from __future__ import annotations

import base64
import os
import tempfile
import time

from ..errors import InputError
from . import page as pg

__all__ = ["corpus_page"]


def _uri(path: str) -> str:
    with open(path, "rb") as f:
        return "data:image/png;base64," + base64.b64encode(f.read()).decode()


def corpus_page(folder: str, schemes: str | None, min_size: int = 0, config=None, jobs: int | None = None,
                progress: bool = False) -> tuple[str, dict, dict]:
    """The page of a texture folder: (HTML, the numbers as ``omaps eval --json`` writes them,
    timings)."""
    from .. import __version__
    from ..corpus import EvalConfig, evaluate_many
    from ..corpus.report import plot_savings, show_texture, to_json
    from ..schemes import DEFAULT_SCHEMES, EVAL_KINDS, parse_schemes
    from ..texture import find_images, without_alpha

    config = EvalConfig() if config is None else config
    parsed = parse_schemes(schemes or ",".join(DEFAULT_SCHEMES), EVAL_KINDS, config.encoder, config.effort,
                           "omaps report")
    names = [s.name for s in parsed]
    if min_size < 0:
        raise InputError(f"min_size must be >= 0, got {min_size}", param="min_size")
    items, _ = find_images([folder])
    no_alpha = []
    if config.channel is None:  # images that are not alpha masks (as omaps eval on a folder)
        why = [without_alpha(f) for f in items]
        no_alpha = [(f, w) for f, w in zip(items, why) if w is not None]
        items = [f for f, w in zip(items, why) if w is None]
    if not items:
        raise InputError("no image files found" if not no_alpha else
                         f"no image with an alpha channel found ({len(no_alpha)} without one)", folder)
    timings = {}
    t = time.perf_counter()
    unreadable: list = []
    results, small = evaluate_many(items, parsed, config, jobs, keep_maps=True, min_size=min_size,
                                   progress=progress, unreadable=unreadable)
    timings["eval_s"] = time.perf_counter() - t
    if not results:
        raise InputError("no texture could be read" if unreadable else f"no texture is at least {min_size} px", folder)
    settings = {"source": folder, **config.settings(), "min_size": min_size,
                "schemes": {s.name: s.settings() for s in parsed}}
    numbers = to_json(results, names, settings, unreadable)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="omaps-report-") as tmp:
        chart = os.path.join(tmp, "savings.png")
        plot_savings(chart, results, names, title=f"Savings on {os.path.basename(os.path.normpath(folder))}")
        chart_uri = _uri(chart)
        panels = []
        for i, r in enumerate(results):
            p = os.path.join(tmp, f"{i}.png")
            show_texture(p, r, panel=128)
            panels.append(_uri(p))
            r.maps.clear()
    timings["pictures_s"] = time.perf_counter() - t
    mean = numbers["mean"]
    head = [("scheme", "scheme"), ("bits per pair", "mean bits per pair"),
            ("mean savings", "mean share of hits without an any-hit call")]
    mean_rows = [[pg.esc(n), (f"{mean[n]['bits']:g}", mean[n]["bits"]),
                  (f"{mean[n]['savings']:.4f}", mean[n]["savings"])] for n in names]
    heads = [("texture", "file"), ("size", "width x height (sorts by texels)")] + [
        (n, f"savings of {n}") for n in names] + [("panels", "the alpha texture and each scheme's map")]
    rows = []
    for r, uri in zip(results, panels):
        rows.append([pg.esc(os.path.basename(r.name)), (f"{r.width}x{r.height}", r.width * r.height)]
                    + [(f"{r.savings[n]:.3f}", r.savings[n]) for n in names]
                    + [f"<img loading=\"lazy\" src=\"{uri}\" alt=\"maps of {pg.esc(os.path.basename(r.name))}\">"])
    st = numbers["settings"]
    body = [f"<h1>omaps report: {pg.esc(os.path.basename(os.path.normpath(folder)))}</h1>",
            f"<p class=\"settings\">{len(results)} textures from {pg.esc(folder)}"
            + (f"; {len(small)} smaller than {min_size} px skipped" if small else "")
            + (f"; {len(unreadable)} unreadable" if unreadable else "")
            + (f"; {len(no_alpha)} images without alpha skipped (not alpha masks)" if no_alpha else "")
            + f". Settings: rule {pg.esc(st.get('mode', ''))}, filter {pg.esc(st['filter'])}, wrap "
            f"{pg.esc(st['wrap'])}; schemes <code>{pg.esc(','.join(names))}</code>. omaps {pg.esc(__version__)}.</p>",
            "<p class=\"key\">States:<span style=\"background:#0ff\"></span>T"
            "<span style=\"background:#f0f\"></span>O<span style=\"background:#00c800\"></span>C</p>",
            "<h2>Savings against bits</h2>",
            pg.figure(chart_uri, "Mean savings (share of hits without an any-hit call) against bits per pair.",
                      "savings chart"),
            pg.table(head, mean_rows, caption="Means over the textures, each weighing the same "
                     "(omaps.corpus.evaluate_many)."),
            "<h2>Textures</h2>",
            pg.table(heads, rows, caption="Click a column to sort. Each texture covers the corpus pair.",
                     cls="sortable panel")]
    if no_alpha:
        body.append("<h2>Skipped: images without alpha</h2><ul>"
                    + "".join(f"<li>{pg.esc(p)}: {pg.esc(w)}</li>" for p, w in no_alpha) + "</ul>")
    if unreadable:
        body.append("<h2>Unreadable</h2><ul>" + "".join(f"<li>{pg.esc(p)}: {pg.esc(w)}</li>" for p, w in unreadable)
                    + "</ul>")
    return pg.page(f"omaps report: {folder}", "\n".join(body), {"eval": numbers}, three=False), numbers, timings
