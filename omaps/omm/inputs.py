"""What ``omaps omm`` reads: a texture plus a UV array, or a glTF scene, as ``Geometry`` lists.

An input is described by a small JSON-able ``spec`` (kept in omm.json), so ``--verify`` can
load the same geometry again and re-bake it.

glTF materials: MASK is alpha-tested (opaque iff alpha * baseColorFactor.a >= alphaCutoff,
default 0.5; texels within CUTOFF_TOLERANCE of the cut-off are unknown); BLEND follows ``blend``: ``levels`` (T only where alpha is 0, O only where it is 1,
unknown between: exact for blending), ``cutoff`` (alpha-tested like MASK, at the cut-off) or
``skip``. A base colour texture that cannot be read gives a warning naming the file, and its
primitive's micro-triangles are all unknown (the any-hit shader decides every hit). Triangles
with zero UV area (they read a line or a point of the texture) are all unknown too.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from ..errors import InputError
from ..maps import check_uv_triangles
from ..texture import load_alpha
from .alpha_test import AlphaTest
from .pipeline import Geometry

BLEND_RULES = ("levels", "cutoff", "skip")
# glTF texels whose alpha * baseColorFactor.a is this close to the cut-off are unknown: a shader's
# float32 product may fall on either side (exact 8-bit alphas are 1/255 = 0.0039 apart)
CUTOFF_TOLERANCE = 1e-6
_DUMMY_UV = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


def _warn(msg: str) -> None:
    print(f"omaps: warning: {msg}", file=sys.stderr)


def texture_spec(texture, uvs, cutoff=None, filter=None, wrap=None, channel=None) -> dict:
    return {"kind": "texture", "texture": os.path.abspath(texture), "uvs": os.path.abspath(uvs),
            "cutoff": 0.5 if cutoff is None else float(cutoff), "filter": filter or "nearest",
            "wrap": wrap or "clamp", "channel": channel}


def gltf_spec(path, cutoff=None, filter=None, wrap=None, blend="levels") -> dict:
    """``cutoff``, ``filter``, ``wrap``: None keeps each material's and sampler's own."""
    if blend not in BLEND_RULES:
        raise InputError(f"unknown blend rule {blend!r} (choose from {', '.join(BLEND_RULES)})")
    return {"kind": "gltf", "path": os.path.abspath(path), "cutoff": cutoff, "filter": filter, "wrap": wrap,
            "blend": blend}


def load_uvs(path) -> np.ndarray:
    try:
        uvs = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read UV array ({exc})", path) from None
    try:
        return check_uv_triangles(uvs)
    except InputError as exc:
        raise InputError(exc.problem, path) from None


def load_geometries(spec: dict, warn=_warn) -> tuple[list[Geometry], list[dict]]:
    """(geometries, skipped primitives) of an input spec."""
    if spec["kind"] == "texture":
        tex = load_alpha(spec["texture"], spec.get("channel"))
        test = AlphaTest.from_cutoff(tex, spec["cutoff"], spec["filter"], spec["wrap"])
        return [Geometry(os.path.basename(spec["texture"]), test, load_uvs(spec["uvs"]))], []
    return _gltf_geometries(spec, warn)


def _zero_uv_area(tris: np.ndarray, w: int, h: int) -> np.ndarray:
    t = tris * np.array([w, h], dtype=np.float64)
    e1 = t[:, 1] - t[:, 0]
    e2 = t[:, 2] - t[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    scale = np.maximum(np.abs(tris).max(axis=(1, 2)), 1.0) if len(tris) else np.ones(0)
    return ~np.isfinite(t).all(axis=(1, 2)) | (area2 <= 1e-12 * scale * scale * w * h)


def _gltf_geometries(spec, warn):
    from .. import gltf

    scene = gltf.alpha_primitives(spec["path"])
    geoms, skipped = [], list(scene.skipped)
    for p in scene.primitives:
        where = {"mesh": p.mesh, "primitive": p.primitive, "name": p.name}
        rule = "test"
        if p.alpha_mode == "BLEND":
            if spec["blend"] == "skip":
                skipped.append({**where, "reason": "BLEND material (--blend skip)"})
                continue
            rule = "blend" if spec["blend"] == "levels" else "test"
        cutoff = p.cutoff if spec["cutoff"] is None else float(spec["cutoff"])
        filt = spec["filter"] or p.filter
        wrap_u = spec["wrap"] or p.wrap_u
        wrap_v = spec["wrap"] or p.wrap_v
        tris = p.tris_uv
        unknown = None
        if p.alpha is not None:
            value = p.alpha.values.astype(np.float64) / p.alpha.maxval * p.alpha_factor
            name = p.texture_name
        elif p.problem is not None:
            warn(f"{spec['path']}: mesh {p.mesh} primitive {p.primitive}: base colour texture "
                 f"{p.texture_name!r} cannot be read ({p.problem}); its micro-triangles are all unknown")
            value, rule, name = np.ones((1, 1)), "unknown", p.texture_name
        else:  # no texture: the factor alone decides, uniformly
            value, name = np.full((1, 1), p.alpha_factor), None
            tris = np.broadcast_to(_DUMMY_UV, tris.shape).copy()
        test = AlphaTest(name or "(no texture)", value, cutoff, True, filt, wrap_u, wrap_v, rule, CUTOFF_TOLERANCE)
        bad = _zero_uv_area(tris, test.width, test.height)
        if bad.any():
            unknown = bad
            tris = tris.copy()
            tris[bad] = _DUMMY_UV
        info = {**where, "alpha_mode": p.alpha_mode, "alpha_factor": p.alpha_factor,
                "zero_uv_area_triangles": int(bad.sum())}
        if p.problem is not None:
            info["problem"] = p.problem
        geoms.append(Geometry(f"{p.name} (mesh {p.mesh}, primitive {p.primitive})", test, tris, area=p.areas, info=info,
                              unknown=unknown))
    if not geoms:
        raise InputError("no alpha-tested primitive in the scene "
                         f"({len(skipped)} skipped: {', '.join(sorted({s['reason'] for s in skipped})) or 'none'})",
                         spec["path"])
    return geoms, skipped

