"""The alpha-tested triangles of a scene's prototypes, paired, in the order a tracer sees them.

Both the tracer and the OMM baker start here, so both see the same triangles, the same pairs
and the same square corners. Pairs never cross primitives (a primitive is one geometry of a
BLAS, and hardware pairs within a geometry); within a primitive they follow
``scene.pairing`` (shared edge and material, maximal matching).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..alpha_test import MaterialRules
from ..pair import corner_uvs
from ..rows import first_occurrences
from .model import Scene
from .pairing import pair_triangles
from ..checks import typed

__all__ = ["AlphaTriangles", "alpha_triangles", "pair_corner_uvs", "distinct_rows"]


@dataclass
class AlphaTriangles:
    """Every alpha-tested triangle of the prototypes, in trace order: prototype p's alpha
    triangles are rows base[p] .. base[p+1]-1, in the order of its alpha geometry (primID)."""

    base: np.ndarray  # int64 (P + 1,)
    mesh_tri: np.ndarray  # int64 (T,) index of the triangle in its mesh's merged list
    primitive: np.ndarray  # int32 (T,) index of its primitive in the mesh
    local: np.ndarray  # int64 (T,) index of the triangle in its primitive
    material: np.ndarray  # int32 (T,)
    uv: np.ndarray  # float64 (T, 3, 2) per vertex
    unknown: np.ndarray  # bool (T,) maps must be all C (scene.gltf's policies)
    vertex_alpha: np.ndarray  # float64 (T, 3): COLOR_0 alpha per vertex (1 without)
    corners: np.ndarray  # int8 (T, 3) square corner codes of the vertices (omaps.pair)
    pair: np.ndarray  # int64 (T,) global pair index
    pair_first: np.ndarray  # int64 (Q,) row of the pair's A triangle
    pair_second: np.ndarray  # int64 (Q,) row of its B triangle, -1 for a lone triangle
    paired_fraction: float

    @property
    def count(self) -> int:
        return len(self.mesh_tri)


@typed
def alpha_triangles(scene: Scene, rules: MaterialRules = MaterialRules(), improve_pairing: bool = True) -> AlphaTriangles:
    alpha = scene.alpha_tested(rules)
    base = [0]
    parts = {k: [] for k in ("mesh_tri", "primitive", "local", "material", "uv", "unknown", "valpha", "corners",
                             "pair", "first", "second")}
    row0 = 0
    q0 = 0
    for mesh in scene.meshes:
        offset = 0
        for k, p in enumerate(mesh.primitives):
            nt = len(p.triangles)
            if alpha[p.material] and nt:
                pr = pair_triangles(p.triangles, p.positions, np.full(nt, p.material), None, improve_pairing)
                rows = np.arange(nt) + row0
                parts["mesh_tri"].append(np.arange(nt) + offset)
                parts["primitive"].append(np.full(nt, k, np.int32))
                parts["local"].append(np.arange(nt))
                parts["material"].append(np.full(nt, p.material, np.int32))
                parts["uv"].append(p.uvs[p.triangles])
                parts["unknown"].append(p.unknown)
                va = np.ones(len(p.positions)) if p.vertex_alpha is None else p.vertex_alpha
                parts["valpha"].append(va[p.triangles])
                parts["corners"].append(pr.corners)
                parts["pair"].append(pr.pair_of + q0)
                parts["first"].append(rows[pr.first])
                parts["second"].append(np.where(pr.second >= 0, rows[np.maximum(pr.second, 0)], -1))
                row0 += nt
                q0 += len(pr.first)
            offset += nt
        base.append(row0)

    def cat(key, dtype, shape=(0,)):
        return np.concatenate(parts[key]).astype(dtype) if parts[key] else np.zeros(shape, dtype)

    second = cat("second", np.int64)
    frac = 2 * int(np.count_nonzero(second >= 0)) / row0 if row0 else 0.0
    return AlphaTriangles(np.array(base, np.int64), cat("mesh_tri", np.int64), cat("primitive", np.int32),
                          cat("local", np.int64), cat("material", np.int32), cat("uv", np.float64, (0, 3, 2)),
                          cat("unknown", bool), cat("valpha", np.float64, (0, 3)), cat("corners", np.int8, (0, 3)),
                          cat("pair", np.int64), cat("first", np.int64), second, frac)


def pair_corner_uvs(at: AlphaTriangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pair: its corner UVs (``pair.corner_uvs``), whether B exists, and the material."""
    uv, has_b = corner_uvs(at.uv, at.corners, at.pair_first, at.pair_second)
    return uv, has_b, at.material[at.pair_first]


def distinct_rows(*arrays) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the first occurrence of each distinct row across the arrays (their bytes side by
    side), and for every row the index of its distinct representative (0..D-1, in the order of
    first use): ``rows.first_occurrences``."""
    parts = [np.ascontiguousarray(a).reshape(len(a), -1).view(np.uint8) for a in arrays]
    return first_occurrences(np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0])
