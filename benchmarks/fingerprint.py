#!/usr/bin/env python
"""Fingerprints of segmentations, to show that a refactor leaves the output identical.

Usage::

    python benchmarks/fingerprint.py record FILE.json [--jobs 2] [--fit4cad DIR]
    python benchmarks/fingerprint.py check FILE.json [--jobs 2] [--fit4cad DIR]

The cases are the synthetic parts (simple families; the composites with ``all``) at noise 0 and
0.005 of the diagonal, seed 0, and 20 Fit4CAD training clouds spread over the set (every ninth by
number; ``simple``). A fingerprint is a SHA-256 of each segment's type, point indices and
parameters (12 significant digits), its parts, the groups and the unsegmented points. ``record``
writes them; ``check`` recomputes them and lists the cases that differ (exit 1 if any).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_FIT4CAD = REPO.parent / "shared" / "fit4cad" / "training_set"
SIMPLE_PARTS = ("block_with_hole_and_slot", "plate_with_holes", "shaft_with_groove", "mirrored_cones",
                "gear_like", "filleted_block")
COMPOSITES = ("screw_part", "generalized_cone_part", "ellipsoid_part")
FIT4CAD_CLOUDS = tuple(f"PC{k}" for k in range(1, 190, 9))[:20]


def _num(v) -> object:
    """A JSON value with every float at 12 significant digits."""
    if isinstance(v, float):
        return float(f"{v:.12g}")
    if isinstance(v, (list, tuple)):
        return [_num(x) for x in v]
    if isinstance(v, dict):
        return {k: _num(x) for k, x in sorted(v.items())}
    return v


def fingerprint(result) -> str:
    """SHA-256 (hex) of a Result's segments, parts (with their boundary curves), groups and
    unsegmented points."""
    h = hashlib.sha256()
    for s in result.segments:
        h.update(s.type.encode())
        h.update(np.asarray(s.indices, np.int64).tobytes())
        h.update(json.dumps(_num(s.params), sort_keys=True).encode())
        h.update(np.asarray(s.edges, np.int64).tobytes())
        for p in s.parts:
            h.update(np.asarray(p.indices, np.int64).tobytes())
            h.update(np.asarray(p.edges, np.int64).tobytes())
    for g in result.groups:
        h.update(json.dumps([g.kind, list(g.members)]).encode())
    h.update(np.asarray(result.unsegmented, np.int64).tobytes())
    return h.hexdigest()


def cases(fit4cad: Path) -> list[tuple[str, str, float, str]]:
    """(kind, name, noise, families) of every case."""
    out = [("synth", p, nz, "simple") for nz in (0.0, 0.005) for p in SIMPLE_PARTS]
    out += [("synth", p, nz, "all") for nz in (0.0, 0.005) for p in COMPOSITES]
    if fit4cad.is_dir():
        out += [("fit4cad", str(fit4cad / f"{n}.txt"), 0.0, "simple") for n in FIT4CAD_CLOUDS
                if (fit4cad / f"{n}.txt").is_file()]
    return out


def run_case(case: tuple[str, str, float, str]) -> tuple[str, str, float]:
    import houghcad
    from houghcad import synth

    kind, name, noise, families = case
    if kind == "synth":
        pts = synth.PARTS[name](seed=0, n_points=12000, noise=noise).points
        key = f"{name}@{noise:g}/{families}"
    else:
        pts = houghcad.read_points(name).points
        key = f"{Path(name).stem}/{families}"
    t = time.perf_counter()
    res = houghcad.segment(pts, families=families, seed=0)
    return key, fingerprint(res), time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=("record", "check"))
    ap.add_argument("file", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--fit4cad", type=Path, default=DEFAULT_FIT4CAD)
    ap.add_argument("--only", default=None, help="comma-separated substrings of case keys")
    a = ap.parse_args(argv)
    todo = cases(a.fit4cad)
    if a.only:
        keys = a.only.split(",")
        todo = [c for c in todo if any(k in f"{Path(c[1]).stem}@{c[2]:g}/{c[3]}" for k in keys)]
    got: dict[str, str] = {}
    t0 = time.perf_counter()
    with mp.get_context("spawn").Pool(a.jobs) as pool:
        for key, fp, dt in pool.imap(run_case, todo):
            got[key] = fp
            print(f"{key:<45} {fp[:16]} {dt:6.1f} s", file=sys.stderr, flush=True)
    print(f"{len(got)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if a.mode == "record":
        a.file.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
        return 0
    ref = json.loads(a.file.read_text())
    bad = [k for k in got if ref.get(k) != got[k]]
    for k in bad:
        print(f"DIFFERS: {k}")
    print("identical" if not bad else f"{len(bad)} of {len(got)} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
