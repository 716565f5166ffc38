"""``python -m houghcad``: same as the ``houghcad`` console script."""

import sys

from ._console import run

sys.exit(run())
