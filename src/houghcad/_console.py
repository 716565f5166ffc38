"""The ``houghcad`` command's entry point: imports nothing heavy before it can catch a Ctrl-C.

A Ctrl-C while Python imports numpy, scipy and the pipeline (about 0.3 s of every command) printed
Python's traceback; here it prints one line and exits 130, as :func:`houghcad.cli.main` does later.
"""

from __future__ import annotations

import sys


def run() -> int:
    """Import the command line, then run it (:func:`houghcad.cli.run`)."""
    try:
        from .cli import run as cli_run
    except KeyboardInterrupt:
        print("houghcad: interrupted", file=sys.stderr)
        return 130
    return cli_run()
