"""The runnable examples in the public API's docstrings run and print what they say: every module
of the package whose source holds an example (``>>>``) is found and run, none listed by hand."""

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "omaps"


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = sorted(_module(p) for p in PACKAGE.rglob("*.py")
                 if "__pycache__" not in p.parts and ">>> " in p.read_text(encoding="utf-8"))


def test_examples_are_found():
    assert {"omaps", "omaps.jobs", "omaps.codecs.dispatch", "omaps.text"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
    source = Path(importlib.import_module(name).__file__).read_text(encoding="utf-8")
    assert result.attempted > 0 or "doctest: +SKIP" in source  # (an example that needs a scene is skipped)
