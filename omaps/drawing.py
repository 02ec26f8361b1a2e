"""Pictures of maps in the deck's colours (T cyan, O magenta, C green), as RGB arrays; the
``omaps decode --show`` picture; and the charts' helpers that keep markers and labels apart."""

from __future__ import annotations

import numpy as np
from numba import njit

from . import birdcurve, pair, states


def colourise(map_states: np.ndarray) -> np.ndarray:
    return states.COLOURS[np.asarray(map_states)]


def square_image(sq: np.ndarray, size: int) -> np.ndarray:
    """An N x N map (rows = v) drawn at ``size`` pixels, nearest-neighbour."""
    n_rows, n_cols = sq.shape
    ys = (np.arange(size) * n_rows) // size
    xs = (np.arange(size) * n_cols) // size
    return colourise(sq[np.ix_(ys, xs)])


@njit(cache=True)
def _pair_tri_lookup(tri_maps, level, size):
    out = np.empty((size, size), dtype=np.uint8)
    for y in range(size):
        v = (y + 0.5) / size
        for x in range(size):
            u = (x + 0.5) / size
            t, b1, b2 = pair.uv_to_hit(u, v)
            out[y, x] = tri_maps[t, birdcurve.bary_to_index(b1, b2, level)]
    return out


def pair_triangle_image(tri_maps: np.ndarray, size: int) -> np.ndarray:
    """The pair's two micromaps (2, 4**L) drawn over the square, each pixel looked up through
    the bird curve as a ray hit would be."""
    level = int(round(np.log(tri_maps.shape[1]) / np.log(4)))
    return colourise(_pair_tri_lookup(np.ascontiguousarray(tri_maps), level, size))


def scheme_image(kind: str, map_states: np.ndarray, size: int) -> np.ndarray:
    """A scheme's map of the corpus pair drawn over the square (``Scheme.kind``)."""
    if kind == "micromap":
        return pair_triangle_image(map_states, size)
    return square_image(map_states, size)


# --- charts: markers set apart, labels placed apart with leader lines ------------------------

def dodge(ax, xs, ys, min_px: float) -> np.ndarray:
    """New x data values for the points (``xs``, ``ys``) so that no two markers lie closer than
    ``min_px`` display pixels: points that would are set side by side horizontally (ordered by
    x, then y), around their mean display x. The axes' limits and layout must be final."""
    tr = ax.transData
    pts = tr.transform(np.column_stack([np.asarray(xs, float), np.asarray(ys, float)]))
    n = len(pts)
    for _ in range(20):
        d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        close = (d < min_px - 1e-6) & ~np.eye(n, dtype=bool)
        if not close.any():
            break
        comp = np.arange(n)  # connected groups of close points (union-find by relabelling)
        for i, j in zip(*np.nonzero(close)):
            a, b = comp[i], comp[j]
            if a != b:
                comp[comp == b] = a
        for c in np.unique(comp):
            members = np.flatnonzero(comp == c)
            if len(members) < 2:
                continue
            order = members[np.lexsort((pts[members, 1], pts[members, 0]))]
            centre = pts[order, 0].mean()
            pts[order, 0] = centre + (np.arange(len(order)) - (len(order) - 1) / 2) * min_px
    return tr.inverted().transform(pts)[:, 0]


def _line_samples(ax, step: float = 3.0) -> np.ndarray:
    """Display points every ``step`` pixels along every drawn line of ``ax`` (labels keep off them)."""
    out = [np.empty((0, 2))]
    for line in ax.lines:
        if not line.get_visible() or line.get_linestyle() in ("None", "none", "", " "):
            continue
        p = line.get_transform().transform(np.asarray(line.get_xydata(), float))
        for a, b in zip(p[:-1], p[1:]):
            k = max(2, int(np.hypot(*(b - a)) / step) + 1)
            out.append(a + (b - a) * np.linspace(0, 1, k)[:, None])
    return np.concatenate(out)


