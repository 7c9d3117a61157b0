"""Forward kinematics at hand-checked joints, batch consistency and the Jacobian against finite differences."""

import numpy as np
import pytest

from robocal.solver.kinematics import Layout, flange_frames, predict, predict_with_jacobian
from robocal.solver.robot import IRB2600, robot_from_degrees

PLANAR_MDH = robot_from_degrees(
    "planar",
    "mdh",
    [
        (0.0, 0.0, 0.0, 0.0, (-170, 170)),
        (300.0, 0.0, 0.0, 0.0, (-170, 170)),
    ],
)


def frame(robot, q_deg):
    lay = Layout(robot, np.eye(4), ("A",))
    R, o = flange_frames(lay, lay.initial([[0, 0, 0]]), np.deg2rad(np.atleast_2d(q_deg)))
    return R[0], o[0]


def test_irb2600_home_pose_by_hand():
    # base 445 + upper arm 900 + elbow offset 150 high; 150 + forearm 938 + flange 200 ahead
    R, o = frame(IRB2600, [0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(o, [1288.0, 0.0, 1495.0], atol=1e-9)
    np.testing.assert_allclose(R, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_irb2600_joint1_turns_the_arm_about_the_vertical():
    _, o = frame(IRB2600, [90, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(o, [0.0, 1288.0, 1495.0], atol=1e-9)


def test_irb2600_upper_arm_forward():
    # joint 2 at +90 deg lays the upper arm forward (elbow at x = 150 + 900, z = 445), the
    # elbow offset adds 150 ahead and the forearm (938) and flange (200) then point down
    _, o = frame(IRB2600, [0, 90, 0, 0, 0, 0])
    np.testing.assert_allclose(o, [1200.0, 0.0, 445.0 - 938.0 - 200.0], atol=1e-9)


def test_planar_mdh_by_hand():
    q = [30.0, 45.0]
    lay = Layout(PLANAR_MDH, np.eye(4), ("A",))
    p = predict(lay, lay.initial([[200.0, 0.0, 0.0]]), np.deg2rad([q]))[0, 0]
    q1, q12 = np.deg2rad(30), np.deg2rad(75)
    np.testing.assert_allclose(
        p,
        [300 * np.cos(q1) + 200 * np.cos(q12), 300 * np.sin(q1) + 200 * np.sin(q12), 0.0],
        atol=1e-9,
    )
    assert PLANAR_MDH.parallel == (False, True)


def test_batch_equals_one_pose_at_a_time():
    rng = np.random.default_rng(3)
    lay = Layout(IRB2600, np.eye(4), ("A", "B", "C"))
    x = lay.initial([[60, 0, 35], [-30, 52, 35], [-30, -52, 35]])
    q = rng.uniform(IRB2600.lower, IRB2600.upper, size=(7, 6))
    batch = predict(lay, x, q)
    for i in range(7):
        np.testing.assert_allclose(predict(lay, x, q[i : i + 1])[0], batch[i], atol=1e-9)


@pytest.mark.parametrize(
    "robot",
    [
        IRB2600,
        PLANAR_MDH,
        robot_from_degrees(
            "mdh6",
            "mdh",
            [
                (0, 400, 0, 0, (-170, 170)),
                (25, 0, -90, -90, (-120, 120)),
                (455, 0, 0, 0, (-200, 70)),
                (35, 420, 0, -90, (-350, 350)),
                (0, 0, 0, 90, (-125, 125)),
                (0, 80, 0, -90, (-350, 350)),
            ],
        ),
    ],
)
def test_jacobian_matches_finite_differences(robot):
    rng = np.random.default_rng(0)
    base = np.array([[0, -1, 0, 2500.0], [1, 0, 0, 300.0], [0, 0, 1, -400.0], [0, 0, 0, 1]])
    lay = Layout(robot, base, ("A", "B", "C"))
    x = lay.initial([[60, 0, 35], [-30, 52, 35], [-30, -52, 35]])
    x = x + rng.normal(0, 1e-2, x.shape)
    q = rng.uniform(robot.lower, robot.upper, size=(6, robot.n_joints))
    _, J, Jq = predict_with_jacobian(lay, x, q)
    h = 1e-6
    for i in range(lay.n_params):
        e = np.zeros_like(x)
        e[i] = h
        num = (predict(lay, x + e, q) - predict(lay, x - e, q)) / (2 * h)
        np.testing.assert_allclose(
            J[..., i], num, atol=1e-5 * max(1.0, np.abs(num).max()), err_msg=lay.names()[i]
        )
    for j in range(robot.n_joints):
        dq = np.zeros_like(q)
        dq[:, j] = h
        num = (predict(lay, x, q, dq) - predict(lay, x, q, -dq)) / (2 * h)
        np.testing.assert_allclose(Jq[..., j], num, atol=1e-5 * max(1.0, np.abs(num).max()))


def test_base_entries_move_the_base_as_documented():
    lay = Layout(IRB2600, np.eye(4), ("A",))
    x = lay.initial([[10.0, 0, 0]])
    x[lay.base_slice] = [5.0, -3.0, 2.0, 0.01, -0.02, 0.03]
    B = lay.base(x)
    lay2, y = lay.rebased(x)
    q = np.zeros((1, 6))
    np.testing.assert_allclose(predict(lay, x, q), predict(lay2, y, q), atol=1e-9)
    np.testing.assert_allclose(lay2.base_ref, B)
