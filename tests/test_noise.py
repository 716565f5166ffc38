"""The noise policy: one choice per run, listed in one place."""

from __future__ import annotations

from dataclasses import fields

import pytest

import houghcad
from houghcad import synth
from houghcad.noise import CLEAN, NOISY, NOISY_SPACINGS, choose


def test_auto_reads_noise_against_the_spacing():
    assert choose("auto", 0.2, 1.0) is NOISY and choose("auto", 0.1, 1.0) is CLEAN
    assert choose("auto", NOISY_SPACINGS, 1.0) is NOISY
    assert choose("clean", 5.0, 1.0) is CLEAN and choose("noisy", 0.0, 1.0) is NOISY
    with pytest.raises(ValueError, match="noise must be one of"):
        choose("loud", 0.0, 1.0)


def test_the_policies_differ_in_every_change():
    for f in fields(CLEAN):
        if f.name != "name":
            assert getattr(CLEAN, f.name) is False and getattr(NOISY, f.name) is True, f.name


def _steps(points, **options):
    steps: list[str] = []
    res = houghcad.segment(points, trace=lambda step, name, seg: steps.append(name), **options)
    return res, steps


def test_the_noise_option_chooses_the_policy_once():
    noisy = synth.block_with_hole_and_slot(seed=1, n_points=2500, noise=0.005).points
    res, steps = _steps(noisy)
    assert res.options["derived"]["noise_policy"] == "noisy" and "settle_noisy_edges" in steps
    res, steps = _steps(noisy, noise="clean")
    assert res.options["derived"]["noise_policy"] == "clean"
    assert "settle_edges" in steps and "settle_noisy_edges" not in steps and "revisit_poor_fits" not in steps
    clean = synth.block_with_hole_and_slot(seed=1, n_points=2500).points
    res, steps = _steps(clean, noise="noisy")
    assert res.options["noise"] == "noisy" and res.options["normals_used"].startswith("pca-k")
    assert "settle_noisy_edges" in steps and "settle_edges" not in steps
    with pytest.raises(houghcad.InputError, match="noise must be one of"):
        houghcad.segment(clean, noise="loud")
