"""What a scene file is named: the one rule of every command that reads a scene (``omaps trace``,
``omaps omm``), checked by the loader before it opens the file. Standard library only, so a
command can apply the rule without loading the reader."""

from __future__ import annotations

import os

from ..errors import InputError
from ..checks import typed

__all__ = ["SCENE_SUFFIXES", "SCENE_RULE", "is_scene_file", "check_scene_file"]

SCENE_SUFFIXES = (".gltf", ".glb")
SCENE_RULE = "a scene must end in .gltf or .glb"


@typed
def is_scene_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is named as a scene (.gltf or .glb, any case)."""
    return os.fspath(path).lower().endswith(SCENE_SUFFIXES)


@typed
def check_scene_file(path: str | os.PathLike[str]) -> None:
    """An ``InputError`` naming ``path`` unless it is named as a scene (``SCENE_RULE``)."""
    if not is_scene_file(path):
        raise InputError(f"not a glTF scene: {SCENE_RULE}", os.fspath(path))
