"""One SMR on the last joint's axis (a common nest): every method fits, holding what it cannot move."""

import dataclasses

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver.calibrate import calibrate
from robocal.solver.kinematics import predict
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.robots import IIWA_LIKE, KUKA_LIKE, PUMA_LIKE, UR5

ROBOTS = {
    "irb2600": IRB2600,
    "kuka-like": KUKA_LIKE,
    "puma-like": PUMA_LIKE,
    "ur5": UR5,
    "iiwa": IIWA_LIKE,
}
METHODS = ["ls-sum", "ls-single:A", "minimax"]
ON_AXIS = {"A": [0.0, 0.0, 35.0]}


def one_smr(robot, seed, exactly_on_axis, n_cal=40, n_hold=30):
    """A campaign of one SMR nominally on the flange axis; exactly there too, or off by the cell's
    random SMR error (~1 mm) as `robocal simulate` draws it."""
    cell = VirtualCell.random(robot, ON_AXIS, seed=seed)
    if exactly_on_axis:
        cell = dataclasses.replace(cell, true_targets=cell.nominal_targets.copy())
    meas = cell.campaign(n_cal + n_hold, seed=seed + 1000)
    return cell, meas.subset(np.arange(n_cal)), meas.subset(np.arange(n_cal, n_cal + n_hold))


@pytest.mark.parametrize("exactly", [True, False], ids=["exactly", "nominally"])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_one_smr_on_the_axis_calibrates_holding_the_last_joints_offset(name, exactly):
    robot = ROBOTS[name]
    n = robot.n_joints
    cell, cal, hold = one_smr(robot, 11 + list(ROBOTS).index(name), exactly)
    floor = np.sqrt(np.nanmean(np.sum((hold.xyz - cell.true_points(hold.q)) ** 2, axis=-1)))
    for method in METHODS:
        c = calibrate(Problem(robot, np.array([ON_AXIS["A"]]), ("A",), cal.q, cal.xyz), method)
        assert f"theta{n}" in c.fixed and f"d{n}" in c.fixed, (method, c.fixed)
        if exactly:
            assert "no effect on the measured SMRs" in c.fixed[f"theta{n}"]
        assert np.isfinite(c.condition) and c.condition < 1e4, (method, c.condition)
        err = predict(c.layout, c.x, hold.q)[:, 0] - hold.xyz[:, 0]
        rms = np.sqrt(np.mean(np.sum(err**2, axis=-1)))
        assert rms <= 2.0 * floor, (name, method, rms, floor)


def test_ls_pose_needs_three_smrs_whatever_their_layout():
    cell, cal, _ = one_smr(IRB2600, 3, True)
    with pytest.raises(ValueError, match="three SMRs"):
        calibrate(Problem(IRB2600, np.array([ON_AXIS["A"]]), ("A",), cal.q, cal.xyz), "ls-pose")


def test_diagnose_refuses_too_few_poses_before_any_selection():
    """Too few poses are refused by the geometric check up front, not after the selection."""
    from robocal.solver.diagnose import diagnose
    from robocal.solver.identifiability import NotIdentifiable

    _, cal, _ = one_smr(IRB2600, 3, True, n_cal=6, n_hold=0)
    said = []
    with pytest.raises(NotIdentifiable, match="poses"):
        diagnose(
            Problem(IRB2600, np.array([ON_AXIS["A"]]), ("A",), cal.q, cal.xyz), log=said.append
        )
    assert said == []
