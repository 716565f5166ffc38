#!/usr/bin/env python
"""Both cores inside one cloud (issue 20): each Fit4CAD cloud segmented with ``n_jobs=1`` and with
``n_jobs=N``, one cloud at a time in this process.

Usage::

    python benchmarks/cloud_jobs.py ../shared/fit4cad/training_set [--jobs 2] [--limit N] [--no-write]

For every cloud it times the ``Segmenter.fit`` call with one job and with ``--jobs`` jobs (the
families of a round and the clusters of the splitting phase on forked workers, see
:mod:`houghcad.parallel`), checks that both results are identical (segments, parameters, labels),
and reports the median time per cloud of each and their ratio (the issue's figure: ≤ 0.65 at 2
jobs). It also sums the CPU time of each run, this process's and its workers' (reaped when ``fit``
closes its pool), to show where the second core goes: the extra CPU a parallel run spends, and the
work this process does that no worker takes. Run it on an otherwise idle machine: the parallel run
needs the second core.

The summary goes between the ``<!-- jobs:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fit4cad import find_clouds, publish_section  # run from benchmarks/, beside fit4cad.py


@dataclass(frozen=True)
class Timed:
    """One ``fit``: its wall time, this process's CPU time and its workers' (s), and the result's
    JSON without its timings."""

    wall: float
    main_cpu: float
    workers_cpu: float
    result: str


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(points: np.ndarray, n_jobs: int) -> Timed:
    from houghcad.pipeline import Segmenter

    c0, p0, t = _children_cpu(), time.process_time(), time.perf_counter()
    result = Segmenter(seed=0, n_jobs=n_jobs).fit(points).result_
    # The workers are reaped when ``fit`` closes its pool: their CPU time is counted by then.
    dt, main, workers = time.perf_counter() - t, time.process_time() - p0, _children_cpu() - c0
    d = result.to_dict()
    d.pop("timing")
    return Timed(dt, main, workers, json.dumps(d, sort_keys=True))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--limit", type=int, default=None, help="only the first N clouds")
    ap.add_argument("--every", type=int, default=1, help="every K-th cloud only (a quick sample)")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    from houghcad.io import read_points

    clouds = find_clouds(a.dir)[::a.every][:a.limit]
    _run(read_points(str(clouds[0][1])).points, 1)  # warm-up: numba's cache, imports
    rows = []
    for i, (name, path, _) in enumerate(clouds):
        pts = read_points(str(path)).points
        # Alternate which runs first: a cloud's first run pays the first touch of its memory.
        if i % 2:
            many = _run(pts, a.jobs)
            one = _run(pts, 1)
        else:
            one = _run(pts, 1)
            many = _run(pts, a.jobs)
        same_result = one.result == many.result
        rows.append(dict(name=name, n=len(pts), t1=one.wall, tn=many.wall, cpu1=one.main_cpu + one.workers_cpu,
                         main_n=many.main_cpu, cpu_n=many.main_cpu + many.workers_cpu, same=same_result))
        print(f"{name:<6} {len(pts):>6} pts  1 job {one.wall:6.2f} s  {a.jobs} jobs {many.wall:6.2f} s  "
              f"x{many.wall / one.wall:.2f}  {'same' if same_result else 'DIFFERENT'}", file=sys.stderr, flush=True)
    t1 = np.array([r["t1"] for r in rows])
    tn = np.array([r["tn"] for r in rows])
    cpu1, cpu_n, main_n = (sum(r[k] for r in rows) for k in ("cpu1", "cpu_n", "main_n"))
    big = np.array([r["n"] >= 10_000 for r in rows])
    ratio = float(np.median(tn) / np.median(t1))
    same = sum(r["same"] for r in rows)
    lines = ["| run | median s per cloud | mean s per cloud | clouds ≥ 10,000 points: median s |",
             "|---|---|---|---|",
             f"| `n_jobs=1` | {np.median(t1):.2f} | {t1.mean():.2f} | {np.median(t1[big]) if big.any() else float('nan'):.2f} |",
             f"| `n_jobs={a.jobs}` | {np.median(tn):.2f} | {tn.mean():.2f} | {np.median(tn[big]) if big.any() else float('nan'):.2f} |",
             "",
             f"- Median time with {a.jobs} jobs / with 1 job: **{ratio:.2f}** (target ≤ 0.65 at 2 jobs); "
             f"per cloud, the median of the ratios: {np.median(tn / t1):.2f}; total time "
             f"{tn.sum():.0f} s against {t1.sum():.0f} s.",
             f"- Where the second core goes (sums over the clouds): CPU time {cpu1:.0f} s with 1 job, "
             f"{cpu_n:.0f} s with {a.jobs} ({100 * (cpu_n / cpu1 - 1):+.0f} %: forked pages, pickling, both "
             f"cores busy at once). This process's own CPU time in the {a.jobs}-job runs (its preprocessing "
             f"threads included) was {main_n:.0f} s of their {tn.sum():.0f} s: the work no worker takes, "
             f"{main_n / t1.sum():.2f} of the 1-job time on its own.",
             f"- Identical results (segments, parameters, labels, groups): {same} of {len(rows)} clouds"
             + (f"; different: {', '.join(r['name'] for r in rows if not r['same'])}." if same < len(rows) else ".")]
    publish_section("jobs", "Both cores inside one cloud", "cloud_jobs.py", argv, [
        f"- Clouds: {len(rows)}, one at a time in one process; the `Segmenter.fit` call timed with "
        f"`n_jobs=1` and `n_jobs={a.jobs}` (families and clusters on forked workers).",
    ], lines, not a.no_write, summary=[f"median {np.median(t1):.2f} s -> {np.median(tn):.2f} s "
                                       f"(x{ratio:.2f}); identical on {same}/{len(rows)}"])
    return 0 if same == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