def place_labels(ax, xs, ys, labels, fontsize: float = 7, marker_px: float = 8.0, avoid=()) -> list:
    """Label each point (``xs``, ``ys`` in data) with ``labels``: each label is put at the nearest
    free place around its point -- off every other label, every marker, the frame and the boxes
    in ``avoid`` (display bboxes; the axes' legend is added), and off the drawn lines where it
    can -- and joined to its point by a thin leader line when it sits away from it. The axes'
    limits and layout must be final. Returns the annotations."""
    from matplotlib.transforms import Bbox

    fig = ax.figure
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    pts = ax.transData.transform(np.column_stack([np.asarray(xs, float), np.asarray(ys, float)]))
    frame = ax.get_window_extent(r)
    half = marker_px / 2 + 1.5
    hard = [Bbox.from_extents(x - half, y - half, x + half, y + half) for x, y in pts]
    legend = ax.get_legend()
    if legend is not None:
        hard.append(legend.get_window_extent(r))
    hard += list(avoid)
    lines = _line_samples(ax)
    px_per_pt = fig.dpi / 72
    sizes = []
    for lab in labels:
        t = ax.text(0, 0, lab, fontsize=fontsize, transform=None)
        bb = t.get_window_extent(r)
        t.remove()
        sizes.append((bb.width, bb.height))
    # crowded points first: they have the fewest free places
    crowd = [int(np.sum(np.hypot(*(pts - p).T) < 60)) for p in pts]
    angles = np.deg2rad([0, 180, 30, 150, -30, -150, 60, 120, -60, -120, 90, -90, 15, 165, -15, -165])
    radii = [3, 7, 12, 18, 26, 35, 46, 58, 72, 88, 106, 126, 150]
    pad = 1.5
    out = [None] * len(labels)
    for i in sorted(range(len(labels)), key=lambda k: -crowd[k]):
        (px, py), (w, h) = pts[i], sizes[i]
        best, best_score, best_rad = None, np.inf, radii[0]
        for rank, (rad, ang) in enumerate((rad, ang) for rad in radii for ang in angles):
            c, s = np.cos(ang), np.sin(ang)
            ox, oy = px + (half + rad) * c, py + (half + rad) * s
            x0 = ox if c > 0.3 else ox - w if c < -0.3 else ox - w / 2
            y0 = oy if s > 0.3 else oy - h if s < -0.3 else oy - h / 2
            box = Bbox.from_extents(x0, y0, x0 + w, y0 + h)
            if (box.x0 < frame.x0 + 2 or box.x1 > frame.x1 - 2 or box.y0 < frame.y0 + 2
                    or box.y1 > frame.y1 - 2):
                continue
            grown = Bbox.from_extents(x0 - pad, y0 - pad, x0 + w + pad, y0 + h + pad)
            if any(grown.overlaps(b) for b in hard):
                continue
            on_lines = 0
            if len(lines):
                on_lines = int(np.count_nonzero((lines[:, 0] > grown.x0) & (lines[:, 0] < grown.x1)
                                                & (lines[:, 1] > grown.y0) & (lines[:, 1] < grown.y1)))
            score = rad + 0.01 * rank + (25 + 2 * on_lines if on_lines else 0)
            if score < best_score:
                best, best_score, best_rad = box, score, rad
            if rad > best_score:  # no farther place can score lower
                break
        if best is None:  # nowhere free: right of the point
            best = Bbox.from_extents(px + half, py - h / 2, px + half + w, py + h / 2)
        hard.append(best)
        # a leader line unless the label touches its marker (the nearest ring of places)
        far = best_rad > radii[0]
        arrow = dict(arrowstyle="-", color="0.45", lw=0.6, shrinkA=1, shrinkB=marker_px / 2 / px_per_pt + 0.5)
        out[i] = ax.annotate(labels[i], (xs[i], ys[i]), xytext=((best.x0 - px) / px_per_pt, (best.y0 - py) / px_per_pt),
                             textcoords="offset points", ha="left", va="bottom", fontsize=fontsize,
                             arrowprops=arrow if far else None, annotation_clip=False)
    return out


def _text_length(renderer, text: str, prop) -> float:
    """Display pixels of ``text``'s longest line in font ``prop`` (unrotated)."""
    return max(renderer.get_text_width_height_descent(line, prop, ismath=False)[0]
               for line in text.split("\n"))


def wrap_to(renderer, text: str, prop, length: float) -> str:
    """``text`` with its lines broken at spaces so that each is at most ``length`` display pixels
    long in font ``prop`` (a word longer than that keeps a line of its own)."""
    out = []
    for para in text.split("\n"):
        line = ""
        for word in para.split(" "):
            cand = f"{line} {word}" if line else word
            if line and _text_length(renderer, cand, prop) > length:
                out.append(line)
                line = word
            else:
                line = cand
        out.append(line)
    return "\n".join(out)


