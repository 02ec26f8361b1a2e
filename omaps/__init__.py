"""omaps: opacity maps for ray tracing alpha-tested geometry.

Bakes 3-state (T/O/C) maps from alpha textures -- square maps per triangle pair, compressed by the
deck's VQ codecs, and per-triangle micromaps in the VK_EXT_opacity_micromap order -- and measures
how many any-hit shader calls they remove, on a corpus of textures and in ray-traced scenes.

The core, used by every command: ``alpha_test`` (the one alpha test), ``bake`` (the micromap and
pair-square bakers), ``codecs`` (every stored square map, raw ``sqN`` included), ``schemes`` (the
one scheme grammar), ``scene`` (the one glTF reader), ``coverage`` and ``promotion`` (C to O/T).
On top: ``corpus`` (``omaps eval``), ``trace`` (``omaps trace``), ``omm`` (``omaps omm``); then
one call per command, each returning a result object: ``evaluate_corpus``, ``trace_scene``,
``bake_omms`` and ``run_batch``; the ``cli`` parses, calls them and prints.

Example::

    >>> import numpy as np, omaps
    >>> alpha = np.array([[0, 40, 250, 255]], np.uint8)
    >>> grid = omaps.StateRule("levels").alpha_test(alpha).grid()
    >>> omaps.bake_square(grid, 4).tolist()[0]
    [0, 2, 1, 1]
"""

__version__ = "0.1.0"

import os as _os

# numba's OpenMP threads wait for work asleep, not spinning: spinning, each took its share of a
# core between parallel loops (a serial batch used 2-3x the CPU-seconds of one thread on a busy
# 2-core machine). Read when the OpenMP runtime starts, with the first parallel kernel; a value
# the caller set stays.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# numba's cache keys each omaps kernel on the content of every module it imports, not on its own
# file alone (``kernel_cache``): a kernel that inlines a codec's lookup or the registry's format
# codes is recompiled when they change, never loaded stale
from . import kernel_cache as _kernel_cache  # noqa: E402

_kernel_cache.watch(_os.path.dirname(_os.path.abspath(__file__)), __name__)
_kernel_cache.watch_numba()

# the public names, imported on first use (PEP 562): ``import omaps`` (and so parsing a command
# line, ``omaps omm --help``) loads neither numpy nor numba until a name is used
_LAZY = {
    "states": (".states", None), "AlphaTest": (".alpha_test", "AlphaTest"),
    "MaterialRules": (".alpha_test", "MaterialRules"), "StateRule": (".alpha_test", "StateRule"),
    "bake_micromaps": (".bake", "bake_micromaps"), "bake_pair_squares": (".bake", "bake_pair_squares"),
    "bake_pair_triangles": (".bake", "bake_pair_triangles"), "bake_square": (".bake", "bake_square"),
    "known_fraction": (".bake", "known_fraction"), "texel_limit": (".bake", "texel_limit"),
    "get_codec": (".codecs", "get_codec"), "EvalConfig": (".corpus", "EvalConfig"),
    "default_corpus": (".corpus", "default_corpus"), "evaluate_many": (".corpus", "evaluate_many"),
    "evaluate_texture": (".corpus", "evaluate_texture"), "InputError": (".errors", "InputError"),
    "InputTypeError": (".errors", "InputTypeError"),
    "footprint_grid": (".sampling", "footprint_grid"), "get_scheme": (".schemes", "get_scheme"),
    "parse_schemes": (".schemes", "parse_schemes"), "AlphaTexture": (".texture", "AlphaTexture"),
    "load_alpha": (".texture", "load_alpha"), "as_texture": (".texture", "as_texture"),
    "evaluate_corpus": (".corpus", "evaluate_corpus"), "trace_scene": (".trace", "trace_scene"),
    "bake_omms": (".jobs", "bake_omms"), "verify_omms": (".jobs", "verify_omms"), "expand_omms": (".jobs", "expand_omms"),
    "run_batch": (".batch", "run_batch"),
}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module 'omaps' has no attribute {name!r}")
    import importlib

    module, attr = _LAZY[name]
    mod = importlib.import_module(module, __name__)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


def load_scene(path, root=None, allow_outside=False, max_bytes=None):
    """Load a glTF 2.0 scene or an OpenUSD stage (``omaps.scene.load_scene``; USD needs the extra
    ``omaps[usd]``): the files it names only under ``root`` (default: its own folder) unless
    ``allow_outside``; never a URI with a scheme; each file at most ``max_bytes`` (default 2 GiB,
    or the environment variable ``OMAPS_MAX_ASSET_BYTES``)."""
    from .scene import load_scene as load

    return load(path, root=root, allow_outside=allow_outside, max_bytes=max_bytes)


__all__ = [
    "evaluate_corpus", "trace_scene", "bake_omms", "verify_omms", "expand_omms", "run_batch", "states", "AlphaTest", "MaterialRules", "StateRule", "bake_micromaps", "bake_pair_squares", "bake_pair_triangles",
    "bake_square", "known_fraction", "texel_limit", "get_codec", "EvalConfig", "default_corpus", "evaluate_many",
    "evaluate_texture", "InputError", "InputTypeError", "footprint_grid", "get_scheme", "parse_schemes", "AlphaTexture", "load_alpha",
    "as_texture", "load_scene",
]
