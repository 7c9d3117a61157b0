"""The solver's Problem: inputs checked once with a clear message, and the helpers its callers
use (a campaign's Measurements, folds of poses, other readings)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver.finite import NonFinite
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.sim import default_cell

CELL = default_cell()


@pytest.fixture(scope="module")
def meas():
    return VirtualCell.random(CELL.robot, CELL.targets, seed=2).campaign(12, seed=2)


def test_of_measurements_carries_every_column(meas):
    p = CELL.problem(meas)
    assert p.target_names == meas.target_names and p.pose_ids == tuple(meas.pose_ids)
    assert p.q is meas.q and p.meas is meas.xyz  # no copy of float arrays
    np.testing.assert_array_equal(p.time_s, meas.time_s)
    assert p.targets.shape == (3, 3) and p.n_poses == 12
    assert p.mask.shape == (12, 3) and p.mask.all()
    assert p.inputs().q is p.q
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.q = meas.q  # type: ignore[misc]


def test_subset_keeps_the_poses_columns_together(meas):
    p = CELL.problem(meas)
    rows = np.array([3, 1, 7])
    s = p.subset(rows)
    np.testing.assert_array_equal(s.q, meas.q[rows])
    np.testing.assert_array_equal(s.meas, meas.xyz[rows])
    np.testing.assert_array_equal(s.time_s, meas.time_s[rows])
    assert s.pose_ids == ("4", "2", "8")
    mask = np.zeros(12, dtype=bool)
    mask[rows] = True
    assert p.subset(mask).pose_ids == ("2", "4", "8")  # a mask keeps the campaign's order


def test_with_meas_replaces_the_readings_only(meas):
    p = CELL.problem(meas)
    xyz = meas.xyz.copy()
    xyz[0, 0] = np.nan
    w = p.with_meas(xyz)
    assert w.meas is xyz and not w.mask[0, 0] and w.q is p.q and w.pose_ids == p.pose_ids
    with pytest.raises(ValueError, match=r"readings have shape \(11, 3, 3\)"):
        p.with_meas(xyz[1:])


def test_inputs_that_do_not_fit_together_are_named(meas):
    targets = CELL.target_positions(meas.target_names)
    with pytest.raises(ValueError, match="3 target names, 2 nominal positions"):
        Problem(IRB2600, targets[:2], meas.target_names, meas.q, meas.xyz)
    with pytest.raises(ValueError, match="joint angles must have 2 dimensions"):
        Problem(IRB2600, targets, meas.target_names, meas.q[0], meas.xyz)
    with pytest.raises(ValueError, match=r"time_s has shape \(12,\)"):
        Problem(IRB2600, targets, meas.target_names, meas.q, meas.xyz, time_s=np.zeros(12))
    with pytest.raises(ValueError, match="11 pose ids for 12 poses"):
        Problem(IRB2600, targets, meas.target_names, meas.q, meas.xyz, pose_ids=["a"] * 11)
    q = meas.q.copy()
    q[2, 1] = np.inf
    with pytest.raises(NonFinite, match="non-finite values in the joint angles"):
        Problem(IRB2600, targets, meas.target_names, q, meas.xyz)


def test_a_pose_without_any_reading_keeps_the_thermal_drift_a_candidate(meas):
    """A pose whose beams all broke has no temperature either; its readings are out of every fit,
    so its input takes a finite value and the campaign's thermal drift stays a candidate (bench
    seed 12, one SMR a pose: a tenth of the poses blank, thermal drift never tried)."""
    from robocal.solver.vocabulary import KINDS

    span = np.linspace(20.0, 26.0, meas.n_poses)[:, None] * np.ones(meas.xyz.shape[1])
    p = dataclasses.replace(CELL.problem(meas), temp_c=span)
    xyz, temp = meas.xyz.copy(), span.copy()
    xyz[4], temp[4] = np.nan, np.nan
    blank = dataclasses.replace(p.with_meas(xyz), temp_c=temp)
    got = blank.inputs()
    assert np.isfinite(got.temp_c).all() and np.isfinite(got.time_s).all()
    np.testing.assert_array_equal(got.temp_c[[3, 5]], span[[3, 5]])  # measured poses as read
    (drift,) = KINDS["thermal_drift"].candidates(None, None, got)  # it reads the inputs alone
    assert drift.variable == "temp_c"
