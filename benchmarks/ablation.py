#!/usr/bin/env python
"""Ablation: each extension pass switched off, each tolerance at 0.5× and 2× its default.

Usage::

    python benchmarks/ablation.py [--fit4cad DIR] [--jobs 2] [--only PATTERN,...] [--list]
                                  [--no-write] [--max-variants N] [--cache DIR] [--older DIR]
                                  [--report-only]

For every variant it segments the Fit4CAD training clouds (faces scored, as
``benchmarks/fit4cad.py`` does) and a set of synthetic parts (simple parts at noise 0, 0.002 and
0.005, seeds 0-1; the complex composites with all families at noise 0 and 0.005, seeds 0-1). It
reports the change against the baseline of the mean DSC of each of the 5 fixed folds (clouds by
number mod 5), of the overall mean, of the synthetic rows and of the median time per cloud.

A variant is not run on a case its change cannot reach, and the baseline's row stands for it: the
baseline records, for every case, which tolerances and noise-policy switches the run read and which
passes changed the state (:func:`reads_recorded`, :func:`passes_that_change`). A tolerance the run
never read, a policy switch it never consulted or a pass that left the state as it was cannot change
that case's output (the pipeline is deterministic), so the variant's row there is the baseline's.
This is exact, and it replaces hand-kept lists of what is inactive where (those had gone stale:
they called consolidation inactive on Fit4CAD, where it changes 56 clouds). Variants of the
association's tolerances, which no pass before it reads, recognise each case once and run the
association again per variant (:func:`run_association_task`). A variant whose change no Fit4CAD
cloud reads shows ``not read`` on the folds. Measured on commit 619e0ac: of 302 variants, 99 reach
no Fit4CAD cloud and 32 are association-only; the whole study costs about 9 hours on 2 cores
instead of 19.

Each variant's rows are cached in ``benchmarks/results/ablation/<variant>.csv``; a later run only
computes the variants not cached yet (delete a file to recompute it), so the study can be spread
over several sessions. The folder's ``COMMIT`` names the code it was measured on. An earlier study,
on older code, moves to a folder ``benchmarks/results/ablation-<commit>`` (``--older``): the report
takes a variant the current study has not measured from the newest older study that has, against
that study's own baseline, and says so in its ``code`` column. Unless ``--no-write``, the table goes
between the ``<!-- ablation:begin/end -->`` markers of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import csv
import io
import multiprocessing as mp
import pickle
import re
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Callable, Iterator

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
#: Special cases inside the passes, switched off by a tolerance that can no longer be met.
SPECIAL_CASES: tuple[tuple[str, dict[str, float]], ...] = (
    ("aligned_features", {"splitting.aligned_cover": 1.01}),   # cylinders and planes aligned with the neighbours
    ("ransac_fallback", {"splitting.ransac_min_size": 1e9}),  # CGAL's RANSAC on unplaced clusters
    ("slice_gate", {"recognition.slice_sigmas": 1e9, "recognition.slice_taus": 1e9}),  # tangent slices
    ("clean_trimming", {"recognition.clean_trim_rounds": 0}),  # refits on the closer half
    ("beside_top", {"recognition.beside_top_peaks": 0}),  # stacked surfaces' lower peaks
    ("fillet_alignment", {"fillets.aligned_max_deg": 0.5}),  # short cylinders snapped to a plane's normal
    ("facets", {"consolidation.facet_cover": 1.01}),  # loose curves split into exact planes (chamfered edges)
    ("sampling_gaps", {"association.gap_links": 0.0}),  # parts joined across holes in the sampling
)


@dataclass(frozen=True)
class Variant:
    """One configuration: passes skipped and tolerances changed."""

    name: str
    skip: tuple[str, ...] = ()
    tolerances: tuple[tuple[str, float], ...] = ()
    #: Switches of the noise policy turned on for clean clouds (``houghcad.noise.NoisePolicy`` fields).
    clean_policy: tuple[str, ...] = ()

    def reaches(self, reads: frozenset[str]) -> bool:
        """Whether the change can touch a case whose baseline run read ``reads`` (the baseline row's
        ``reads``, from :func:`reads_recorded` and :func:`passes_that_change`): a tolerance or
        switch it read, a pass (or a follow-up of it) that changed the state."""
        keys = {k for k, _ in self.tolerances} | {f"policy.{f}" for f in self.clean_policy}
        if keys & reads:
            return True
        return any(r == f"pass:{p}" or r.startswith(f"pass:{p}.") for p in self.skip for r in reads)

    def association_only(self, reads_before: frozenset[str]) -> bool:
        """Whether only the association (the last pass) can see the change: association tolerances
        that no pass before it read. Such a variant needs no new recognition, only the association
        again on the baseline's segments (``Segmenter.reassociate``)."""
        keys = [k for k, _ in self.tolerances]
        return bool(keys) and not self.skip and not self.clean_policy and \
            all(k.startswith("association.") and k not in reads_before for k in keys)


