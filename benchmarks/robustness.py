#!/usr/bin/env python
"""Robustness benchmark (issue 23): single primitives and parts under what scans do.

Usage::

    python benchmarks/robustness.py [--seeds 8] [--points 3000] [--part-seeds 2] [--part-points 12000]
                                    [--only singles|parts] [--jobs 2] [--no-write]

The perturbation kinds are those of the SHREC 2022 primitive-fitting track (Romanengo et al.,
Computers & Graphics 2022): clean; uniform and Gaussian noise at three levels up to 1 % of the
diagonal; undersampling to a few hundred points and uneven density; missing parts (holes, 10-40 %
of the surface); noise with undersampling and noise with missing parts; small smooth bumps; and,
beyond SHREC, uniform outliers in the bounding box (5-30 % of the points). Each is a
:class:`houghcad.synth.Perturbation` applied by :func:`houghcad.synth.perturb` to a clean cloud.

- **Single primitives**: every simple family, ``--seeds`` random shapes and poses each, through
  ``houghcad.segment(points)``. The type is right when the largest segment has the family's type
  (SHREC's classification). Parameter errors (``houghcad.evaluate.parameter_errors``) are
  measured on the right-typed ones; "within tolerance" means every error within
  ``PARAMETER_TOLERANCES`` (1 % of the diagonal, 1°).
- **Parts**: the synthetic parts of ``parts.py``, ``--part-seeds`` seeds, scored with the Fit4CAD
  measures over the faces (mean DSC; outliers are not in the ground truth, so an outlier taken into
  a segment lowers that segment's precision).

The summary goes between the ``<!-- robustness:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry with the headline figures to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from fit4cad import publish_section, run_cases  # the scripts run from benchmarks/, beside fit4cad.py

from houghcad.synth.perturb import Perturbation


@dataclass(frozen=True)
class Kind:
    """One perturbation of the table: its SHREC category, its name and what it does."""

    category: str
    name: str
    perturbation: Perturbation
    #: The clean cloud sampled this many times denser before the perturbation (scan rows keep a
    #: twentieth of the points).
    density: int = 1


P = Perturbation
#: A part's face left with fewer points than this is out of the ground truth.
MIN_FACE_POINTS = 20
#: Every kind the single primitives go through, in table order.
SINGLE_KINDS: tuple[Kind, ...] = (
    Kind("clean", "clean", P()),
    *(Kind("Gaussian noise", f"σ {x:.2%}", P(gaussian=x)) for x in (0.0025, 0.005, 0.01)),
    *(Kind("uniform noise", f"±{x:.2%}", P(uniform=x)) for x in (0.0025, 0.005, 0.01)),
    Kind("undersampling", "1,000 points", P(n_points=1000)),
    Kind("undersampling", "300 points", P(n_points=300)),
    Kind("undersampling", "uneven density 10:1", P(uneven=0.9)),
    *(Kind("missing parts", f"{x:.0%} cut in 3 holes", P(missing=x)) for x in (0.1, 0.25, 0.4)),
    Kind("noise + undersampling", "σ 0.5 %, 500 points", P(gaussian=0.005, n_points=500)),
    Kind("noise + missing parts", "σ 0.5 %, 25 % missing", P(gaussian=0.005, missing=0.25)),
    *(Kind("local deformation", f"3 bumps {x:.0%} high", P(bumps=x)) for x in (0.02, 0.05)),
    *(Kind("outliers", f"{x:.0%} of the points", P(outliers=x)) for x in (0.05, 0.15, 0.3)),
)
#: The kinds the parts go through (the issue's figures: 20 % outliers, 30 % missing).
PART_KINDS: tuple[Kind, ...] = (
    Kind("clean", "clean", P()),
    Kind("Gaussian noise", "σ 0.5 %", P(gaussian=0.005)),
    Kind("uniform noise", "±0.5 %", P(uniform=0.005)),
    Kind("undersampling", "3,000 points", P(n_points=3000)),
    Kind("undersampling", "uneven density 10:1", P(uneven=0.9)),
    *(Kind("missing parts", f"{x:.0%} cut in 3 holes", P(missing=x)) for x in (0.1, 0.3)),
    Kind("noise + missing parts", "σ 0.5 %, 30 % missing", P(gaussian=0.005, missing=0.3)),
    Kind("local deformation", "3 bumps 2 % high", P(bumps=0.02)),
    *(Kind("outliers", f"{x:.0%} of the points", P(outliers=x)) for x in (0.05, 0.2, 0.3)),
    # Beyond SHREC, as the outliers: a scanner's rows, 10 spacings of a 20 times denser sample
    # apart and about 2 along them: the clean part's number of points, in rows 1:5.
    Kind("scan rows", "rows 1:5", P(rows=10.0, row_band=0.05), density=20),
    Kind("scan rows", "rows 1:5, σ 0.1 % along the normal", P(rows=10.0, row_band=0.05, normal_noise=0.001),
         density=20),
)


def run_single(args: tuple[str, int, int, int]) -> dict[str, Any]:
    family, seed, n_points, k = args
    import houghcad
    from houghcad import synth
    from houghcad.evaluate import PARAMETER_TOLERANCES, parameter_errors

    kind = SINGLE_KINDS[k]
    clean = synth.single(family, seed, n_points=n_points)
    cloud = synth.perturb(clean, kind.perturbation, seed=seed)
    t = time.perf_counter()
    res = houghcad.segment(cloud.points, seed=0)
    dt = time.perf_counter() - t
    best = max(res.segments, key=lambda s: len(s.indices), default=None)
    found = best.type if best is not None else "-"
    errs: dict[str, float] = {}
    if found == family:
        errs = parameter_errors(family, cloud.primitives[0]["params"], best.params, clean.diagonal(),
                                cloud.points[cloud.labels >= 0])
    within = found == family and all(v <= PARAMETER_TOLERANCES[e] for e, v in errs.items())
    return dict(family=family, seed=seed, kind=k, type=found, right=found == family, within=within,
                angle=max((v for e, v in errs.items() if e.endswith("_deg")), default=np.nan),
                length=max((v for e, v in errs.items() if not e.endswith("_deg")), default=np.nan),
                seconds=dt)


def run_part(args: tuple[str, int, int, int]) -> dict[str, Any]:
    name, seed, n_points, k = args
    import houghcad
    from houghcad import synth
    from houghcad.evaluate import classification_measures

    kind = PART_KINDS[k]
    cloud = synth.perturb(synth.PARTS[name](seed=seed, n_points=n_points * kind.density), kind.perturbation, seed=seed)
    t = time.perf_counter()
    res = houghcad.segment(cloud.points, seed=0)
    dt = time.perf_counter() - t
    # A face the holes or the undersampling leave with a handful of points is no longer in the
    # data: it leaves the ground truth, and its points count as clutter, like outliers.
    faces = [f for f in cloud.segments() if len(f) >= MIN_FACE_POINTS]
    m = classification_measures([np.asarray(f) for f in res.faces()], faces, len(cloud.points))
    return dict(part=name, seed=seed, kind=k, dsc=float(m["DSC"]), seconds=dt,
                gone=len(cloud.primitives) - len(faces))


def _pct(x: float) -> str:
    return "—" if not np.isfinite(x) else f"{100 * x:.2f} %"


def singles_table(rows: list[dict[str, Any]], families: tuple[str, ...]) -> tuple[list[str], list[str]]:
    lines = ["| kind | perturbation | type right | " + " | ".join(families)
             + " | within tolerance | median axis/normal error | median length error | median s |",
             "|---|---|---|" + "---|" * len(families) + "---|---|---|---|"]
    for k, kind in enumerate(SINGLE_KINDS):
        rs = [r for r in rows if r["kind"] == k]
        right = [r for r in rs if r["right"]]
        per = []
        for f in families:
            rf = [r for r in rs if r["family"] == f]
            miss = sorted({r["type"] for r in rf if not r["right"]})
            per.append(f"{sum(r['right'] for r in rf)}/{len(rf)}" + (f" ({', '.join(miss)})" if miss else ""))
        lines.append(
            f"| {kind.category} | {kind.name} | {sum(r['right'] for r in rs)}/{len(rs)} | " + " | ".join(per)
            + f" | {sum(r['within'] for r in rs)}/{len(rs)} | "
            f"{np.nanmedian([r['angle'] for r in right]) if right else np.nan:.2f}° | "
            f"{_pct(np.nanmedian([r['length'] for r in right]) if right else np.nan)} | "
            f"{np.median([r['seconds'] for r in rs]):.2f} |")
    n_right, n = sum(r["right"] for r in rows), len(rows)
    total = (f"Single primitives, every kind together: type right in {n_right}/{n} "
             f"({100 * n_right / n:.1f} %); every parameter within tolerance in "
             f"{sum(r['within'] for r in rows)}/{n}.")
    lines += ["", total]
    return lines, [total]


def parts_table(rows: list[dict[str, Any]], parts: list[str]) -> tuple[list[str], list[str]]:
    clean = {p: np.mean([r["dsc"] for r in rows if r["part"] == p and r["kind"] == 0]) for p in parts}
    lines = ["| kind | perturbation | mean DSC | change from clean | " + " | ".join(parts)
             + " | faces left out | median s |",
             "|---|---|---|---|" + "---|" * len(parts) + "---|---|"]
    summary = []
    base = float(np.mean(list(clean.values())))
    for k, kind in enumerate(PART_KINDS):
        rs = [r for r in rows if r["kind"] == k]
        mean = float(np.mean([r["dsc"] for r in rs]))
        per = [f"{np.mean([r['dsc'] for r in rs if r['part'] == p]):.3f}" for p in parts]
        lines.append(f"| {kind.category} | {kind.name} | {mean:.3f} | {mean - base:+.3f} | " + " | ".join(per)
                     + f" | {sum(r['gone'] for r in rs)} | {np.median([r['seconds'] for r in rs]):.1f} |")
        summary.append(f"{kind.name}: {mean:.3f} ({mean - base:+.3f})")
    return lines, ["Parts, mean DSC by kind: " + "; ".join(summary)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=8, help="random instances per family and kind")
    ap.add_argument("--points", type=int, default=3000, help="points of a clean single primitive")
    ap.add_argument("--part-seeds", type=int, default=2)
    ap.add_argument("--part-points", type=int, default=12000)
    ap.add_argument("--only", choices=("singles", "parts"), default=None)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    from houghcad import synth

    from parts import simple_parts  # run from benchmarks/, beside this script

    body: list[str] = []
    summary: list[str] = []
    notes: list[str] = []
    if a.only != "parts":
        cases = [(f, s, a.points, k) for k in range(len(SINGLE_KINDS)) for f in synth.FAMILIES
                 for s in range(a.seeds)]
        rows = run_cases(run_single, cases, a.jobs, lambda r: (
            f"{SINGLE_KINDS[r['kind']].name:<24} {r['family']:<9} seed {r['seed']:<3} "
            f"{'ok ' if r['right'] else 'MISS'} {r['type']:<9} {r['seconds']:.2f} s"))
        lines, s = singles_table(rows, synth.FAMILIES)
        body += ["### Single primitives", "", *lines, ""]
        summary += s
        notes.append(f"- Single primitives: {a.seeds} random shapes and poses per family and kind, "
                     f"{a.points} points before the perturbation; `segment(points)`. Type right: the largest "
                     "segment's type. Errors (of the right-typed): the largest angle error and the largest "
                     "length error of each instance, as in `singles.py`; lengths as fractions of the diagonal.")
    if a.only != "singles":
        parts = simple_parts()
        cases = [(p, s, a.part_points, k) for k in range(len(PART_KINDS)) for p in parts
                 for s in range(a.part_seeds)]
        rows = run_cases(run_part, cases, a.jobs, lambda r: (
            f"{PART_KINDS[r['kind']].name:<24} {r['part']:<26} seed {r['seed']:<3} DSC {r['dsc']:.3f} "
            f"{r['seconds']:.1f} s"))
        lines, s = parts_table(rows, parts)
        body += ["### Parts", "", *lines, ""]
        summary += s
        notes.append(f"- Parts: {a.part_seeds} seeds per part and kind, {a.part_points} points before the "
                     "perturbation; mean DSC over the part's faces (Fit4CAD measure). A face the perturbation "
                     f"leaves with fewer than {MIN_FACE_POINTS} points (a small face inside a hole) is no longer "
                     "in the data: it leaves the ground truth and its points count as clutter (\"faces left "
                     "out\", over all seeds and parts).")
    publish_section("robustness", "Robustness: what scans do (issue 23)", "robustness.py", argv, [
        "- Perturbations of the SHREC 2022 primitive-fitting track, and uniform outliers "
        "(`houghcad.synth.Perturbation`); lengths are fractions of the clean cloud's diagonal.",
        *notes], body, not a.no_write, summary=summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
