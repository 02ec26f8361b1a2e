"""The runnable examples in the public API's docstrings run and print what they say."""

import doctest
import importlib

import pytest

MODULES = ["omaps", "omaps.alpha_test", "omaps.atomic", "omaps.coverage", "omaps.promotion", "omaps.bake.micromap",
           "omaps.bake.square", "omaps.bake.pair_maps", "omaps.codecs.raw", "omaps.codecs.registry", "omaps.schemes",
           "omaps.corpus.evaluate", "omaps.omm", "omaps.omm.pipeline", "omaps.texture"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0
    assert result.failed == 0