def variants() -> list[Variant]:
    """The baseline, each extension pass off, each tolerance at 0.5× and 2× (within the bounds a
    tolerance declares: a quantile's 2× is 1)."""
    from houghcad.noise import NoisePolicy
    from houghcad.tolerances import Tolerances

    out = [Variant("baseline")]
    out += [Variant(f"skip-{p}", skip=(p,)) for p in EXTENSION_PASSES]
    out += [Variant(f"off-{name}", tolerances=tuple(tol.items())) for name, tol in SPECIAL_CASES]
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
            least, most = f.metadata.get("least"), f.metadata.get("most")
            for factor in (0.5, 2.0):
                new = v * factor
                new = new if most is None else min(new, most)
                new = new if least is None else max(new, least)
                if isinstance(v, int):
                    new = max(1, int(round(new)))
                if new == v:
                    continue
                out.append(Variant(f"{key}x{factor:g}", tolerances=((key, new),)))
    return out


# ------------------------------------------------------------------------------------- running

from houghcad.noise import CLEAN as _CLEAN  # noqa: E402  (the policy variants start from it)


#: Frames in these files read every field at once (copies, the JSON options, the tolerance list):
#: not a read that steers the run.
_BULK_READERS = ("dataclasses.py", "tolerances.py")


@contextmanager
def reads_recorded() -> Iterator[set[str]]:
    """Record which tolerances (``stage.name``) and noise-policy switches (``policy.name``) the code
    reads while the block runs, in this process.

    The stage classes of :class:`houghcad.tolerances.Tolerances` and
    :class:`houghcad.noise.NoisePolicy` get a ``__getattribute__`` that notes every field read from
    a frame outside :data:`_BULK_READERS`, for the block's duration. A field read in a forked
    worker is not seen: run the block with ``n_jobs=1``.
    """
    from houghcad.noise import NoisePolicy
    from houghcad.tolerances import Tolerances

    t = Tolerances()
    classes = {type(getattr(t, f.name)): f.name for f in fields(t)}
    classes[NoisePolicy] = "policy"
    reads: set[str] = set()
    saved = {}
    for cls, stage in classes.items():
        names = frozenset(f.name for f in fields(cls))

        def getattribute(self, name, _names=names, _stage=stage):
            if name in _names and not sys._getframe(1).f_code.co_filename.endswith(_BULK_READERS):
                reads.add(f"{_stage}.{name}")
            return object.__getattribute__(self, name)

        saved[cls] = cls.__dict__.get("__getattribute__")
        cls.__getattribute__ = getattribute
    try:
        yield reads
    finally:
        for cls, old in saved.items():
            if old is None:
                del cls.__getattribute__
            else:
                cls.__getattribute__ = old


def passes_that_change(changed: set[str], reads: set[str] | None = None,
                       before_association: set[str] | None = None) -> Callable:
    """A ``trace`` callable that adds ``pass:NAME`` to ``changed`` for every pass after which the
    labels or the segment records differ from before it; with ``reads``, it also keeps in
    ``before_association`` what had been read when the passes before the association ended."""
    last: list[bytes] = [b""]

    def trace(step: int, name: str, seg) -> None:
        if reads is not None and before_association is not None and name != "association":
            before_association.clear()
            before_association.update(reads)
        try:
            state = pickle.dumps((np.asarray(seg.labels),
                                  [(r.family.name, r.prim, r.fixed, r.boundary) for r in seg.records]))
        except (pickle.PicklingError, TypeError, AttributeError):
            state = b"unpicklable %d" % step  # cannot tell: count the pass as changing the state
        if state != last[0] and step > 1:
            changed.add(f"pass:{name}")
        last[0] = state

    return trace


