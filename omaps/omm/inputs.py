"""What ``omaps omm`` reads: a texture plus a UV array, or a scene (glTF or OpenUSD), as ``Geometry``
lists.

An input is described by a small JSON-able ``spec`` (kept in omm.json), so ``--verify`` can
load the same geometry again and re-bake it; its kind ``gltf`` stands for any scene file (the
loader reads it by its suffix). Scenes go through the one scene loader (``omaps.scene``) and
the one material rule (``alpha_test.MaterialRules``), with the tracer's pairs: every
alpha-tested primitive is one geometry (a USD one records its prim and each triangle's face).
"""

from __future__ import annotations

import os

import numpy as np

from ..alpha_test import MaterialRules, StateRule
from ..bake.micromap import check_uv_triangles
from ..errors import InputError
from ..texture import load_alpha
from .pipeline import Geometry

__all__ = ["texture_spec", "scene_spec", "check_spec", "load_uvs", "load_geometries"]


def texture_spec(texture, uvs, cutoff=None, filter=None, wrap=None, channel=None) -> dict:
    return {"kind": "texture", "texture": os.path.abspath(texture), "uvs": os.path.abspath(uvs),
            "cutoff": 0.5 if cutoff is None else float(cutoff), "filter": filter or "nearest",
            "wrap": wrap or "clamp", "channel": channel}


def scene_spec(path, rules: MaterialRules = MaterialRules()) -> dict:
    """A scene file's spec (glTF or OpenUSD: ``scene.load_scene`` reads either)."""
    return {"kind": "scene", "path": os.path.abspath(path), **rules.settings()}


def check_spec(spec) -> dict:
    """An input spec as omm.json records it (``texture_spec`` / ``scene_spec``), checked: an
    InputError saying which field is wrong (the caller names the file)."""
    if not isinstance(spec, dict):
        raise InputError(f"input is {spec!r}, not an object")

    def field(key, kinds, optional=False):
        v = spec.get(key)
        if v is None and optional:
            return None
        if kinds is str:
            if not isinstance(v, str) or not v:
                raise InputError(f"input.{key} is {v!r}, a non-empty string expected")
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not -1e300 < v < 1e300:  # no NaN, no inf
            raise InputError(f"input.{key} is {v!r}, a finite number expected")
        return v

    kind = spec.get("kind")
    if kind == "texture":
        field("texture", str), field("uvs", str)
        channel = spec.get("channel")
        if channel is not None and (not isinstance(channel, (str, int)) or isinstance(channel, bool)):
            raise InputError(f"input.channel is {channel!r}, a channel name or index expected")
        StateRule("cutoff", cutoff=field("cutoff", float))
        MaterialRules(filter=field("filter", str), wrap=field("wrap", str))  # checks the names
    elif kind == "scene":
        field("path", str)
        blend = field("blend", str) if "blend" in spec else "levels"
        blend_cutoff = field("blend_cutoff", float) if "blend_cutoff" in spec else 0.5
        MaterialRules(field("cutoff", float, True), field("filter", str, True), field("wrap", str, True), blend,
                      blend_cutoff)
    else:
        raise InputError(f"input.kind is {kind!r}, texture or scene expected")
    return spec


def load_uvs(path) -> np.ndarray:
    """A .npy array of UV triangles (T, 3, 2), checked (``bake.micromap.check_uv_triangles``);
    an InputError naming the file otherwise."""
    if not os.path.exists(path):
        raise InputError("no such file", path)
    try:
        uvs = np.load(path, allow_pickle=False)
    except Exception as exc:  # numpy's .npy parsing: the third-party decode boundary, message kept
        raise InputError(f"cannot read UV array ({type(exc).__name__}: {exc})", path) from None
    if not isinstance(uvs, np.ndarray):
        uvs.close()
        raise InputError("not a .npy array (an .npz archive?)", path)
    if uvs.dtype.kind not in "biuf":
        raise InputError(f"UV array of dtype {uvs.dtype}, numbers expected", path)
    try:
        return check_uv_triangles(uvs)
    except InputError as exc:
        raise InputError(exc.problem, path) from None


