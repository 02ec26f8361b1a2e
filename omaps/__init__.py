"""omaps: opacity maps for ray tracing alpha-tested geometry.

Bakes 3-state (T/O/C) maps from alpha textures -- square maps per triangle pair and per-triangle
micromaps in the VK_EXT_opacity_micromap order -- and measures how many any-hit shader calls
they remove.
"""

__version__ = "0.1.0"

from . import states  # noqa: E402
from .errors import InputError  # noqa: E402
from .evaluate import EvalConfig, evaluate_many, evaluate_texture  # noqa: E402
from .maps import bake_pair_triangles, bake_square, bake_triangles, known_fraction, texel_limit  # noqa: E402
from .procedural import default_corpus  # noqa: E402
from .sampling import footprint_grid  # noqa: E402
from .schemes import get_scheme, parse_schemes  # noqa: E402
from .texel_states import StateRule  # noqa: E402
from .texture import AlphaTexture, load_alpha  # noqa: E402

__all__ = [
    "states", "InputError", "EvalConfig", "evaluate_many", "evaluate_texture", "bake_pair_triangles",
    "bake_square", "bake_triangles", "known_fraction", "texel_limit", "default_corpus", "footprint_grid",
    "get_scheme", "parse_schemes", "StateRule", "AlphaTexture", "load_alpha",
]
