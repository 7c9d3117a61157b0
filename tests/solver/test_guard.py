"""The validation guard's numerics: leave-one-pose-out residuals equal refits (exactly for a
linear model, closely for the arm's), poses the others cannot do without are named, the
strongest correlations are found, and each limit gives its reason."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.solver import guard
from robocal.solver.uncertainty import Rows


def linear_rows(rng, m=12, per_pose=6, P=4):
    """A least-squares fit of a linear model over m poses of per_pose rows each."""
    J = rng.normal(size=(m * per_pose, P))
    y = J @ rng.normal(size=P) + 0.1 * rng.normal(size=len(J))
    theta = np.linalg.lstsq(J, y, rcond=None)[0]
    pose = np.repeat(np.arange(m), per_pose)
    rows = Rows(J, J.copy(), J @ theta - y, pose, np.zeros(len(J), int))
    return rows, y


def test_leave_one_pose_out_is_the_refit_of_a_linear_model():
    rng = np.random.default_rng(0)
    rows, y = linear_rows(rng)
    h = guard.leave_one_pose_out(rows)
    for p in range(12):
        out = rows.pose == p
        theta = np.linalg.lstsq(rows.J[~out], y[~out], rcond=None)[0]
        want = (rows.J[out] @ theta - y[out]).reshape(-1, 3)
        np.testing.assert_allclose(h.residuals[2 * p : 2 * p + 2], want, rtol=1e-9, atol=1e-12)
    assert h.rms() > np.sqrt(np.mean(np.sum(rows.r.reshape(-1, 3) ** 2, axis=1)))
    assert len(h.unsupported) == 0


def test_a_pose_the_others_cannot_do_without_is_named():
    rng = np.random.default_rng(1)
    rows, _ = linear_rows(rng, P=5)
    rows.J[:, 4] = 0.0
    rows.J[rows.pose == 7, 4] = 1.0  # only pose 7 moves the fifth parameter
    rows.G = rows.J.copy()
    h = guard.leave_one_pose_out(rows)
    assert h.unsupported.tolist() == [7]
    assert np.isnan(h.residuals[14:16]).all() and np.isfinite(h.residuals[:14]).all()


def test_the_point_rows_alone_are_reported():
    rng = np.random.default_rng(2)
    rows, _ = linear_rows(rng)
    point = np.tile([True, True, True, False, False, False], 12)
    assert guard.leave_one_pose_out(rows, point).residuals.shape == (12, 3)


def test_strongest_correlations():
    sd = np.array([1.0, 2.0, 0.5, 3.0])
    R = np.eye(4)
    R[0, 1] = R[1, 0] = 0.2
    R[1, 3] = R[3, 1] = -0.9
    R[0, 2] = R[2, 0] = 0.5
    top = guard.strongest_correlations(R * np.outer(sd, sd), k=2)
    assert [(i, j) for i, j, _ in top] == [(1, 3), (0, 2)]
    assert top[0][2] == pytest.approx(-0.9) and top[1][2] == pytest.approx(0.5)


class _Holdout(guard.Holdout):
    def __init__(self, rms, unsupported=()):
        self._rms = rms
        self.unsupported = np.array(unsupported, dtype=int)
        self.residuals = np.zeros((1, 3))

    def rms(self):
        return self._rms

    def max(self):
        return self._rms


def verdict(**change):
    figures = dict(
        fit_rms_mm=0.015,
        holdout=_Holdout(0.016),
        condition_number=17.0,
        equations=900,
        free_parameters=33,
        poses=100,
        noise_floor_mm=0.0155,
    )
    figures.update(change)
    return guard.judge(**figures)


def test_each_limit_gives_its_reason_and_a_healthy_fit_none():
    assert verdict().deployable and verdict().reasons == []
    cases = {
        "too few poses: 10 poses give 90 equations": dict(equations=90, poses=10),
        "fit RMS 0.0050 mm is below 0.6 x the tracker's noise floor": dict(
            fit_rms_mm=0.005, holdout=_Holdout(0.012)
        ),
        "condition number 2e+03 exceeds 1000": dict(condition_number=2000.0),
        "held-out RMS 0.04 mm is 2.67 x the fit RMS": dict(
            holdout=_Holdout(0.04), noise_floor_mm=0.0145
        ),
        "held-out RMS 0.04 mm is 2.58 x the noise floor 0.0155 mm": dict(holdout=_Holdout(0.04)),
        "2 of 100 poses cannot be held out": dict(holdout=_Holdout(0.016, [3, 9])),
    }
    for start, change in cases.items():
        v = verdict(**change)
        assert not v.deployable and len(v.reasons) == 1, (start, v.reasons)
        assert v.reasons[0].startswith(start), v.reasons
    assert "measure at least 11 poses" in verdict(equations=90, poses=10).reasons[0]
    # a held-out error near the tracker's noise is no alarm, however small the fit's
    assert verdict(fit_rms_mm=0.01, holdout=_Holdout(0.025), noise_floor_mm=0.015).deployable
    assert verdict(condition_number=float("nan")).reasons  # not a figure: not deployable


def test_a_fit_below_a_floor_its_held_out_error_matches_is_a_quiet_tracker_not_overfit():
    """A one-SMR campaign judged against the cell's tracker spec (MPE 15 um + 6 um/m, a real
    tracker's) that the tracker beats: fit 0.0114 mm, held out 0.0136 mm, floor 0.0248 mm was
    'not deployable: the fit absorbed measurement noise', which no campaign could mend. The
    held-out error beside the fit says the floor is above the noise: a warning."""
    v = verdict(fit_rms_mm=0.0114, holdout=_Holdout(0.0136), noise_floor_mm=0.0248)
    assert v.deployable and v.reasons == [], v.reasons
    assert v.warnings[0].startswith("fit RMS 0.0114 mm is below 0.6 x the tracker's noise floor")
    assert "quieter than that floor" in v.warnings[0]
    v = verdict(fit_rms_mm=0.0114, holdout=_Holdout(0.024), noise_floor_mm=0.0248)
    assert not v.deployable and v.reasons[0].endswith("the fit absorbed measurement noise")


def test_a_tolerance_below_the_noise_floor_is_said_so():
    """A tolerance below the readings' noise (1e-9 mm, or 0.0005: metres typed for mm) was
    judged without a word on why no model could meet it."""
    for tol in (1e-9, 0.0005):
        v = verdict(tolerance_mm=tol, noise_floor_source="SMR-to-SMR distances in the data")
        below = [w for w in v.warnings if "below the readings' noise floor 0.0155 mm" in w]
        assert len(below) == 1 and "can be shown to meet it" in below[0], v.warnings
        assert ("0.0005 m is 0.5 mm" in below[0]) == (tol == 0.0005), below
    assert not any("noise floor" in w for w in verdict(tolerance_mm=0.05).warnings)
    assert not any(
        "noise floor" in w for w in verdict(tolerance_mm=0.01, noise_floor_mm=None).warnings
    )


def test_a_condition_number_near_its_layouts_warns_and_one_far_above_it_refuses():
    """Past the limit within LAYOUT_EXCESS of the layout's own: the robot's and SMRs', a warning;
    far above it (few or alike poses): the poses', a reason."""
    v = verdict(condition_number=1535.0, layout_condition=1311.0)
    assert v.deployable and "layout's own (1.31e+03" in v.warnings[0], v.warnings
    v = verdict(condition_number=1959.0, layout_condition=15.6)
    assert not v.deployable and v.reasons[0].startswith("condition number 1.96e+03"), v.reasons
    assert not verdict(condition_number=2000.0, layout_condition=float("nan")).deployable
