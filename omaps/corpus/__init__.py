"""The corpus evaluation: savings of every scheme on alpha textures mapped to the corpus pair
(``evaluate``), its outputs (``report``) and the embedded default corpus (``procedural``); one
call does what ``omaps eval`` does (``evaluate_corpus``, returning a ``CorpusResult``)."""

from .evaluate import EvalConfig, TextureResult, evaluate_many, evaluate_texture, mean_results
from .experiment import CorpusResult, evaluate_corpus
from .procedural import default_corpus

__all__ = ["evaluate_corpus", "CorpusResult", "EvalConfig", "TextureResult", "evaluate_many", "evaluate_texture",
           "mean_results", "default_corpus"]