def _segment(points: np.ndarray, families: str, v: Variant, record: bool = False):
    """Segment with the variant's change (one process: ``n_jobs=1``, the same output for any
    number); with ``record``, also what the run read and which passes changed the state."""
    import dataclasses

    import houghcad
    from houghcad import noise

    # The clean policy is a module constant read when a run chooses its policy; a variant replaces
    # it for the run, and the constant is put back after it (callers compare policies by identity).
    if v.clean_policy:
        noise.CLEAN = dataclasses.replace(_CLEAN, **{f: True for f in v.clean_policy})
    kw = dict(families=families, seed=0, skip=v.skip, tolerances=dict(v.tolerances), n_jobs=1)
    try:
        if not record:
            return houghcad.segment(points, **kw), None
        changed: set[str] = set()
        before: set[str] = set()
        with reads_recorded() as reads:
            res = houghcad.segment(points, trace=passes_that_change(changed, reads, before), **kw)
        return res, (frozenset(reads | changed), frozenset(before))
    finally:
        noise.CLEAN = _CLEAN


def _case(kind: str, name: str, arg) -> tuple[np.ndarray, list, str]:
    """A case's points, ground-truth segments and families."""
    from houghcad import synth
    from houghcad.evaluate import read_fit4cad_segments
    from houghcad.io import read_points

    if kind == "fit4cad":
        cloud, gt_path = arg
        return read_points(str(cloud)).points, read_fit4cad_segments(gt_path), "simple"
    noise, seed, families = arg
    c = synth.PARTS[name](seed=seed, n_points=12000, noise=noise)
    return c.points, c.segments(), families


def _dsc(res, gt: list, n: int) -> float:
    from houghcad.evaluate import classification_measures

    return float(classification_measures([np.asarray(f) for f in res.faces()], gt, n)["DSC"])


def _failed(v: Variant, kind: str, name: str, arg, exc: Exception) -> dict:
    """A failing case scores 0, like the Fit4CAD benchmark."""
    return dict(variant=v.name, kind=kind, name=name, key=_key(kind, name, arg), dsc=0.0, seconds=float("nan"),
                error=f"{type(exc).__name__}: {exc}")


def run_task(task: tuple) -> dict:
    """One (variant, case): the row {variant, kind, name, key, dsc, seconds}; the baseline's row
    also holds ``reads`` and ``reads_before_association`` (see :meth:`Variant.reaches`)."""
    v, kind, name, arg = task
    try:
        pts, gt, families = _case(kind, name, arg)
        t = time.perf_counter()
        res, reads = _segment(pts, families, v, record=v.name == "baseline")
        dt = time.perf_counter() - t
        row = dict(variant=v.name, kind=kind, name=name, key=_key(kind, name, arg), dsc=_dsc(res, gt, len(pts)),
                   seconds=dt)
        if reads is not None:
            row["reads"], row["reads_before_association"] = (" ".join(sorted(r)) for r in reads)
        return row
    except Exception as exc:  # noqa: BLE001  (one failing case must not stop the study)
        return _failed(v, kind, name, arg, exc)


