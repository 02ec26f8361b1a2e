"""The bakers: T/O/C maps of regions of a texture's footprint grid.

* ``micromap``: per-triangle micromaps in the bird-curve order (eval's and the tracer's
  ``triL``, standard OMMs), levels 0..12;
* ``square``: an N x N map over a pair of triangles' square (eval's ``sqN``, the tracer's square
  and codec maps, ``omm --from``);
* ``pair_maps``: both on the corpus pair, and the savings metric.
"""

from ..lazy import exports

# each public name's module, imported on first use: ``omaps omm`` from a texture loads the micromap
# baker alone (start-up is part of every run's time)
_HOME = {**dict.fromkeys(("GROW_TEXEL", "bake_micromap_rows", "bake_micromap_runs", "bake_micromaps", "check_level",
                          "dynamic_levels", "micro_starts"), "micromap"),
         **dict.fromkeys(("bake_pair_triangles", "bake_square", "known_fraction", "texel_limit"), "pair_maps"),
         **dict.fromkeys(("bake_pair_flags", "bake_pair_squares", "check_square_size", "or_downsample"), "square")}

__all__ = ["GROW_TEXEL", "bake_micromaps", "bake_micromap_runs", "bake_micromap_rows", "check_level", "dynamic_levels", "micro_starts",
           "bake_pair_triangles", "bake_square", "known_fraction", "texel_limit", "bake_pair_flags",
           "bake_pair_squares", "check_square_size", "or_downsample"]


__getattr__, __dir__ = exports(__name__, _HOME)
