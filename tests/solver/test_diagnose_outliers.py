"""Gross outliers in the diagnosis, in process: the moved readings are listed by pose and target,
left out of the fits, and the floor and the named effect stay right (the command line's printing
and files are checked in tests/server/test_outliers.py on the same campaign)."""

import numpy as np

from robocal.drivers.cell import VirtualCell, displace
from robocal.drivers.effects import make_effects
from tests.sim import default_cell
from tests.solver.test_diagnose_effects import diagnosed

SEED = 21


def test_diagnosis_lists_the_outliers_and_keeps_the_floor():
    """40 poses x 3 SMRs with joint-2 compliance and 4 of 120 readings moved 0.3-2 mm."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects(["joint_compliance:2=0.2"], vc, SEED))
    meas = vc.campaign(40, seed=SEED)
    meas.xyz[:], moved = displace(meas.xyz, SEED, 4 / 120)
    bad = {(int(meas.pose_ids[p]), meas.target_names[k]) for p, k in np.argwhere(moved)}
    floor = vc.noise_floor_mm(meas.q)
    report = diagnosed(cell, meas).report.to_json()  # as report.json has it
    assert {(o["pose"], o["target"]) for o in report["outliers"]} == bad
    assert all(o["residual_mm"] > 0.2 for o in report["outliers"])
    assert abs(report["noise_floor_mm"] / floor - 1) < 0.3
    assert [(e["name"], e["joint"]) for e in report["effects"]] == [("joint_compliance", 2)]
    assert report["final"]["holdout_rmse_mm"] < 1.5 * floor
