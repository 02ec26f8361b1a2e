"""Evaluation output: JSON, CSV, the savings-against-bits chart and per-texture map pictures."""

from __future__ import annotations

import csv
import io
import json
import os

import numpy as np
from PIL import Image

from .. import atomic, drawing
from ..schemes import get_scheme
from .evaluate import TextureResult, mean_results


def to_json(results: list[TextureResult], scheme_names: list[str], settings: dict | None = None,
            unreadable=None) -> dict:
    """Settings, every texture's results, the means, and the files that could not be read."""
    return {"settings": settings or {},
        "textures": [
            {"name": r.name, "width": r.width, "height": r.height,
             "schemes": {s: {"savings": r.savings[s], "bits": r.bits[s]} for s in scheme_names}}
            for r in results
        ],
        "mean": mean_results(results, scheme_names),
        "unreadable": [{"path": p, "problem": why} for p, why in (unreadable or [])],
    }


def write_json(path, results, scheme_names, settings: dict | None = None, unreadable=None) -> None:
    atomic.write_text(path, json.dumps(to_json(results, scheme_names, settings, unreadable), indent=1) + "\n")


def write_csv(path, results, scheme_names) -> None:
    """One row per texture and scheme, then one ``(mean)`` row per scheme."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["texture", "width", "height", "scheme", "bits", "savings"])
    for r in results:
        for s in scheme_names:
            w.writerow([r.name, r.width, r.height, s, r.bits[s], f"{r.savings[s]:.6f}"])
    for s, m in mean_results(results, scheme_names).items():
        w.writerow(["(mean)", "", "", s, m["bits"], f"{m['savings']:.6f}"])
    atomic.write_text(path, buf.getvalue())


def family_of(name: str) -> str:
    """Plot line of a scheme (``Scheme.family``): sqN, triL; vq4 and vq4x64 share one."""
    return get_scheme(name).family


# the families that are no codec of the registry; a codec's line is labelled by its map and bits
# (``family_label``)
FAMILY_LABELS = {"sq": "square map per pair (sqN, 2 bits/cell)",
                 "tri": "micromap per triangle (triL, 2 bits/micro-tri)",
                 "succinct": "succinct micromap per triangle (succinctL, its exact bits)",
                 "csm": "merged subtrees of a pair's micromaps (csmL, its exact bits)"}


def family_label(family: str, schemes=()) -> str:
    """A plot line's label: ``FAMILY_LABELS``, or for a codec's family (a codec, or a codec and its
    variant: ``vq2-paper``) the codec's name, map and bits (the registry's), its variant and the
    other codecs of the line's ``schemes`` (vq4x64 on vq4's line); the family itself when it is
    neither. (Short: a legend; the docs' codec table has each codec's description.)"""
    if family in FAMILY_LABELS:
        return FAMILY_LABELS[family]
    from ..errors import InputError

    try:  # a codec's family is a scheme name: the codec, with its variant (the scheme grammar's)
        codec = get_scheme(family).codec
    except InputError:
        codec = None
    if codec is None or not codec.compressed:
        return family
    variant = family[len(codec.name) + 1:]
    how = {"": "", "paper": ", the deck's encoder"}.get(variant, f", effort {variant}")
    others = [c for c in dict.fromkeys(getattr(get_scheme(n).codec, "name", None) for n in schemes)
              if c not in (None, codec.name)]
    with_others = f" (with {', '.join(others)})" if others else ""
    return f"{family}{with_others}: {codec.map_size}x{codec.map_size} in {codec.bits} bits{how}"


MARKER_PX = 7.0  # a chart marker's diameter, points


def plot_savings(path, results, scheme_names, title="Shader invocation savings") -> None:
    """Mean savings against bits per pair, a line per family, like the deck's charts: every
    scheme named at its point (labels set apart, with a leader line when away from it), points
    of equal bits that would cover each other set side by side, the families' key below. The
    Pareto front (``omaps.frontier``: no other scheme saves more in as few bits) is the dark
    line; dominated points are drawn lighter."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    means = mean_results(results, scheme_names)
    dpi = 120
    fig, ax = plt.subplots(figsize=(8.0, 6.4), dpi=dpi)
    families: dict[str, list[tuple[float, float, str]]] = {}
    for name, m in means.items():
        if name == "texel":
            continue
        families.setdefault(family_of(name), []).append((m["bits"], m["savings"], name))
    markers = "osD^vP*Xph<>"
    drawn = []  # (line, its points)
    for k, (fam, pts) in enumerate(families.items()):
        pts.sort()
        xs, ys, _ = zip(*pts)
        line, = ax.plot(xs, ys, marker=markers[k % len(markers)], ms=MARKER_PX, label=family_label(fam, [p[2] for p in pts]))
        drawn.append((line, pts))
    if "texel" in means:
        ax.axhline(means["texel"]["savings"], color="grey", ls="--", lw=1,
                   label=f"texel limit ({means['texel']['savings']:.1%})")
    ax.set_xscale("log", base=2)
    bits = [p[0] for _, pts in drawn for p in pts]
    if bits:
        ax.set_xlim(min(bits) / 2 ** 0.6, max(bits) * 2 ** 0.6)
    ax.set_xlabel("bits per triangle pair (points of equal bits set side by side)")
    ax.set_ylabel("mean fraction of hits without any-hit call")
    ax.set_ylim(0, 1)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"{title} ({len(results)} textures); the Pareto front marked")
    ax.plot([], [], "-", color="0.1", lw=2.4, alpha=0.55, label="Pareto front: no scheme saves more in as few bits")
    ax.plot([], [], "o", color="0.6", mfc="0.85", mec="0.75", ms=MARKER_PX, ls="none", label="dominated (lighter)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.11), ncol=2, fontsize=7, frameon=False)
    fig.tight_layout()
    _label_points(ax, drawn, MARKER_PX * dpi / 72, front=True)
    fmt = os.path.splitext(os.fspath(path))[1][1:].lower() or "png"
    with atomic.atomic_path(path, suffix="." + fmt) as tmp:
        fig.savefig(tmp, format=fmt, dpi=dpi)
    plt.close(fig)


def _mark_front(ax, drawn, bits, xs, ys) -> None:
    """The Pareto front of the points (``bits``, savings ``ys``; drawn at ``xs``, in ``drawn``'s
    order) as a line behind the markers through the non-dominated ones; each family's markers
    drawn on their own, the dominated ones lighter (the key keeps the family's marker)."""
    import numpy as np

    from ..frontier import front_mask

    front = front_mask(bits, ys, larger_is_better=True)
    xs, ys = np.asarray(xs, float), np.asarray(ys, float)
    order = np.flatnonzero(front)[np.argsort(np.asarray(bits, float)[front], kind="stable")]
    ax.plot(xs[order], ys[order], "-", color="0.1", lw=2.4, alpha=0.55, zorder=1.5)
    i = 0
    for line, pts in drawn:
        marker = line.get_marker()
        line.set_marker("None")
        for k in range(len(pts)):
            ax.plot([xs[i + k]], [ys[i + k]], ls="none", marker=marker, ms=line.get_markersize(),
                    color=line.get_color(), alpha=1.0 if front[i + k] else 0.3)
        i += len(pts)


def _label_points(ax, drawn, marker_px: float, front: bool = False) -> None:
    """Set the markers of every (line, [(x, y, label)]) apart, mark the Pareto front
    (``front``: ``_mark_front``), then name each point at its place."""
    xs = [p[0] for _, pts in drawn for p in pts]
    ys = [p[1] for _, pts in drawn for p in pts]
    labels = [p[2] for _, pts in drawn for p in pts]
    if not xs:
        return
    new_x = drawing.dodge(ax, xs, ys, marker_px + 5)
    i = 0
    for line, pts in drawn:
        line.set_xdata(new_x[i:i + len(pts)])
        i += len(pts)
    drawing.place_labels(ax, new_x, ys, labels, fontsize=7, marker_px=marker_px)
    if front:  # (after the labels: their places are the chart's without it)
        _mark_front(ax, drawn, xs, new_x, ys)


def plot_suffixes() -> tuple[str, ...]:
    """The file suffixes ``plot_savings`` can write (matplotlib's formats: .png, .svg, .pdf, ...)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    return tuple(sorted("." + k for k in FigureCanvasAgg.get_supported_filetypes()))


def _fit(image: np.ndarray, size: int) -> np.ndarray:
    """``image`` (H, W[, 3]) scaled nearest-neighbour to fit a ``size`` square, aspect kept."""
    h, w = image.shape[:2]
    scale = size / max(h, w)
    ys = np.minimum((np.arange(max(1, round(h * scale))) / scale).astype(np.int64), h - 1)
    xs = np.minimum((np.arange(max(1, round(w * scale))) / scale).astype(np.int64), w - 1)
    return image[np.ix_(ys, xs)]


def show_texture(path, result: TextureResult, panel: int = 192) -> None:
    """One PNG: the alpha texture, then each scheme's map in the deck's colours.

    The panels are put together as one image at their pixel size and drawn with the titles on a
    figure without axes: a matplotlib axes per panel (imshow resampling, a tight layout) took
    0.37 s a picture, most of ``omaps eval --show`` on the shared corpus."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result.maps)
    gap, top, title = 14, 40, 22  # pixels: between panels, the figure's title rows, a panel's title
    cols = len(names) + 1
    width, height = cols * (panel + gap) + gap, top + title + panel + gap
    canvas = np.full((height, width, 3), 255, dtype=np.uint8)
    alpha = np.asarray(result.alpha, dtype=np.float64)
    grey = np.round(255 * (alpha - alpha.min()) / max(float(np.ptp(alpha)), 1e-12)).astype(np.uint8)  # as imshow scales
    panels = [np.repeat(_fit(grey, panel)[..., None], 3, axis=2)]
    panels += [drawing.scheme_image(get_scheme(n).kind, result.maps[n], panel) for n in names]
    # the number is the scheme's savings: the share of the pair's area (of the hits) in T or O
    titles = [f"alpha {result.width}x{result.height}"] + [f"{n}: known {result.savings[n]:.1%}" for n in names]
    dpi = 100
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    renderer = fig.canvas.get_renderer()
    y0 = top + title
    for i, img in enumerate(panels):
        x0 = gap + i * (panel + gap)
        h, w = img.shape[:2]
        oy, ox = y0 + (panel - h) // 2, x0 + (panel - w) // 2
        canvas[oy - 1:oy + h + 1, ox - 1:ox + w + 1] = 0  # a frame, as the axes' spines drew
        canvas[oy:oy + h, ox:ox + w] = img
        t = fig.text((x0 + panel / 2) / width, 1 - (y0 - 6) / height, titles[i], ha="center", va="bottom", fontsize=8)
        while t.get_window_extent(renderer).width > panel + gap - 4 and t.get_fontsize() > 4:
            t.set_fontsize(t.get_fontsize() - 0.5)  # narrow panels: a smaller title, not one over the next
    key = "T cyan, O magenta, C green; known = share of the pair's area in T or O (hits without any-hit call)"
    head = fig.text(0.5, 1 - 4 / height, f"{result.name}\n{key}", ha="center", va="top", fontsize=9,
                    linespacing=1.3)
    while head.get_window_extent(renderer).width > width - 8 and head.get_fontsize() > 4:
        head.set_fontsize(head.get_fontsize() - 0.5)
    fig.canvas.draw()  # the text alone, black on white; the panels go in where it left white
    text = np.asarray(fig.canvas.buffer_rgba())[:height, :width, :3]
    plt.close(fig)
    with atomic.atomic_path(path, suffix=".png") as tmp:
        Image.fromarray(np.minimum(text, canvas)).save(tmp, format="PNG")


def show_file_name(result: TextureResult, index: int) -> str:
    stem = os.path.splitext(os.path.basename(result.name))[0]
    return f"{index:03d}_{stem}.png"


SHOW_MANIFEST = "show.json"


def write_show(folder, results: list[TextureResult], settings: dict | None = None, progress: bool = False) -> None:
    """``omaps eval --show``: one PNG per texture into an existing, empty ``folder``, and its
    manifest ``show.json`` (settings, and which picture shows which texture)."""
    from tqdm import tqdm

    from .. import __version__

    pictures = []
    for i, r in enumerate(tqdm(results, desc="pictures", unit="png", disable=not progress, leave=False)):
        name = show_file_name(r, i)
        show_texture(os.path.join(folder, name), r)
        pictures.append({"file": name, "texture": r.name, "path": r.path})
    doc = {"omaps": __version__, "settings": settings or {}, "pictures": pictures}
    atomic.write_text(os.path.join(folder, SHOW_MANIFEST), json.dumps(doc, indent=1) + "\n")