def run_association_task(task: tuple) -> list[dict]:
    """Association-only variants on one case: the baseline's recognition once, then the
    association again for each (exact: nothing before the association reads their tolerances).
    A row's seconds are the whole run's, with the association's own time its variant's."""
    from houghcad.pipeline import Segmenter

    vs, kind, name, arg = task
    try:
        pts, gt, families = _case(kind, name, arg)
        t = time.perf_counter()
        seg = Segmenter(families=families, seed=0, n_jobs=1).fit(pts)
        before = time.perf_counter() - t - seg.result_.timing.get("association", 0.0)
    except Exception as exc:  # noqa: BLE001
        return [_failed(v, kind, name, arg, exc) for v in vs]
    rows = []
    for v in vs:
        try:
            t = time.perf_counter()
            res = seg.reassociate(association={k.split(".", 1)[1]: x for k, x in v.tolerances})
            rows.append(dict(variant=v.name, kind=kind, name=name, key=_key(kind, name, arg),
                             dsc=_dsc(res, gt, len(pts)), seconds=before + time.perf_counter() - t))
        except Exception as exc:  # noqa: BLE001
            rows.append(_failed(v, kind, name, arg, exc))
    return rows


def _key(kind: str, name: str, arg) -> str:
    if kind == "fit4cad":
        return name
    noise, seed, families = arg
    return f"{name}@{noise:g}#{seed}/{families}"


def tasks(v: Variant, fit4cad: Path) -> list[tuple]:
    out = []
    if fit4cad.is_dir():
        for cloud in sorted(fit4cad.glob("PC*.txt"), key=lambda p: int(re.sub(r"\D", "", p.stem) or 0)):
            if "_" in cloud.stem:
                continue
            out.append((v, "fit4cad", cloud.stem, (cloud, cloud.with_name(cloud.stem + "_primitives.txt"))))
    out += [(v, "parts", p, (nz, s, "simple")) for nz in PART_NOISE for p in SIMPLE_PARTS for s in SEEDS]
    out += [(v, "composites", p, (nz, s, "all")) for nz in COMPOSITE_NOISE for p in COMPOSITES for s in SEEDS]
    return out


COLUMNS = ("variant", "kind", "name", "key", "dsc", "seconds", "error", "reused", "reads", "reads_before_association")


def _read(path: Path) -> list[dict]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r["dsc"] = float(r["dsc"])
        r["seconds"] = float(r["seconds"])
        r["reused"] = r.get("reused") == "1"
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
    if f4 and not all(r.get("reused") for r in f4):
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


@dataclass(frozen=True)
class Study:
    """One ablation study: its variants' rows, measured on one commit's code against its baseline."""

    commit: str
    baseline: list[dict]
    rows: dict[str, list[dict]]

    @classmethod
    def read(cls, cache: Path) -> "Study | None":
        if not (cache / "baseline.csv").exists():
            return None
        commit = (cache / "COMMIT").read_text().strip() if (cache / "COMMIT").exists() else ""
        rows = {p.stem: _read(p) for p in sorted(cache.glob("*.csv"))}
        return cls(commit, rows.pop("baseline"), rows)


def _commit_time(folder: Path) -> int:
    """Commit time (s) of the code a study folder was measured on; 0 when git does not know it."""
    import subprocess

    try:
        commit = (folder / "COMMIT").read_text().strip()
        out = subprocess.run(["git", "log", "-1", "--format=%ct", commit], cwd=REPO, capture_output=True,
                             text=True, check=True).stdout.strip()
        return int(out)
    except (OSError, ValueError, subprocess.CalledProcessError):
        return 0


def older_studies() -> list[Path]:
    """The earlier studies' folders (``benchmarks/results/ablation-*``), newest code first."""
    return sorted(CACHE.parent.glob("ablation-*"), key=lambda p: (_commit_time(p), p.name), reverse=True)


def _baseline_line(study: Study) -> str:
    f4 = [r for r in study.baseline if r["kind"] == "fit4cad"]
    folds = [np.mean([r["dsc"] for r in f4 if int(re.sub(r"\D", "", r["name"])) % FOLDS == k]) for k in range(FOLDS)]
    return (f"`{study.commit[:7]}`: Fit4CAD mean DSC {np.mean([r['dsc'] for r in f4]):.4f}, folds "
            + ", ".join(f"{x:.4f}" for x in folds) + f"; median time {np.median([r['seconds'] for r in f4]):.2f} s.")


