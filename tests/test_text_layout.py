"""No clipped or overlapping text in what omaps draws: every matplotlib figure (heat maps,
charts, map pictures) is drawn with the Agg renderer it is saved with, and every text drawn --
titles, labels, tick labels, legends, point labels -- must lie inside the figure and off every
other text (touching within a pixel is allowed). The layouts are the ones users get: 1, 2, 3, 4,
6 and 8 schemes, with and without shadows, short and long scheme names. The HTML report is
opened in headless Chromium at a desktop size and its text boxes are checked the same way."""

from __future__ import annotations

import contextlib
import types
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from omaps.report.browser import find_chromium

CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium; "
                                    "or set OMAPS_CHROMIUM): the browser check is skipped")

TOUCH = 1.0  # pixels two text boxes may share, and a box may stand out of the figure


# ---- the check ----------------------------------------------------------------------------------

@contextlib.contextmanager
def drawn_text():
    """While inside: every figure drawn by Agg (``savefig`` to PNG, ``canvas.draw``) records the
    texts its latest draw drew -- (string, display box) -- and its size in pixels at that draw
    (``savefig``'s dpi). Yields the dict id(figure) -> (width, height, [(text, bbox)])."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    figures: dict = {}
    current: list = []
    text_draw, canvas_draw = Text.draw, FigureCanvasAgg.draw

    def record_text(self, renderer):
        out = text_draw(self, renderer)
        if current and self.get_visible() and self.get_text().strip():
            # (the text's own box: an annotation's would take in its leader line)
            current[-1][2][id(self)] = (self.get_text(), Text.get_window_extent(self, renderer).frozen())
        return out

    def record_canvas(self, *a, **k):
        fig = self.figure
        current.append((fig, fig.bbox.frozen(), {}))
        try:
            return canvas_draw(self, *a, **k)
        finally:
            f, box, texts = current.pop()
            figures[id(f)] = (box.width, box.height, list(texts.values()))

    with mock.patch.object(Text, "draw", record_text), mock.patch.object(FigureCanvasAgg, "draw", record_canvas):
        yield figures


def layout_problems(width: float, height: float, texts) -> list[str]:
    """Texts standing out of a width x height figure, and pairs of texts that overlap."""
    out = []
    for s, b in texts:
        if b.x0 < -TOUCH or b.y0 < -TOUCH or b.x1 > width + TOUCH or b.y1 > height + TOUCH:
            out.append(f"{s!r} at x {b.x0:.0f}..{b.x1:.0f}, y {b.y0:.0f}..{b.y1:.0f} is outside the "
                       f"{width:.0f}x{height:.0f} figure")
    for i, (s, a) in enumerate(texts):
        for t, b in texts[i + 1:]:
            w = min(a.x1, b.x1) - max(a.x0, b.x0)
            h = min(a.y1, b.y1) - max(a.y0, b.y0)
            if w > TOUCH and h > TOUCH:
                out.append(f"{s!r} and {t!r} overlap by {w:.0f}x{h:.0f} px")
    return out


def check_figures(figures: dict, at_least: int = 1) -> None:
    assert len(figures) >= at_least, "no figure was drawn"
    problems = []
    for width, height, texts in figures.values():
        assert texts, "a figure drew no text"
        problems += layout_problems(width, height, texts)
    assert problems == [], "\n".join(problems)


def test_the_check_finds_clipped_and_overlapping_text():
    """The check itself: a label longer than its figure and two titles on one spot are found."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with drawn_text() as figures:
        fig, ax = plt.subplots(figsize=(3, 2), dpi=100)
        ax.set_ylabel("a label far longer than this small figure is high, clipped at both ends")
        fig.text(0.5, 0.5, "first text")
        fig.text(0.52, 0.51, "second text")
        fig.canvas.draw()
        plt.close(fig)
    (width, height, texts), = figures.values()
    problems = layout_problems(width, height, texts)
    assert any("outside" in p and "a label far longer" in p for p in problems), problems
    assert any("'first text' and 'second text' overlap" in p for p in problems), problems
    assert not any("'first text'" in p and "outside" in p for p in problems)


