"""The data of a report's 3D view: every prototype mesh (opaque and alpha-tested triangles), its
instances, each alpha material's texture, and per scheme a *state atlas* that draws each alpha
triangle's map states on the mesh.

A state atlas holds one small right-triangle image per distinct alpha triangle map: texel (i, j)
of a triangle's image is the state the tracer reads at barycentrics ((i + ½)/R, (j + ½)/R) --
the scheme's own state function (``trace.lookups.state_function``) on its stored data, so a
micromap, a pair's square map, a codec's block, a budget's mixed maps and the micromaps or pair
blocks stored in a file are all drawn as the any-hit filter sees them. Two triangle images share
one tile of R × (R + 1) texels (the second turned half a turn); the page reads the tile of a
triangle with ``texelFetch``. Identical triangle images are stored once.
"""

from __future__ import annotations

import base64
import io

import numpy as np
from numba import njit

from .. import states

__all__ = ["scene_view", "state_atlas", "atlas_resolution", "uv_overlay", "MAX_ATLAS"]

MAX_ATLAS = 8192  # texels per side of a state atlas (WebGL's usual MAX_TEXTURE_SIZE, SwiftShader's too)
MAX_TEXTURE = 512  # an alpha texture's longest side on the page
MAX_OVERLAY_TRIANGLES = 200_000  # triangles drawn over one material's UV layout


@njit  # not cached: its key holds the state function's dispatcher, which numba's cache cannot pickle reliably
def _triangle_images(state_fn, table, n_tris, res):
    """Every alpha triangle's image: (n_tris, res * (res + 1) / 2) states, texels (i, j) with
    i + j <= res - 1 in order of j, then i."""
    n = res * (res + 1) // 2
    out = np.empty((n_tris, n), np.uint8)
    for t in range(n_tris):
        k = 0
        for j in range(res):
            for i in range(res - j):
                out[t, k] = state_fn(table, t, (i + 0.5) / res, (j + 0.5) / res)
                k += 1
    return out


def atlas_resolution(sm) -> int:
    """Texels R along a triangle image's legs for a scheme's maps (``trace.maps.SchemeMaps``):
    two per micro-triangle edge of a level-L micromap, two per cell of an N x N square map (a
    triangle covers half the pair's square, sheared), 8 to 64."""
    if sm.kind == "none":
        return 8
    if sm.kind == "micromap":
        return int(np.clip(2 << int(sm.param), 8, 64))
    if sm.kind == "stored_micromap":  # each row its own level: the finest stored
        from ..trace.tables import T_MAP_LEVEL

        levels = sm.extra.get(T_MAP_LEVEL)
        return int(np.clip(2 << int(levels.max() if levels is not None and len(levels) else 3), 8, 64))
    if sm.kind == "square":
        return int(np.clip(2 * int(sm.param), 8, 64))
    return 64


