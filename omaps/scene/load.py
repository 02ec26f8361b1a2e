"""``load_scene``: the one entry every command reads a scene through. It picks the reader by the
file's suffix (``files``): glTF (``scene.gltf``) or OpenUSD (``scene.usd``, which needs usd-core);
both build the same scene model, so the tracer, the bakers and the budgets never learn which
format a scene came from."""

from __future__ import annotations

from .files import check_scene_file, is_usd_file
from .model import Scene

__all__ = ["load_scene"]


def load_scene(path, *, root=None, allow_outside: bool = False, max_bytes: int | None = None) -> Scene:
    """Load a scene file (.gltf, .glb, .usd, .usda, .usdc, .usdz) into the scene model.

    Parameters
    ----------
    path : str or path
        The scene file.
    root : str or path, optional
        The folder every file the scene names must lie under (default: the scene's own folder).
    allow_outside : bool
        Read files the scene names wherever they are (for an asset you trust). URIs with a
        scheme (``http:``, ...) are never fetched.
    max_bytes : int, optional
        The size cap of the scene file and each file it names (default: the environment
        variable ``OMAPS_MAX_ASSET_BYTES``, else 2 GiB).

    Returns
    -------
    Scene

    Raises
    ------
    InputError
        Naming the file: a name that is not a scene's, a file that cannot be read, a USD stage
        without usd-core installed (``pip install 'omaps[usd]'``); recoverable problems are
        ``SceneWarning``s (also kept in ``Scene.warnings``).

    Example::

        >>> from omaps.scene import load_scene                       # doctest: +SKIP
        >>> scene = load_scene("palm.glb")                            # doctest: +SKIP
        >>> scene.counts()["alpha_triangles"]                         # doctest: +SKIP
        3840
    """
    from ..checks import path as checked_path

    path = checked_path(path, "path")
    check_scene_file(path)
    if is_usd_file(path):
        from .usd import load_scene as read
    else:
        from .gltf import load_scene as read
    return read(path, root=root, allow_outside=allow_outside, max_bytes=max_bytes)
