#!/usr/bin/env python
"""Synthetic mechanical parts benchmark: segmentation of whole parts at several noise levels.

Usage::

    python benchmarks/parts.py [--seeds 3] [--points 12000] [--noise 0,0.0005,0.002,0.005]
                               [--families simple] [--jobs 2] [--no-write]

Every part of :data:`houghcad.synth.PARTS` except the complex composites (scored by
``complex.py``) the parts with many small faces (``small_faces.py``, at their own sizes) and the paper's part
(``paper_table5.py``) is generated at each noise level (σ as a fraction of the diagonal; 0 is a sampled
CAD model; 0.0005 is about a tenth of the point spacing at 12,000 points, noise the noise policy reads
as clean) for ``--seeds`` seeds and goes through ``houghcad.segment(points, families=...)``.
Each run is scored with the Fit4CAD measures (mean DSC over the part's faces); the table gives
the mean over seeds, each seed's figure, the face with the lowest DSC over the seeds and the
median time.

The summary goes between the ``<!-- parts:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry with the mean DSC per noise level to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from complex import COMPOSITES, NEAREST_NOTE, _mean_or_dash, nearest_face_dsc, segment_part  # run from benchmarks/
from fit4cad import publish_section, run_cases


def simple_parts() -> list[str]:
    """The parts of ``synth.PARTS`` with simple surfaces only, as this benchmark runs them: not
    the complex composites, the parts with many small faces nor the paper's part."""
    from houghcad import synth

    return [p for p in synth.PARTS if p not in COMPOSITES and p not in synth.SMALL_FACE_PARTS
            and p not in synth.PAPER_PARTS]


def run_part(args):
    name, seed, n_points, noise, families = args
    cloud, _, dt, m = segment_part(name, seed, n_points, noise, families)
    per = np.asarray(m["per_segment"]["DSC"], dtype=float)
    k = int(np.argmin(per))
    return dict(part=name, seed=seed, noise=noise, dsc=float(m["DSC"]), seconds=dt,
                nearest=nearest_face_dsc(name, seed, n_points, noise),
                worst=(float(per[k]), cloud.primitives[k]["name"]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--points", type=int, default=12000)
    ap.add_argument("--noise", default="0,0.0005,0.002,0.005", help="comma-separated noise levels (σ / diagonal)")
    ap.add_argument("--families", default="simple")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    parts = simple_parts()
    noise = [float(x) for x in a.noise.split(",") if x.strip()]
    cases = [(p, s, a.points, nz, a.families) for nz in noise for p in parts for s in range(a.seeds)]
    rows = run_cases(run_part, cases, a.jobs, lambda r: (
        f"{r['part']:<26} noise {r['noise']:<6} seed {r['seed']:<3} DSC {r['dsc']:.3f} "
        f"worst {r['worst'][1]} {r['worst'][0]:.2f}  {r['seconds']:.1f} s"))
    lines = [NEAREST_NOTE, "", "| part | noise σ | mean DSC | per seed | nearest true face | worst face (DSC) | median s |",
             "|---|---|---|---|---|---|---|"]
    summary = []
    for nz in noise:
        for p in parts:
            rs = [r for r in rows if r["part"] == p and r["noise"] == nz]
            w = min(rs, key=lambda r: r["worst"][0])["worst"]
            lines.append(f"| {p} | {nz:g} | {np.mean([r['dsc'] for r in rs]):.3f} | "
                         f"{', '.join('%.3f' % r['dsc'] for r in rs)} | {_mean_or_dash([r['nearest'] for r in rs])} | "
                         f"{w[1]} ({w[0]:.2f}) | "
                         f"{np.median([r['seconds'] for r in rs]):.1f} |")
        rs = [r for r in rows if r["noise"] == nz]
        lines.append(f"| **all** | {nz:g} | **{np.mean([r['dsc'] for r in rs]):.3f}** | | "
                     f"{_mean_or_dash([r['nearest'] for r in rs])} | | "
                     f"{np.median([r['seconds'] for r in rs]):.1f} |")
        summary.append(f"Noise σ {nz:g}: mean DSC {np.mean([r['dsc'] for r in rs]):.3f} (nearest true face "
                       f"{_mean_or_dash([r['nearest'] for r in rs])}); per part "
                       + ", ".join(f"{p} {np.mean([r['dsc'] for r in rs if r['part'] == p]):.3f}" for p in parts)
                       + f"; median {np.median([r['seconds'] for r in rs]):.1f} s")
    publish_section("parts", "Synthetic parts", "parts.py", argv, [
        f"- {a.seeds} seeds per part and noise level, {a.points} points, random pose; "
        f"`segment(families=\"{a.families}\")`; mean DSC over the part's faces (Fit4CAD measure).",
    ], lines, not a.no_write, summary=summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
