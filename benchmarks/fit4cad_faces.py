#!/usr/bin/env python
"""Where the Fit4CAD loss is: every ground-truth face's DSC, and the lost faces by cause.

Usage::

    python benchmarks/fit4cad_faces.py ../shared/fit4cad/training_set [--fraction 0.35]
                                       [--below 0.5] [--jobs 2] [--out faces.csv] [--no-write]

Every cloud is segmented as ``benchmarks/fit4cad.py`` does (simple families, seed 0, faces scored
with their boundary curves; ``--fraction`` keeps the same seeded share of the points). Each
ground-truth face is matched as the benchmark matches it (the predicted face sharing most of its
points), and its DSC is kept. The loss is counted in the benchmark's units: a face costs
(1 − DSC) / (faces of its cloud) / (clouds), so the losses of all faces add up to 1 − mean DSC.

A face under ``--below`` is *lost*; its cause is the first of these that holds (:func:`cause`):

- ``boundary only``: most of its points (``BOUNDARY_SHARE``) lie in another ground-truth face as
  well: the face is little more than the curves it shares, and has no interior to find;
- ``below the smallest segment``: fewer points than the run's smallest segment;
- ``unsegmented``: half its points or more belong to no face;
- ``cut into pieces``: no predicted face holds half its points;
- ``joined with a face of its type``: the face that holds most of it is another true face's, of
  the same type (one surface that the CAD model cut in two, or a neighbour of its type that took
  it: from the points alone the two often cannot be told apart);
- ``taken by another face``: the face that holds most of it is another true face's, not all of one type;
- ``wrong type``: its own predicted face, of another type;
- ``other``.

The per-face table goes to ``--out`` (CSV). The summary (losses by DSC band and by cause, per fold)
goes between the ``<!-- fit4cad_faces:begin/end -->`` markers of BENCHMARKS.md, and a dated entry
to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from fit4cad import FOLDS, _fold, find_clouds, publish_section, run_cases, sparser  # run from benchmarks/

#: Share of a face's points also in another ground-truth face from which it is "boundary only".
BOUNDARY_SHARE = 0.85
#: Share of a face's points that one predicted face (or no face) must hold to be where it went.
HELD_SHARE = 0.5
#: The causes of a lost face, in the order they are tested.
CAUSES = ("boundary only", "below the smallest segment", "unsegmented", "cut into pieces",
          "joined with a face of its type", "taken by another face", "wrong type", "other")
#: The type of a ground-truth face whose file gives none.
UNKNOWN = "unknown"
#: DSC bands of the loss split (lower bounds, highest first).
BANDS = ((0.9, "≥ 0.9"), (0.5, "0.5–0.9"), (0.0, "< 0.5"))


@dataclass(frozen=True)
class FaceRow:
    """One ground-truth face of one cloud."""

    cloud: str
    fold: int
    face: int  # 1-based, as the ground-truth file numbers its blocks
    type: str
    points: int
    dsc: float
    loss: float  # in the benchmark's units, over this run's clouds
    matched_type: str  # the matched predicted face's type ("" when none)
    cause: str  # "" when the face is not lost


def cause(k: int, gt: list[np.ndarray], gt_types: list[str], faces: list[np.ndarray],
          face_types: list[str], match: int, n_points: int, min_points: int) -> str:
    """The cause of the lost ground-truth face ``gt[k]``, one of :data:`CAUSES`.

    ``gt`` and ``gt_types``: every ground-truth face (indices) and its type; ``faces`` and ``face_types``:
    the predicted faces (index arrays, overlapping where they share boundary curves) and their
    types; ``match``: the index of the predicted face the benchmark matched with it (-1: none).
    """
    g = gt[k]
    m = len(g)
    in_gt = np.zeros(n_points, np.int32)
    for h in gt:
        in_gt[h] += 1
    if m and np.mean(in_gt[g] > 1) >= BOUNDARY_SHARE:
        return "boundary only"
    if m < min_points:
        return "below the smallest segment"
    owned = np.zeros(n_points, bool)
    for f in faces:
        owned[f] = True
    if np.mean(~owned[g]) >= HELD_SHARE:
        return "unsegmented"
    if match < 0 or np.isin(g, faces[match]).sum() < HELD_SHARE * m:
        return "cut into pieces"
    f = faces[match]
    # The true face holding most of the matched predicted face (ties: the lower index).
    shares = np.array([np.isin(f, h).sum() for h in gt])
    top = int(np.argmax(shares))
    if top != k and shares[top] > shares[k]:
        if face_types[match] == gt_types[k] == gt_types[top] != UNKNOWN:
            return "joined with a face of its type"
        return "taken by another face" if UNKNOWN not in (gt_types[k], gt_types[top]) else "other"
    if face_types[match] != gt_types[k] != UNKNOWN:
        return "wrong type"
    return "other"


def cloud_rows(args: tuple) -> list[dict]:
    """Segment one cloud and return its faces' rows (dicts of :class:`FaceRow`, loss per cloud)."""
    name, cloud_path, gt_path, fraction, below = args
    from houghcad.evaluate import classification_measures
    from houghcad.groundtruth import read_fit4cad_segments, read_fit4cad_types
    from houghcad.io import read_points
    from houghcad.pipeline import Segmenter

    gt = read_fit4cad_segments(gt_path)
    parametric = Path(gt_path).with_name(f"{name}_parametric.txt")
    types = read_fit4cad_types(parametric) if parametric.is_file() else []
    points = np.asarray(read_points(str(cloud_path)).points)
    if fraction < 1.0:
        points, gt = sparser(name, points, gt, fraction)
    res = Segmenter(families="simple", seed=0, n_jobs=1).fit(points).result_
    faces = [np.asarray(f, np.int64) for f in res.faces()]
    face_types = [s.type for s in res.segments for _ in s.faces()]
    per = classification_measures(faces, gt, len(points), per_segment=True)["per_segment"]
    min_points = int(res.options["derived"]["min_points"])
    if len(types) != len(gt):  # no parametric file beside it: no cause that compares types
        types = [UNKNOWN] * len(gt)
    rows = []
    for k, g in enumerate(gt):
        dsc, match = float(per["DSC"][k]), int(per["match"][k])
        why = cause(k, gt, types, faces, face_types, match, len(points), min_points) if dsc < below else ""
        rows.append(asdict(FaceRow(name, _fold(name), k + 1, types[k], len(g), dsc, (1 - dsc) / len(gt),
                                   face_types[match] if match >= 0 else "", why)))
    return rows


