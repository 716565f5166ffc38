"""The declared passes: order, timing by name, tracing, and each pass alone on a small case."""

from __future__ import annotations

import numpy as np
import pytest

import houghcad
from _helpers import state_before
from houghcad import synth
from houghcad.passes import EXTENSION, PAPER_5_2, PAPER_5_3, PAPER_5_4, Pass, Run
from houghcad.pipeline import PIPELINE, pass_names
from houghcad.associate import Associator
from houghcad.families import select
from houghcad.state import Segmentation


@pytest.fixture(scope="module")
def clean_part():
    return synth.block_with_hole_and_slot(seed=1, n_points=2500)


@pytest.fixture(scope="module")
def noisy_part():
    return synth.block_with_hole_and_slot(seed=1, n_points=2500, noise=0.005)


def test_the_pipeline_reads_like_the_paper():
    sources = [p.source for p in PIPELINE]
    assert [p.name for p in PIPELINE[:2]] == ["recognition", "splitting"]
    assert sources[:2] == [PAPER_5_2, PAPER_5_3] and sources[-1] == PAPER_5_4
    assert set(sources[2:-1]) == {EXTENSION}
    names = [p.name for p in PIPELINE]
    assert len(set(names)) == len(names)


def test_timing_gives_every_pass_that_ran_by_name(clean_part, noisy_part):
    declared = set(pass_names())
    for cloud, noisy in ((clean_part, False), (noisy_part, True)):
        steps: list[str] = []
        res = houghcad.segment(cloud.points, trace=lambda step, name, seg: steps.append(name))
        assert set(steps) <= declared
        assert [k for k in res.timing if k in declared] == steps
        assert all(res.timing[k] >= 0 for k in steps)
        assert res.timing["total"] == pytest.approx(sum(v for k, v in res.timing.items() if k != "total"))
        assert ("settle_edges" in steps) != noisy and ("settle_noisy_edges" in steps) == noisy
        assert steps[0] == "recognition" and steps[-1] == "association"


def test_trace_sees_the_state_after_each_pass_in_order(clean_part):
    seen: list[tuple[int, str, Segmentation]] = []
    res = houghcad.segment(clean_part.points, trace=lambda step, name, seg: seen.append((step, name, seg.copy())))
    assert [s for s, _, _ in seen] == list(range(1, len(seen) + 1))
    for _, _, seg in seen:
        seg.check()
    final = seen[-1][2]
    assert sorted(map(len, (final.indices(k) for k in range(len(final))))) == \
        sorted(len(s.indices) for s in res.segments)
    np.testing.assert_array_equal(np.flatnonzero(final.free), res.unsegmented)


def _pass(name: str) -> Pass:
    return next(p for p in PIPELINE if p.name == name)


@pytest.mark.parametrize("name", [p.name for p in PIPELINE])
def test_each_pass_alone_keeps_the_state_consistent_and_is_deterministic(name, clean_part, noisy_part):
    p = _pass(name)
    fams = select("simple")
    ran = 0
    for cloud in (clean_part, noisy_part):
        before, ctx = state_before(cloud.points, name, seed=0)
        if not p.when(ctx):
            assert before is None
            continue
        ran += 1
        outs = [p.run(before.copy(), Run(ctx, fams, fams, Associator())) for _ in range(2)]
        for out in outs:
            out.check()
        np.testing.assert_array_equal(outs[0].labels, outs[1].labels)
        assert [r.family.name for r in outs[0].records] == [r.family.name for r in outs[1].records]
        if name == "recognition":
            assert len(before) == 0 and len(outs[0]) >= 3  # the block's big faces
        if name == "association":
            assert outs[0].parts is not None and len(outs[0]) <= len(before)
    assert ran >= 1


def test_a_follow_up_runs_only_when_its_pass_changed_the_state(noisy_part):
    # On this noisy part no segment is fitted worse than the noise after the
    # edges settle: revisit_poor_fits changes nothing and its follow-ups do not run.
    steps: list[str] = []
    houghcad.segment(noisy_part.points, trace=lambda step, name, seg: steps.append(name))
    assert "revisit_poor_fits" in steps
    follow = [s for s in steps if s.startswith("revisit_poor_fits.")]
    assert follow in ([], ["revisit_poor_fits.absorb", "revisit_poor_fits.settle_noisy_edges"])


def test_skipped_passes_do_not_run_and_unknown_ones_are_refused(noisy_part):
    steps: list[str] = []
    houghcad.segment(noisy_part.points, skip=("fillets", "consolidation.absorb"),
                     trace=lambda step, name, seg: steps.append(name))
    assert "fillets" not in steps and not any(s.startswith("fillets.") for s in steps)
    assert "consolidation" in steps and "consolidation.absorb" not in steps
    with pytest.raises(houghcad.InputError, match="unknown pass 'filets'"):
        houghcad.segment(noisy_part.points, skip=("filets",))
    # One pass's name alone is that pass, in the run and in the result's record.
    steps.clear()
    res = houghcad.segment(noisy_part.points, skip="fillets", trace=lambda step, name, seg: steps.append(name))
    assert "fillets" not in steps and res.options["skip"] == ["fillets"]
