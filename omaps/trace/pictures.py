"""Pictures of a traced scene: the heat map of alpha tests per pixel (the deck's) and the
alpha-tested render."""

from __future__ import annotations

import math

import numpy as np

from ..atomic import atomic_path

__all__ = ["heatmap", "render", "budget_plot", "frontier_plot"]


def _tests_image(run, shadows: bool) -> np.ndarray:
    img = run.primary.tests.astype(np.float64)
    if shadows and run.shadow is not None:
        img = img + run.shadow.tests
    return img


def heatmap(path: str, runs: dict, names: list[str], shadows: bool, scene: str | None = None) -> None:
    """Alpha tests per pixel, 'none' first then each scheme, on one colour scale with its colour
    bar: a pixel's primary ray, plus with ``shadows`` its shadow ray (traced without deferring
    the C candidates). Each panel gives its mean per pixel (primary + shadow with ``shadows``:
    the primary share is the table's alpha tests per primary ray)."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..drawing import fit_texts

    shadows = bool(shadows) and all(runs[n].shadow is not None for n in names if n in runs)
    shown = ["none"] + [n for n in names if n != "none"]
    imgs = [_tests_image(runs[n], shadows) for n in shown]
    vmax = max(1.0, float(np.percentile(imgs[0], 99.5)))
    cols = min(len(shown), 4)
    rows = math.ceil(len(shown) / cols)
    h, w = imgs[0].shape
    dpi = 110  # (laid out at the dpi it is saved at: fit_texts keeps that layout)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols * w / h + 1.2, 3.4 * rows + 0.5), squeeze=False,
                             constrained_layout=True, dpi=dpi)
    what = "primary + shadow rays" if shadows else "primary rays"
    for ax, n, img in zip(axes.flat, shown, imgs):
        im = ax.imshow(img, cmap="inferno", vmin=0, vmax=vmax, interpolation="nearest")
        prim = float(runs[n].primary.tests.mean())
        if shadows:
            shad = float(runs[n].shadow.tests.mean())
            ax.set_title(f"{n}: {prim + shad:.2f} per pixel\n= {prim:.2f} primary + {shad:.2f} shadow", fontsize=9)
        else:
            ax.set_title(f"{n}: {prim:.2f} per pixel (primary)", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(shown):]:
        ax.axis("off")
    where = f" on {os.path.basename(scene)}" if scene else ""
    rays = ("a primary ray and, where it hits, a shadow ray per pixel" if shadows else "a primary ray per pixel")
    head = fig.suptitle(f"Alpha tests per pixel{where}, {w}x{h}: {rays}", fontsize=11)
    bar = fig.colorbar(im, ax=axes, shrink=0.8, extend="max",
                       label=f"alpha tests per pixel ({what})\ntop colour: {vmax:.0f} or more")
    # every text within its room: the title across the figure, a panel's title over its panel,
    # the bar's label along the bar (lines broken at spaces; a long name in a smaller font)
    fit_texts(fig, [(head, lambda r: fig.bbox.width - 12)]
              + [(ax.title, lambda r, ax=ax: ax.get_window_extent(r).width) for ax in list(axes.flat)[:len(shown)]]
              + [(bar.ax.yaxis.label, lambda r: bar.ax.get_window_extent(r).height)])
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)


def render(path: str, prep, run, cam: np.ndarray, light) -> None:
    """The alpha-tested albedo image (base colour, nearest texel), lit by |N.L| and the shadow
    rays when traced, over a sky colour."""
    from PIL import Image

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
        m = scene.meshes[k].merged
        vi = m["triangles"][tri[sel]]
        uv = ((1 - b1[sel] - b2[sel])[:, None] * m["uvs"][vi[:, 0]] + b1[sel][:, None] * m["uvs"][vi[:, 1]]
              + b2[sel][:, None] * m["uvs"][vi[:, 2]])
        mats = m["material"][tri[sel]]
        col = np.empty((len(vi), 3))
        for mi in np.unique(mats):
            s2 = mats == mi
            mat = scene.materials[mi]
            c = np.asarray(mat.base_colour[:3], np.float64)
            rgb = scene.textures[mat.texture].rgb if mat.texture >= 0 else None
            if rgb is not None:
                th, tw = rgb.shape[:2]
                x = np.floor(uv[s2, 0] * tw).astype(np.int64) % tw
                y = np.floor(uv[s2, 1] * th).astype(np.int64) % th
                c = c * rgb[y, x] / 255.0
            col[s2] = c
        colour[sel] = col
        if light is not None:
            pos = m["positions"][vi].astype(np.float64)
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


def _plot_family(name: str, settings: dict) -> str:
    kind = settings.get("kind")
    if kind == "micromap":
        rep = settings.get("representation", "raw")
        return {"succinct": "succinctL (succinct trees)", "csm": "csmL (merged subtrees)"}.get(
            rep, "triL (per-triangle micromaps)")
    if kind == "square" and settings.get("codec", "").startswith("sq"):
        return "sqN (raw square maps)"
    if kind == "budget":
        return "budget (per-pair choice)"
    if kind == "square":
        return "codecs"
    return name


MARKER_PT = 7.0  # a chart marker's diameter


def _bytes_axis(ax, xs: list[float]) -> float:
    """Fit the x axis to the map sizes (in KiB or MiB, returned as the divisor): a log axis when
    they span more than 16x, else a linear one padded around them (one size: centred on it)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator

    unit, name = (1024.0 ** 2, "MiB") if max(xs) >= 16 * 1024 ** 2 else (1024.0, "KiB")
    lo, hi = min(xs) / unit, max(xs) / unit
    if lo > 0 and hi / lo > 16:
        ax.set_xscale("log", base=2)
        ax.set_xlim(lo / 2 ** 0.5, hi * 2 ** 0.5)
        ax.xaxis.set_major_locator(LogLocator(base=2))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    else:
        pad = max(0.15 * (hi - lo), 0.05 * hi, 1 / unit)
        ax.set_xlim(max(0.0, lo - pad) if lo - pad > 0 or lo == 0 else 0.0, hi + pad)
        if lo == 0:
            ax.set_xlim(-pad, hi + pad)
        ax.xaxis.set_major_locator(MaxNLocator(6))
    ax.set_xlabel(f"map bytes, {name} (every prototype pair or triangle)")
    return unit


