"""What a scene file is named: the one rule of every command that reads a scene (``omaps trace``,
``omaps omm``, ``omaps report``, ``omaps batch``), checked by the loader before it opens the file,
and which reader reads it (glTF or OpenUSD). Standard library only, so a command can apply the
rule without loading a reader."""

from __future__ import annotations

import os

from ..errors import InputError
from ..checks import typed

__all__ = ["SCENE_SUFFIXES", "GLTF_SUFFIXES", "USD_SUFFIXES", "SCENE_RULE", "is_scene_file", "is_usd_file",
           "check_scene_file"]

GLTF_SUFFIXES = (".gltf", ".glb")
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")  # read with usd-core (the extra omaps[usd])
SCENE_SUFFIXES = GLTF_SUFFIXES + USD_SUFFIXES
SCENE_RULE = "a scene must end in .gltf, .glb, .usd, .usda, .usdc or .usdz"


@typed
def is_scene_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is named as a scene (glTF or OpenUSD, any case)."""
    return os.fspath(path).lower().endswith(SCENE_SUFFIXES)


@typed
def is_usd_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is named as an OpenUSD stage (.usd, .usda, .usdc, .usdz, any case)."""
    return os.fspath(path).lower().endswith(USD_SUFFIXES)


@typed
def check_scene_file(path: str | os.PathLike[str]) -> None:
    """An ``InputError`` naming ``path`` unless it is named as a scene (``SCENE_RULE``)."""
    if not is_scene_file(path):
        raise InputError(f"not a scene: {SCENE_RULE}", os.fspath(path))