# ---- heat maps ---------------------------------------------------------------------------------

SHORT = ["vq4", "tri3", "sq16", "vq2", "vq4x64", "wavelet3", "sq8"]
LONG = ["vq4x64-paper-thorough", "budget:1.2MiB", "file:vq4-paper", "succinct5", "vq4-synth-medium",
        "wavelet3-paper", "csm4"]


def fake_runs(names, shape, shadows):
    """Runs as ``heatmap`` reads them: per pixel alpha tests of the primary (and shadow) rays."""
    rng = np.random.default_rng(7)
    out = {}
    for n in names:
        primary = types.SimpleNamespace(tests=rng.integers(0, 14, shape))
        shadow = types.SimpleNamespace(tests=rng.integers(0, 6, shape)) if shadows else None
        out[n] = types.SimpleNamespace(primary=primary, shadow=shadow)
    return out


@pytest.mark.parametrize("shadows", [False, True], ids=["primary", "shadows"])
@pytest.mark.parametrize("count", [1, 2, 3, 4, 6, 8])
def test_heatmap(tmp_path, count, shadows):
    from omaps.trace.pictures import heatmap

    names = ["none"] + SHORT[:count - 1]
    with drawn_text() as figures:
        heatmap(str(tmp_path / "h.png"), fake_runs(names, (96, 128), shadows), names, shadows,
                "/data/scenes/palm.glb")
    check_figures(figures)


@pytest.mark.parametrize("count", [2, 3, 5])
def test_heatmap_long_names(tmp_path, count):
    from omaps.trace.pictures import heatmap

    names = ["none"] + LONG[:count - 1]
    with drawn_text() as figures:
        heatmap(str(tmp_path / "h.png"), fake_runs(names, (128, 128), True), names, True,
                "/data/scenes/a_scene_with_quite_a_long_file_name_of_its_own.glb")
    check_figures(figures)


# ---- trace charts ------------------------------------------------------------------------------

SCHEME_SETTINGS = {
    "tri3": {"kind": "micromap", "representation": "raw"}, "tri4": {"kind": "micromap", "representation": "raw"},
    "succinct4": {"kind": "micromap", "representation": "succinct"},
    "csm4": {"kind": "micromap", "representation": "csm"},
    "sq8": {"kind": "square", "codec": "sq8"}, "sq16": {"kind": "square", "codec": "sq16"},
    "vq2": {"kind": "square", "codec": "vq2"}, "vq4": {"kind": "square", "codec": "vq4"},
    "vq4x64-paper-thorough": {"kind": "square", "codec": "vq4x64-paper-thorough"},
    "budget:1.2MiB": {"kind": "budget"}, "budget:400KiB": {"kind": "budget"},
}


