"""The scene model every command reads: meshes of primitives, instances, materials, textures.

A glTF mesh referenced by a node is a *prototype*; each node referencing it an *instance* (its
world transform), as a BLAS shared by several TLAS instances. Each mesh keeps its primitives:
positions, triangles, the texture coordinates the material's base colour texture reads
(``KHR_texture_transform`` applied) and the material. Materials keep what the alpha test needs;
``Scene.alpha_test`` turns one into the core ``AlphaTest`` under ``MaterialRules`` -- the same
for ``omaps trace`` and ``omaps omm``. ``omaps.scene.load_scene`` builds it, from glTF
(``scene.gltf``) or OpenUSD (``scene.usd``: a mesh prim is a mesh, its faces bound to one
material a primitive, and each primitive names its prim (``source``) and each triangle the face
it comes from (``faces``), so that an engine can attach the maps baked for it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..alpha_test import AlphaTest, MaterialRules, material_test

__all__ = ["Material", "Texture", "Primitive", "Mesh", "Scene", "SceneCamera", "SceneWarning"]

ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")


class SceneWarning(UserWarning):
    """A problem in a scene file with a documented consequence (a missing image, NaN UVs)."""


@dataclass(frozen=True)
class Texture:
    """A base colour image: ``alpha`` raw values (H, W) uint8 or uint16 up to ``maxval``, ``rgb``
    for pictures; ``problem`` says why it could not be read (then ``alpha`` is None)."""

    name: str
    alpha: np.ndarray | None
    maxval: int = 255
    rgb: np.ndarray | None = None
    problem: str | None = None
    has_alpha: bool = True

    @classmethod
    def from_image(cls, label: str, pil) -> "Texture":
        """A decoded Pillow image as a texture: 16-bit greyscale as a 16-bit mask (``maxval``
        65535), anything else through RGBA (its alpha band, or opaque where it has none)."""
        if pil.mode in ("P", "PA", "RGBa", "La", "1"):
            pil = pil.convert("RGBA")
        bands = pil.getbands()
        if pil.mode in ("I;16", "I;16B", "I;16L", "I"):
            alpha = np.clip(np.asarray(pil, dtype=np.int64), 0, 65535).astype(np.uint16)  # a 16-bit mask
            grey = (alpha >> 8).astype(np.uint8)
            return cls(label, np.ascontiguousarray(alpha), 65535, np.repeat(grey[..., None], 3, axis=2), None, True)
        rgba = np.asarray(pil.convert("RGBA"), dtype=np.uint8)
        return cls(label, np.ascontiguousarray(rgba[..., 3]), 255, np.ascontiguousarray(rgba[..., :3]), None,
                   "A" in bands)


def own_vertices(positions, uvs, tris, vertex_alpha, sel):
    """Triangles ``sel`` get three new vertices each (same positions and vertex alpha) at UV
    (0, 0): a triangle with NaN texture coordinates reads one defined point of the texture, and
    its neighbours keep theirs. Pairing welds by position, so the pairs are unchanged."""
    k = np.flatnonzero(sel)
    old = tris[k].ravel()
    tris = tris.copy()
    tris[k] = len(positions) + np.arange(3 * len(k)).reshape(-1, 3)
    positions = np.concatenate([positions, positions[old]])
    uvs = np.concatenate([uvs, np.zeros((len(old), 2))])
    if vertex_alpha is not None:
        vertex_alpha = np.concatenate([vertex_alpha, vertex_alpha[old]])
    return positions, uvs, tris, vertex_alpha


@dataclass(frozen=True)
class Material:
    index: int
    name: str
    alpha_mode: str  # OPAQUE / MASK / BLEND as declared
    cutoff: float  # MASK: alphaCutoff (default 0.5)
    base_colour: tuple[float, float, float, float]
    texture: int  # index into Scene.textures, -1 for none
    filter: str  # "nearest" | "linear" (the sampler's magFilter; the test samples mip level 0)
    wrap_u: str
    wrap_v: str
    texcoord: int  # the TEXCOORD_n set the base colour texture reads
    double_sided: bool = False


@dataclass
class Primitive:
    mesh: int  # glTF mesh index
    index: int  # primitive index within the mesh
    positions: np.ndarray  # float64 (V, 3), mesh space
    uvs: np.ndarray  # float64 (V, 2), the base colour texture's set, transform applied (zeros: none)
    triangles: np.ndarray  # int64 (T, 3)
    material: int  # index into Scene.materials
    vertex_alpha: np.ndarray | None = None  # COLOR_0 alpha (V,) when it is not 1 everywhere
    unknown: np.ndarray | None = None  # (T,) bool: triangles whose maps must be all C (see scene.gltf)
    source: str | None = None  # where it comes from in its file when mesh/primitive do not say (a USD prim path)
    faces: np.ndarray | None = None  # (T,) int64: the face of ``source`` each triangle comes from (None: glTF)

    def __post_init__(self):
        from .. import checks

        for name in ("mesh", "index", "material"):
            checks.integer(getattr(self, name), name)
        checks.array(self.positions, "positions", shape=(None, 3), kinds="iuf")
        checks.array(self.uvs, "uvs", shape=(None, 2), kinds="iuf")
        checks.array(self.triangles, "triangles", shape=(None, 3), kinds="iu")
        if self.unknown is None:
            self.unknown = np.zeros(len(self.triangles), bool)
        if self.faces is not None:
            checks.array(self.faces, "faces", shape=(len(self.triangles),), kinds="iu")

    @property
    def tris_uv(self) -> np.ndarray:
        return self.uvs[self.triangles]

    @property
    def areas(self) -> np.ndarray:
        """Mesh-space area of each triangle."""
        p = self.positions[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    @property
    def label(self) -> str:
        return f"mesh {self.mesh} primitive {self.index}" + (f" ({self.source})" if self.source else "")


@dataclass
class Mesh:
    index: int  # glTF mesh index
    name: str
    primitives: list[Primitive]

    @cached_property
    def merged(self) -> dict:
        """The primitives as one triangle list: positions (V, 3) float32, uvs (V, 2), triangles
        (T, 3) int64, material (T,) int32, primitive (T,) int32 (index into ``primitives``),
        local (T,) the triangle's index in its primitive, unknown (T,) bool and vertex_alpha (V,)."""
        pos, uv, tri, mat, prim, local, unk, va = [], [], [], [], [], [], [], []
        base = 0
        for k, p in enumerate(self.primitives):
            pos.append(p.positions)
            uv.append(p.uvs)
            tri.append(p.triangles + base)
            mat.append(np.full(len(p.triangles), p.material, np.int32))
            prim.append(np.full(len(p.triangles), k, np.int32))
            local.append(np.arange(len(p.triangles)))
            unk.append(p.unknown)
            va.append(np.ones(len(p.positions)) if p.vertex_alpha is None else p.vertex_alpha)
            base += len(p.positions)
        if not pos:
            return {"positions": np.zeros((0, 3), np.float32), "uvs": np.zeros((0, 2)),
                    "triangles": np.zeros((0, 3), np.int64), "material": np.zeros(0, np.int32),
                    "primitive": np.zeros(0, np.int32), "local": np.zeros(0, np.int64),
                    "unknown": np.zeros(0, bool), "vertex_alpha": np.zeros(0)}
        return {"positions": np.concatenate(pos).astype(np.float32), "uvs": np.concatenate(uv),
                "triangles": np.concatenate(tri).astype(np.int64), "material": np.concatenate(mat),
                "primitive": np.concatenate(prim), "local": np.concatenate(local),
                "unknown": np.concatenate(unk), "vertex_alpha": np.concatenate(va)}


