"""Named tolerances: fields with unit and reason, settable, recorded, documented."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import pytest

import houghcad
from houghcad import synth
from houghcad.tolerances import Tolerances, markdown

DOCS = Path(__file__).resolve().parents[1] / "docs" / "tolerances.md"


@pytest.fixture(scope="module")
def part():
    return synth.block_with_hole_and_slot(seed=1, n_points=2500)


def test_every_tolerance_has_a_unit_and_a_reason():
    for stage in fields(Tolerances):
        for f in fields(stage.default_factory()):
            assert f.metadata.get("unit") and f.metadata.get("why"), f"{stage.name}.{f.name}"


def test_round_trip_through_a_dict():
    t = Tolerances().updated({"recognition": {"keep_share": 0.55}, "fillets.lr_min": 30})
    assert t.recognition.keep_share == 0.55 and t.fillets.lr_min == 30.0
    assert Tolerances.from_dict(t.to_dict()) == t
    assert t.changed() == {"recognition.keep_share": 0.55, "fillets.lr_min": 30.0}
    assert Tolerances().changed() == {}


@pytest.mark.parametrize("bad, message", [
    ({"recognize": {"keep_share": 0.5}}, "unknown tolerance stage 'recognize'"),
    ({"recognition": {"keep": 0.5}}, "unknown tolerance recognition.keep"),
    ({"recognition.keep_share": "half"}, "must be a number"),
    ({"splitting.max_rounds": 2.5}, "whole number"),
    ({"recognition.keep_share": float("nan")}, "finite"),
    ({"recognition.keep_share": None}, "cannot be None"),
    ({"recognition": 0.5}, "stage's dict"),
    ({"recognition.neighbours": 0}, "must be positive"),  # these broke the run deep inside
    ({"association.length_tol": 0.0}, "must be positive"),
    ({"association.angle_tol": -1}, "must be positive"),
    ({"recognition.refit_points": -1}, "must be positive"),
    ({"scale.min_points_floor": 1}, "at least 2"),
    ({"fillets.extent_quantile": 1.5}, "at most 1"),
    ({"recognition.keep_share": 7}, "at most 1"),  # a share above 1 left every point unsegmented
    ({"scale.first_round_share": 1.01}, "at most 1"),
])
def test_bad_tolerances_are_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        Tolerances.from_dict(bad)


def test_every_share_is_bounded_by_one():
    for f in fields(Tolerances):
        for g in fields(f.default_factory()):
            if g.metadata["unit"].startswith("share"):
                assert g.metadata["most"] == 1.0, f"{f.name}.{g.name}"


def test_bad_tolerances_give_an_input_error(part):
    with pytest.raises(houghcad.InputError, match="tolerances: unknown tolerance recognition.keep"):
        houghcad.segment(part.points, tolerances={"recognition": {"keep": 0.5}})


def test_the_run_records_its_tolerances_and_scales_in_the_json(part):
    res = houghcad.segment(part.points, tolerances={"scale": {"tau_spacings": 0.2}}, association={"contact": 0.5})
    opts = json.loads(res.to_json())["options"]
    t = Tolerances.from_dict(opts["tolerances"])
    assert t.changed() == {"scale.tau_spacings": 0.2, "association.contact": 0.5}
    d = opts["derived"]
    assert d["noise_policy"] == "clean" and d["tau"] > 0 and d["epsilon"] >= d["tau"] and d["spacing"] > 0
    # A clean sample: τ is 0.2 spacings here, not the default 0.1.
    assert d["tau"] == pytest.approx(0.2 * d["spacing"], rel=1e-9)


def test_a_tolerance_changes_what_the_run_does(part):
    base = houghcad.segment(part.points)
    big = houghcad.segment(part.points, tolerances={"scale": {"min_points_floor": 400}})
    assert min(len(s.indices) for s in big.segments) >= 400
    assert len(big.segments) < len(base.segments)


def test_docs_list_every_tolerance():
    assert DOCS.read_text() == markdown(), "regenerate: python -m houghcad.tolerances > docs/tolerances.md"


def test_the_smallest_segment_is_a_size_on_the_part():
    """The default smallest segment is a patch ``min_face_diagonals`` wide at the cloud's density:
    the same patch on the part whatever the sampling, so its points grow with the density."""
    from houghcad.context import derive_context, points_in_patch
    from houghcad.noise import CLEAN
    from houghcad.preprocess import preprocess

    t = Tolerances()
    sizes = {}
    for n in (4_000, 60_000, 240_000):
        pre = preprocess(synth.gear_like(seed=0, n_points=n).points, workers=2)
        ctx = derive_context(pre, n, t, CLEAN)
        want = points_in_patch(pre, t.scale.min_face_diagonals * pre.diagonal)
        assert ctx.min_points == max(t.scale.min_points_floor, int(want))
        sizes[n] = want
    # Points per patch follow the density (a patch's area over a point's share of it).
    assert sizes[240_000] / sizes[60_000] == pytest.approx(4.0, rel=0.15)
    assert ctx.min_points > t.scale.min_points_floor
    # A sparse cloud keeps the floor: fewer points do not pin a primitive down.
    small = preprocess(synth.gear_like(seed=0, n_points=4_000).points)
    assert derive_context(small, 4_000, t, CLEAN).min_points == t.scale.min_points_floor
    # On a noisy cloud the floor is higher: a handful of noisy points fits some primitive.
    from houghcad.noise import NOISY
    assert derive_context(small, 4_000, t, NOISY).min_points == t.scale.noisy_min_points_floor
    assert t.scale.noisy_min_points_floor > t.scale.min_points_floor
