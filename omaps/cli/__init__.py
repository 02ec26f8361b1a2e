"""The ``omaps`` command line (``main``); each command composes the core and re-implements none of it."""

from .main import main, run

__all__ = ["main", "run"]