def budget_plot(path: str, report: dict) -> None:
    """Alpha tests per primary ray against map bytes of every traced scheme (``omaps trace``'s
    report), a line per family: uniform sqN, triL, the codecs, the budgets; 'none' as a level.
    The x axis is fitted to the sizes traced; every scheme is named at its point (labels set
    apart, a leader line when away from it); points that would cover each other are set side by
    side."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..drawing import dodge, place_labels

    dpi = 110
    fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=dpi)
    families: dict[str, list] = {}
    for n, r in report["schemes"].items():
        if n == "none" or not r.get("map_bytes"):
            continue
        fam = _plot_family(n, report["settings"]["schemes"].get(n, {}))
        families.setdefault(fam, []).append((r["map_bytes"], r["alpha_tests_per_primary_ray"], n))
    pts_all = [p for pts in families.values() for p in pts]
    unit = _bytes_axis(ax, [p[0] for p in pts_all]) if pts_all else 1024.0
    markers = "osD^vP*X"
    drawn = []
    for k, (fam, pts) in enumerate(families.items()):
        pts.sort()
        xs, ys, _ = zip(*pts)
        line, = ax.plot([x / unit for x in xs], ys, marker=markers[k % len(markers)], ms=MARKER_PT, label=fam,
                        ls="-" if len(pts) > 1 else "none")
        drawn.append((line, pts))
    none = report["schemes"].get("none")
    top = max([p[1] for p in pts_all] + [none["alpha_tests_per_primary_ray"] if none else 0.0] + [1e-9])
    if none is not None:
        ax.axhline(none["alpha_tests_per_primary_ray"], color="grey", ls="--", lw=1,
                   label=f"none, no maps ({none['alpha_tests_per_primary_ray']:.2f})")
    ax.set_ylabel("alpha tests per primary ray")
    ax.set_ylim(0, top * 1.15)
    ax.grid(True, which="both", alpha=0.3)
    cam = report["camera"]
    ax.set_title(f"Alpha tests per primary ray against map bytes\n{os.path.basename(report['scene']['file'])}, "
                 f"{cam['width']}x{cam['height']}", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    if pts_all:
        xs = [p[0] / unit for _, pts in drawn for p in pts]
        ys = [p[1] for _, pts in drawn for p in pts]
        marker_px = MARKER_PT * dpi / 72
        new_x = dodge(ax, xs, ys, marker_px + 5)
        i = 0
        for line, pts in drawn:
            line.set_xdata(new_x[i:i + len(pts)])
            i += len(pts)
        place_labels(ax, new_x, ys, [p[2] for _, pts in drawn for p in pts], fontsize=7.5, marker_px=marker_px)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)


def _frontier_points(report: dict) -> list[tuple]:
    """(family, label, map bytes, lines per ray or None, tests per ray) of every traced scheme
    but ``none``: its own layout and, where ``--memory`` measured it and its bytes differ, its
    shared one (``triL``'s: the standard OMMs, labelled OMM)."""
    out = []
    for n, r in report["schemes"].items():
        if n == "none" or not r.get("map_bytes"):
            continue
        settings = report["settings"]["schemes"].get(n, {})
        fam = _plot_family(n, settings)
        mem = r.get("memory")
        tests = r["alpha_tests_per_primary_ray"]
        out.append((fam, n, r["map_bytes"], mem["own"]["map_lines_per_ray"] if mem else None, tests))
        if mem and mem["shared"]["map_bytes"] != mem["own"]["map_bytes"]:
            tag = "OMM" if settings.get("kind") == "micromap" and settings.get("representation", "raw") == "raw" \
                else "shared"
            out.append((fam, f"{n} {tag}", mem["shared"]["map_bytes"], mem["shared"]["map_lines_per_ray"], tests))
    return out


def _total_points(report: dict) -> list[tuple]:
    """(family, label, map + texture lines per ray, tests per ray) of every (scheme, layout) that
    ``--memory`` measured with its texture lines, ``_frontier_points``' labels, and ``none`` (its
    texture lines alone)."""
    out = []
    for n, r in report["schemes"].items():
        mem = r.get("memory")
        if not mem or "texture_lines_per_ray" not in mem:
            continue
        tests = r["alpha_tests_per_primary_ray"]
        if n == "none":
            out.append(("none", "none", mem["texture_lines_per_ray"], tests))
            continue
        settings = report["settings"]["schemes"].get(n, {})
        fam = _plot_family(n, settings)
        out.append((fam, n, mem["own"]["total_lines_per_ray"], tests))
        if mem["shared"]["map_bytes"] != mem["own"]["map_bytes"]:
            tag = "OMM" if settings.get("kind") == "micromap" and settings.get("representation", "raw") == "raw" \
                else "shared"
            out.append((fam, f"{n} {tag}", mem["shared"]["total_lines_per_ray"], tests))
    return out


def frontier_plot(path: str, report: dict) -> None:
    """Alpha tests per primary ray against map bytes (log x) and, when ``--memory`` measured it,
    against 64-byte lines of map data per primary ray and against map plus alpha-texture lines
    per primary ray (``none`` a point there: its texture lines): every traced scheme (its own
    layout and its shared one), the Pareto front marked (``omaps.frontier``), dominated points
    lighter, 'none' as a level; a colour per family."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..frontier import front_panel, label_panel

    pts = _frontier_points(report)
    with_lines = [p for p in pts if p[3] is not None]  # (a budget's or a file's maps: no memory model)
    totals = _total_points(report) if with_lines else []
    n_panels = 1 + bool(with_lines) + bool(totals)
    dpi = 110
    fig, axes = plt.subplots(1, n_panels, figsize=(6.75 * n_panels if n_panels > 1 else 7.5, 5.6), dpi=dpi,
                             squeeze=False)
    axes = axes[0]
    fams = list(dict.fromkeys([p[0] for p in pts] + [p[0] for p in totals]))
    none = report["schemes"].get("none")
    top = max([p[4] for p in pts] + [none["alpha_tests_per_primary_ray"] if none else 0.0] + [1e-9])
    cam = report["camera"]
    scene = os.path.basename(report["scene"]["file"])
    panels = [(axes[0], pts, [p[2] for p in pts], [p[4] for p in pts])]
    if with_lines:
        panels.append((axes[1], with_lines, [p[3] for p in with_lines], [p[4] for p in with_lines]))
    if totals:
        panels.append((axes[2], totals, [p[2] for p in totals], [p[3] for p in totals]))
    titles = ["Alpha tests per primary ray against map bytes", "Alpha tests per primary ray against map lines read per ray",
              "Alpha tests per primary ray against map + texture lines per ray"]
    drawn = []
    for k, (ax, ps, xs, ys) in enumerate(panels):
        if k == 0 and ps:
            unit = _bytes_axis(ax, xs)
            xs = [x / unit for x in xs]
        elif ps:
            ax.set_xlim(0, max(xs) * 1.12 + 1e-9)
            ax.set_xlabel("64-byte lines of map data per primary ray (own or shared layout)" if k == 1 else
                          "64-byte lines of map data + alpha texture (RGBA8, 4x4 tiles) per primary ray")
        if ps:
            front_panel(ax, xs, ys, colours=[f"C{fams.index(p[0]) % 10}" for p in ps], marker_pt=MARKER_PT)
        drawn.append((ax, xs, ys, [p[1] for p in ps]))
        if none is not None:
            ax.axhline(none["alpha_tests_per_primary_ray"], color="grey", ls="--", lw=1,
                       label=f"none, no maps ({none['alpha_tests_per_primary_ray']:.2f})")
        for f in dict.fromkeys(p[0] for p in ps):
            ax.plot([], [], "o", color=f"C{fams.index(f) % 10}", ls="none", label=f)
        ax.set_ylabel("alpha tests per primary ray")
        ax.set_ylim(0, top * 1.15)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_title(titles[k] + "\n"
                     + f"{scene}, {cam['width']}x{cam['height']}; Pareto front: fewer is better on both axes",
                     fontsize=9.5)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, fontsize=7.5, frameon=False)
    fig.tight_layout()
    for ax, xs, ys, labels in drawn:
        if xs:
            label_panel(ax, xs, ys, labels, marker_pt=MARKER_PT)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
