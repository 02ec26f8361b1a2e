"""The Pareto front of a cost-benefit chart, one place for ``omaps trace --plot-frontier`` and
``omaps eval --plot``: which representations no other beats on both axes, and the chart panel
that marks them (a line through the non-dominated points, dominated points drawn lighter); and
how far a point is from the fronts of alpha tests against bytes and against lines read
(``gaps``, for ``omaps trace --memory``).

Example::

    >>> front_mask([1, 2, 3, 4], [5.0, 3.0, 4.0, 1.0]).tolist()   # (3, 4.0) is beaten by (2, 3.0)
    [True, True, False, True]
"""

from __future__ import annotations

import numpy as np

__all__ = ["front_mask", "front_panel", "label_panel", "gaps"]


def front_mask(cost, value, larger_is_better: bool = False) -> np.ndarray:
    """True for each point that no other dominates: another point dominates it when its cost is
    no higher and its value no worse, one of the two strictly (value: lower is better, or higher
    with ``larger_is_better``). Equal points do not dominate each other.

    Examples
    --------
    >>> front_mask([1, 1, 2], [0.5, 0.5, 0.4], larger_is_better=True).tolist()   # equal points both stay
    [True, True, False]
    >>> front_mask([1, 2, 2], [0.5, 0.5, 0.4]).tolist()   # (2, 0.5) costs more for the same value
    [True, False, True]
    """
    c = np.asarray(cost, float)
    v = np.asarray(value, float)
    if larger_is_better:
        v = -v
    no_worse = (c[None, :] <= c[:, None]) & (v[None, :] <= v[:, None])  # [i, j]: j no worse than i
    strictly = (c[None, :] < c[:, None]) | (v[None, :] < v[:, None])
    return ~(no_worse & strictly).any(axis=1)


def gaps(tests, cost) -> list[float | None]:
    """Each point's gap to the front of ``cost`` against alpha ``tests`` (both per ray): its cost
    over the least cost of any point with no more tests (itself included), so 1 means no point
    as good costs less. None where that least cost is 0 and its own is not (an unbounded gap) or
    where its cost is unknown (None); points of unknown cost are no one's reference.

    A point's *both-fronts gap* is the larger of its gaps in map bytes and in map lines read.

    Examples
    --------
    >>> gaps([0.5, 0.4, 0.3], [100, 300, 150])   # (0.5, 100) is on the front; 300 is 2x 150
    [1.0, 2.0, 1.0]
    >>> gaps([0.5, 0.4], [None, 80])
    [None, 1.0]
    """
    t = np.asarray(tests, float)
    known = np.array([c is not None for c in cost])
    c = np.array([np.nan if v is None else float(v) for v in cost])
    out: list[float | None] = []
    for i in range(len(t)):
        if not known[i]:
            out.append(None)
            continue
        best = c[known & (t <= t[i])].min()
        out.append(1.0 if c[i] == best else (None if best == 0 else float(c[i] / best)))
    return out


def front_panel(ax, xs, ys, larger_is_better: bool = False, colours=None, marker_pt: float = 7.0,
                front_label: str = "Pareto front") -> np.ndarray:
    """Draw points (``xs``, ``ys``) on ``ax``: the non-dominated ones (``front_mask``, small x
    better) full and joined by the front's line in order of x, the dominated ones lighter (name
    them with ``label_panel`` once the layout is final). Returns the front's mask."""
    xs = np.asarray(xs, float)
    ys = np.asarray(ys, float)
    mask = front_mask(xs, ys, larger_is_better)
    colours = colours if colours is not None else ["C0"] * len(xs)
    order = np.flatnonzero(mask)[np.argsort(xs[mask], kind="stable")]
    if len(order):
        ax.plot(xs[order], ys[order], "-", color="0.2", lw=1.2, zorder=2, label=front_label)
    for i in range(len(xs)):
        ax.plot([xs[i]], [ys[i]], "o", ms=marker_pt, color=colours[i], alpha=1.0 if mask[i] else 0.3,
                mec="0.1" if mask[i] else "none", zorder=3, ls="none")
    ax.plot([], [], "o", color="0.5", alpha=0.3, mec="none", ls="none", label="dominated (lighter)")
    return mask


def label_panel(ax, xs, ys, labels, marker_pt: float = 7.0) -> None:
    """Name each point at its place, labels apart (``drawing.place_labels``)."""
    from .drawing import place_labels

    place_labels(ax, xs, ys, labels, fontsize=7, marker_px=marker_pt * ax.figure.dpi / 72)
