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


FAMILY_LABELS = {"sq": "square map per pair (sqN, 2 bits/cell)",
                 "tri": "micromap per triangle (triL, 2 bits/micro-tri)",
                 "vq2": "VQ2: 16x16 in 256 bits (our encoder)",
                 "vq2-paper": "VQ2, the deck's naive encoder",
                 "vq4": "VQ4: 32x32 in 512 bits, 64x64 in 4 blocks (our encoder)",
                 "vq4-paper": "VQ4, the deck's top-down encoder",
                 "vq4-synth": "VQ4-synth: 32x32 in 512 bits, a synthesised 14th vector",
                 "wavelet3": "wavelet3: 64x64 in 512 bits, three levels"}


def plot_savings(path, results, scheme_names, title="Shader invocation savings") -> None:
    """Mean savings against bits per pair, a line per family, like the deck's charts."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    means = mean_results(results, scheme_names)
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=120)
    families: dict[str, list[tuple[float, float, str]]] = {}
    for name, m in means.items():
        if name == "texel":
            continue
        families.setdefault(family_of(name), []).append((m["bits"], m["savings"], name))
    placed: dict[float, list[float]] = {}  # heights of the lone labels at each x
    for fam, pts in families.items():
        pts.sort()
        xs, ys, labels = zip(*pts)
        ax.plot(xs, ys, marker="o", label=FAMILY_LABELS.get(fam, fam))
        for x, y, lab in pts:
            if len(pts) == 1:  # a lone point: label left of it, lower than the lone labels above
                y_text = min([y] + [u - 0.03 for u in placed.get(x, []) if u - 0.03 < y + 0.03])
                placed.setdefault(x, []).append(y_text)
                ax.annotate(lab, (x, y), xytext=(x / 1.06, y_text - 0.008), ha="right", fontsize=7)
            else:  # below the line; a family's other encoders above (they sit close)
                above = fam not in ("sq", "tri") and not fam.endswith("-paper")
                ax.annotate(lab, (x, y), textcoords="offset points", xytext=(-14, 7) if above else (4, -11),
                            fontsize=7)
    if "texel" in means:
        ax.axhline(means["texel"]["savings"], color="grey", ls="--", lw=1,
                   label=f"texel limit ({means['texel']['savings']:.1%})")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("bits per triangle pair")
    ax.set_ylabel("mean fraction of hits without any-hit call")
    ax.set_ylim(0, 1)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"{title} ({len(results)} textures)")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fmt = os.path.splitext(os.fspath(path))[1][1:].lower() or "png"
    with atomic.atomic_path(path, suffix="." + fmt) as tmp:
        fig.savefig(tmp, format=fmt)
    plt.close(fig)


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
    gap, top, title = 14, 26, 22  # pixels: between panels, the figure's title row, a panel's title
    cols = len(names) + 1
    width, height = cols * (panel + gap) + gap, top + title + panel + gap
    canvas = np.full((height, width, 3), 255, dtype=np.uint8)
    alpha = np.asarray(result.alpha, dtype=np.float64)
    grey = np.round(255 * (alpha - alpha.min()) / max(float(np.ptp(alpha)), 1e-12)).astype(np.uint8)  # as imshow scales
    panels = [np.repeat(_fit(grey, panel)[..., None], 3, axis=2)]
    panels += [drawing.scheme_image(get_scheme(n).kind, result.maps[n], panel) for n in names]
    titles = [f"alpha {result.width}x{result.height}"] + [f"{n}: {result.savings[n]:.1%}" for n in names]
    dpi = 100
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    y0 = top + title
    for i, img in enumerate(panels):
        x0 = gap + i * (panel + gap)
        h, w = img.shape[:2]
        oy, ox = y0 + (panel - h) // 2, x0 + (panel - w) // 2
        canvas[oy - 1:oy + h + 1, ox - 1:ox + w + 1] = 0  # a frame, as the axes' spines drew
        canvas[oy:oy + h, ox:ox + w] = img
        fig.text((x0 + panel / 2) / width, 1 - (y0 - 6) / height, titles[i], ha="center", va="bottom", fontsize=8)
    fig.text(0.5, 1 - 6 / height, f"{result.name}   T cyan, O magenta, C green", ha="center", va="top", fontsize=9)
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
