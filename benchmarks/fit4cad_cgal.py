#!/usr/bin/env python
"""Fit4CAD clouds through each tool's own process, against CGAL's Efficient RANSAC (issue 20).

Usage::

    python benchmarks/fit4cad_cgal.py ../shared/fit4cad/training_set [--every K] [--limit N] [--no-write]

For every cloud, one at a time on an otherwise idle machine:

- houghcad: ``python -m houghcad segment CLOUD.txt -o OUT.json --quiet`` in a fresh process, with
  its defaults (every core); the wall time of the whole process: interpreter start, imports,
  numba's cached code, reading the Fit4CAD text file, segmenting and writing the JSON;
- CGAL: a fresh process running ``scale.py``'s CGAL child (the ``cgal`` bindings: reading a binary
  PLY of the same points, its PCA normals on 12 neighbours, Efficient RANSAC with epsilon 0.5 % of
  the diagonal, cluster_epsilon 1 %, normal_threshold 0.9, min_points max(50, n / 2000),
  probability 0.05, every simple shape), its wall time likewise. The PLY is written beforehand and
  not timed.

Both are scored with the Fit4CAD measures against the ground truth: houghcad on the faces of its
JSON (a maximal primitive's parts with their boundary curves, as ``--fit4cad`` writes them), CGAL
on its shapes. The issue's
figure is the median wall time per cloud, houghcad's against CGAL's: ≤ 1.5.

The summary goes between the ``<!-- cgal:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry to the top of docs/benchmark-log.md, unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fit4cad import compile_bytecode, find_clouds, publish_section  # run from benchmarks/, beside fit4cad.py

HERE = Path(__file__).resolve().parent
#: A run taking longer than this is stopped and reported as such.
TIMEOUT = 600


def _timed(cmd: list[str]) -> tuple[float, str]:
    """Wall time (s) of a fresh process running ``cmd``, and its error line ('' on success)."""
    t = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return time.perf_counter() - t, f"over {TIMEOUT} s"
    dt = time.perf_counter() - t
    if proc.returncode != 0:
        return dt, (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1][:120]
    return dt, ""


def _faces(doc: dict) -> list[np.ndarray]:
    """The faces of a houghcad JSON, as ``--fit4cad`` writes them: each segment's parts, or the
    segment when it has none, each with its boundary curves (:meth:`houghcad.Result.faces`)."""
    from houghcad.result import Result

    return Result.from_dict(doc).faces()


def measure(name: str, cloud: Path, gt_path: Path, work: Path) -> dict:
    from houghcad.evaluate import classification_measures, read_fit4cad_segments
    from houghcad.io import read_points, write_points_ply

    points = read_points(str(cloud)).points
    n, gt = len(points), read_fit4cad_segments(gt_path)
    row: dict = {"name": name, "n": n}
    out = work / f"{name}.json"
    row["houghcad_s"], err = _timed([sys.executable, "-m", "houghcad", "segment", str(cloud), "-o", str(out),
                                     "--quiet"])
    row["houghcad_dsc"] = float("nan") if err else float(
        classification_measures(_faces(json.loads(out.read_text())), gt, n)["DSC"])
    row["houghcad_error"] = err
    ply, stem = work / f"{name}.ply", work / f"cgal_{name}"
    write_points_ply(ply, points, binary=True)
    diag = float(np.linalg.norm(np.ptp(points, axis=0)))
    row["cgal_s"], err = _timed([sys.executable, str(HERE / "scale.py"), "--child", "cgal", str(ply), str(stem),
                                 "0.0", str(diag)])
    if not err:
        labels = np.load(str(stem) + ".npy")
        pred = [np.flatnonzero(labels == k) for k in range(int(labels.max()) + 1)]
        row["cgal_dsc"] = float(classification_measures(pred, gt, n)["DSC"])
    else:
        row["cgal_dsc"] = float("nan")
    row["cgal_error"] = err
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--limit", type=int, default=None, help="only the first N clouds")
    ap.add_argument("--every", type=int, default=1, help="every K-th cloud only (a quick sample)")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    compile_bytecode()  # fresh processes load houghcad as an installed copy does
    clouds = find_clouds(a.dir)[::a.every][:a.limit]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        measure(*clouds[0], Path(tmp))  # warm-up: numba's cache, the file system's
        for name, path, gt in clouds:
            r = measure(name, path, gt, Path(tmp))
            rows.append(r)
            print(f"{name:<6} {r['n']:>6} pts  houghcad {r['houghcad_s']:6.2f} s DSC {r['houghcad_dsc']:.3f}  "
                  f"CGAL {r['cgal_s']:6.2f} s DSC {r['cgal_dsc']:.3f}  {r['houghcad_error']}{r['cgal_error']}",
                  file=sys.stderr, flush=True)
    h = np.array([r["houghcad_s"] for r in rows])
    c = np.array([r["cgal_s"] for r in rows])
    hd = np.array([r["houghcad_dsc"] for r in rows])
    cd = np.array([r["cgal_dsc"] for r in rows])
    fails = sum(bool(r["houghcad_error"]) for r in rows), sum(bool(r["cgal_error"]) for r in rows)
    ratio = float(np.median(h) / np.median(c))
    lines = ["| tool | median s per cloud | mean s | 90th percentile s | mean DSC | failures |",
             "|---|---|---|---|---|---|",
             f"| houghcad (`houghcad segment`, every core) | {np.median(h):.2f} | {h.mean():.2f} | "
             f"{np.quantile(h, 0.9):.2f} | {np.nanmean(hd):.3f} | {fails[0]} |",
             f"| CGAL Efficient RANSAC (with its PCA normals) | {np.median(c):.2f} | {c.mean():.2f} | "
             f"{np.quantile(c, 0.9):.2f} | {np.nanmean(cd):.3f} | {fails[1]} |",
             "",
             f"- Median wall time per cloud, houghcad's against CGAL's: **{ratio:.2f}×** (target ≤ 1.5×); "
             f"per cloud, the median of the ratios: {np.median(h / c):.2f}×.",
             "- DSC: houghcad on the faces of its JSON (with their boundary curves), CGAL on its shapes (a failure scores nothing and is "
             "left out of the mean)."]
    publish_section("cgal", "Fit4CAD clouds against CGAL, process start included", "fit4cad_cgal.py", argv, [
        f"- Clouds: {len(rows)}, one at a time; each tool in a fresh process per cloud, its wall time "
        "from process start to exit (houghcad: reading the Fit4CAD text file and writing the JSON included; "
        "CGAL: reading a binary PLY of the same points, written beforehand). houghcad's modules "
        "byte-compiled first, as `pip install .` leaves them.",
    ], lines, not a.no_write, summary=[f"median {np.median(h):.2f} s against CGAL {np.median(c):.2f} s "
                                       f"(x{ratio:.2f}); mean DSC {np.nanmean(hd):.3f} against {np.nanmean(cd):.3f}"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
