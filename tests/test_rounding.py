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


def _profiled_cylinder() -> np.ndarray:
    """An exact cylinder sampled on profiles at z = k * 0.01, as a laser line profiler on a stage
    gives it: z lies on a grid, x and y on none, and nothing is rounded."""
    rng = np.random.default_rng(0)
    z = np.repeat(np.arange(0.0, 2.0, 0.01), 150)
    th = rng.uniform(0.0, 2.0 * np.pi, len(z))
    return np.column_stack([0.5 * np.cos(th) + 0.123456789, 0.5 * np.sin(th) - 0.3456789, z])


def test_a_grid_on_one_axis_is_sampling_and_does_not_warn(part):
    P = _profiled_cylinder()
    assert grid_step(P) == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_coarse_coordinates(P, 0.007, "profiles.ply")  # the stage step is 1.4 spacings
    # Scan lines along any one axis of a part: no rounding either.
    for axis in range(3):
        Q = part.copy()
        Q[:, axis] = np.round(Q[:, axis] / 0.02) * 0.02
        assert grid_step(Q) == 0.0


def test_stage_steps_under_a_storage_rounding_report_the_storage_step():
    # The profiler's cloud stored at 1 mm (a LAS scale): every axis is on the 1 mm grid, the
    # stage steps on a coarser one; the rounding is the grid they share.
    P = np.round(_profiled_cylinder() / 0.001) * 0.001
    assert grid_step(P) == pytest.approx(0.001, rel=1e-6)
    with pytest.warns(InputWarning, match="grid 0.001 units apart, 1 point spacings"):
        warn_coarse_coordinates(P, 0.001, "profiles.las")


def test_a_flat_part_is_judged_by_the_axes_that_vary(part):
    # A plate lying in z = 0: its single z value lies on any grid, so x and y decide.
    flat = part.copy()
    flat[:, 2] = 0.0
    assert grid_step(flat) == 0.0
    rounded = np.round(flat / 0.02) * 0.02
    assert grid_step(rounded) == pytest.approx(0.02, rel=1e-6)
    with pytest.warns(InputWarning, match="grid 0.02 units apart"):
        warn_coarse_coordinates(rounded, 0.02, "plate.txt")


def test_las_scale_and_text_decimals_read_from_files_warn(tmp_path, part):
    import laspy

    from houghcad.io import read_points

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([5e5, 4e6, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = (part * 0.05 + [5e5, 4e6, 100.0]).T  # a part of ~0.1 units at 1 mm
    las.write(tmp_path / "scan.las")
    text = tmp_path / "scan.xyz"
    np.savetxt(text, part, fmt="%.2f")
    for path, step in ((tmp_path / "scan.las", 0.001), (text, 0.01)):
        with pytest.warns(InputWarning, match=f"grid {step:g} units apart, 1 point spacings"):
            warn_coarse_coordinates(read_points(path).points, step, str(path))