def table(studies: list[Study], order: list[Variant]) -> list[str]:
    """The report: each variant from the first study in ``studies`` that measured it, against that
    study's baseline."""
    syn_cols = [f"parts@{nz:g}" for nz in PART_NOISE] + [f"composites@{nz:g}" for nz in COMPOSITE_NOISE]
    source = {v.name: next((st for st in studies if v.name in st.rows), None) for v in order if v.name != "baseline"}
    used = [st for st in studies if any(src is st for src in source.values())]
    lines = ["Baselines, one per study the table draws on (the code each was measured on):", ""]
    lines += [f"- {_baseline_line(st)}" for st in used]
    lines += ["",
              "Changes against the baseline of the variant's study, `code` (DSC in thousandths; time: median "
              "seconds per Fit4CAD cloud, in %; "
              "variants run at different moments on a shared 2-core machine, so only large time changes mean "
              "anything). `not read`: no Fit4CAD cloud's run reads the tolerance or switch, or the pass changes "
              "none (noisy-policy or complex-family code on Fit4CAD's clean `simple` run, for instance); "
              "`runs`: on how many of the 188 clouds the change can act, the others keep the baseline's row.",
              "",
              "| variant | code | runs | fold 0 | fold 1 | fold 2 | fold 3 | fold 4 | mean | time | "
              + " | ".join(syn_cols) + " |",
              "|---|" + "---|" * (9 + len(syn_cols))]
    for v in order:
        study = source.get(v.name)
        if study is None:
            continue
        rows = study.rows[v.name]
        s = summarise(study.baseline, rows)
        if "folds" in s:
            cells = [f"{1000 * d:+.1f}" for d in s["folds"]] + [f"**{1000 * s['mean']:+.1f}**",
                                                                 f"{100 * s['time']:+.0f}%"]
        else:
            cells = ["not read"] * 5 + ["not read", ""]
        f4_rows = [r for r in rows if r["kind"] == "fit4cad"]
        cells.insert(0, str(sum(not r.get("reused") for r in f4_rows)) if f4_rows else "")
        cells.insert(0, f"`{study.commit[:7]}`")
        cells += [f"{1000 * s[c]:+.1f}" if c in s else "" for c in syn_cols]
        lines.append(f"| `{v.name}` | " + " | ".join(cells) + " |")
    return lines