def summary(rows: list[dict], n_clouds: int) -> list[str]:
    """The summary tables (markdown lines): the loss by DSC band, and the lost faces by cause."""
    loss = np.array([r["loss"] for r in rows]) / n_clouds
    dsc = np.array([r["dsc"] for r in rows])
    fold = np.array([r["fold"] for r in rows])
    folds = [f for f in range(FOLDS) if (fold == f).any()]
    per_fold = {f: len({r["cloud"] for r in rows if r["fold"] == f}) for f in folds}

    def fold_loss(sel: np.ndarray) -> str:
        # Each fold's loss in its own units (its clouds' mean), so that it reads against its mean DSC.
        return " / ".join(f"{loss[sel & (fold == f)].sum() * n_clouds / per_fold[f]:.4f}" for f in folds)

    out = ["| faces | count | loss | loss per fold (" + ", ".join(map(str, folds)) + ") |", "|---|---|---|---|"]
    lo_prev = np.inf
    for lo, label in BANDS:
        sel = (dsc >= lo) & (dsc < lo_prev)
        out.append(f"| DSC {label} | {int(sel.sum())} | {loss[sel].sum():.4f} | {fold_loss(sel)} |")
        lo_prev = lo
    everything = np.ones(len(rows), bool)
    out.append(f"| all | {len(rows)} | {loss.sum():.4f} | {fold_loss(everything)} |")
    causes = np.array([r["cause"] for r in rows])
    out += ["", "| lost face, cause | faces | clouds | loss | loss per fold |", "|---|---|---|---|---|"]
    for c in CAUSES:
        sel = causes == c
        if sel.any():
            clouds = len({r["cloud"] for r, s in zip(rows, sel) if s})
            out.append(f"| {c} | {int(sel.sum())} | {clouds} | {loss[sel].sum():.4f} | {fold_loss(sel)} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("directory", type=Path, help="a Fit4CAD split (NAME.txt beside NAME_primitives.txt)")
    ap.add_argument("--fraction", type=float, default=1.0, help="share of each cloud's points kept")
    ap.add_argument("--below", type=float, default=0.5, help="DSC under which a face is lost")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, help="per-face CSV")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    if not a.directory.is_dir():
        print(f"fit4cad_faces: {a.directory} is not a directory", file=sys.stderr)
        return 2
    if not 0 < a.fraction <= 1:
        print(f"fit4cad_faces: --fraction must be in (0, 1], got {a.fraction}", file=sys.stderr)
        return 2
    clouds = find_clouds(a.directory)
    if not clouds:
        print(f"fit4cad_faces: no clouds with ground truth in {a.directory}", file=sys.stderr)
        return 2
    per_cloud = run_cases(cloud_rows, [(n, c, g, a.fraction, a.below) for n, c, g in clouds], a.jobs,
                          lambda rs: f"{rs[0]['cloud']}: DSC {1 - sum(r['loss'] for r in rs):.3f}")
    rows = [r for rs in per_cloud for r in rs]
    if a.out:
        from houghcad.io import atomic_write

        with atomic_write(a.out) as fh:  # whole or not at all
            w = csv.DictWriter(fh, fieldnames=list(FaceRow.__dataclass_fields__))
            w.writeheader()
            w.writerows(rows)
    mean = 1 - sum(r["loss"] for r in rows) / len(clouds)
    lens = "" if a.fraction == 1 else f" at {a.fraction:g} of the points"
    notes = [f"- Clouds: {len(clouds)}{lens}; faces: {len(rows)}; mean DSC {mean:.4f} (faces scored, simple families, "
             f"seed 0, as `fit4cad.py`). A face's loss is (1 − DSC) / its cloud's faces / the clouds: the "
             f"losses add up to 1 − mean DSC; per fold, over that fold's clouds.",
             f"- A face is lost under DSC {a.below:g}; its cause is the first that holds, in the table's order "
             f"(see the script's docstring)."]
    publish_section("fit4cad_faces", "Where the Fit4CAD loss is", "fit4cad_faces.py", argv, notes,
                    summary(rows, len(clouds)), write=not a.no_write,
                    summary=[f"- mean DSC {mean:.4f}{lens}; lost faces (DSC < {a.below:g}): "
                             f"{sum(1 for r in rows if r['cause'])}"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
