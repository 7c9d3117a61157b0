"""A simulated fleet: arms of the IRB 2600 drawn with small manufacturing errors, each
calibrated for real on a small simulated campaign and stored as a done calibration job."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal.drivers.cell import GeometricErrors, VirtualCell
from robocal.server import store
from robocal.server.calibration import workflow
from robocal.server.calibration.identified import arm_parameters
from robocal.server.formats import cell_to_json, default_cell
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.model_json import to_plain

ARMS = 12
POSES = 30
BENT = "SN-1007"  # this arm's upper arm (a2) is 1 mm long at its second calibration
BEND_MM = 1.0
# arms calibrated twice, the second time unchanged (their jump must stay within uncertainty)
TWICE = ("SN-1001", "SN-1002")
# One model's arms differ far less than the simulator's default arm (0.5 mm, 0.05 deg): the
# fleet view can only tell a bend that stands out of the fleet's own spread.
SPREAD = GeometricErrors(length_mm=0.05, theta_deg=0.005, alpha_deg=0.005, beta_deg=0.005)


def serial(i: int) -> str:
    return f"SN-{1000 + i}"


def calibrate(db, vc: VirtualCell, arm: str, seed: int, tmp_path) -> int:
    """Measure the arm on a new simulated campaign, calibrate it, store both; the job's id."""
    cell = default_cell()
    meas = vc.campaign(POSES, seed=seed)
    path = tmp_path / f"{arm}-{seed}.csv"
    write_campaign(path, meas)
    cid = store.import_csv(db, path=path, cell_json=cell_to_json(cell), name=path.stem, arm=arm)
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-pose"), cell, meas)
    job = store.create_job(db, kind="calibration", campaign_id=cid, method="ls-pose")
    store.update_job(db, job_id=job.id, state="running")
    results = {"parameters": to_plain(arm_parameters(model))}
    return store.update_job(db, job_id=job.id, state="done", results=results).id


def bent(vc: VirtualCell) -> VirtualCell:
    """The same arm after a crash: its a2 link BEND_MM longer."""
    robot = vc.true_robot
    p = robot.param_vector()
    p[robot.param_names().index("a2")] += BEND_MM
    return replace(vc, true_robot=robot.with_params(p))


def build_fleet(db, tmp_path) -> None:
    """ARMS arms, each calibrated once; TWICE and BENT a second time (BENT bent)."""
    cell = default_cell()
    cells = {}
    for i in range(ARMS):
        arm = serial(i)
        cells[arm] = VirtualCell.random(cell.robot, cell.targets, seed=100 + i, errors=SPREAD)
        calibrate(db, cells[arm], arm, 100 + i, tmp_path)
    for arm in (*TWICE, BENT):
        vc = bent(cells[arm]) if arm == BENT else cells[arm]
        calibrate(db, vc, arm, 900 + int(arm[3:]), tmp_path)


__all__ = ["ARMS", "BENT", "TWICE", "build_fleet", "np"]
