#!/usr/bin/env python
"""Simple-primitive benchmark (issue 2): single primitives in random poses with noise.

Usage::

    python benchmarks/singles.py [--seeds 10] [--points 4000] [--noise 0.01,0.002] [--jobs 2] [--no-write]

For each simple family of :mod:`houghcad.synth` and each seed, one primitive in a random pose and
scale with Gaussian noise σ = noise × diagonal goes through ``houghcad.segment(points)``. A case
passes when the largest segment has the right type, holds at least 70 % of the points, and its
world parameters are within :data:`houghcad.evaluate.PARAMETER_TOLERANCES` (radius and offset
errors ≤ 1 % of the diagonal, axis errors ≤ 1°).

The summary goes between the ``<!-- singles:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry with the pass counts to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time

import numpy as np

from fit4cad import publish_section  # the scripts run from benchmarks/, beside fit4cad.py

MIN_COVERAGE = 0.7


def run_case(args):
    family, seed, n_points, noise = args
    import houghcad
    from houghcad import synth
    from houghcad.evaluate import PARAMETER_TOLERANCES, parameter_errors

    cloud = synth.single(family, seed, n_points=n_points, noise=noise)
    t = time.perf_counter()
    res = houghcad.segment(cloud.points, seed=0)
    dt = time.perf_counter() - t
    best = max(res.segments, key=lambda s: len(s.indices), default=None)
    cover = len(best.indices) / len(cloud.points) if best is not None else 0.0
    errs: dict[str, float] = {}
    if best is not None and best.type == family:
        errs = parameter_errors(family, cloud.primitives[0]["params"], best.params, cloud.diagonal(),
                                cloud.points)
    bad = {k: v for k, v in errs.items() if not v <= PARAMETER_TOLERANCES[k]}
    ok = best is not None and best.type == family and cover >= MIN_COVERAGE and not bad
    return {"family": family, "seed": seed, "noise": noise, "ok": ok, "type": best.type if best else "-",
            "cover": cover, "errors": errs, "bad": bad, "seconds": dt}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--noise", default="0.01,0.002", help="comma-separated noise levels (σ / diagonal)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    from houghcad import synth

    noises = [float(x) for x in a.noise.split(",") if x.strip()]
    cases = [(f, s, a.points, nz) for nz in noises for f in synth.FAMILIES for s in range(a.seeds)]
    rows = []
    with mp.get_context("spawn").Pool(a.jobs) as pool:
        for r in pool.imap(run_case, cases):
            rows.append(r)
            err = ", ".join(f"{k} {v:.4f}" for k, v in r["errors"].items())
            print(f"{r['family']:<9} noise {r['noise']:<6} seed {r['seed']:<3} {'ok ' if r['ok'] else 'MISS'} "
                  f"{r['type']} {r['cover']:.0%}  {err}  {r['seconds']:.1f} s", file=sys.stderr, flush=True)

    lines = ["| family | noise σ | passed | worst errors (max over seeds) | misses | median s |",
             "|---|---|---|---|---|---|"]
    for nz in noises:
        for f in synth.FAMILIES:
            rs = [r for r in rows if r["family"] == f and r["noise"] == nz]
            keys = sorted({k for r in rs for k in r["errors"]})
            worst = "; ".join(f"{k} {max(r['errors'].get(k, 0.0) for r in rs):.4f}" for k in keys) or "—"
            miss = "; ".join(f"seed {r['seed']}: {r['type']} {r['cover']:.0%}"
                             + (f" {', '.join(f'{k} {v:.4f}' for k, v in r['bad'].items())}" if r["bad"] else "")
                             for r in rs if not r["ok"])
            lines.append(f"| {f} | {nz:g} | {sum(r['ok'] for r in rs)}/{len(rs)} | {worst} | {miss} | "
                         f"{np.median([r['seconds'] for r in rs]):.1f} |")
    passed = {nz: [r["ok"] for r in rows if r["noise"] == nz] for nz in noises}
    summary = [f"Passed: {sum(sum(v) for v in passed.values())}/{len(rows)} ("
               + "; ".join(f"noise σ {nz:g}: {sum(v)}/{len(v)}" for nz, v in passed.items()) + ")"]
    misses = [f"{r['family']} noise σ {r['noise']:g} seed {r['seed']}" for r in rows if not r["ok"]]
    if misses:
        summary.append("Misses: " + ", ".join(misses))
    publish_section("singles", "Simple primitives (issue 2)", "singles.py", argv, [
        f"- {a.seeds} seeds per family and noise level, {a.points} points, random pose and scale; "
        "`segment(points)`.",
        f"- Pass: the largest segment has the right type, ≥ {MIN_COVERAGE:.0%} of the points, radius / offset / "
        "centre / apex / axis-line errors ≤ 1 % of the diagonal, axis, normal and half-angle errors ≤ 1°. "
        "Angles in degrees, lengths as fractions of the diagonal.",
    ], lines, not a.no_write, summary=summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