def trace_report(names, memory: bool) -> dict:
    """A report as ``omaps trace --json`` writes it, with made-up numbers (only the layout is checked)."""
    rng = np.random.default_rng(3)
    schemes = {"none": {"alpha_tests_per_primary_ray": 0.48, "map_bytes": 0}}
    for k, n in enumerate(names):
        size = int(4096 * 2 ** (k % 6) * rng.uniform(0.8, 1.2))
        r = {"alpha_tests_per_primary_ray": float(rng.uniform(0.1, 0.45)), "map_bytes": size}
        if memory and SCHEME_SETTINGS[n]["kind"] != "budget":
            lines = float(rng.uniform(0.2, 3.0))
            r["memory"] = {"own": {"map_bytes": size, "map_lines_per_ray": lines},
                           "shared": {"map_bytes": size // 3, "map_lines_per_ray": lines * 1.4}}
        schemes[n] = r
    return {"schemes": schemes, "settings": {"schemes": {n: SCHEME_SETTINGS[n] for n in names}},
            "camera": {"width": 512, "height": 512}, "scene": {"file": "/data/scenes/forest.glb"}}


CHART_SETS = {1: ["vq4"], 2: ["tri3", "vq4"], 3: ["tri3", "sq16", "vq4"], 4: ["tri3", "sq8", "vq2", "vq4"],
              6: ["tri3", "tri4", "sq8", "sq16", "vq2", "vq4"],
              9: ["tri3", "tri4", "succinct4", "csm4", "sq8", "sq16", "vq2", "vq4", "budget:400KiB"],
              "long": ["vq4x64-paper-thorough", "budget:1.2MiB", "succinct4", "csm4", "vq4"]}


@pytest.mark.parametrize("which", list(CHART_SETS))
def test_budget_plot(tmp_path, which):
    from omaps.trace.pictures import budget_plot

    with drawn_text() as figures:
        budget_plot(str(tmp_path / "b.png"), trace_report(CHART_SETS[which], memory=False))
    check_figures(figures)


@pytest.mark.parametrize("memory", [False, True], ids=["bytes", "lines"])
@pytest.mark.parametrize("which", list(CHART_SETS))
def test_frontier_plot(tmp_path, which, memory):
    from omaps.trace.pictures import frontier_plot

    with drawn_text() as figures:
        frontier_plot(str(tmp_path / "f.png"), trace_report(CHART_SETS[which], memory))
    check_figures(figures)


# ---- eval: the savings chart, the map pictures ---------------------------------------------------

EVAL_SETS = {1: ["vq4"], 2: ["sq8", "vq4"], 3: ["sq8", "tri3", "vq4"], 4: ["sq8", "sq16", "tri3", "vq4"],
             6: ["sq4", "sq8", "sq16", "tri2", "tri3", "vq4", "texel"],
             12: ["sq4", "sq8", "sq16", "tri2", "tri3", "tri4", "vq2", "vq4", "vq4x64", "wavelet3", "vq4-paper",
                  "succinct3", "csm3", "texel"]}


def texture_results(names, n=3, maps=False):
    from omaps.corpus.evaluate import TextureResult
    from omaps.schemes import get_scheme

    rng = np.random.default_rng(5)
    out = []
    for i in range(n):
        res = TextureResult(name=f"textures/leaf_cluster_with_a_long_name_{i:02d}.png", width=256, height=128,
                            savings={s: float(rng.uniform(0.3, 0.95)) for s in names},
                            bits={s: 2 ** (4 + k % 9) for k, s in enumerate(names)})
        if maps:
            for s in names:
                kind = get_scheme(s).kind
                res.maps[s] = (rng.integers(0, 3, (2, 4 ** 3)) if kind == "micromap"
                               else rng.integers(0, 3, (16, 16))).astype(np.uint8)
            res.alpha = rng.uniform(0, 1, (128, 256))
        out.append(res)
    return out


@pytest.mark.parametrize("which", list(EVAL_SETS))
def test_savings_chart(tmp_path, which):
    from omaps.corpus.report import plot_savings

    names = EVAL_SETS[which]
    with drawn_text() as figures:
        plot_savings(tmp_path / "s.png", texture_results(names), names,
                     title="Savings on a_corpus_folder_with_a_long_name")
    check_figures(figures)


@pytest.mark.parametrize("which", [1, 3, 6])
def test_show_texture(tmp_path, which):
    from omaps.corpus.report import show_texture

    names = [n for n in EVAL_SETS[which] if n != "texel"]
    with drawn_text() as figures:
        show_texture(tmp_path / "t.png", texture_results(names, n=1, maps=True)[0])
    check_figures(figures)


@pytest.mark.parametrize("shape", [(16, 16), (64, 32), (8, 64)])
def test_map_picture(tmp_path, shape):
    from omaps.drawing import map_picture

    states = np.random.default_rng(1).integers(0, 3, shape).astype(np.uint8)
    with drawn_text() as figures:
        map_picture(tmp_path / "m.png", states, "/data/maps/a_map_file_with_a_long_name.omap", "vq4x64-paper")
    check_figures(figures)


# ---- the HTML report ---------------------------------------------------------------------------

TEXT_BOXES_JS = r"""(() => {
  // every visible text on the page, a box per line it is laid out on
  const out = [];
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    if (!node.textContent.trim()) continue;
    const el = node.parentElement;
    if (!el || el.closest("script, style, select, option, [hidden]")) continue;
    const css = getComputedStyle(el);
    if (css.display === "none" || css.visibility !== "visible" || Number(css.opacity) === 0) continue;
    const range = document.createRange();
    range.selectNodeContents(node);
    for (const r of range.getClientRects()) {
      if (r.width < 0.5 || r.height < 0.5) continue;
      out.push({text: node.textContent.trim().slice(0, 60), tag: el.tagName.toLowerCase(),
                x0: r.left + scrollX, y0: r.top + scrollY, x1: r.right + scrollX, y1: r.bottom + scrollY});
    }
  }
  return {boxes: out, width: document.documentElement.clientWidth,
          scrollWidth: document.documentElement.scrollWidth, height: document.documentElement.scrollHeight};
})()"""


def page_problems(found: dict) -> list[str]:
    """Texts outside the page (left of it, beyond the viewport's width, above or below it), and
    pairs of texts that overlap."""
    out = []
    if found["scrollWidth"] > found["width"] + TOUCH:
        out.append(f"the page is {found['scrollWidth']} px wide in a {found['width']} px viewport")
    boxes = found["boxes"]
    for b in boxes:
        if b["x0"] < -TOUCH or b["y0"] < -TOUCH or b["x1"] > found["width"] + TOUCH \
                or b["y1"] > found["height"] + TOUCH:
            out.append(f"{b['tag']} {b['text']!r} at x {b['x0']:.0f}..{b['x1']:.0f}, y {b['y0']:.0f}..{b['y1']:.0f}"
                       " is outside the page")
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            w = min(a["x1"], b["x1"]) - max(a["x0"], b["x0"])
            h = min(a["y1"], b["y1"]) - max(a["y0"], b["y0"])
            if w > TOUCH and h > TOUCH:
                out.append(f"{a['tag']} {a['text']!r} and {b['tag']} {b['text']!r} overlap by {w:.0f}x{h:.0f} px")
    return out


def text_boxes(path, width=1440, height=900) -> dict:
    from omaps.report.browser import open_page

    with open_page(CHROMIUM, path, width=width, height=height) as p:
        p.wait("document.readyState === 'complete' && (!window.omapsReport || window.omapsReport.ready)")
        return p.evaluate(TEXT_BOXES_JS)


@needs_chromium
def test_the_page_check_finds_clipped_and_overlapping_text(tmp_path):
    page = tmp_path / "bad.html"
    page.write_text("<!DOCTYPE html><html><body style=\"margin:0\"><p>a paragraph</p>"
                    "<div style=\"position:absolute; left:2000px; top:10px\">far right</div>"
                    "<div style=\"position:absolute; left:0; top:16px\">over the paragraph</div></body></html>")
    problems = page_problems(text_boxes(page))
    assert any("'far right'" in p and "outside" in p for p in problems), problems
    assert any("'a paragraph'" in p and "'over the paragraph'" in p and "overlap" in p for p in problems), problems


@pytest.fixture(scope="module")
def quad_report(tmp_path_factory):
    from gltf_files import write_quad_gltf

    from omaps.report import build_report

    d = tmp_path_factory.mktemp("layout")
    y, x = np.mgrid[:64, :64]
    alpha = np.where((x - 31.5) ** 2 + (y - 31.5) ** 2 < 26 ** 2, 255, 0).astype(np.uint8)
    scene = d / "quad.gltf"
    # (a cutoff, filter and wrap modes of its own: the settings line must name these)
    write_quad_gltf(scene, alpha, material={"alphaMode": "MASK", "alphaCutoff": 0.35},
                    sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33648})
    return build_report(scene, d / "quad.html", "none,tri3,sq8,sq16", size=48, jobs=1).path


@needs_chromium
@pytest.mark.parametrize("size", [(1440, 900), (1280, 800), (1920, 1080)], ids=lambda s: f"{s[0]}x{s[1]}")
def test_scene_report_text(quad_report, size):
    found = text_boxes(quad_report, *size)
    assert len(found["boxes"]) > 40  # the headings, settings, table, captions were all found
    problems = page_problems(found)
    assert problems == [], "\n".join(problems)


@pytest.fixture(scope="module")
def corpus_report(tmp_path_factory):
    from PIL import Image

    from omaps.report import build_report

    d = tmp_path_factory.mktemp("layout_corpus")
    folder = d / "textures"
    folder.mkdir()
    y, x = np.mgrid[:64, :64]
    for k in range(2):
        a = np.where((x - 31.5) ** 2 + (y - 31.5 - 6 * k) ** 2 < (20 + 4 * k) ** 2, 255, 0).astype(np.uint8)
        Image.fromarray(a, "L").save(folder / f"leaf_{k}.png")
    return build_report(folder, d / "corpus.html", "sq8,sq16,tri3,vq4", jobs=1).path


@needs_chromium
def test_corpus_report_text(corpus_report):
    found = text_boxes(corpus_report)
    assert len(found["boxes"]) > 20
    problems = page_problems(found)
    assert problems == [], "\n".join(problems)


# ---- what the report's words say -----------------------------------------------------------------

def settings_line(path) -> str:
    import html
    import re

    text = Path(path).read_text(encoding="utf-8")
    line = re.search(r'<p class="settings">Settings: (.*?)</p>', text).group(1)
    return html.unescape(re.sub(r"<[^>]+>", "", line))


def test_settings_name_the_materials_own_settings(quad_report):
    """No override: the line says so and gives what the file's material and sampler hold."""
    line = settings_line(quad_report)
    assert "None" not in line
    assert "none overridden" in line
    assert "leaf: MASK, cutoff 0.35, filter nearest, wrap mode clamp (u), mirror (v)" in line


def test_settings_name_the_overrides(tmp_path):
    from gltf_files import write_quad_gltf

    from omaps import MaterialRules
    from omaps.report import build_report

    scene = tmp_path / "quad.gltf"
    write_quad_gltf(scene, np.full((8, 8), 255, np.uint8), material={"alphaMode": "MASK", "alphaCutoff": 0.35})
    res = build_report(scene, tmp_path / "q.html", "none,tri2", size=16, jobs=1, view=False,
                       rules=MaterialRules(cutoff=0.6, filter="nearest"))
    line = settings_line(res.path)
    assert "None" not in line
    assert "cutoff 0.6, filter nearest for every material (overridden)" in line
    assert "leaf: MASK, cutoff 0.6, filter nearest, wrap mode wrap" in line


STATE_WORDS = {0: "cyan T", 1: "magenta O", 2: "green C"}


def test_material_panel_colours_are_in_its_caption(quad_report):
    """Each colour of a material panel is the alpha grey or a state colour blended over it; the
    caption names every state colour shown and says how the grey changes them."""
    import base64
    import html
    import io
    import re

    from PIL import Image

    from omaps import states

    text = Path(quad_report).read_text(encoding="utf-8")
    figures = re.findall(r'<figure><img src="data:image/png;base64,([^"]+)"[^>]*alt="material [^"]*">'
                         r"<figcaption>(.*?)</figcaption>", text)
    assert figures
    for data, caption in figures:
        caption = html.unescape(caption)
        img = np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB")).reshape(-1, 3).astype(int)
        colours = np.unique(img, axis=0)
        assert "grey" in caption
        # the greys: texels no triangle covers, and the disc's alpha (0 or 255) under the triangles
        grey = {0, 255} | {int(c[0]) for c in colours if c[0] == c[1] == c[2]}
        shown = set()
        for c in colours:
            if c[0] == c[1] == c[2]:
                continue
            # a state colour blended over a grey the texture has (0.35 grey + 0.65 colour)
            s = [k for k in STATE_WORDS for g in grey
                 if np.all(np.abs(0.35 * g + 0.65 * states.COLOURS[k] - c) <= 1)]
            assert s, f"colour {c} is neither grey nor a state colour over the alpha grey"
            shown.add(s[0])
        assert shown, "no state drawn"
        for k in shown:
            assert STATE_WORDS[k] in caption, (STATE_WORDS[k], caption)
        assert "lighter over opaque" in caption and "darker over transparent" in caption
