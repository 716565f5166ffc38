#!/usr/bin/env python
"""Complex-family benchmark (issue 3): single instances and composite parts.

Usage::

    python benchmarks/complex.py [--instances 20] [--points 4000] [--noise 0.005] [--missing 0.1]
                                 [--families NAMES] [--part-noise 0,0.005] [--jobs 2] [--no-write]

For every complex family of :mod:`houghcad.synth` (a family registered with ``role = "complex"``
that has a sampler), ``--instances`` random instances (random pose and scale, Gaussian noise σ =
``--noise`` × diagonal, ``--missing`` of the surface cut away as one region) go through
``houghcad.segment(points, families="all")``. An instance passes when

- a segment of the right type has DSC ≥ 0.9 against the surface's points, and
- its key parameters (:data:`KEY_PARAMS`: radii, a, b, semi-axes…) are within 2 % relative,
  integers exact.

Composite parts (:data:`COMPOSITES`, when present in ``synth.PARTS``) are scored with the
Fit4CAD measures (mean DSC over their faces) and the largest MFE of a complex segment, at each
``--part-noise`` level (default: 0, a sampled CAD model as in the paper's composite examples, and
0.005 as the single instances).

The summary goes between the ``<!-- complex:begin/end -->`` markers of BENCHMARKS.md, and a dated
entry with the pass counts and the composite parts' mean DSC to the top of docs/benchmark-log.md,
unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time

import numpy as np

from fit4cad import publish_section  # the scripts run from benchmarks/, beside fit4cad.py


#: Parameters compared with the ground truth, per family (world units). Integers must be exact,
#: other values within ``REL_TOL`` relative; vectors are compared sorted, element-wise.
KEY_PARAMS: dict[str, tuple[str, ...]] = {
    "ellipsoid": ("semi_axes",),
    "generalized_cylinder": ("a", "b", "n"),
    "generalized_cone": ("a", "b", "n"),
    "surface_of_revolution": (),  # the profile's own parameters, see _keys
    "helical_surface": ("R1", "R2", "n", "k1"),
    "helical_strip": ("r_inner", "r_outer", "pitch"),
    "annulus": ("r_inner", "r_outer"),
}
INTEGER_PARAMS = ("n",)
REL_TOL = 0.02
DSC_MIN = 0.9
COMPOSITES = ("screw_part", "generalized_cone_part", "ellipsoid_part")


def complex_families() -> list[str]:
    from houghcad import synth
    from houghcad.families import REGISTRY

    return [n for n, f in REGISTRY.items() if f.role == "complex" and n in synth.SAMPLERS]


def _keys(family: str, truth: dict) -> list[str]:
    keys = [k for k in KEY_PARAMS.get(family, ()) if k in truth]
    if family == "surface_of_revolution":
        # Every scalar the profile has, except placement along the axis.
        keys = [k for k, v in truth.items() if np.isscalar(v) and not isinstance(v, str)
                and k not in ("offset",)]
    return keys


def param_errors(family: str, truth: dict, found: dict) -> dict[str, float]:
    """Relative error per key parameter (integers: 0 when equal, inf otherwise)."""
    out: dict[str, float] = {}
    if family == "surface_of_revolution" and truth.get("profile") != found.get("profile"):
        return {"profile": float("inf")}
    for k in _keys(family, truth):
        if k not in found:
            out[k] = float("inf")
            continue
        g, f = np.atleast_1d(np.asarray(truth[k], float)), np.atleast_1d(np.asarray(found[k], float))
        if g.shape != f.shape:
            out[k] = float("inf")
            continue
        if k in INTEGER_PARAMS:
            out[k] = 0.0 if np.array_equal(np.round(g), np.round(f)) else float("inf")
            continue
        if g.size > 1:
            g, f = np.sort(g), np.sort(f)
        out[k] = float(np.max(np.abs(f - g) / np.maximum(np.abs(g), 1e-12)))
    return out


def run_single(args):
    family, seed, n_points, noise, missing = args
    import houghcad
    from houghcad import synth

    cloud = synth.single(family, seed=seed, n_points=n_points, noise=noise, missing=missing)
    truth_idx = np.flatnonzero(cloud.labels == 0)
    t = time.perf_counter()
    res = houghcad.segment(cloud.points, families="all", seed=0)
    dt = time.perf_counter() - t
    best, best_dsc = None, 0.0
    for s in res.segments:
        if s.type != family:
            continue
        inter = len(np.intersect1d(s.indices, truth_idx, assume_unique=True))
        dsc = 2 * inter / (len(s.indices) + len(truth_idx))
        if dsc > best_dsc:
            best, best_dsc = s, dsc
    types = sorted({s.type for s in res.segments})
    if best is None:
        return dict(family=family, seed=seed, ok=False, dsc=0.0, errors={}, mfe=float("nan"), seconds=dt,
                    found=",".join(types))
    errs = param_errors(family, cloud.primitives[0]["params"], best.params)
    ok = best_dsc >= DSC_MIN and all(e <= REL_TOL for e in errs.values())
    return dict(family=family, seed=seed, ok=ok, dsc=best_dsc, errors=errs, mfe=best.mfe, seconds=dt,
                found=",".join(types))


def segment_part(name: str, seed: int, n_points: int, noise: float, families):
    """Generate ``synth.PARTS[name]`` and segment it: (cloud, result, seconds, the Fit4CAD
    measures over its faces, per face too)."""
    import houghcad
    from houghcad import synth
    from houghcad.evaluate import classification_measures

    cloud = synth.PARTS[name](seed=seed, n_points=n_points, noise=noise)
    t = time.perf_counter()
    res = houghcad.segment(cloud.points, families=families, seed=0)
    dt = time.perf_counter() - t
    m = classification_measures([np.asarray(f) for f in res.faces()], cloud.segments(), len(cloud.points),
                                per_segment=True)
    return cloud, res, dt, m


def nearest_face_dsc(name: str, seed: int, n_points: int, noise: float, dense: int = 20) -> float:
    """What labelling every point by its nearest true face gives: the mean DSC when each point of
    ``synth.PARTS[name]`` goes to the face of its nearest point in a noise-free sample of the same
    part ``dense`` times denser (the same shape and pose: the generator's streams are independent).

    On a noisy part this is the reference a segmentation can hope to reach: a point scattered
    across an edge reads as the other face's, whoever labels it. nan when ``noise`` is 0.
    """
    from scipy.spatial import cKDTree

    from houghcad import synth
    from houghcad.evaluate import classification_measures

    if noise <= 0:
        return float("nan")
    cloud = synth.PARTS[name](seed=seed, n_points=n_points, noise=noise)
    clean = synth.PARTS[name](seed=seed, n_points=dense * n_points, noise=0.0)
    faces = clean.segments()
    d = np.stack([cKDTree(clean.points[f]).query(cloud.points)[0] for f in faces], axis=1)
    lab = np.argmin(d, axis=1)
    m = classification_measures([np.flatnonzero(lab == k) for k in range(len(faces))], cloud.segments(),
                                len(cloud.points))
    return float(m["DSC"])


def run_part(args):
    name, seed, n_points, noise = args
    from houghcad.families import REGISTRY

    cloud, res, dt, m = segment_part(name, seed, n_points, noise, "all")
    cplx = [s for s in res.segments if s.type in REGISTRY and REGISTRY[s.type].role == "complex"]
    worst = max(cplx, key=lambda s: s.mfe) if cplx else None
    # MFE is relative to the segment's own bounding-box diagonal, while the noise is relative to the
    # part's: the exact surface fits Gaussian noise to a mean distance of sqrt(2/π) σ, so a small face
    # has that MFE however well it is recognised.
    floor = float("nan")
    if worst is not None:
        floor = np.sqrt(2 / np.pi) * cloud.sigma / float(np.linalg.norm(np.ptp(cloud.points[worst.indices], axis=0)))
    return dict(part=name, seed=seed, noise=noise, dsc=float(m["DSC"]), nearest=nearest_face_dsc(name, seed, n_points, noise),
                max_mfe=worst.mfe if worst is not None else float("nan"), noise_mfe=floor,
                n_complex=len(cplx), seconds=dt, types=",".join(sorted({s.type for s in res.segments})))


#: The composite and parts tables' reference column.
NEAREST_NOTE = ("\"Nearest true face\": the mean DSC when every point goes to the face of its nearest point in a "
                "noise-free sample of the same part, 20 times denser (see `nearest_face_dsc` in `complex.py`). "
                "Noise scatters points across edges, where they read as the other face's: this is what "
                "labelling by the true faces themselves reaches, not a bound no method can pass.")


def _mean_or_dash(xs) -> str:
    xs = [x for x in xs if np.isfinite(x)]
    return f"{np.mean(xs):.3f}" if xs else "—"


def _fmt(x: float) -> str:
    return "—" if not np.isfinite(x) else f"{100 * x:.2f} %"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--instances", type=int, default=20)
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--noise", type=float, default=0.005)
    ap.add_argument("--missing", type=float, default=0.1)
    ap.add_argument("--families", default=None, help="comma-separated complex families (default: all)")
    ap.add_argument("--part-seeds", type=int, default=3)
    ap.add_argument("--part-points", type=int, default=12000)
    ap.add_argument("--part-noise", default="0,0.005",
                    help="comma-separated noise levels (σ / diagonal) for the composite parts; 0 is a sampled "
                         "CAD model, as the paper's composite examples")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    if a.instances == 0 and not a.no_write:
        # The single-family table would be written with no row, over the measured one.
        print("complex.py: --instances 0 runs the composite parts only; add --no-write", file=sys.stderr)
        return 2
    from houghcad import synth

    fams = complex_families() if a.families is None else [f.strip() for f in a.families.split(",") if f.strip()]
    cases = [(f, s, a.points, a.noise, a.missing) for f in fams for s in range(a.instances)]
    parts = [p for p in COMPOSITES if p in synth.PARTS]
    part_noise = [float(x) for x in a.part_noise.split(",") if x.strip()]
    part_cases = [(p, s, a.part_points, nz) for nz in part_noise for p in parts for s in range(a.part_seeds)]
    rows, prow = [], []
    with mp.get_context("spawn").Pool(a.jobs) as pool:
        for r in pool.imap(run_single, cases):
            rows.append(r)
            err = ", ".join(f"{k} {_fmt(v)}" for k, v in r["errors"].items())
            print(f"{r['family']:<22} seed {r['seed']:<3} {'ok ' if r['ok'] else 'MISS'} DSC {r['dsc']:.3f} "
                  f"{err}  MFE {r['mfe']:.4f}  {r['seconds']:.1f} s  [{r['found']}]", file=sys.stderr, flush=True)
        for r in pool.imap(run_part, part_cases):
            prow.append(r)
            print(f"{r['part']:<22} noise {r['noise']:<6} seed {r['seed']:<3} DSC {r['dsc']:.3f} (nearest face {r['nearest']:.3f}) "
                  f"max complex MFE {r['max_mfe']:.4f} "
                  f"{r['seconds']:.1f} s [{r['types']}]", file=sys.stderr, flush=True)

    lines = ["| family | passed | segment DSC ≥ 0.9 | key parameters (median / max rel. error) | "
             "integers exact | max MFE | median s |", "|---|---|---|---|---|---|---|"]
    for f in fams if rows else []:  # --instances 0: parts only
        rs = [r for r in rows if r["family"] == f]
        keys = sorted({k for r in rs for k in r["errors"]} - set(INTEGER_PARAMS))
        per = []
        for k in keys:
            e = np.array([r["errors"][k] for r in rs if k in r["errors"]])
            per.append(f"{k} {_fmt(float(np.median(e)))} / {_fmt(float(e.max()))}" if len(e) else f"{k} —")
        ints = [r["errors"][k] == 0 for r in rs for k in INTEGER_PARAMS if k in r["errors"]]
        mfe = np.array([r["mfe"] for r in rs if np.isfinite(r["mfe"])])
        lines.append(f"| {f} | {sum(r['ok'] for r in rs)}/{len(rs)} | {sum(r['dsc'] >= DSC_MIN for r in rs)}/{len(rs)} | "
                     f"{'; '.join(per) or '—'} | {f'{sum(ints)}/{len(ints)}' if ints else '—'} | "
                     f"{mfe.max() if len(mfe) else float('nan'):.4f} | "
                     f"{np.median([r['seconds'] for r in rs]):.1f} |")
    plines = []
    if prow:
        plines = ["", f"Composite parts: {a.part_points} points, {a.part_seeds} seeds, noise σ per row "
                  "(0: a sampled CAD model, as the paper's composite examples).", "",
                    "The last MFE column is the noise's own MFE on the worst segment's points (√(2/π) σ over its "
                  "bounding-box diagonal): what the exact surface would give there.", "",
                  NEAREST_NOTE, "",
                  "| composite part | noise σ | mean DSC | per seed | nearest true face | max MFE of a complex segment | "
                  "noise's MFE there | median s |",
                  "|---|---|---|---|---|---|---|---|"]
        for nz in part_noise:
            for p in parts:
                rs = [r for r in prow if r["part"] == p and r["noise"] == nz]
                per_seed = ", ".join("%.3f" % r["dsc"] for r in rs)
                fin = [r for r in rs if np.isfinite(r["max_mfe"])]
                w = max(fin, key=lambda r: r["max_mfe"]) if fin else {"max_mfe": float("nan"), "noise_mfe": float("nan")}
                plines.append(f"| {p} | {nz:g} | {np.mean([r['dsc'] for r in rs]):.3f} | {per_seed} | "
                              f"{_mean_or_dash([r['nearest'] for r in rs])} | "
                              f"{w['max_mfe']:.4f} | {w['noise_mfe']:.4f} | {np.median([r['seconds'] for r in rs]):.1f} |")
    summary = []
    if rows:
        summary.append("Passed: " + ", ".join(
            f"{f} {sum(r['ok'] for r in rows if r['family'] == f)}/{sum(r['family'] == f for r in rows)}"
            for f in fams))
    for nz in part_noise if prow else []:
        rs = [r for r in prow if r["noise"] == nz]
        mfe = [r["max_mfe"] for r in rs if np.isfinite(r["max_mfe"])]
        summary.append(f"Composite parts at noise σ {nz:g}: mean DSC "
                       + ", ".join(f"{p} {np.mean([r['dsc'] for r in rs if r['part'] == p]):.3f}" for p in parts)
                       + (f"; max MFE of a complex segment {max(mfe):.4f}" if mfe else ""))
    publish_section("complex", "Complex families (issue 3)", "complex.py", argv, [
        f"- {a.instances} instances per family, {a.points} points, noise σ = {a.noise} × diagonal, "
        f"{a.missing:.0%} of the surface cut away, random pose and scale; `segment(families=\"all\")`.",
        f"- Pass: a segment of the right type with DSC ≥ {DSC_MIN} and key parameters within "
        f"{REL_TOL:.0%} (integers exact). Targets: ≥ 95 % of instances; MFE ≤ 0.01.",
    ], lines + plines, not a.no_write, summary=summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
