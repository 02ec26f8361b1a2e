"""Pictures of a traced scene: the heat map of alpha tests per pixel (the deck's) and the
alpha-tested render."""

from __future__ import annotations

import math

import numpy as np

from ..atomic import atomic_path

__all__ = ["heatmap", "render", "budget_plot"]


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
        return "triL (per-triangle micromaps)"
    if kind == "square" and settings.get("codec", "").startswith("sq"):
        return "sqN (raw square maps)"
    if kind == "budget":
        return "budget (per-pair choice)"
    if kind == "square":
        return "codecs"
    return name


def budget_plot(path: str, report: dict) -> None:
    """Alpha tests per primary ray against map bytes of every traced scheme (``omaps trace``'s
    report), a line per family: uniform sqN, triL, the codecs, the budgets; 'none' as a level."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=120)
    families: dict[str, list] = {}
    for n, r in report["schemes"].items():
        if n == "none" or not r.get("map_bytes"):
            continue
        fam = _plot_family(n, report["settings"]["schemes"].get(n, {}))
        families.setdefault(fam, []).append((r["map_bytes"], r["alpha_tests_per_primary_ray"], n))
    for fam, pts in families.items():
        pts.sort()
        xs, ys, labels = zip(*pts)
        ax.plot(xs, ys, marker="o", label=fam, ls="-" if len(pts) > 1 else "none")
        for x, y, lab in pts:
            ax.annotate(lab, (x, y), textcoords="offset points", xytext=(4, 5), fontsize=7)
    none = report["schemes"].get("none")
    if none is not None:
        ax.axhline(none["alpha_tests_per_primary_ray"], color="grey", ls="--", lw=1,
                   label=f"none ({none['alpha_tests_per_primary_ray']:.2f})")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("map bytes (every prototype pair or triangle)")
    ax.set_ylabel("alpha tests per primary ray")
    ax.set_ylim(bottom=0)
    ax.grid(True, which="both", alpha=0.3)
    cam = report["camera"]
    ax.set_title(f"{report['scene']['file']} at {cam['width']}x{cam['height']}", fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
