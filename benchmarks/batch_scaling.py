"""Batch scaling: a dataset through ``houghcad batch`` against one process per cloud.

Three runs over the same folder, one after the other, each timed from its first process start to
the end of its last process (wall time):

- ``processes``: ``houghcad segment CLOUD -o ... --fit4cad ...`` once per cloud, two processes at a
  time (what a shell loop with ``xargs -P 2`` does, and how the benchmarks ran before the batch
  engine): every cloud pays the interpreter, the imports and numba's cache loading;
- ``batch --workers 2``: the batch engine on a local Dask cluster of two worker processes;
- ``batch --workers 1``: the same on one worker, for the speed-up from 1 to 2 workers.

Every run scores its clouds against the Fit4CAD ground truth beside them (faces, as
``houghcad evaluate`` and ``benchmarks/fit4cad.py``); the table checks that all three give the same
DSC for every cloud. It also projects, from the measured worker-seconds per cloud, the wall time of
a 10,000-cloud dataset on 16 workers.

Usage::

    python benchmarks/batch_scaling.py ../shared/fit4cad/training_set            # about 20 min
    python benchmarks/batch_scaling.py ../shared/fit4cad/training_set --limit 10 --no-write
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fit4cad import publish_section  # run from benchmarks/

from houghcad.batch import expand_inputs
from houghcad.evaluate import classification_measures, read_fit4cad_segments

#: The projection's dataset: clouds and workers.
PROJECTED_CLOUDS, PROJECTED_WORKERS = 10_000, 16


@dataclass
class Run:
    """One way of running the dataset: its wall time and each cloud's DSC and seconds."""

    name: str
    wall: float
    dsc: dict[str, float] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)  # segment call inside the worker
    errors: int = 0


def _houghcad() -> list[str]:
    return [sys.executable, "-m", "houghcad"]


def run_processes(clouds: list[Path], out: Path, jobs: int) -> Run:
    """One ``houghcad segment`` process per cloud, ``jobs`` at a time."""
    out.mkdir(parents=True)

    def one(path: Path) -> tuple[str, float | None]:
        cmd = [*_houghcad(), "segment", str(path), "-o", str(out / f"{path.stem}_segments.json"),
               "--fit4cad", str(out), "--quiet"]
        ok = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0
        return path.stem, _score(out / path.stem, path) if ok else None

    t0 = time.perf_counter()
    with ThreadPoolExecutor(jobs) as pool:
        scored = list(pool.map(one, clouds))
    run = Run("processes", time.perf_counter() - t0)
    for stem, dsc in scored:
        if dsc is None:
            run.errors += 1
        else:
            run.dsc[stem] = dsc
    return run


def _score(written: Path, cloud: Path) -> float:
    """DSC of the Fit4CAD segmentation ``segment`` wrote beside ``written``_segments.json against
    the ground truth beside the cloud (the point count from the JSON: the cloud is not read again)."""
    gt = read_fit4cad_segments(cloud.with_name(f"{cloud.stem}_primitives.txt"))
    pred = read_fit4cad_segments(written.with_name(f"{written.name}_primitives.txt"))
    with open(written.with_name(f"{written.name}_segments.json"), encoding="utf-8") as fh:
        n = int(json.load(fh)["n_points"])
    return float(classification_measures(pred, gt, n)["DSC"])


def run_batch(folder_or_files: list[str], out: Path, workers: int) -> Run:
    """``houghcad batch`` on a local cluster of ``workers`` processes."""
    cmd = [*_houghcad(), "batch", *folder_or_files, "-o", str(out), "--workers", str(workers), "--quiet"]
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run = Run(f"batch --workers {workers}", time.perf_counter() - t0)
    with open(out / "summary.csv", newline="", encoding="utf-8") as fh:
        for rec in csv.DictReader(fh):
            if rec["input"].startswith("#"):
                continue
            if rec["status"] != "ok" or not rec.get("DSC"):
                run.errors += 1
                continue
            stem = Path(rec["input"]).stem
            run.dsc[stem] = float(rec["DSC"])
            run.seconds[stem] = float(rec["seconds"])
    return run


