"""``python -m omaps.cli``: the ``omaps`` command line."""

import sys

from .main import main

sys.exit(main())
