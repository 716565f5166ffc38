#!/usr/bin/env python
"""Ablation: each extension pass switched off, each tolerance at 0.5× and 2× its default.

Usage::

    python benchmarks/ablation.py [--fit4cad DIR] [--jobs 2] [--only PATTERN,...] [--list]
                                  [--no-write] [--max-variants N]

For every variant it segments the Fit4CAD training clouds (faces scored, as
``benchmarks/fit4cad.py`` does) and a set of synthetic parts (simple parts at noise 0, 0.002 and
0.005, seeds 0-1; the complex composites with all families at noise 0 and 0.005, seeds 0-1). It
reports the change against the baseline of the mean DSC of each of the 5 fixed folds (clouds by
number mod 5), of the overall mean, of the synthetic rows and of the median time per cloud.

Variants whose change cannot reach a cloud are not run there: the tolerances and passes that only
the noisy policy reads are not run on Fit4CAD (every training cloud reads clean), and those only
complex families read are not run on Fit4CAD's ``simple`` run. Such cells read ``inactive``.

Each variant's rows are cached in ``benchmarks/results/ablation/<variant>.csv``; a later run only
computes the variants not cached yet (delete a file to recompute it), so the study can be spread
over several sessions. Unless ``--no-write``, the table goes between the ``<!-- ablation:begin/end
-->`` markers of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import csv
import io
import multiprocessing as mp
import re
import sys
import time
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "benchmarks" / "results" / "ablation"
DEFAULT_FIT4CAD = REPO.parent / "shared" / "fit4cad" / "training_set"
FOLDS = 5
SIMPLE_PARTS = ("block_with_hole_and_slot", "plate_with_holes", "shaft_with_groove", "mirrored_cones",
                "gear_like", "filleted_block")
COMPOSITES = ("screw_part", "generalized_cone_part", "ellipsoid_part")
PART_NOISE = (0.0, 0.002, 0.005)
COMPOSITE_NOISE = (0.0, 0.005)
SEEDS = (0, 1)
#: Extension passes (paper passes and association are not ablated).
EXTENSION_PASSES = ("recognition.absorb", "consolidation", "consolidation.absorb", "dissolve_redundant",
                    "settle_edges", "settle_noisy_edges", "revisit_poor_fits", "fillets", "prefer_planes", "refine")
#: Passes that run only under the noisy policy, or only do something with complex families:
#: inactive on Fit4CAD's clean clouds segmented with the simple families.
NOT_ON_FIT4CAD_PASSES = {"settle_noisy_edges", "revisit_poor_fits", "fillets", "prefer_planes", "consolidation",
                         "consolidation.absorb", "refine"}
#: Tolerances read only under the noisy policy or by complex families / consolidation (inactive
#: on Fit4CAD simple): whole stages, then single fields.
NOT_ON_FIT4CAD_STAGES = {"fillets", "consolidation", "adjacency"}
NOT_ON_FIT4CAD_FIELDS = {
    "recognition.noisy_trim_rounds", "recognition.trim_sigmas", "recognition.compete_sigmas",
    "recognition.noise_mean_sigmas", "recognition.noise_floor_size", "recognition.noise_floor_se",
    "recognition.noise_floor_least", "recognition.complex_max_peaks", "recognition.beside_top_peaks",
    "recognition.beside_top_persistence", "recognition.covers_size", "recognition.covers_mfe",
    "recognition.complex_wins_mfe", "recognition.complex_wins_abs",
    "boundaries.noisy_rounds", "boundaries.side_links", "boundaries.side_majority", "boundaries.sound_fit",
}


#: Special cases inside the passes, switched off by a tolerance that can no longer be met.
SPECIAL_CASES: tuple[tuple[str, dict[str, float], bool], ...] = (
    ("aligned_features", {"splitting.aligned_cover": 1.01}, True),   # cylinders and planes aligned with the neighbours
    ("ransac_fallback", {"splitting.ransac_min_size": 1e9}, True),  # CGAL's RANSAC on unplaced clusters
    ("strip_rows", {"recognition.strip_min_points": 10 ** 9}, True),  # one-row strips of narrow faces
    ("slice_gate", {"recognition.slice_sigmas": 1e9, "recognition.slice_taus": 1e9}, True),  # tangent slices
    ("clean_trimming", {"recognition.clean_trim_rounds": 0}, True),  # refits on the closer half
    ("beside_top", {"recognition.beside_top_peaks": 0}, False),  # stacked surfaces' lower peaks
    ("fillet_alignment", {"fillets.aligned_max_deg": 0.5}, False),  # short cylinders snapped to a plane's normal
)


@dataclass(frozen=True)
class Variant:
    """One configuration: passes skipped and tolerances changed."""

    name: str
    skip: tuple[str, ...] = ()
    tolerances: tuple[tuple[str, float], ...] = ()
    on_fit4cad: bool = True
    #: Switches of the noise policy turned on for clean clouds (``houghcad.noise.NoisePolicy`` fields).
    clean_policy: tuple[str, ...] = ()


def variants() -> list[Variant]:
    """The baseline, each extension pass off, each tolerance at 0.5× and 2×."""
    from houghcad.noise import NoisePolicy
    from houghcad.tolerances import Tolerances

    out = [Variant("baseline")]
    out += [Variant(f"skip-{p}", skip=(p,), on_fit4cad=p not in NOT_ON_FIT4CAD_PASSES) for p in EXTENSION_PASSES]
    out += [Variant(f"off-{name}", tolerances=tuple(tol.items()), on_fit4cad=active)
            for name, tol, active in SPECIAL_CASES]
    # Each behaviour the noisy policy adds, tried on clean clouds too.
    out += [Variant(f"clean+{f.name}", clean_policy=(f.name,)) for f in fields(NoisePolicy) if f.type in (bool, "bool")]
    t = Tolerances()
    for stage in fields(t):
        group = getattr(t, stage.name)
        for f in fields(group):
            v = getattr(group, f.name)
            if v is None or isinstance(v, bool):
                continue
            key = f"{stage.name}.{f.name}"
            active = stage.name not in NOT_ON_FIT4CAD_STAGES and key not in NOT_ON_FIT4CAD_FIELDS
            for factor in (0.5, 2.0):
                new = v * factor
                if isinstance(v, int):
                    new = max(1, int(round(new)))
                    if new == v:
                        continue
                out.append(Variant(f"{key}x{factor:g}", tolerances=((key, new),), on_fit4cad=active))
    return out


# ------------------------------------------------------------------------------------- running

from houghcad.noise import CLEAN as _CLEAN  # noqa: E402  (the policy variants start from it)


def _segment(points: np.ndarray, families: str, v: Variant):
    import dataclasses

    import houghcad
    from houghcad import noise

    # The clean policy is a module constant read when a run chooses its policy; a variant replaces
    # it in this worker process for the run.
    noise.CLEAN = dataclasses.replace(_CLEAN, **{f: True for f in v.clean_policy})
    return houghcad.segment(points, families=families, seed=0, skip=v.skip, tolerances=dict(v.tolerances))


def run_task(task: tuple) -> dict:
    """One (variant, case): the row {variant, kind, name, fold/noise, dsc, seconds}."""
    from houghcad import synth
    from houghcad.evaluate import classification_measures, read_fit4cad_segments
    from houghcad.io import read_points

    v, kind, name, arg = task
    try:
        if kind == "fit4cad":
            cloud, gt_path = arg
            pts = read_points(str(cloud)).points
            gt = read_fit4cad_segments(gt_path)
            families = "simple"
        else:
            noise, seed, families = arg
            c = synth.PARTS[name](seed=seed, n_points=12000, noise=noise)
            pts, gt = c.points, c.segments()
        t = time.perf_counter()
        res = _segment(pts, families, v)
        dt = time.perf_counter() - t
        dsc = classification_measures([np.asarray(f) for f in res.faces()], gt, len(pts))["DSC"]
        return dict(variant=v.name, kind=kind, name=name, key=_key(kind, name, arg), dsc=float(dsc), seconds=dt)
    except Exception as exc:  # a failing case scores 0, like the Fit4CAD benchmark
        return dict(variant=v.name, kind=kind, name=name, key=_key(kind, name, arg), dsc=0.0, seconds=float("nan"),
                    error=f"{type(exc).__name__}: {exc}")


def _key(kind: str, name: str, arg) -> str:
    if kind == "fit4cad":
        return name
    noise, seed, families = arg
    return f"{name}@{noise:g}#{seed}/{families}"


def tasks(v: Variant, fit4cad: Path) -> list[tuple]:
    out = []
    if v.on_fit4cad and fit4cad.is_dir():
        for cloud in sorted(fit4cad.glob("PC*.txt"), key=lambda p: int(re.sub(r"\D", "", p.stem) or 0)):
            if "_" in cloud.stem:
                continue
            out.append((v, "fit4cad", cloud.stem, (cloud, cloud.with_name(cloud.stem + "_primitives.txt"))))
    out += [(v, "parts", p, (nz, s, "simple")) for nz in PART_NOISE for p in SIMPLE_PARTS for s in SEEDS]
    out += [(v, "composites", p, (nz, s, "all")) for nz in COMPOSITE_NOISE for p in COMPOSITES for s in SEEDS]
    return out


COLUMNS = ("variant", "kind", "name", "key", "dsc", "seconds", "error")


def _read(path: Path) -> list[dict]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r["dsc"] = float(r["dsc"])
        r["seconds"] = float(r["seconds"])
    return rows


def _write(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in COLUMNS})
    tmp = path.with_suffix(".tmp")
    tmp.write_text(buf.getvalue())
    tmp.replace(path)


# ------------------------------------------------------------------------------------- report

def _head() -> str:
    """The repository's current commit (empty outside a git checkout)."""
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def summarise(base: list[dict], rows: list[dict]) -> dict:
    """Changes of a variant against the baseline: per fold, overall, synthetic rows, time."""
    b = {r["key"]: r for r in base}
    out: dict = {}
    f4 = [r for r in rows if r["kind"] == "fit4cad"]
    if f4:
        deltas = {}
        for r in f4:
            k = int(re.sub(r"\D", "", r["name"])) % FOLDS
            deltas.setdefault(k, []).append(r["dsc"] - b[r["key"]]["dsc"])
        out["folds"] = [float(np.mean(deltas.get(k, [np.nan]))) for k in range(FOLDS)]
        out["mean"] = float(np.mean([d for v in deltas.values() for d in v]))
        t_var = np.nanmedian([r["seconds"] for r in f4])
        t_base = np.nanmedian([b[r["key"]]["seconds"] for r in f4])
        out["time"] = float(t_var / t_base - 1.0)
    for kind, levels in (("parts", PART_NOISE), ("composites", COMPOSITE_NOISE)):
        for nz in levels:
            sel = [r for r in rows if r["kind"] == kind and f"@{nz:g}#" in r["key"]]
            if sel:
                out[f"{kind}@{nz:g}"] = float(np.mean([r["dsc"] - b[r["key"]]["dsc"] for r in sel]))
    return out


