"""Every picture reads at a glance: a title, a key (legend or colour key), no two text labels
overlapping and no two markers on top of each other, measured on the drawn figure in display
space (``get_window_extent``). The data are small and made so that labels would collide."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.text import Text  # noqa: E402

from omaps import states  # noqa: E402
from omaps.corpus.evaluate import TextureResult  # noqa: E402


@pytest.fixture
def figures(monkeypatch):
    """The figures a picture function closes once written (every one calls ``plt.close(fig)``)."""
    seen = []
    close = plt.close

    def keep(fig=None):
        if isinstance(fig, matplotlib.figure.Figure):
            seen.append(fig)
        close(fig)

    monkeypatch.setattr(plt, "close", keep)
    return seen


def _draw(fig):
    """Draw a closed figure again on an Agg canvas (closing left it a bare one)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()


def _texts(fig):
    _draw(fig)
    r = fig.canvas.get_renderer()
    out = []
    for t in fig.findobj(Text):
        if t.get_visible() and t.get_text().strip() and t.figure is fig:
            out.append((t.get_text(), t.get_window_extent(r)))
    return out


def _markers(fig):
    """Display positions and sizes (px) of every drawn data marker (lines and scatters; not legend
    handles)."""
    _draw(fig)
    pts = []
    for ax in fig.axes:
        legend = ax.get_legend()
        handles = set(legend.legend_handles if legend is not None else [])
        for line in ax.lines:
            if line in handles or line.get_marker() in (None, "None", "", " ") or not line.get_visible():
                continue
            size = line.get_markersize() * fig.dpi / 72
            for xy in line.get_transform().transform(np.asarray(line.get_xydata(), float)):
                pts.append((xy, size, line.get_label()))
        for coll in ax.collections:
            offs = coll.get_offsets()
            if len(offs) == 0 or not hasattr(coll, "get_sizes") or len(coll.get_sizes()) == 0:
                continue
            size = float(np.sqrt(np.max(coll.get_sizes()))) * fig.dpi / 72
            for xy in coll.get_offset_transform().transform(np.asarray(offs, float)):
                pts.append((xy, size, coll.get_label()))
    return pts


def assert_readable(fig, min_texts=1):
    texts = _texts(fig)
    assert len(texts) >= min_texts
    for (ta, a), (tb, b) in itertools.combinations(texts, 2):
        assert not a.overlaps(b), f"labels overlap: {ta!r} and {tb!r}"
    for (pa, sa, la), (pb, sb, lb) in itertools.combinations(_markers(fig), 2):
        assert np.hypot(*(pa - pb)) >= 0.8 * (sa + sb) / 2, f"markers on top of each other: {la} {pa}, {lb} {pb}"
    # a label sits on no marker
    annotations = [t for ax in fig.axes for t in ax.texts if t.get_visible() and t.get_text().strip()]
    r = fig.canvas.get_renderer()
    for t in annotations:
        box = t.get_window_extent(r)
        for p, _, lab in _markers(fig):
            assert not box.contains(*p), f"label {t.get_text()!r} covers a marker of {lab}"


def has_title(fig) -> bool:
    return bool((fig._suptitle is not None and fig._suptitle.get_text().strip())
                or any(ax.get_title().strip() for ax in fig.axes))


def has_legend(fig) -> bool:
    return bool(fig.legends or any(ax.get_legend() is not None for ax in fig.axes))


def _result(name, savings: dict, bits: dict) -> TextureResult:
    return TextureResult(name, 64, 64, savings, bits)


