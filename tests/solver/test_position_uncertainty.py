"""The expanded uncertainty U of a calibrated model's positions holds what it states: over 204
simulated calibrations (three arms; clean, with the arm's scatter, with effects the model does
not have) 95 % +- 3 % of independent positions' true errors lie within U; so too over 204
extended models (tests/solver/extended_coverage.py); with the covariance too small the same
check fails, so it can."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import guard
from robocal.solver import position_uncertainty as pu
from robocal.solver.calibrate import calibrate
from robocal.solver.fit_errors import angles, calibration_rows, point_errors
from robocal.solver.kinematics import predict
from robocal.solver.problem import Problem
from robocal.solver.uncertainty import errors_from_rows
from tests.solver import extended_coverage
from tests.solver.coverage_suite import ARMS, SEEDS, TARGETS, TEST_POSES, coverage

EFFECTS = ("joint_compliance:2=0.3", "joint_periodic:3=0.01", "joint_compliance:3=0.3")


@cache
def _fitted(robot, seed: int, kind: str):
    """A 40-pose ls-sum calibration, its errors and joint scatter, the TEST_POSES independent
    poses and the true error at their SMRs, mm (kept: the too-small check scales the very
    calibrations the coverage check judged)."""
    vc = VirtualCell.random(robot, TARGETS, seed=seed)
    scatter = 0.003 if kind == "scatter" else 0.0
    if kind == "effect":
        vc.effects = make_effects([EFFECTS[seed % len(EFFECTS)]], vc, seed)
    train = vc.campaign(40, seed, arm_scatter_deg=scatter)
    names = train.target_names
    nominal = np.array([TARGETS[t] for t in names])
    cal = calibrate(Problem.of(robot, nominal, train), "ls-sum")
    rows, column = calibration_rows(cal, train.q, train.xyz)
    errors = errors_from_rows(rows, cal.layout.names(), column, angles(cal.layout))
    holdout = guard.leave_one_pose_out(rows, point_errors(cal, rows)).rms()
    trained = pu.spread_at(cal.layout, cal.x, train.q, errors.cov, errors.column)
    s = pu.joint_scatter_rad(*pu.mean_traces(trained), holdout, vc.last_campaign["noise_floor_mm"])
    rng = np.random.default_rng([7, seed])
    q = vc.sample_poses(TEST_POSES, rng)
    truth = vc.true_points(q, pose_dq=np.deg2rad(scatter) * rng.normal(size=q.shape))
    err = np.linalg.norm(predict(cal.layout, cal.x, q) - truth, axis=-1)
    return cal, errors, s, q, err


def _case(robot, seed: int, kind: str, shrink: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(true error, U) at the SMRs of TEST_POSES independent poses, mm, of a 40-pose ls-sum
    calibration; its covariance and scatter multiplied by `shrink`."""
    cal, errors, s, q, err = _fitted(robot, seed, kind)
    at = pu.spread_at(cal.layout, cal.x, q, errors.cov * shrink, errors.column)
    return err, pu.position_uncertainty(at, s * np.sqrt(shrink)).expanded_mm


# per suite: one calibration's (true error, U) at its test positions, and the kinds in turn
SUITES = {
    "geometric": (_case, ("clean", "scatter", "effect")),
    "extended": (extended_coverage.case, extended_coverage.KINDS),
}


@pytest.mark.parametrize("suite", SUITES)
def test_stated_uncertainty_covers_95_percent_of_true_errors(suite):
    covered, by_kind = coverage(*SUITES[suite])
    print(f"\n{suite}: coverage {covered:.3f} over {len(ARMS) * SEEDS} calibrations; {by_kind}")
    assert 0.92 <= covered <= 0.98, (covered, by_kind)


@pytest.mark.parametrize("suite", SUITES)
def test_a_covariance_too_small_fails_the_same_check(suite):
    covered, _ = coverage(*SUITES[suite], shrink=0.3)
    print(f"\n{suite}: coverage with the covariance x0.3: {covered:.3f}")
    assert covered < 0.92


@pytest.mark.parametrize("lam", [(1.0, 1.0, 1.0), (4.0, 1.0, 0.01), (1.0, 0.0, 0.0)])
def test_radius_matches_the_distribution_it_states(lam):
    """Patnaik's approximation against 200,000 draws of the same Gaussian (within 2 %)."""
    cov = np.diag(lam)
    r = pu.radius(cov)
    draws = np.random.default_rng(0).normal(size=(200_000, 3)) * np.sqrt(lam)
    q = np.quantile(np.linalg.norm(draws, axis=1), pu.COVERAGE)
    assert abs(r - q) / q < 0.02, (r, q)
