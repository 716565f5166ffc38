#!/usr/bin/env python
"""The fixed cost of a houghcad run (issue 20): what a small cloud pays before and around its work.

Usage::

    python benchmarks/startup.py [--repeat 5] [--no-write]

Each figure is the median of ``--repeat`` fresh processes, on an otherwise idle machine:

- ``python -c pass``: the interpreter;
- the libraries houghcad imports (numpy, scipy's spatial and csgraph modules), alone, and with
  numba;
- ``import houghcad.cli, houghcad.pipeline``: what ``houghcad segment`` imports; and, from
  ``python -X importtime``, the import time spent in houghcad's own modules (their self time, the
  libraries they import left out);
- a kernel's first call in a process: from the kernels compiled ahead of time
  (``houghcad._aot``, see :mod:`houghcad.kernels`), and with ``HOUGHCAD_JIT=1`` from numba's
  cache on disk;
- ``houghcad segment`` of a 1,000-point synthetic part (``synth`` block, written as XYZ) to JSON,
  both ways: the whole process, and the segmentation's own time from its JSON ``timing``.

The code's share is houghcad's own import time plus what the segment call spends beyond the
segmentation work; the issue's figure is that share below 0.5 s. The summary goes between the
``<!-- startup:begin/end -->`` markers of BENCHMARKS.md, and a dated entry to the top of
docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fit4cad import compile_bytecode, publish_section  # run from benchmarks/, beside fit4cad.py

LIBRARIES = "import numpy, scipy.spatial, scipy.sparse.csgraph"
#: What ``houghcad segment`` imports before its first point is segmented (the CLI imports the
#: pipeline lazily).
HOUGHCAD = "import houghcad.cli, houghcad.pipeline"
FIRST_CALL = ("import numpy as np, time; from houghcad.hough import persistent_peaks; "
                    "t = time.perf_counter(); persistent_peaks(np.ones((4, 4)), 0.1); "
                    "print(time.perf_counter() - t)")


#: The environment of each way to run the kernels: ahead of time (the extension) and numba's JIT.
MODES = {"ahead of time": {"HOUGHCAD_JIT": "0"}, "numba's JIT (`HOUGHCAD_JIT=1`)": {"HOUGHCAD_JIT": "1"}}


def _wall(cmd: list[str], env: dict[str, str] | None = None) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, **(env or {})})
    return time.perf_counter() - t


def _exit_seconds(cmd_args: list[str]) -> float:
    """Seconds from the end of the ``houghcad`` command's work (cli.run returning) to the end of
    its process: the interpreter's finalization."""
    code = ("import sys, time; from houghcad.cli import run; sys.argv = ['houghcad'] + sys.argv[1:]; "
            "c = run(); print(time.time(), flush=True); sys.exit(c)")
    proc = subprocess.run([sys.executable, "-c", code, *cmd_args], check=True, capture_output=True, text=True)
    return time.time() - float(proc.stdout.split()[-1])


def _own_import_seconds() -> float:
    """Self import time (s) of houghcad's modules when the CLI is imported (-X importtime)."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", HOUGHCAD], check=True,
                          capture_output=True, text=True)
    total = 0
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s+(\S+)", line)
        if m and m.group(2).split(".")[0] == "houghcad":
            total += int(m.group(1))
    return total / 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    compile_bytecode()  # fresh processes load houghcad as an installed copy does
    py = sys.executable
    from houghcad import kernels, synth

    if not kernels.aot_loaded():
        print("houghcad._aot is not built: `pip install .` compiles it", file=sys.stderr)
        return 1
    med = lambda f: float(np.median([f() for _ in range(a.repeat)]))  # noqa: E731
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        xyz, out = Path(tmp) / "part.xyz", Path(tmp) / "part.json"
        np.savetxt(xyz, synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=1000).points)
        seg = [py, "-m", "houghcad", "segment", str(xyz), "-o", str(out), "--quiet"]
        for env in MODES.values():
            _wall(seg, env)  # warm caches
        libraries, own = med(lambda: _wall([py, "-c", LIBRARIES])), med(_own_import_seconds)
        rows += [("`python -c pass` (the interpreter)", med(lambda: _wall([py, "-c", "pass"]))),
                 ("the libraries (numpy, scipy's spatial and csgraph)", libraries),
                 ("the libraries and numba", med(lambda: _wall([py, "-c", LIBRARIES + ", numba"]))),
                 ("`import houghcad.cli, houghcad.pipeline` (libraries included)", med(lambda: _wall([py, "-c", HOUGHCAD]))),
                 ("of which houghcad's own modules (self import time, `-X importtime`)", own)]
        summary = {}
        for mode, env in MODES.items():
            first = med(lambda: float(subprocess.run([py, "-c", FIRST_CALL], check=True, capture_output=True, text=True,
                                                     env={**os.environ, **env}).stdout.split()[-1]))
            runs = []
            for _ in range(a.repeat):
                runs.append((_wall(seg, env), json.loads(out.read_text())["timing"]["total"]))
            wall = float(np.median([r[0] for r in runs]))
            work = float(np.median([r[1] for r in runs]))
            rows += [(f"{mode}: a kernel's first call in a process", first),
                     (f"{mode}: `houghcad segment` of 1,000 points, whole process", wall),
                     (f"{mode}: of which the segmentation (JSON `timing.total`, the first calls included)", work)]
            summary[mode] = (wall, work)
        exit_s = med(lambda: _exit_seconds(["segment", str(xyz), "-o", str(out), "--quiet"]))
        rows.append(("of which the exit after the command (the interpreter's finalization)", exit_s))
    (wall, work), (jwall, jwork) = summary.values()
    lines = ["| what | median s |", "|---|---|", *(f"| {k} | {v:.3f} |" for k, v in rows), "",
             f"- Fixed cost of a run: {wall - work:.2f} s of the {wall:.2f} s process beside the segmentation's "
             f"{work:.2f} s with the kernels compiled ahead of time ({jwall - jwork:.2f} s of {jwall:.2f} s with "
             f"numba's JIT); the interpreter and the libraries take {libraries:.2f} s of it, houghcad's own "
             f"imports {own:.2f} s (the issue's figure: the code's share under 0.5 s)."]
    publish_section("startup", "Start-up: the fixed cost of a run", "startup.py", argv, [
        f"- Median of {a.repeat} fresh processes each; the 1,000-point cloud is `synth` "
        "`block_with_hole_and_slot` (seed 0) written as XYZ, segmented to JSON with the defaults. "
        "houghcad's modules byte-compiled first, as `pip install .` leaves them.",
    ], lines, not a.no_write, summary=[f"segment of 1,000 points {wall:.2f} s ahead of time, {jwall:.2f} s JIT, "
                                       f"own imports {own:.2f} s, libraries {libraries:.2f} s"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
