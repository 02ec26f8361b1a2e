"""Scenes: the model (``model``), the glTF reader (``gltf``, the only user of pygltflib), the
OpenUSD reader (``usd``, the only user of usd-core's pxr), the one loader choosing between them
(``load``), the pairing of triangles that share an edge (``pairing``) and the alpha-tested triangles of a scene
with their pairs and alpha tests (``alpha``), shared by the tracer and the OMM baker; what a
scene file is named (``files``: the rule every command applies).

The public names are imported on first use (PEP 562): ``omaps.scene.files`` (the naming rule)
loads neither the reader nor numba."""

_LAZY = {
    "load_scene": "load", "Scene": "model", "Mesh": "model", "Primitive": "model", "Material": "model",
    "Texture": "model", "SceneCamera": "model", "SceneWarning": "model", "Pairing": "pairing",
    "pair_triangles": "pairing", "AlphaTriangles": "alpha", "alpha_triangles": "alpha",
    "SCENE_RULE": "files", "SCENE_SUFFIXES": "files", "is_scene_file": "files", "check_scene_file": "files",
    "is_usd_file": "files",
}

__all__ = list(_LAZY)


def __getattr__(name):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    elif name in ("alpha", "files", "gltf", "load", "micromaps", "model", "pairing", "usd"):
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