def _tile_layout(n_images: int, res: int) -> tuple[int, int, int]:
    """Columns, rows and (width, height) fit of ``n_images`` triangle images in tiles of
    res x (res + 1), two per tile; None when they do not fit in MAX_ATLAS x MAX_ATLAS."""
    tiles = (n_images + 1) // 2
    cols = max(1, min(tiles, MAX_ATLAS // res))
    rows = -(-tiles // cols)
    return cols, rows, rows * (res + 1)


def state_atlas(prep, name: str, order: np.ndarray | None = None, res: int | None = None) -> dict:
    """The state atlas of scheme ``name`` of a prepared scene (``trace.prepare``).

    Parameters
    ----------
    prep : omaps.trace.Prepared
        The prepared scene; ``prep.maps[name]`` are the scheme's stored maps.
    name : str
        The scheme.
    order : ndarray of int, optional
        The alpha triangles (rows of ``prep.alpha``) in the order the page draws them.
    res : int, optional
        Texels along a triangle image's legs (default ``atlas_resolution``); halved until the
        atlas fits in ``MAX_ATLAS`` texels per side.

    Returns
    -------
    dict
        ``res``, ``cols`` (tiles per row), ``image`` (H, W, 3) uint8 in the state colours,
        ``slots`` (per triangle of ``order``: its image's slot, tile = slot // 2, second half
        when odd) and ``known`` (the share of T or O texels over the triangles).
    """
    from ..rows import unique_rows
    from ..trace.lookups import state_function
    from ..trace.tables import scheme_tables

    sm = prep.maps[name]
    n_tris = prep.alpha.count
    order = np.arange(n_tris) if order is None else np.asarray(order)
    res = atlas_resolution(sm) if res is None else int(res)
    tables = scheme_tables(prep.base, sm)
    fn = state_function(sm)
    while True:
        if n_tris:
            imgs = _triangle_images(fn, tables.table, n_tris, res)
            uniq, inverse = unique_rows(imgs)
        else:
            imgs = uniq = np.zeros((0, res * (res + 1) // 2), np.uint8)
            inverse = np.zeros(0, np.int64)
        cols, rows, height = _tile_layout(max(1, len(uniq)), res)
        if height <= MAX_ATLAS or res <= 2:
            break
        res //= 2
    known = float((imgs != states.C).mean()) if n_tris else 0.0
    atlas = np.full((rows * (res + 1), cols * res), 3, np.uint8)  # 3: no triangle
    jj, ii = np.nonzero(np.arange(res)[:, None] + np.arange(res)[None, :] <= res - 1)  # (j, i) in image order
    for slot in range(len(uniq)):
        tile = slot // 2
        ox, oy = (tile % cols) * res, (tile // cols) * (res + 1)
        if slot % 2 == 0:
            atlas[oy + jj, ox + ii] = uniq[slot]
        else:
            atlas[oy + res - jj, ox + res - 1 - ii] = uniq[slot]
    palette = np.vstack([states.COLOURS, [[40, 40, 40]]]).astype(np.uint8)
    return {"res": res, "cols": cols, "image": palette[atlas], "states": atlas,
            "slots": np.asarray(inverse, np.int64)[order].astype(np.uint32), "known": known,
            "distinct": int(len(uniq))}


@njit(cache=True)
def _draw_uv(uv, slots, atlas, res, cols, size, out):
    """Draw triangles (UV corners ``uv`` (n, 3, 2), each moved by whole textures so its centroid
    lies in [0, 1)^2) over ``out`` (size, size): every pixel centre inside one gets the state of
    its texel in the atlas, as the page's shader reads it."""
    for t in range(uv.shape[0]):
        cu = np.floor((uv[t, 0, 0] + uv[t, 1, 0] + uv[t, 2, 0]) / 3)
        cv = np.floor((uv[t, 0, 1] + uv[t, 1, 1] + uv[t, 2, 1]) / 3)
        u0, v0 = uv[t, 0, 0] - cu, uv[t, 0, 1] - cv
        e1u, e1v = uv[t, 1, 0] - cu - u0, uv[t, 1, 1] - cv - v0
        e2u, e2v = uv[t, 2, 0] - cu - u0, uv[t, 2, 1] - cv - v0
        det = e1u * e2v - e1v * e2u
        if det == 0.0:
            continue
        lo_u = min(u0, u0 + e1u, u0 + e2u)
        hi_u = max(u0, u0 + e1u, u0 + e2u)
        lo_v = min(v0, v0 + e1v, v0 + e2v)
        hi_v = max(v0, v0 + e1v, v0 + e2v)
        x0, x1 = max(0, int(np.floor(lo_u * size))), min(size - 1, int(np.ceil(hi_u * size)))
        y0, y1 = max(0, int(np.floor(lo_v * size))), min(size - 1, int(np.ceil(hi_v * size)))
        slot = slots[t]
        tile = slot // 2
        ox, oy = (tile % cols) * res, (tile // cols) * (res + 1)
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                du, dv = (x + 0.5) / size - u0, (y + 0.5) / size - v0
                b1 = (du * e2v - dv * e2u) / det
                b2 = (e1u * dv - e1v * du) / det
                if b1 < -1e-9 or b2 < -1e-9 or b1 + b2 > 1 + 1e-9:
                    continue
                i = min(max(int(np.floor(b1 * res)), 0), res - 1)
                j = min(max(int(np.floor(b2 * res)), 0), res - 1 - i)
                if slot % 2 == 0:
                    out[y, x] = atlas[oy + j, ox + i]
                else:
                    out[y, x] = atlas[oy + res - j, ox + res - 1 - i]


def uv_overlay(texture_rgba: np.ndarray, uv: np.ndarray, slots: np.ndarray, atlas: dict, size: int = 384) -> np.ndarray:
    """A material's alpha texture (grey) at ``size`` px with its triangles' map states drawn over
    their UV layout (``uv`` (n, 3, 2), ``slots`` of ``state_atlas``): (size, size, 3) uint8."""
    h, w = texture_rgba.shape[:2]
    ys = (np.arange(size) * h) // size
    xs = (np.arange(size) * w) // size
    grey = texture_rgba[np.ix_(ys, xs)][..., 3].astype(np.float64)
    drawn = np.full((size, size), 3, np.uint8)
    rows = np.column_stack([np.asarray(uv, np.float64).reshape(len(uv), 6), np.asarray(slots, np.float64)])
    rows = np.unique(rows, axis=0)  # instances of a card: each distinct triangle drawn once
    uv, slots = rows[:, :6].reshape(-1, 3, 2), rows[:, 6].astype(np.int64)
    _draw_uv(np.ascontiguousarray(uv, np.float64), np.ascontiguousarray(slots, np.int64), atlas["states"],
             atlas["res"], atlas["cols"], size, drawn)
    out = np.repeat(grey[..., None], 3, axis=2)
    hit = drawn < 3
    out[hit] = 0.35 * out[hit] + 0.65 * states.COLOURS[drawn[hit]]
    return np.round(out).astype(np.uint8)


# ---- encoding ---------------------------------------------------------------------------------

def b64(a: np.ndarray, dtype) -> str:
    """An array as base64 of its little-endian bytes in ``dtype``."""
    return base64.b64encode(np.ascontiguousarray(a, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()).decode()


def png_data_uri(img: np.ndarray, palette: bool = False) -> str:
    """A PNG data URI of an (H, W), (H, W, 3) or (H, W, 4) uint8 image; ``palette``: stored with
    a colour palette (few colours: far smaller)."""
    from PIL import Image

    im = Image.fromarray(np.ascontiguousarray(img))
    if palette and im.mode == "RGB":
        im = im.quantize(colors=8, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    buf = io.BytesIO()
    im.save(buf, format="PNG", compress_level=9 if im.width * im.height <= 1 << 22 else 6)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _texture_image(prep, m: int) -> tuple[np.ndarray, float]:
    """Material m's base colour and alpha as RGBA uint8 (longest side at most MAX_TEXTURE), and
    its alpha test's threshold on the same 0..1 scale."""
    scene = prep.scene
    mat = scene.materials[m]
    test = prep.tests[m]
    v = np.asarray(test.value, np.float64)
    tex = scene.textures[mat.texture] if mat.texture >= 0 else None
    scale = float(tex.maxval) if tex is not None and np.asarray(test.value).dtype.kind in "ui" else 1.0
    alpha = np.clip(v / scale, 0, 1)
    h, w = alpha.shape
    rgba = np.empty((h, w, 4), np.uint8)
    rgb = tex.rgb if tex is not None and tex.rgb is not None and tex.rgb.shape[:2] == (h, w) else None
    if rgb is not None:
        rgba[..., :3] = np.asarray(rgb)[..., :3]
    else:
        rgba[..., :3] = np.round(np.clip(np.asarray(mat.base_colour[:3], np.float64), 0, 1) * 255).astype(np.uint8)
    rgba[..., 3] = np.round(alpha * 255).astype(np.uint8)
    step = max(1, -(-max(h, w) // MAX_TEXTURE))
    return rgba[::step, ::step], float(test.threshold) / scale


def scene_view(prep, names, camera=None) -> dict:
    """The 3D view's data for a prepared scene and the schemes ``names`` (JSON-ready: arrays as
    base64, images as PNG data URIs).

    Parameters
    ----------
    prep : omaps.trace.Prepared
        The prepared scene (``trace.prepare``, or ``TraceResult.prep``).
    names : list of str
        The schemes drawn, each in ``prep.maps``.
    camera : omaps.trace.Camera, optional
        The initial view (the traced one); None: framed by the page.

    Returns
    -------
    view : dict
        ``protos`` (per prototype mesh its opaque and alpha triangles, its instances),
        ``materials``, ``schemes`` (per scheme its atlas and triangle slots), ``camera``,
        ``bounds``.
    overlays : dict
        Per alpha material (its index as text), per scheme: the PNG data URI of its texture with
        the scheme's states over its triangles' UV layout (``uv_overlay``).
    """
    scene, at = prep.scene, prep.alpha
    protos, order = [], []
    used = sorted({mi for mi, _ in scene.instances})
    inst = {k: [] for k in used}
    for mi, mtx in scene.instances:
        inst[mi].append(np.asarray(mtx, np.float64).T.ravel())  # column-major, as three.js reads it
    alpha_mats: set[int] = set()
    start = 0
    for k in used:
        mg = scene.meshes[k].merged
        pos = np.asarray(mg["positions"], np.float32)
        op = prep.opaque_tris[k]
        op = op[np.argsort(mg["material"][op], kind="stable")]
        groups = []
        for m in np.unique(mg["material"][op]):
            sel = np.flatnonzero(mg["material"][op] == m)
            c = scene.materials[int(m)].base_colour
            tex = scene.textures[scene.materials[int(m)].texture] if scene.materials[int(m)].texture >= 0 else None
            if tex is not None and tex.rgb is not None:
                c = np.asarray(c[:3]) * np.asarray(tex.rgb, np.float64)[..., :3].reshape(-1, 3).mean(axis=0) / 255
            groups.append([int(sel[0]) * 3, len(sel) * 3, [float(x) for x in np.asarray(c[:3])]])
        rows = np.arange(at.base[k], at.base[k + 1]) if k < len(at.base) - 1 else np.zeros(0, np.int64)
        rows = rows[np.argsort(at.material[rows], kind="stable")]
        agroups = []
        for m in np.unique(at.material[rows]):
            sel = np.flatnonzero(at.material[rows] == m)
            agroups.append([int(sel[0]) * 3, len(sel) * 3, int(m)])
            alpha_mats.add(int(m))
        order.append(rows)
        tri = mg["triangles"]
        protos.append({
            "mesh": int(k), "name": scene.meshes[k].name,
            "opaque": {"pos": b64(pos[tri[op]].reshape(-1), np.float32), "groups": groups},
            "alpha": {"pos": b64(pos[tri[at.mesh_tri[rows]]].reshape(-1), np.float32),
                      "uv": b64(at.uv[rows].reshape(-1), np.float32), "groups": agroups, "start": start,
                      "count": int(len(rows))},
            "instances": b64(np.concatenate(inst[k]), np.float32), "instance_count": len(inst[k]),
        })
        start += len(rows)
    order = np.concatenate(order) if order else np.zeros(0, np.int64)
    materials, images = {}, {}
    for m in sorted(alpha_mats):
        images[m], thr = _texture_image(prep, m)
        materials[str(m)] = {"name": scene.materials[m].name, "texture": png_data_uri(images[m]), "threshold": thr}
    schemes = []
    overlays = {str(m): {} for m in alpha_mats}
    mat_of = at.material[order]
    for n in names:
        a = state_atlas(prep, n, order)
        for m in alpha_mats:
            sel = np.flatnonzero(mat_of == m)[:MAX_OVERLAY_TRIANGLES]
            overlays[str(m)][n] = png_data_uri(uv_overlay(images[m], at.uv[order[sel]], a["slots"][sel], a))
        schemes.append({"name": n, "res": a["res"], "cols": a["cols"], "width": int(a["image"].shape[1]),
                        "height": int(a["image"].shape[0]), "atlas": png_data_uri(a["image"], palette=True),
                        "slots": b64(a["slots"], np.uint32), "distinct": a["distinct"], "known": a["known"]})
    lo, hi = scene.bounds()
    cam = None if camera is None else {k: v for k, v in camera.to_json().items()}
    return {"protos": protos, "materials": materials, "schemes": schemes, "camera": cam,
            "bounds": [[float(x) for x in lo], [float(x) for x in hi]]}, overlays
