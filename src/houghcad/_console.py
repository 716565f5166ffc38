"""The ``houghcad`` command's entry point: imports nothing heavy before it can catch a Ctrl-C.

A Ctrl-C while Python imports numpy, scipy and the pipeline (about 0.3 s of every command) printed
Python's traceback; here it prints one line and exits 130, as :func:`houghcad.cli.main` does later.
"""

from __future__ import annotations

import os
import sys


def run() -> int:
    """Import the command line, then run it (:func:`houghcad.cli.run`)."""
    # One BLAS thread unless the user says otherwise, set before numpy loads OpenBLAS, so it
    # starts no thread pool at all: see houghcad.parallel.blas_one_thread, which does the same
    # for the Python API while a run lasts.
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    try:
        from .cli import run as cli_run
    except KeyboardInterrupt:
        print("houghcad: interrupted", file=sys.stderr)
        return 130
    return cli_run()
