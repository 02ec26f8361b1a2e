"""omaps: opacity maps for ray tracing alpha-tested geometry.

Bakes 3-state (T/O/C) maps from alpha textures -- square maps per triangle pair, compressed by the
deck's VQ codecs, and per-triangle micromaps in the VK_EXT_opacity_micromap order -- and measures
how many any-hit shader calls they remove, on a corpus of textures and in ray-traced scenes.

The core, used by every command: ``alpha_test`` (the one alpha test), ``bake`` (the micromap and
pair-square bakers), ``codecs`` (every stored square map, raw ``sqN`` included), ``schemes`` (the
one scheme grammar), ``scene`` (the one glTF reader), ``coverage`` and ``promotion`` (C to O/T).
On top: ``corpus`` (``omaps eval``), ``trace`` (``omaps trace``), ``omm`` (``omaps omm``), ``cli``.

Example::

    >>> import numpy as np, omaps
    >>> tex = omaps.load_alpha(np.array([[0, 40, 250, 255]], np.uint8))
    >>> grid = omaps.StateRule("levels").alpha_test(tex).grid()
    >>> omaps.bake_square(grid, 4).tolist()[0]
    [0, 2, 1, 1]
"""

__version__ = "0.1.0"

from . import states  # noqa: E402
from .alpha_test import AlphaTest, MaterialRules, StateRule  # noqa: E402
from .bake import (bake_micromaps, bake_pair_squares, bake_pair_triangles, bake_square, known_fraction,  # noqa: E402
                   texel_limit)
from .codecs import get_codec  # noqa: E402
from .corpus import EvalConfig, default_corpus, evaluate_many, evaluate_texture  # noqa: E402
from .errors import InputError  # noqa: E402
from .sampling import footprint_grid  # noqa: E402
from .schemes import get_scheme, parse_schemes  # noqa: E402
from .texture import AlphaTexture, load_alpha  # noqa: E402


def load_scene(path):
    """Load a glTF 2.0 scene (``omaps.scene.load_scene``)."""
    from .scene import load_scene as load

    return load(path)


__all__ = [
    "states", "AlphaTest", "MaterialRules", "StateRule", "bake_micromaps", "bake_pair_squares", "bake_pair_triangles",
    "bake_square", "known_fraction", "texel_limit", "get_codec", "EvalConfig", "default_corpus", "evaluate_many",
    "evaluate_texture", "InputError", "footprint_grid", "get_scheme", "parse_schemes", "AlphaTexture", "load_alpha",
    "load_scene",
]
