"""Standard opacity micromaps (VK_EXT/KHR_opacity_micromap, DXR 1.2): bake, reuse, expand the
deck's square maps into them, write and verify the files an engine loads.

    from omaps.omm import AlphaTest, Geometry, OmmSettings, build, write, read
    test = AlphaTest.from_cutoff(omaps.load_alpha("leaf.png"), 0.5, "linear", "wrap")
    result = build([Geometry("leaf", test, uv_triangles)], OmmSettings(level=4))
    result.data, result.triangles, result.index, result.usage   # the buffers, as numpy arrays
    write("out/", result)
"""

from .alpha_test import AlphaTest
from .bake import bake_levels, dynamic_levels
from .pipeline import Geometry, OmmResult, OmmSettings, build
from .files import read, write
from .pairs import expand, merge

__all__ = ["AlphaTest", "bake_levels", "dynamic_levels", "Geometry", "OmmResult", "OmmSettings", "build",
           "read", "write", "expand", "merge"]
