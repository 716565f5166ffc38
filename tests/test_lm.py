"""The families' Levenberg–Marquardt (houghcad.families._lm) against scipy's MINPACK."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from houghcad.families import _lm
from houghcad.families._geometry import tangent_basis, unit
from houghcad.families.cone import _refit_rows as cone_rows
from houghcad.families.torus import _refit_rows as torus_rows


def _cone_problem(rng: np.random.Generator, m: int, noise: float, half_angle: float, arc: float):
    """Points on a cone patch and a perturbed start, in the cone refit's parametrisation."""
    a, apex = unit(rng.normal(size=3)), rng.normal(size=3)
    e1, e2 = tangent_basis(a)
    h, th = rng.uniform(0.5, 2.0, m), rng.uniform(0.0, arc, m)
    P = apex + h[:, None] * a + (h * np.tan(half_angle))[:, None] * (
        np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
    P += rng.normal(scale=noise, size=P.shape)
    p0, a0 = apex + rng.normal(scale=0.05, size=3), unit(a + rng.normal(scale=0.05, size=3))
    b1, b2 = tangent_basis(a0)
    return (P, p0, a0, b1, b2), np.r_[0, 0, 0, 0, 0, half_angle * rng.uniform(0.9, 1.1)]


def _torus_problem(rng: np.random.Generator, m: int, noise: float):
    R = rng.uniform(0.5, 3.0)
    r = rng.uniform(0.1, 0.9) * R
    a, c = unit(rng.normal(size=3)), rng.normal(size=3)
    e1, e2 = tangent_basis(a)
    u, v = rng.uniform(0, 2 * np.pi, m), rng.uniform(0, rng.uniform(0.5, 2 * np.pi), m)
    rad = np.cos(u)[:, None] * e1 + np.sin(u)[:, None] * e2
    P = c + (R + r * np.cos(v))[:, None] * rad + (r * np.sin(v))[:, None] * a
    P += rng.normal(scale=noise, size=P.shape)
    c0, a0 = c + rng.normal(scale=0.05, size=3), unit(a + rng.normal(scale=0.05, size=3))
    b1, b2 = tangent_basis(a0)
    return (P, c0, a0, b1, b2), np.r_[0, 0, 0, 0, 0, R * rng.uniform(0.9, 1.1), r * rng.uniform(0.9, 1.1)]


def _scipy(rows, x0, args, max_nfev):
    return least_squares(lambda x: rows(*args, x, False)[0], x0, jac=lambda x: rows(*args, x, True)[1],
                         method="lm", max_nfev=max_nfev)


@pytest.mark.parametrize("seed", range(6))
def test_cone_and_torus_refits_match_scipys_minpack_to_rounding(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for k in range(20):
        m, noise = int(rng.integers(8, 400)), float(rng.choice([0.0, 1e-3, 1e-2]))
        if k % 2:
            rows, (args, x0), nfev = torus_rows, _torus_problem(rng, m, noise), 50
        else:
            rows, (args, x0), nfev = cone_rows, _cone_problem(rng, m, noise, rng.uniform(0.05, 1.3),
                                                              rng.uniform(0.3, 2 * np.pi)), 40
        ours, ref = _lm.solve(rows, x0, args, max_nfev=nfev), _scipy(rows, x0, args, nfev)
        assert np.abs(ours.x - ref.x).max() <= 1e-12 * (1 + np.abs(ref.x).max())
        assert ours.status == ref.status
        assert ours.nfev == ref.nfev
        np.testing.assert_allclose(ours.fun, rows(*args, ours.x, False)[0], rtol=0, atol=0)


def test_a_thin_cones_ill_conditioned_refit_is_bit_identical_whatever_memory_held() -> None:
    # A 24-point strip of a cone of half-angle 0.07 rad: its apex is barely determined, so a
    # last-bit difference anywhere in the solver moves it by whole units.
    rng = np.random.default_rng(3)
    args, x0 = _cone_problem(rng, 24, 2e-3, 0.07, 0.4)
    first = _lm.solve(cone_rows, x0, args, max_nfev=40).x
    for fill in (0.0, 1e300, np.nan, -1.0):
        junk = [np.full(int(s), fill) for s in (7, 49, 24 * 6, 24, 1000)]  # recycled by the allocator
        del junk
        assert _lm.solve(cone_rows, x0, args, max_nfev=40).x.tobytes() == first.tobytes()


def test_a_linear_problem_ends_at_the_least_squares_solution() -> None:
    rng = np.random.default_rng(0)
    A, b = rng.normal(size=(30, 4)), rng.normal(size=30)

    def rows(x, jacobian):
        return A @ x - b, A

    sol = _lm.solve(rows, np.zeros(4))
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(A, b, rcond=None)[0], rtol=1e-9, atol=1e-12)
    assert sol.status in (1, 2, 3, 4)


def test_running_out_of_evaluations_reports_status_0_like_scipy() -> None:
    # Rosenbrock's valley from its classic start: far more than 6 evaluations to the minimum.
    def rows(x, jacobian):
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]]), np.array([[-20 * x[0], 10.0], [-1.0, 0.0]])

    x0 = np.array([-1.2, 1.0])
    ours = _lm.solve(rows, x0, max_nfev=6)
    ref = least_squares(lambda x: rows(x, False)[0], x0, jac=lambda x: rows(x, True)[1], method="lm", max_nfev=6)
    assert ours.status == ref.status == 0
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-12)
    full = _lm.solve(rows, x0)
    np.testing.assert_allclose(full.x, [1.0, 1.0], atol=1e-7)


def test_fewer_residuals_than_parameters_or_a_non_finite_start_is_refused() -> None:
    with pytest.raises(ValueError, match="residuals for"):
        _lm.solve(lambda x, j: (np.zeros(2), np.zeros((2, 3))), np.zeros(3))
    with pytest.raises(ValueError, match="not finite"):
        _lm.solve(lambda x, j: (np.array([np.nan, 1.0, 2.0]), np.zeros((3, 1))), np.zeros(1))