def load_geometries(spec: dict, view=None, **assets) -> tuple[list[Geometry], list[dict], list[str]]:
    """(geometries, skipped primitives, warnings) of an input spec. ``view``: a scene's --budget
    weights and hits per alpha triangle (``view.scene_view_samples``) instead of area.
    ``assets``: ``root``, ``allow_outside``, ``max_bytes`` of a scene's ``load_scene``."""
    if spec["kind"] == "texture":
        tex = load_alpha(spec["texture"], spec.get("channel"))
        test = StateRule("cutoff", cutoff=spec["cutoff"]).alpha_test(tex, spec["filter"], spec["wrap"])
        return [Geometry(os.path.basename(spec["texture"]), test, load_uvs(spec["uvs"]))], [], []
    return _gltf_geometries(spec, view, assets)


def _gltf_geometries(spec, view=None, assets=None):
    from ..budget import triangle_weights
    from ..scene import alpha_triangles, load_scene

    rules = MaterialRules(spec.get("cutoff"), spec.get("filter"), spec.get("wrap"), spec.get("blend", "levels"),
                          spec.get("blend_cutoff", 0.5))
    scene = load_scene(spec["path"], **(assets or {}))
    at = alpha_triangles(scene, rules)
    weight = triangle_weights(scene, at) if view is None else view[0]  # --budget's: world area x instances
    hits = None if view is None else np.asarray(view[1], np.int64).reshape(-1, 2)
    if len(weight) != at.count:
        raise InputError(f"{len(weight)} view weights for {at.count} alpha triangles", spec["path"])
    tested = scene.alpha_tested(rules)
    skipped = list(scene.skipped)
    geoms = []
    tests = {}
    for k, mesh in enumerate(scene.meshes):
        rows_mesh = np.arange(at.base[k], at.base[k + 1])
        for pi, p in enumerate(mesh.primitives):
            where = {"mesh": p.mesh, "primitive": p.index, "name": mesh.name}
            mat = scene.materials[p.material]
            if not tested[p.material]:
                reason = "BLEND material (--blend skip)" if mat.alpha_mode == "BLEND" else "opaque material (no alpha test)"
                skipped.append({**where, "reason": reason})
                continue
            rows = rows_mesh[at.primitive[rows_mesh] == pi]
            if p.material not in tests:
                tests[p.material] = scene.alpha_test(p.material, rules)
            test = tests[p.material]
            pair_rows = at.pair[rows]
            _, pair_of = np.unique(pair_rows, return_inverse=True)
            info = {**where, "material": mat.name, "alpha_mode": mat.alpha_mode, "alpha_factor": mat.base_colour[3],
                    "unknown_triangles": int(at.unknown[rows].sum())}
            if p.source is not None:  # a USD prim: its path, and per triangle the face it comes from
                info["prim"] = p.source
            if p.faces is not None:
                info["faces"] = p.faces[at.local[rows]].tolist()
            tex = scene.textures[mat.texture] if mat.texture >= 0 else None
            if tex is not None and tex.problem is not None:
                info["problem"] = tex.problem
            local = None
            if hits is not None:  # the hits on these rows, by their index among them
                pos = np.full(at.count, -1, np.int64)
                pos[rows] = np.arange(len(rows))
                mine = hits[pos[hits[:, 0]] >= 0]
                local = np.stack([pos[mine[:, 0]], mine[:, 1]], axis=1)
            geoms.append(Geometry(f"{mesh.name} (mesh {p.mesh}, primitive {p.index})", test, at.uv[rows],
                                  area=p.areas[at.local[rows]], unknown=at.unknown[rows], info=info,
                                  pair_of=pair_of.ravel(), corners=at.corners[rows], weight=weight[rows],
                                  hits=local))
    if not geoms:
        raise InputError("no alpha-tested primitive in the scene "
                         f"({len(skipped)} skipped: {', '.join(sorted({s['reason'] for s in skipped})) or 'none'})",
                         spec["path"])
    return geoms, skipped, list(scene.warnings)