def fit_texts(fig, items, min_fontsize: float = 5.0, rounds: int = 4) -> None:
    """Fit each text of ``items`` -- (Text, space) pairs, ``space(renderer)`` the display pixels
    it may run along its direction (a rotated text: its height) -- by breaking its lines at
    spaces, then, where one word alone is longer, a smaller font. The figure is laid out between
    rounds (drawn without rendering pixels), so a layout engine (constrained or tight) places
    what the new lines take; the texts' first strings are the ones wrapped each round. The
    layout the texts settled in is kept (the engine is then set to none): call this last, just
    before saving, on a figure made at the dpi it is saved at."""
    first = [(t, t.get_text()) for t, _ in items]
    # (the images are hidden meanwhile: a layout does not depend on them, resampling them is slow)
    images = [im for ax in fig.axes for im in ax.images if im.get_visible()]
    for im in images:
        im.set_visible(False)
    try:
        settled = _fit_rounds(fig, items, first, min_fontsize, rounds)
    finally:
        for im in images:
            im.set_visible(True)
    if settled and fig.get_layout_engine() is not None:
        # the last layout is the one for these texts: kept, so that saving does not lay out again
        # (a layout in figure fractions holds at any dpi)
        fig.set_layout_engine("none")


def _fit_rounds(fig, items, first, min_fontsize, rounds) -> bool:
    """True when the last layout was made with the texts as they are left."""
    for _ in range(rounds):
        fig.draw_without_rendering()
        r = fig.canvas.get_renderer()
        changed = False
        for (t, space), (_, text) in zip(items, first):
            room = max(1.0, float(space(r)))
            prop = t.get_fontproperties().copy()
            new = wrap_to(r, text, prop, room)
            while _text_length(r, new, prop) > room and prop.get_size_in_points() > min_fontsize:
                prop.set_size(prop.get_size_in_points() - 0.5)
                t.set_fontproperties(prop)
                new = wrap_to(r, text, prop, room)
                changed = True
            if new != t.get_text():
                t.set_text(new)
                changed = True
        if not changed:
            return True
    return False


def state_key_handles():
    """Legend handles for the three states in the deck's colours."""
    from matplotlib.patches import Patch

    return [Patch(facecolor=states.COLOURS[s] / 255, edgecolor="0.3", lw=0.5, label=lab)
            for s, lab in ((states.T, "T transparent (hit ignored)"), (states.O, "O opaque (hit accepted)"),
                           (states.C, "C check (any-hit shader runs)"))]


def map_picture(path, map_states: np.ndarray, name: str, codec: str, dpi: int = 100) -> None:
    """``omaps decode --show``: a decoded square map (rows = v) in the deck's colours, a title
    (file, codec, size, known share) and the key of the three states, written as PNG."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .bake import known_fraction

    m = np.asarray(map_states)
    rows, cols = m.shape
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=dpi)
    ax.imshow(colourise(m), interpolation="nearest", extent=(0, cols, rows, 0))
    ax.set_xticks([0, cols // 2, cols])
    ax.set_yticks([0, rows // 2, rows])
    ax.tick_params(labelsize=7)
    ax.set_xlabel("u (cells)", fontsize=8)
    ax.set_ylabel("v (cells, rows)", fontsize=8)
    ax.set_title(f"{os.path.basename(os.fspath(name))}: {codec}, {cols}x{rows} map\n"
                 f"known (T or O) {known_fraction(m):.1%} of the area", fontsize=9)
    ax.legend(handles=state_key_handles(), loc="upper left", bbox_to_anchor=(1.03, 1.0), fontsize=8,
              frameon=False, title="key", title_fontsize=8)
    fig.set_layout_engine("tight")
    # a map far wider than high (or the reverse): the labels along its short side fit it
    fit_texts(fig, [(ax.title, lambda r: fig.bbox.width - 12),
                    (ax.xaxis.label, lambda r: ax.get_window_extent(r).width),
                    (ax.yaxis.label, lambda r: ax.get_window_extent(r).height)])
    fig.savefig(path, format="png", dpi=dpi)
    plt.close(fig)