def _run_variants(pool, todo: list[Variant], fit4cad: Path, cache: Path) -> None:
    """Compute and cache the variants of ``todo``: each only on the cases it can reach (the
    baseline's row stands for the others), and those only the association sees in one batch that
    recognises each case once."""
    if not todo:
        return
    base_file = cache / "baseline.csv"
    base = {r["key"]: r for r in _read(base_file)} if base_file.exists() else {}
    recorded = bool(base) and all(r.get("reads_before_association") is not None for r in base.values())
    before = frozenset(k for r in base.values() for k in (r.get("reads_before_association") or "").split())
    batch = [v for v in todo if recorded and v.association_only(before)]
    rows: dict[str, list[dict]] = {v.name: [] for v in todo}
    runs: dict[str, list[tuple]] = {v.name: [] for v in todo}
    per_case: dict[str, tuple[list[Variant], tuple]] = {}
    t0 = time.perf_counter()
    for v in todo:
        for task in tasks(v, fit4cad):
            key = _key(task[1], task[2], task[3])
            b = base.get(key)
            if b is not None and b.get("reads") is not None and not v.reaches(frozenset(b["reads"].split())):
                rows[v.name].append(dict(b, variant=v.name, reused="1", reads="", reads_before_association=""))
            elif v in batch:
                per_case.setdefault(key, ([], task[1:]))[0].append(v)
            else:
                runs[v.name].append(task)
    if per_case:
        for out in pool.imap(run_association_task, [(tuple(vs), *rest) for vs, rest in per_case.values()]):
            for r in out:
                rows[r["variant"]].append(r)
        print(f"{len(batch)} association-only variants: {len(per_case)} cases recognised once, "
              f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for v in batch:
        _write(cache / f"{v.name}.csv", rows[v.name])
    # The rest one by one: the passes, special cases and policy switches first (what the study may
    # delete or switch on), then the tolerances; within each, those reaching the fewest cases first,
    # so that a study cut short has measured the most variants.
    rest = sorted((v for v in todo if v not in batch),
                  key=lambda v: (not (v.skip or v.clean_policy or v.name.startswith("off-")), len(runs[v.name])))
    for v in rest:
        t = time.perf_counter()
        mine = runs[v.name]
        rows[v.name] += list(pool.imap(run_task, mine, chunksize=1))
        _write(cache / f"{v.name}.csv", rows[v.name])
        print(f"{v.name}: {len(mine)} cases run, {len(rows[v.name]) - len(mine)} kept from the baseline "
              f"(not reached), {time.perf_counter() - t:.0f} s", file=sys.stderr, flush=True)


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
    ap.add_argument("--older", type=Path, action="append", default=None,
                    help="an earlier study's folder, for the variants --cache lacks (repeatable; default: "
                         "benchmarks/results/ablation-*, newest first)")
    a = ap.parse_args(argv)
    if not (a.list or a.report_only or a.fit4cad.is_dir()):
        # Without the clouds every variant would be measured on the synthetic cases alone, and
        # its cached rows would read as if no Fit4CAD cloud could change.
        print(f"ablation.py: no Fit4CAD folder at {a.fit4cad}; give it with --fit4cad", file=sys.stderr)
        return 2
    order = variants()
    cache = a.cache
    older = older_studies() if a.older is None else a.older
    cache.mkdir(parents=True, exist_ok=True)
    commit_file = cache / "COMMIT"
    if not commit_file.exists():  # the code the cached variants were measured on
        commit_file.write_text(_head() + "\n")
    if a.list:
        measured = [st for st in map(Study.read, older) if st is not None]
        for v in order:
            where = "cached " if (cache / f"{v.name}.csv").exists() else \
                next((f"{st.commit[:7]}" for st in measured if v.name in st.rows), "       ")
            print(f"{where} {v.name}")
        return 0
    todo = [v for v in order if v.name == "baseline" or not a.only or
            any(re.search(p, v.name) for p in a.only.split(","))]
    todo = [v for v in todo if not (cache / f"{v.name}.csv").exists()] if not a.report_only else []
    if a.max_variants is not None:
        todo = todo[: a.max_variants + (1 if todo and todo[0].name == "baseline" else 0)]
    with mp.get_context("spawn").Pool(a.jobs, maxtasksperchild=40) as pool:
        if todo and todo[0].name == "baseline":
            _run_variants(pool, todo[:1], a.fit4cad, cache)
            todo = todo[1:]
        _run_variants(pool, todo, a.fit4cad, cache)
    studies = [st for st in map(Study.read, [cache, *older]) if st is not None]
    if not (cache / "baseline.csv").exists():
        print("no baseline yet", file=sys.stderr)
        return 1
    lines = table(studies, order)
    print("\n".join(lines))
    if not a.no_write:
        sys.path.insert(0, str(REPO / "benchmarks"))
        from fit4cad import publish_section

        names = [v.name for v in order if v.name != "baseline"]
        per = [(st.commit[:10], sum(n in st.rows and all(n not in o.rows for o in studies[:i])
                                   for n in names)) for i, st in enumerate(studies)]
        measured = sum(k for _, k in per)
        publish_section("ablation", "Ablation", "ablation.py", argv, [
            f"- {measured} of {len(names)} variants measured: "
            + ", ".join(f"{k} on the code of commit `{c}`" for c, k in per if k)
            + "; `python benchmarks/ablation.py --list` lists them. Each study has its own baseline (below); "
            "a variant is reported from the newest study that measured it. Each variant: the 188 Fit4CAD "
            "training clouds (`simple`, faces scored) and the synthetic parts "
            "(seeds 0-1, 12000 points), run only on the cases whose baseline run read what the variant changes "
            "(a tolerance, a noise-policy switch) or where the pass it skips changed the state; the other cases "
            "keep the baseline's row, exactly (the script's docstring). Cheapest variants first, the passes, "
            "special cases and policy switches before the tolerances.",
            "- The `resolution` tolerances serve clouds above 100,000 points (recognised on a subsample), which "
            "no case here reaches: `benchmarks/scale.py` measures that path.",
        ], lines, True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
