"""On a small real campaign the data cannot tell joint 2's compliance from a look-alike; the
tie goes to the most gravity-loaded joint's one stiffness (solver.selection.tied_suspect)."""

from __future__ import annotations

import numpy as np

from robocal.server.calibration import workflow
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnose import diagnose
from robocal.solver.kinematics import predict
from tests.real import REAL
from tests.solver.test_diagnose_effects import predict_poses
from tests.solver.test_extrapolation import rms


def subset_30(k: int, seed: int = 0) -> np.ndarray:
    """The k-th random 30-pose subset of the real UR5's 1,000 (the stress harness's draw)."""
    rng = np.random.default_rng(seed)
    picks = [rng.choice(1000, 30, replace=False) for _ in range(k + 1)]
    return np.sort(picks[k])


def test_a_30_pose_ur5_subset_names_joint_2_stiffness_not_a_joint_4_scale():
    """30 of the real UR5's poses (one SMR): joint 4's scale won the cross-validation by chance
    (paired t 0.95 against joint 2's compliance) and tested 1.030x geometry on the other 970
    poses; joint 2's one stiffness is named instead and tests better than geometry there
    (measured 0.960x)."""
    folder = REAL / "ur5_jacobi"
    cell, meas = workflow.load_data(folder / "train.csv", folder / "cell.json")
    keep = np.zeros(meas.n_poses, dtype=bool)
    keep[subset_30(6)] = True
    train, test = meas.subset(np.flatnonzero(keep)), meas.subset(np.flatnonzero(~keep))
    d = diagnose(workflow.cell_problem(cell, train))
    named = [(e.name, e.joint, e.parameters.get("gravity_terms")) for e in d.report.effects]
    assert named == [("joint_compliance", 2, 1)], named
    geo = calibrate(workflow.cell_problem(cell, train), "ls-sum")
    geometric = rms(predict(geo.layout, geo.x, test.q), test.xyz)
    assert rms(predict_poses(cell, d, test.q), test.xyz) < 0.98 * geometric