def test_savings_chart_keeps_labels_and_points_apart(tmp_path, figures):
    """The shared corpus's crowd: vq4, vq4-synth, wavelet3 (and vq4-paper) at 512 bits within a
    hundredth of each other, vq2 / vq2-paper at 256, tri3 next to them."""
    from omaps.corpus.report import plot_savings

    names = ["sq4", "sq8", "sq16", "sq32", "tri2", "tri3", "tri4", "vq2", "vq2-paper", "vq4", "vq4x64",
             "vq4-paper", "vq4-synth", "wavelet3", "texel"]
    s = {"sq4": 0.14, "sq8": 0.29, "sq16": 0.45, "sq32": 0.58, "tri2": 0.17, "tri3": 0.33, "tri4": 0.48,
         "vq2": 0.436, "vq2-paper": 0.43, "vq4": 0.5307, "vq4x64": 0.66, "vq4-paper": 0.526, "vq4-synth": 0.5322,
         "wavelet3": 0.5320, "texel": 0.96}
    b = {"sq4": 32, "sq8": 128, "sq16": 512, "sq32": 2048, "tri2": 64, "tri3": 256, "tri4": 1024, "vq2": 256,
         "vq2-paper": 256, "vq4": 512, "vq4x64": 2048, "vq4-paper": 512, "vq4-synth": 512, "wavelet3": 512,
         "texel": 32768}
    results = [_result("a", s, b), _result("b", s, b)]
    plot_savings(tmp_path / "p.png", results, names)
    assert (tmp_path / "p.png").stat().st_size > 0
    fig, = figures
    assert has_title(fig) and has_legend(fig)
    assert_readable(fig, min_texts=len(names) - 1)
    drawn = {t for t, _ in _texts(fig)}
    for n in names[:-1]:
        assert n in drawn, n  # every scheme named at its point


def _budget_report(points: dict, none: float) -> dict:
    kinds = {"sq16": {"kind": "square", "codec": "sq16"}, "vq4": {"kind": "square", "codec": "vq4"},
             "vq2": {"kind": "square", "codec": "vq2"}, "tri3": {"kind": "micromap"}}
    schemes = {"none": {"map_bytes": 0, "alpha_tests_per_primary_ray": none}}
    settings = {"none": {"kind": "none"}}
    for n, (nbytes, tests) in points.items():
        schemes[n] = {"map_bytes": nbytes, "alpha_tests_per_primary_ray": tests}
        settings[n] = kinds.get(n, {"kind": "budget"})
    return {"scene": {"file": "scenes/palm.glb"}, "camera": {"width": 256, "height": 256},
            "settings": {"schemes": settings, "shadows": False}, "schemes": schemes}


@pytest.mark.parametrize("points", [
    # palm's three at one x: sq16, vq4 and a budget of vq4's bytes
    {"sq16": (122880, 1.93), "vq4": (122880, 1.61), "budget:120KiB": (122816, 1.58)},
    # and spread over the axis, two budgets close to vq4
    {"tri3": (61440, 2.4), "sq16": (122880, 1.93), "vq2": (61440, 2.0), "vq4": (122880, 1.61),
     "budget:120KiB": (122700, 1.60), "budget:60KiB": (61400, 1.98)},
])
def test_budget_plot_fits_the_data_and_keeps_labels_apart(tmp_path, figures, points):
    from omaps.trace.pictures import budget_plot

    budget_plot(str(tmp_path / "b.png"), _budget_report(points, 4.1))
    fig, = figures
    assert has_title(fig) and has_legend(fig)
    assert_readable(fig, min_texts=len(points))
    ax = fig.axes[0]
    frame = ax.get_window_extent()
    mx = [p[0] for p, _, _ in _markers(fig)]
    assert len(mx) == len(points)
    # the data fill the axis (at least half its width between the outer points when their sizes
    # differ by more than 1 %), and no point sits on the frame
    assert min(mx) - frame.x0 >= 0.05 * frame.width and frame.x1 - max(mx) >= 0.05 * frame.width
    xs = [x for x, _ in points.values()]
    if max(xs) > min(xs) * 1.01:
        assert max(mx) - min(mx) >= 0.5 * frame.width
    # an axis one can read: at least two labelled x ticks inside the axes
    box = ax.get_window_extent()
    fig.canvas.draw()
    ticks = [t for t in ax.get_xticklabels() if t.get_text().strip()
             and box.x0 - 1 <= t.get_window_extent().x0 and t.get_window_extent().x1 <= box.x1 + 20]
    assert len(ticks) >= 2, [t.get_text() for t in ax.get_xticklabels()]
    drawn = {t for t, _ in _texts(fig)}
    for n in points:
        assert n in drawn, n


