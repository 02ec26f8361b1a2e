"""The corpus evaluation: savings of every scheme on alpha textures mapped to the corpus pair
(``evaluate``), its outputs (``report``) and the embedded default corpus (``procedural``)."""

from .evaluate import EvalConfig, TextureResult, evaluate_many, evaluate_texture, mean_results
from .procedural import default_corpus

__all__ = ["EvalConfig", "TextureResult", "evaluate_many", "evaluate_texture", "mean_results", "default_corpus"]