@dataclass(frozen=True)
class SceneCamera:
    """A camera stored in the file (``cameras[index]``), placed by the first node of the default
    scene that references it (depth-first, in the scene's node order): world-space ``eye``,
    unit ``forward`` (the node's -Z) and ``up`` (its +Y, made orthogonal to ``forward``). ``node``
    is None when no node of the default scene places it; ``problem`` says why it cannot be used
    (then eye, forward and up may be None)."""

    index: int
    name: str
    type: str  # "perspective" or "orthographic" (as declared)
    yfov: float | None  # perspective: vertical field of view, radians as stored
    aspect: float | None  # the stored aspectRatio (the tracer uses its image's instead)
    node: int | None
    eye: np.ndarray | None
    forward: np.ndarray | None
    up: np.ndarray | None
    problem: str | None = None


@dataclass
class Scene:
    path: str
    meshes: list[Mesh]  # the prototypes, in order of first use
    instances: list[tuple[int, np.ndarray]]  # (index into meshes, 4x4 float64 world transform)
    materials: list[Material]
    textures: list[Texture]
    warnings: list[str] = field(default_factory=list)
    skipped: list[dict] = field(default_factory=list)  # primitives left out: mesh, primitive, name, reason
    cameras: list[SceneCamera] = field(default_factory=list)  # every camera of the file, in order
    micromaps: object = None  # scene.micromaps.StoredMicromaps: the file's stored opacity micromaps, if any

    def alpha_tested(self, rules: MaterialRules = MaterialRules()) -> np.ndarray:
        """Boolean per material: does the any-hit shader run on it?"""
        return np.array([rules.alpha_tested(m.alpha_mode) for m in self.materials], dtype=bool)

    def alpha_test(self, material: int, rules: MaterialRules = MaterialRules()) -> AlphaTest:
        """The core alpha test of an alpha-tested material (``alpha_test.material_test``)."""
        m = self.materials[material]
        tex = self.textures[m.texture] if m.texture >= 0 else None
        alpha = tex.alpha if tex is not None else None
        maxval = tex.maxval if tex is not None else 255
        name = tex.name if tex is not None else f"{m.name} (no texture)"
        return material_test(name, m.alpha_mode, m.cutoff, m.base_colour[3], alpha, maxval, m.filter, m.wrap_u,
                             m.wrap_v, rules, readable=tex is None or tex.problem is None)

    def bounds(self) -> np.ndarray:
        """World-space box (2, 3) of every instance."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for mi, m in self.instances:
            p = self.meshes[mi].merged["positions"]
            if len(p) == 0:
                continue
            corners = np.array([[x, y, z, 1.0] for x in (p[:, 0].min(), p[:, 0].max())
                                for y in (p[:, 1].min(), p[:, 1].max()) for z in (p[:, 2].min(), p[:, 2].max())])
            w = corners @ m.T
            lo = np.minimum(lo, w[:, :3].min(axis=0))
            hi = np.maximum(hi, w[:, :3].max(axis=0))
        return np.stack([lo, hi])

    def alpha_bounds(self, rules: MaterialRules = MaterialRules()) -> np.ndarray | None:
        """World-space box (2, 3) of the alpha-tested triangles of every instance (their vertices
        transformed exactly); None when nothing is alpha-tested."""
        alpha = self.alpha_tested(rules)
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        verts: dict[int, np.ndarray] = {}
        for mi, m in self.instances:
            if mi not in verts:
                mg = self.meshes[mi].merged
                used = np.unique(mg["triangles"][alpha[mg["material"]]])
                verts[mi] = mg["positions"][used].astype(np.float64)
            p = verts[mi]
            if len(p) == 0:
                continue
            w = p @ m[:3, :3].T + m[:3, 3]
            lo = np.minimum(lo, w.min(axis=0))
            hi = np.maximum(hi, w.max(axis=0))
        return np.stack([lo, hi]) if np.all(lo <= hi) else None

    def counts(self, rules: MaterialRules = MaterialRules()) -> dict:
        """Triangle counts over instances (what is traced) and over prototypes (what is baked)."""
        alpha = self.alpha_tested(rules)
        per_mesh = [len(m.merged["triangles"]) for m in self.meshes]
        per_mesh_alpha = [int(alpha[m.merged["material"]].sum()) for m in self.meshes]
        used = sorted({mi for mi, _ in self.instances})
        return {"instances": len(self.instances), "prototypes": len(used),
                "triangles": int(sum(per_mesh[mi] for mi, _ in self.instances)),
                "alpha_triangles": int(sum(per_mesh_alpha[mi] for mi, _ in self.instances)),
                "prototype_triangles": int(sum(per_mesh[i] for i in used)),
                "prototype_alpha_triangles": int(sum(per_mesh_alpha[i] for i in used))}
