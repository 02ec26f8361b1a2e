"""``python -m omaps.cli``: the ``omaps`` command line."""

from .main import run

run()
