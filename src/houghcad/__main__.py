"""``python -m houghcad``: same as the ``houghcad`` console script."""

import sys

from .cli import run

sys.exit(run())