def table(results: dict[str, list[dict]], order: list[Variant]) -> list[str]:
    base = results["baseline"]
    f4 = [r for r in base if r["kind"] == "fit4cad"]
    folds = [np.mean([r["dsc"] for r in f4 if int(re.sub(r"\D", "", r["name"])) % FOLDS == k]) for k in range(FOLDS)]
    syn_cols = [f"parts@{nz:g}" for nz in PART_NOISE] + [f"composites@{nz:g}" for nz in COMPOSITE_NOISE]
    lines = [f"Baseline: Fit4CAD mean DSC {np.mean([r['dsc'] for r in f4]):.4f}, folds "
             + ", ".join(f"{x:.4f}" for x in folds) + f"; median time {np.median([r['seconds'] for r in f4]):.2f} s.",
             "",
             "Changes against the baseline (DSC in thousandths; time: median seconds per Fit4CAD cloud, in %; "
             "variants run at different moments on a shared 2-core machine, so only large time changes mean "
             "anything). `inactive`: the variant cannot reach those clouds (noisy-policy or complex-family code "
             "on Fit4CAD's clean `simple` run).",
             "",
             "| variant | fold 0 | fold 1 | fold 2 | fold 3 | fold 4 | mean | time | "
             + " | ".join(syn_cols) + " |",
             "|---|" + "---|" * (7 + len(syn_cols))]
    for v in order:
        if v.name == "baseline" or v.name not in results:
            continue
        s = summarise(base, results[v.name])
        if "folds" in s:
            cells = [f"{1000 * d:+.1f}" for d in s["folds"]] + [f"**{1000 * s['mean']:+.1f}**",
                                                                 f"{100 * s['time']:+.0f}%"]
        else:
            cells = ["inactive"] * 5 + ["inactive", ""]
        cells += [f"{1000 * s[c]:+.1f}" if c in s else "" for c in syn_cols]
        lines.append(f"| `{v.name}` | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fit4cad", type=Path, default=DEFAULT_FIT4CAD)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", default=None, help="comma-separated regular expressions on variant names")
    ap.add_argument("--max-variants", type=int, default=None, help="compute at most N uncached variants")
    ap.add_argument("--list", action="store_true", help="list the variants and whether they are cached")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--cache", type=Path, default=CACHE, help="folder of the per-variant CSVs (default %(default)s)")
    ap.add_argument("--report-only", action="store_true", help="compute nothing: the table of the cached variants")
    a = ap.parse_args(argv)
    order = variants()
    cache = a.cache
    cache.mkdir(parents=True, exist_ok=True)
    commit_file = cache / "COMMIT"
    if not commit_file.exists():  # the code the cached variants were measured on
        commit_file.write_text(_head() + "\n")
    if a.list:
        for v in order:
            print(f"{'cached ' if (cache / f'{v.name}.csv').exists() else '       '}{v.name}"
                  f"{'' if v.on_fit4cad else '  (synthetic only)'}")
        return 0
    todo = [v for v in order if v.name == "baseline" or not a.only or
            any(re.search(p, v.name) for p in a.only.split(","))]
    todo = [v for v in todo if not (cache / f"{v.name}.csv").exists()] if not a.report_only else []
    if a.max_variants is not None:
        todo = todo[: a.max_variants + (1 if todo and todo[0].name == "baseline" else 0)]
    with mp.get_context("spawn").Pool(a.jobs, maxtasksperchild=40) as pool:
        for v in todo:
            t0 = time.perf_counter()
            rows = list(pool.imap(run_task, tasks(v, a.fit4cad), chunksize=1))
            _write(cache / f"{v.name}.csv", rows)
            print(f"{v.name}: {len(rows)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    results = {v.name: _read(cache / f"{v.name}.csv") for v in order if (cache / f"{v.name}.csv").exists()}
    if "baseline" not in results:
        print("no baseline yet", file=sys.stderr)
        return 1
    lines = table(results, order)
    print("\n".join(lines))
    if not a.no_write:
        sys.path.insert(0, str(REPO / "benchmarks"))
        from fit4cad import publish_section

        measured = sum(v.name in results for v in order) - 1
        publish_section("ablation", "Ablation", "ablation.py", argv, [
            f"- {measured} of {len(order) - 1} variants measured, on the code of commit "
            f"`{commit_file.read_text().strip()[:10]}`; `python benchmarks/ablation.py --list` lists them. "
            "Each variant: the 188 Fit4CAD training clouds (`simple`, faces scored) and the synthetic parts "
            "(seeds 0-1, 12000 points).",
        ], lines, True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
