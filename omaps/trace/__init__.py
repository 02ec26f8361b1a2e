"""Ray-traced evaluation: alpha tests per ray on a glTF scene, with each scheme's maps read in
Embree's any-hit path (``filter``), split as a codec is: address tables (``tables``), hit ->
state lookups and the shader (``lookups``), the filter, the ray loops (``rays``), the scene's
maps (``maps``), preparation (``prepare``), metrics, the 2-state mode and the pictures.

One call does a whole experiment (``omaps trace``): ``trace_scene`` returns a ``TraceResult``
with the report, the runs and the pictures. The stages it composes are public too.

Example::

    >>> from omaps.scene import load_scene                                        # doctest: +SKIP
    >>> from omaps.schemes import parse_schemes                                   # doctest: +SKIP
    >>> from omaps.trace import choose_default_camera, prepare, trace_scheme, summary  # doctest: +SKIP
    >>> scene = load_scene("palm.glb")                                             # doctest: +SKIP
    >>> prep = prepare(scene, parse_schemes("none,vq4"))                          # doctest: +SKIP
    >>> cam = choose_default_camera(prep, 256, 256)[0].basis(256, 256)            # doctest: +SKIP
    >>> ref, vq4 = (trace_scheme(prep, n, cam, 256, 256) for n in ("none", "vq4"))  # doctest: +SKIP
    >>> summary(vq4, ref, prep.maps["vq4"], 256, 256)["differing_pixels"]         # doctest: +SKIP
    0
"""

from .camera import (DEFAULT_LIGHT, SHADOW_TNEAR, Camera, choose_default_camera, default_camera, gltf_camera,
                     light_direction, parse_camera, parse_light)
from .experiment import DEFAULT_SCHEMES, TraceResult, format_report, trace_scene
from .metrics import coverage_error, differing_pixels, summary
from .prepare import Prepared, SchemeRun, prepare, trace_scheme

__all__ = ["trace_scene", "TraceResult", "format_report", "DEFAULT_SCHEMES", "Camera", "default_camera",
           "choose_default_camera", "gltf_camera", "light_direction", "parse_camera", "parse_light", "DEFAULT_LIGHT",
           "SHADOW_TNEAR", "prepare", "Prepared", "trace_scheme", "SchemeRun", "summary", "differing_pixels",
           "coverage_error"]