def _same(a: Run, b: Run) -> int:
    """Clouds with the same DSC in both runs, at summary.csv's 6 significant digits."""
    return sum(k in b.dsc and f"{v:.6g}" == f"{b.dsc[k]:.6g}" for k, v in a.dsc.items())


def report(runs: dict[str, Run], n: int, write: bool, argv: list[str] | None) -> None:
    proc, two, one = runs["processes"], runs["batch2"], runs["batch1"]
    per_cloud = float(np.sum(list(one.seconds.values()))) / max(len(one.seconds), 1)
    # Worker-seconds per cloud as the 2-worker run paid them (wall time x workers / clouds): what a
    # worker of a bigger cluster, also one per core, spends per cloud, start-up and scheduling included.
    paid = two.wall * 2 / n
    hours = PROJECTED_CLOUDS * paid / PROJECTED_WORKERS / 3600
    rows = [
        "| run | wall time (s) | per cloud (s) | clouds with errors | DSC mean | same DSC as `processes` |",
        "|---|---|---|---|---|---|",
    ]
    for r in (proc, two, one):
        rows.append(f"| `{r.name}` | {r.wall:.1f} | {r.wall / n:.2f} | {r.errors} | "
                    f"{np.mean(list(r.dsc.values())):.4f} | {_same(r, proc)} of {n} |")
    body = rows + [
        "",
        f"- `batch --workers 2` against one process per cloud (two at a time): "
        f"{proc.wall / two.wall:.2f}x faster ({proc.wall:.0f} s -> {two.wall:.0f} s).",
        f"- Speed-up from 1 to 2 workers: {one.wall / two.wall:.2f}x (target >= 1.8x).",
        f"- The segment call alone, one worker: {per_cloud:.2f} s per cloud on average; the 2-worker run "
        f"paid {paid:.2f} worker-seconds per cloud (start-up, reading, scoring and scheduling included).",
        f"- On paper, {PROJECTED_CLOUDS:,} such clouds on {PROJECTED_WORKERS} workers (one per core, the "
        f"same per-cloud cost): {PROJECTED_CLOUDS} x {paid:.2f} s / {PROJECTED_WORKERS} = about {hours:.1f} h, "
        "plus the cluster's start (seconds).",
    ]
    notes = [f"- Clouds: {n}; one run at a time on an otherwise idle machine."]
    summary = notes + [f"- wall: processes {proc.wall:.0f} s, batch 2 workers {two.wall:.0f} s, 1 worker "
                       f"{one.wall:.0f} s; 1->2 workers {one.wall / two.wall:.2f}x; same DSC "
                       f"{_same(two, proc)}/{n} and {_same(one, proc)}/{n}"]
    publish_section("batch", "Batch scaling", "batch_scaling.py", argv, notes, body, write, summary=summary)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="folder of clouds with NAME_primitives.txt ground truth beside them")
    ap.add_argument("--limit", type=int, default=None, help="only the first N clouds (in name order)")
    ap.add_argument("--no-write", action="store_true", help="print the section, do not update BENCHMARKS.md")
    a = ap.parse_args(argv)
    clouds = [p for _, p in expand_inputs([a.dir])]
    clouds.sort(key=lambda p: (len(p.stem), p.stem))
    if a.limit:
        clouds = clouds[: a.limit]
    inputs = [str(p) for p in clouds]
    env_note = os.environ.get("HOUGHCAD_CHECK")
    if env_note:
        print("HOUGHCAD_CHECK is set: the state checks slow every run", file=sys.stderr)
    runs: dict[str, Run] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for key, work in (("processes", lambda: run_processes(clouds, Path(tmp) / "p", 2)),
                          ("batch2", lambda: run_batch(inputs, Path(tmp) / "b2", 2)),
                          ("batch1", lambda: run_batch(inputs, Path(tmp) / "b1", 1))):
            runs[key] = work()
            print(f"{runs[key].name}: {runs[key].wall:.1f} s, {len(runs[key].dsc)} scored", file=sys.stderr,
                  flush=True)
    report(runs, len(clouds), not a.no_write, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
