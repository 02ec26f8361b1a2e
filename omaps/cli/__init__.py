"""The ``omaps`` command line (``main``); each command composes the core and re-implements none of it."""

import os as _os

# numpy's OpenBLAS starts a thread per further core when numpy loads, and each spins about 0.1 s
# of CPU before it sleeps; no command does linear algebra worth a second thread. Set before numpy
# loads (``import omaps`` does not load it); a value the caller set stays, and worker processes
# a command starts inherit it.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .main import main, run  # noqa: E402 (after the variable above, before numpy loads)

__all__ = ["main", "run"]
