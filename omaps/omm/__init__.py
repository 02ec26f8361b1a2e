"""Standard opacity micromaps (VK_EXT/KHR_opacity_micromap, DXR 1.2): bake, reuse, expand the
deck's square maps into them, write and verify the files an engine loads.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.omm import Geometry, OmmSettings, build
    >>> from omaps.texture import load_alpha
    >>> test = StateRule("cutoff").alpha_test(load_alpha(np.array([[0, 255]], np.uint8)), "linear", "wrap")
    >>> result = build([Geometry("leaf", test, np.array([[[0, 0], [1, 0], [0, 1]]]))], OmmSettings(level=4))
    >>> result.data.dtype, result.triangles.dtype.names, result.index.tolist()
    (dtype('uint8'), ('data_offset', 'level', 'format'), [0])
"""

from ..lazy import exports

# where each public name lives: imported on first use, so that a command (``omaps omm``) loads
# only the modules, and the numba kernels, it needs
_HOME = {"read": "files", "write": "files", "expand": "pairs", "merge": "pairs", "Geometry": "pipeline",
         "OmmResult": "pipeline", "OmmSettings": "pipeline", "build": "pipeline", "verify": "verify"}

__all__ = ["Geometry", "OmmResult", "OmmSettings", "build", "read", "write", "expand", "merge", "verify"]


__getattr__, __dir__ = exports(__name__, _HOME)