class _Run(SimpleNamespace):
    pass


def _runs(names, shape=(24, 32), shadows=True):
    rng = np.random.default_rng(1)
    out = {}
    for i, n in enumerate(names):
        p = SimpleNamespace(tests=rng.integers(0, 8 - i, shape).astype(np.int32))
        s = SimpleNamespace(tests=rng.integers(0, 6 - i, shape).astype(np.int32)) if shadows else None
        out[n] = _Run(primary=p, shadow=s)
    return out


@pytest.mark.parametrize("shadows", [True, False])
def test_heatmap_says_what_it_counts(tmp_path, figures, shadows):
    from omaps.trace.pictures import heatmap

    names = ["none", "tri3", "sq16", "vq2", "vq4", "vq4x64"]
    runs = _runs(names, shadows=shadows)
    heatmap(str(tmp_path / "h.png"), runs, names, shadows)
    fig, = figures
    assert fig._suptitle is not None and fig._suptitle.get_text().strip()
    title = fig._suptitle.get_text()
    assert "per pixel" in title
    assert ("shadow" in title) == shadows
    # a colour key: a colour bar axes whose label says what the colours count
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1
    label = bars[0].get_ylabel() + bars[0].get_xlabel()
    assert "alpha tests per pixel" in label and ("shadow" in label) == shadows
    assert_readable(fig, min_texts=len(names) + 1)
    # every panel names its scheme and its mean, the primary rays' share named apart with shadows
    panel_titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    for n in names:
        t = next(t for t in panel_titles if t.startswith(n + ":"))
        prim = runs[n].primary.tests.mean()
        assert f"{prim:.2f}" in t
        if shadows:
            assert "primary" in t and "shadow" in t


def test_decode_show_has_title_and_key(tmp_path, figures):
    from omaps.cli import main
    from omaps.codecs import get_codec

    m = np.zeros((16, 16), np.uint8)
    m[4:12, 4:12] = states.O
    m[4:12, 4] = states.C
    codec = get_codec("sq16")
    block = tmp_path / "leaf.sq16"
    block.write_bytes(codec.encode(m))
    out = tmp_path / "m.png"
    assert main(["decode", str(block), "--codec", "sq16", "--show", str(out)]) == 0
    assert out.stat().st_size > 0
    fig, = figures
    assert has_title(fig) and has_legend(fig)
    text = " ".join(t for t, _ in _texts(fig))
    assert "leaf.sq16" in text and "sq16" in text and "16x16" in text
    legend = next(lg for lg in [*fig.legends, *(ax.get_legend() for ax in fig.axes)] if lg is not None)
    keys = " ".join(t.get_text() for t in legend.get_texts())
    assert "T" in keys and "O" in keys and "C" in keys
    assert_readable(fig)


def test_show_picture_names_its_percentages(tmp_path, figures):
    """The number under each map is the share of the pair's area in T or O: the picture says so."""
    from omaps.corpus.evaluate import evaluate_texture
    from omaps.corpus.report import show_texture
    from omaps.schemes import get_scheme
    from omaps.texture import load_alpha

    a = np.zeros((24, 40), np.uint8)
    a[4:20, 6:30] = 255
    names = ["sq4", "sq16", "tri3", "texel", "vq4x64"]
    r = evaluate_texture(load_alpha(a), [get_scheme(n) for n in names], keep_maps=True)
    show_texture(tmp_path / "s.png", r, panel=96)
    fig, = figures
    texts = [t for t, _ in _texts(fig)]
    for n in names:
        t = next(t for t in texts if t.startswith(n + ":"))
        assert f"known {r.savings[n]:.1%}" in t, t
    assert any("T or O" in t for t in texts)  # the key says what "known" is
    assert_readable(fig)
