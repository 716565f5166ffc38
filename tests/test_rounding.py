"""houghcad.rounding: coordinates rounded coarsely against the point spacing are detected."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from houghcad import synth
from houghcad.errors import InputWarning
from houghcad.rounding import grid_step, warn_coarse_coordinates


@pytest.fixture(scope="module")
def part() -> np.ndarray:
    return synth.block_with_hole_and_slot(seed=2, n_points=5000).points


def test_unrounded_coordinates_lie_on_no_grid(part):
    assert grid_step(part) == 0.0
    assert grid_step(part + [5e5, 4e6, 100.0]) == 0.0  # float64 far from the origin: digits to spare


@pytest.mark.parametrize("offset", [0.0, 5e5])
def test_a_las_scale_is_found(part, offset):
    # A LAS file stores integers times its scale: here 0.01 units, offset as a georeferenced scan.
    q = 0.01
    P = np.round((part + offset) / q) * q
    assert grid_step(P) == pytest.approx(q, rel=1e-6)
    assert grid_step(P, at_least=2 * q) == 0.0  # finer than asked for


def test_a_coarse_grid_warns_and_a_fine_one_does_not(part):
    spacing = 0.02
    with pytest.warns(InputWarning, match="grid 0.02 units apart, 1 point spacings"):
        warn_coarse_coordinates(np.round(part / 0.02) * 0.02, spacing, "scan.las")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_coarse_coordinates(np.round(part / 0.001) * 0.001, spacing, "scan.las")  # 0.05 spacings
