"""solver/check_plan: the change design's columns are the motions they name, joint 1's zero is
absorbed by the rigid motion, batches equal single poses, and interior() keeps the share asked."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from robocal.solver import check_plan as cp
from robocal.solver.kinematics import Layout, predict
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

BASE = np.eye(4)
BASE[:3, 3] = [2500.0, -300.0, -400.0]


def setup(m=12, seed=0):
    lay = Layout(IRB2600, BASE, tuple(TARGETS))
    x = lay.initial(np.array(list(TARGETS.values())))
    rng = np.random.default_rng(seed)
    q = rng.uniform(IRB2600.lower * 0.8, IRB2600.upper * 0.8, size=(m, 6))
    return lay, x, q


def test_columns_are_the_motions_of_the_pose_means():
    lay, x, q = setup()
    d = cp.change_design(lay, x, q, BASE[:3, 3])
    c = predict(lay, x, q).mean(axis=1)
    o = BASE[:3, 3]
    w, t, s = np.array([2e-5, -1e-5, 3e-5]), np.array([0.05, -0.02, 0.03]), 4e-5
    moved = Rotation.from_rotvec(w).apply(c - o) + o + t
    k = d.names.index
    rigid = d.J[:, :, [k(n) for n in cp.RIGID_NAMES]] @ np.concatenate([w, t])
    assert np.allclose(rigid, moved - c, atol=1e-5)  # second order: |w|^2 |c| ~ 5e-6 mm
    assert np.allclose(d.J[:, :, k("scale")] * s, s * (c - o), atol=1e-9)
    step = np.zeros(6)
    step[2] = 1e-5
    j3 = (predict(lay, x, q + step).mean(axis=1) - c) / 1e-5
    assert np.allclose(d.J[:, :, k("joint 3")], j3, rtol=1e-3, atol=1e-3)


def test_joint_1_is_a_rigid_motion_and_the_last_joint_invisible_at_a_threshold():
    lay, x, q = setup()
    d = cp.change_design(lay, x, q, BASE[:3, 3])
    assert d.absorbed == (1,) and "joint 1" not in d.names and "joint 6" in d.names
    # the SMRs' centre is on the flange's axis: the last joint hardly moves it
    seen = cp.change_design(lay, x, q, BASE[:3, 3], visible_mm_per_rad=10.0)
    assert seen.invisible == (6,) and "joint 6" not in seen.names
    assert set(seen.kinds()) == {"rigid", "joint 2", "joint 3", "joint 4", "joint 5", "scale"}


def test_batch_equals_single_poses_and_choice_is_deterministic():
    lay, x, q = setup(m=40)
    d = cp.change_design(lay, x, q, BASE[:3, 3], 10.0)
    one = cp.change_design(lay, x, q[7:8], BASE[:3, 3], like=d)
    assert one.names == d.names and np.allclose(one.J[0], d.J[7])
    # one pose's 3 rows alone are in the rigid motion's span: every joint would be absorbed
    assert cp.change_design(lay, x, q[7:8], BASE[:3, 3]).absorbed == (1, 2, 3, 4, 5, 6)
    a, b = cp.choose(d, 6), cp.choose(d, 6)
    assert np.array_equal(a, b) and len(set(a.tolist())) == 6
    assert np.all(np.isfinite(cp.standard_errors(d.J[a], 0.02)))
    assert np.all(np.isinf(cp.standard_errors(d.J[a[:3]], 0.02)))  # 9 rows, 11 parameters


def test_interior_keeps_the_low_leverage_share():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(200, 3, 4))
    J[:20] *= 5.0  # high leverage poses
    keep = cp.interior(J, 0.5)
    assert keep.sum() == 100 and not keep[:20].any()
