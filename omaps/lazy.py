"""A package's public names imported on first use (PEP 562): a command then loads only the
modules, and the numba kernels, it uses -- start-up is part of every command's time.

Example::

    >>> from omaps.lazy import exports
    >>> __getattr__, __dir__ = exports("omaps", {"InputError": "errors"})
    >>> __getattr__("InputError").__name__
    'InputError'
"""

from __future__ import annotations

import importlib

__all__ = ["exports"]


def exports(package: str, homes: dict[str, str]):
    """``(__getattr__, __dir__)`` for ``package``'s ``__init__``: each name of ``homes`` is
    the attribute of the submodule it maps to, imported when first asked for."""

    def __getattr__(name):
        if name in homes:
            return getattr(importlib.import_module(f".{homes[name]}", package), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(importlib.import_module(package))) | set(homes))

    return __getattr__, __dir__
