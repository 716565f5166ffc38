"""Tests of benchmarks/ablation.py: what a run reads decides where a variant can act."""

from __future__ import annotations

import importlib
import sys
from dataclasses import fields
from pathlib import Path

import pytest

from houghcad import noise, synth
from houghcad.noise import NoisePolicy
from houghcad.tolerances import RecognitionTolerances, Tolerances

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
if str(_BENCH) not in sys.path:
    sys.path.insert(0, str(_BENCH))
ablation = importlib.import_module("ablation")
fingerprint = importlib.import_module("fingerprint").fingerprint


@pytest.fixture(scope="module")
def clean_block():
    """A clean block and its baseline run with what it read."""
    cloud = synth.block_with_hole_and_slot(seed=0, n_points=3000)
    res, reads = ablation._segment(cloud.points, "simple", ablation.Variant("baseline"), record=True)
    return cloud, res, reads


def test_reads_records_fields_read_outside_bulk_copies():
    with ablation.reads_recorded() as reads:
        t = Tolerances()
        t.to_dict()                      # the JSON options read every field: not a read
        _ = t.recognition.refit_points  # a read from here counts
        _ = NoisePolicy("clean", *([False] * (len(fields(NoisePolicy)) - 1))).nearest_edges
    assert reads == {"recognition.refit_points", "policy.nearest_edges"}
    # The classes are as they were after the block.
    assert "__getattribute__" not in RecognitionTolerances.__dict__
    assert "__getattribute__" not in NoisePolicy.__dict__


def test_policy_variant_leaves_the_clean_policy_as_it_was():
    clean = noise.CLEAN
    cloud = synth.block_with_hole_and_slot(seed=0, n_points=1500)
    ablation._segment(cloud.points, "simple", ablation.Variant("x", clean_policy=("strict_cover",)))
    assert noise.CLEAN is clean and noise.choose("clean", 0.0, 1.0) is clean


def test_variant_not_reached_gives_the_baseline_output(clean_block):
    cloud, res, (reads, _) = clean_block
    variants = {v.name: v for v in ablation.variants()}
    # The wide removal threshold is the noisy policy's: a clean cloud never reads it.
    quiet = variants["scale.noisy_epsilon_tausx2"]
    assert not quiet.reaches(reads)
    again, _ = ablation._segment(cloud.points, "simple", quiet)
    assert fingerprint(again) == fingerprint(res)
    # The inlier distance is read by every run, and doubling it changes this cloud's output.
    loud = variants["scale.tau_spacingsx2"]
    assert loud.reaches(reads)
    other, _ = ablation._segment(cloud.points, "simple", loud)
    assert fingerprint(other) != fingerprint(res)


def test_passes_that_change_the_state(clean_block):
    _, _, (reads, _) = clean_block
    changed = {r for r in reads if r.startswith("pass:")}
    # Association always rewrites the records (maximal primitives); the noisy-policy passes never run.
    assert "pass:association" in changed
    assert not {"pass:revisit_poor_fits", "pass:settle_noisy_edges"} & changed
    assert ablation.Variant("x", skip=("consolidation",)).reaches(frozenset({"pass:consolidation.absorb"}))
    assert not ablation.Variant("x", skip=("revisit_poor_fits",)).reaches(frozenset(changed))


def test_association_only_variant_matches_a_whole_run(clean_block):
    _, _, (_, before) = clean_block
    variants = {v.name: v for v in ablation.variants()}
    v = variants["association.verify_tausx2"]
    assert v.association_only(before)            # only the association reads it
    assert not variants["scale.tau_spacingsx2"].association_only(before)
    task = ((v,), "parts", "block_with_hole_and_slot", (0.0, 0, "simple"))
    (row,) = ablation.run_association_task(task)
    whole = ablation.run_task((v, "parts", "block_with_hole_and_slot", (0.0, 0, "simple")))
    assert row["dsc"] == whole["dsc"] and not row.get("error")


def _study(folder: Path, commit: str, dscs: dict[str, list[float]]) -> Path:
    """A cached study: per variant, the DSC of Fit4CAD clouds PC0..PC4 (one per fold)."""
    folder.mkdir()
    (folder / "COMMIT").write_text(commit + "\n")
    for name, values in dscs.items():
        rows = [dict(variant=name, kind="fit4cad", name=f"PC{i}", key=f"PC{i}", dsc=d, seconds=1.0)
                for i, d in enumerate(values)]
        ablation._write(folder / f"{name}.csv", rows)
    return folder


def test_report_takes_each_variant_from_the_newest_study_against_its_own_baseline(tmp_path):
    new = _study(tmp_path / "new", "a" * 40, {"baseline": [0.9] * 5, "skip-fillets": [0.8] * 5})
    old = _study(tmp_path / "old", "b" * 40, {"baseline": [0.5] * 5, "skip-fillets": [0.1] * 5,
                                              "skip-refine": [0.6] * 5})
    studies = [ablation.Study.read(new), ablation.Study.read(old)]
    order = [ablation.Variant("baseline"), ablation.Variant("skip-fillets", skip=("fillets",)),
             ablation.Variant("skip-refine", skip=("refine",)), ablation.Variant("skip-consolidation")]
    rows = {line.split(" | ")[0]: line for line in ablation.table(studies, order) if line.startswith("| `")}
    assert set(rows) == {"| `skip-fillets`", "| `skip-refine`"}   # unmeasured variants are left out
    assert "`aaaaaaa`" in rows["| `skip-fillets`"] and "**-100.0**" in rows["| `skip-fillets`"]
    assert "`bbbbbbb`" in rows["| `skip-refine`"] and "**+100.0**" in rows["| `skip-refine`"]
