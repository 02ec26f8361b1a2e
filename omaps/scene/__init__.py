"""Scenes: the model (``model``), the glTF reader (``gltf``, the only user of pygltflib), the
pairing of triangles that share an edge (``pairing``) and the alpha-tested triangles of a scene
with their pairs and alpha tests (``alpha``), shared by the tracer and the OMM baker."""

from .alpha import AlphaTriangles, alpha_triangles
from .gltf import load_scene
from .model import Material, Mesh, Primitive, Scene, SceneCamera, SceneWarning, Texture
from .pairing import Pairing, pair_triangles

__all__ = ["load_scene", "Scene", "Mesh", "Primitive", "Material", "Texture", "SceneCamera", "SceneWarning", "Pairing",
           "pair_triangles", "AlphaTriangles", "alpha_triangles"]
