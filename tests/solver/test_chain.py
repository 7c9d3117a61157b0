"""The one walk down the chain: the twist normal equations equal J'J of its explicit Jacobian."""

import numpy as np
import pytest

from robocal.drivers.effects import link_frames
from robocal.solver.kinematics import (
    Layout,
    flange_frames,
    joint_frames,
    predict,
    predict_rows,
    predict_with_jacobian,
)
from robocal.solver.normal import PointNormal
from robocal.solver.robot import Joint, Robot


def _random_robot(rng) -> Robot:
    """A robot of 3 to 7 joints with random lengths and twists, some axes parallel (beta)."""
    n = int(rng.integers(3, 8))
    alphas = rng.choice([0.0, np.pi / 2, -np.pi / 2, 0.3], size=n)
    joints = tuple(
        Joint(
            a=float(rng.uniform(0, 800)),
            d=float(rng.uniform(-300, 800)),
            theta=float(rng.uniform(-np.pi, np.pi)),
            alpha=float(alpha),
            limits=(-np.pi, np.pi),
        )
        for alpha in alphas
    )
    return Robot(f"random-{n}", str(rng.choice(["dh", "mdh"])), joints)


def _case(seed, missing):
    rng = np.random.default_rng(seed)
    robot = _random_robot(rng)
    K = int(rng.integers(1, 5))
    angle = rng.uniform(0, 2 * np.pi)
    base = np.eye(4)
    base[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    base[:3, 3] = rng.uniform(-3000, 3000, 3)
    lay = Layout(robot, base, tuple("ABCD"[:K]))
    x = lay.initial(rng.uniform(-80, 80, (K, 3))) + rng.normal(0, 1e-3, lay.n_params)
    q = rng.uniform(-np.pi, np.pi, size=(int(rng.integers(5, 60)), robot.n_joints))
    meas = predict(lay, x + rng.normal(0, 1e-2, lay.n_params), q)
    meas[rng.random(meas.shape[:2]) < missing] = np.nan
    return rng, lay, x, q, meas


@pytest.mark.parametrize("seed", range(12))
def test_twist_normal_equations_equal_the_plain_jacobian_path(seed):
    rng, lay, x, q, meas = _case(seed, missing=0.3 if seed % 2 else 0.0)
    mask = np.all(np.isfinite(meas), axis=-1)
    cols = rng.permutation(lay.n_params)[: rng.integers(lay.n_params // 2, lay.n_params + 1)]
    p, Jt = predict_rows(lay, x, q, mask, cols)
    J = Jt.reshape(len(cols), -1)
    r = (p - meas[mask]).ravel()
    ne = PointNormal(lay, q, mask, meas, cols)(x)
    A = J @ J.T
    np.testing.assert_allclose(ne.A, A, rtol=0, atol=1e-11 * np.abs(A).max())
    np.testing.assert_allclose(ne.g, J @ r, rtol=0, atol=1e-11 * np.abs(J @ r).max())
    assert ne.cost == pytest.approx(r @ r, rel=1e-11)


@pytest.mark.parametrize("seed", range(4))
def test_jacobian_of_the_walk_matches_finite_differences(seed):
    _, lay, x, q, _ = _case(100 + seed, missing=0.0)
    _, J, Jq = predict_with_jacobian(lay, x, q)
    h = 1e-6
    for c in range(lay.n_params):
        e = np.zeros(lay.n_params)
        e[c] = h
        fd = (predict(lay, x + e, q) - predict(lay, x - e, q)) / (2 * h)
        np.testing.assert_allclose(J[..., c], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
    for j in range(q.shape[1]):
        dq = np.zeros_like(q)
        dq[:, j] = h
        fd = (predict(lay, x, q, dq) - predict(lay, x, q, -dq)) / (2 * h)
        np.testing.assert_allclose(Jq[..., j], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("seed", range(4))
def test_link_frames_agree_with_the_walk_and_each_shorter_arm(seed):
    rng = np.random.default_rng(200 + seed)
    robot = _random_robot(rng)
    q = rng.uniform(-np.pi, np.pi, size=(7, robot.n_joints))
    axes, points, R, o = link_frames(robot, q)
    lay = Layout(robot, np.eye(4), ())
    x = lay.initial(np.zeros((0, 3)))
    for j, (Rj, oj) in enumerate(joint_frames(lay, x, q)):
        np.testing.assert_allclose(axes[:, j], Rj[..., 2], atol=1e-12)
        np.testing.assert_allclose(points[:, j], oj, atol=1e-9)
    for j in range(robot.n_joints):
        sub = Robot(robot.name, robot.convention, robot.joints[: j + 1], robot.parallel[: j + 1])
        sl = Layout(sub, np.eye(4), ())
        Rf, of = flange_frames(sl, sl.initial(np.zeros((0, 3))), q[:, : j + 1])
        np.testing.assert_allclose(R[:, j], Rf, atol=1e-12)
        np.testing.assert_allclose(o[:, j], of, atol=1e-9)
