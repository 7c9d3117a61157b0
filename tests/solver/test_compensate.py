"""Compensation on simulated cells: hidden geometric errors and compliance drawn from a seed, a
model calibrated and diagnosed from a campaign, joint commands solved for it and sent to the
virtual cell's true arm."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver.calibrate import calibrate
from robocal.solver.compensate import Model, compensate
from robocal.solver.configuration import confdata
from robocal.solver.diagnose import diagnose
from robocal.solver.robot import IRB2600
from tests.robots import PUMA_LIKE, UR5
from tests.sim import SimCell, default_cell

GRAVITY_JOINTS = (2, 3)  # joints carrying a large gravity torque on both arms


def cell_of(robot: str) -> SimCell:
    irb = default_cell()
    return irb if robot == "irb2600" else SimCell(PUMA_LIKE, irb.targets)


def campaign(robot: str, seed: int):
    """A virtual cell with hidden geometry and compliance on a joint drawn from the seed, and a
    campaign of it: (cell, virtual cell, measurements)."""
    cell = cell_of(robot)
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    joint = GRAVITY_JOINTS[np.random.default_rng(seed).integers(len(GRAVITY_JOINTS))]
    vc.effects.extend(make_effects([f"joint_compliance:{joint}=1.0"], vc, seed))
    return cell, vc, vc.campaign(100, seed=seed)


def simulated(robot: str, seed: int):
    """The campaign and the model a diagnosis of it (as `robocal diagnose` runs it) finds."""
    cell, vc, meas = campaign(robot, seed)
    d = diagnose(cell.problem(meas), screen_outliers=False)
    return cell, vc, meas, Model(d.layout, d.x, d.extensions, cell.robot)


def nominal_model(cell: SimCell, meas) -> Model:
    """What an uncalibrated cell knows: the nominal arm, registered to the tracker."""
    nom = calibrate(cell.problem(meas), "nominal")
    return Model(nom.layout, nom.x, [], cell.robot)


@pytest.mark.parametrize("robot", ["irb2600", "puma-like"])
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_compensated_joints_put_the_true_arm_on_target(robot, seed):
    cell, vc, meas, model = simulated(robot, seed)
    assert any(e.name == "joint_compliance" for e in model.extensions)
    q_want = vc.sample_poses(60, np.random.default_rng([seed, 7]))
    desired = vc.true_points(q_want)
    mask = np.ones(desired.shape[:2], dtype=bool)
    floor = vc.noise_floor_mm(q_want)

    nominal = compensate(nominal_model(cell, meas), desired, mask, q_want)
    calibrated = compensate(model, desired, mask, nominal.q)

    def miss(q):
        return float(np.sqrt(np.mean(np.sum((vc.true_points(q) - desired) ** 2, axis=-1))))

    lo, hi = vc.true_robot.lower, vc.true_robot.upper
    assert np.all((calibrated.q >= lo) & (calibrated.q <= hi))
    assert calibrated.converged.all()
    after = miss(calibrated.q)
    assert after <= 2 * floor, f"true arm misses by {after:.4f} mm RMS, noise floor {floor:.4f}"
    assert miss(nominal.q) > max(0.5, 20 * miss(calibrated.q))


@pytest.mark.parametrize("robot", [IRB2600, PUMA_LIKE, UR5])
def test_a_configuration_alone_gives_back_the_joints_it_was_taken_from(robot):
    """Joints drawn at random, their confdata computed, the SMRs they put on target asked for
    with the confdata alone: the same joints (one solution a configuration), where the old
    search from fixed starts turned joint 1 or the wrist half a turn away."""
    vc = VirtualCell.random(robot, default_cell().targets, seed=3)
    model = Model(*_true_layout(vc), [], robot)
    q = vc.sample_poses(30, np.random.default_rng(1))
    desired = vc.true_points(q)
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), cf=confdata(robot, q))
    assert res.error_mm.max() < 1e-6
    assert np.degrees(np.abs(res.q - q)).max() < 1e-3


def test_one_smr_on_an_arm_of_360_deg_joints_reaches_every_pose_in_its_configuration():
    """The real UR5 cell (every joint +-360 deg, one SMR near the flange axis): poses drawn within
    a turn of zero, asked for with their confdata alone, are all reached in it, joints 2 and 3
    within that turn. Seeded at joint 5's mid-range (180 deg, the wrist's singularity) one of the
    real campaign's own measured poses came out 'unreachable'; with equal seeds first among
    equals, joint 3 a turn away (-250 deg for 110)."""
    ur = replace(UR5, joints=tuple(replace(j, limits=(-2 * np.pi, 2 * np.pi)) for j in UR5.joints))
    vc = VirtualCell.random(ur, {"A": [0.0, 0.09, 31.0]}, seed=3)
    model = Model(*_true_layout(vc), [], ur)
    q = np.radians(np.random.default_rng(5).uniform(-170.0, 170.0, (40, 6)))
    q[:, 4] = np.where(np.abs(q[:, 4]) < np.radians(10.0), np.radians(30.0), q[:, 4])
    desired = vc.true_points(q)
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), cf=confdata(ur, q))
    assert res.error_mm.max() < 1e-6, res.error_mm.max()
    assert np.all(confdata(ur, res.q) == confdata(ur, q))
    assert np.degrees(np.abs(res.q[:, 1:3])).max() <= 180.0


def test_neither_joints_nor_configuration_is_refused():
    vc = VirtualCell.random(IRB2600, default_cell().targets, seed=3)
    model = Model(*_true_layout(vc), [], IRB2600)
    q = vc.sample_poses(3, np.random.default_rng(1))
    desired = vc.true_points(q)
    q0 = q.copy()
    q0[1] = np.nan
    with pytest.raises(ValueError, match="pose 2 has neither starting joints nor a configuration"):
        compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), q0)


def test_a_configuration_the_arm_cannot_take_there_has_no_solution():
    """Joint 1 asked in the quadrant opposite the target: no joints, an infinite miss."""
    vc = VirtualCell.random(IRB2600, default_cell().targets, seed=3)
    model = Model(*_true_layout(vc), [], IRB2600)
    q = vc.sample_poses(4, np.random.default_rng(1))
    desired = vc.true_points(q)
    cf = confdata(IRB2600, q)
    cf[2, 0] = cf[2, 0] + 2 if cf[2, 0] < 0 else cf[2, 0] - 2
    cf[2, 3] &= 3  # wrist centre in front of axis 1: the target is behind it
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), cf=cf)
    assert np.isnan(res.q[2]).all() and np.isinf(res.error_mm[2])
    assert res.error_mm[[0, 1, 3]].max() < 1e-6


def test_a_target_out_of_reach_keeps_its_miss():
    """A target 5 m from the base: the solve stops at the best the arm can do and says so."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=3)
    q = vc.sample_poses(3, np.random.default_rng(1))
    desired = vc.true_points(q)
    desired[1] += 5000.0
    model = Model(
        *_true_layout(vc),
        [],
        cell.robot,
    )
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), q)
    assert res.error_mm[1] > 1000.0
    assert res.error_mm[[0, 2]].max() < 1e-6


def _true_layout(vc):
    from robocal.solver.kinematics import Layout

    lay = Layout(vc.true_robot, vc.base, vc.target_names)
    return lay, lay.initial(vc.true_targets)


def test_backlash_and_thermal_are_compensated_in_the_programs_order():
    """A model with backlash on joint 1 and thermal growth: the joints found put the SMRs on
    target with each joint's approach from the previous pose and the given temperature, and
    differ from the geometric solution by those effects."""
    from robocal.solver.effects import Extension

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=4)
    lay, x = _true_layout(vc)
    exts = [
        Extension("joint_backlash", joint=0, coef=np.array([-np.deg2rad(0.02)])),
        Extension("thermal_drift", variable="temp_c", t_ref=20.0, coef=np.array([50e-6])),
    ]
    model = Model(lay, x, exts, cell.robot)
    q = vc.sample_poses(30, np.random.default_rng(2))
    desired = vc.true_points(q)
    mask = np.ones(desired.shape[:2], dtype=bool)
    temp = np.full(mask.shape, 24.0)
    res = compensate(model, desired, mask, q, temp_c=temp)
    # what is left is the SMR triangle grown by 200 ppm, which no joints can shrink (~0.012 mm)
    assert res.converged.all() and res.error_mm.max() < 0.015
    miss = np.sqrt(np.mean(np.sum((model.predict(res.q, temp_c=temp) - desired) ** 2, -1), 1))
    assert np.allclose(miss, res.error_mm, atol=1e-9)
    geometric = compensate(Model(lay, x, [], cell.robot), desired, mask, q)
    moved = np.degrees(res.q - geometric.q)
    # joint 1 turned by the play against its approach from the previous pose (the first mid-play)
    approach = np.sign(np.diff(res.q[:, 0]))
    # (to a few mdeg: the least-squares fit of the grown SMR triangle turns it a little too)
    assert np.all(np.sign(moved[1:, 0]) == approach)
    assert np.abs(moved[1:, 0] - 0.02 * approach).max() < 0.008
    # growth of 200 ppm two metres out of the base is 0.4 mm: the joints moved to undo it
    assert np.abs(geometric.error_mm).max() < 1e-6 and np.abs(moved[:, 1:3]).max() > 0.005


def test_a_pose_beyond_a_joint_limit_stays_within_it_and_keeps_its_miss():
    """SMRs where the arm would put them with joint 2 six degrees past its limit: the joints
    stay within the limits and the remaining miss says the pose is out of reach."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=3)
    q = vc.sample_poses(4, np.random.default_rng(1))
    q[2, 1] = vc.true_robot.lower[1] - np.deg2rad(6.0)
    desired = vc.true_points(q)
    model = Model(*_true_layout(vc), [], cell.robot)
    start = np.clip(q, vc.true_robot.lower, vc.true_robot.upper)
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), start)
    assert np.all((res.q >= vc.true_robot.lower) & (res.q <= vc.true_robot.upper))
    assert res.error_mm[2] > 10.0
    assert res.error_mm[[0, 1, 3]].max() < 1e-6


def test_prev_q_gives_a_shuffled_program_its_approach_directions():
    """The same backlash model and targets, shuffled, with the joints each pose comes from: the
    joints found are those of the program in order; shuffled without them, they are not."""
    from robocal.solver.effects import Extension

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=4)
    ext = Extension("joint_backlash", joint=1, coef=np.array([-np.deg2rad(0.05)]))
    model = Model(*_true_layout(vc), [ext], cell.robot)
    q = vc.sample_poses(21, np.random.default_rng(2))
    desired = vc.true_points(q)[1:]
    prev, q = q[:-1], q[1:]
    mask = np.ones(desired.shape[:2], dtype=bool)
    ordered = compensate(model, desired, mask, q, prev_q=prev)
    perm = np.random.default_rng(0).permutation(len(q))
    shuffled = compensate(model, desired[perm], mask[perm], q[perm], prev_q=prev[perm])
    assert np.degrees(np.abs(shuffled.q - ordered.q[perm])).max() < 1e-6
    blind = compensate(model, desired[perm], mask[perm], q[perm])
    assert np.degrees(np.abs(blind.q - ordered.q[perm])).max() > 0.05


def test_a_pose_whose_best_joints_lie_on_a_limit_converges_there():
    """SMRs where joint 2 would stand a tenth of a degree past its limit (a calibrated arm's
    pose at its limit, compensated): the best joints within the limits hold joint 2 on it and
    the others where the miss is least given that (no joint's gradient points inside its
    range). The step is solved over the free joints, so the pose meets the step test; the
    clipped full step pushed at the bound, its joint-2 part never shrinking, until max_iter (and
    a configuration search's starts that walked onto a limit kept the whole batch iterating)."""
    from robocal.solver.compensate import solve

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=3)
    q = vc.sample_poses(4, np.random.default_rng(1))
    lo, hi = vc.true_robot.lower, vc.true_robot.upper
    q[2, 1] = lo[1] - np.deg2rad(0.1)
    desired = vc.true_points(q)
    mask = np.ones(desired.shape[:2], dtype=bool)
    model = Model(*_true_layout(vc), [], cell.robot)
    start = np.clip(q + np.deg2rad(3.0), lo, hi)  # off the solutions, joint 2 inside its range
    res = solve(model, desired, mask, start, np.repeat(lo[None], 4, 0), np.repeat(hi[None], 4, 0))
    assert res.converged.all() and res.iterations < 100, res.iterations
    print(
        f"\n{res.iterations} iterations; the pose at the limit misses by {res.error_mm[2]:.3f} mm"
    )
    assert res.q[2, 1] == lo[1] and res.error_mm[2] > 0.1
    assert res.error_mm[[0, 1, 3]].max() < 1e-6
    # at the bound's optimum the cost's gradient is zero in the free joints and points out of
    # the range in the held one
    _, J = model.evaluate(res.q[2:3])
    g = np.einsum("kci,kc->i", J[0], model.predict(res.q[2:3])[0] - desired[2])
    assert g[1] > 0.0 and np.abs(np.delete(g, 1)).max() < 1e-6 * np.abs(g[1]), g


def test_a_batch_of_poses_is_solved_as_each_pose_alone():
    """Poses of a geometric model are walked only while they iterate: each pose's joints in a
    batch are those it is solved to alone, bit for bit."""
    from robocal.solver.compensate import solve

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=5)
    q = vc.sample_poses(12, np.random.default_rng(2))
    lo, hi = vc.true_robot.lower, vc.true_robot.upper
    q[3, 2] = hi[2] + np.deg2rad(4.0)  # one on a limit, iterating longer than the rest
    desired = vc.true_points(q)
    mask = np.ones(desired.shape[:2], dtype=bool)
    model = Model(*_true_layout(vc), [], cell.robot)
    start = np.clip(q + np.deg2rad(2.0), lo, hi)
    both = (np.repeat(lo[None], 12, 0), np.repeat(hi[None], 12, 0))
    batch = solve(model, desired, mask, start, *both)
    for i in range(12):
        one = solve(
            model, desired[i : i + 1], mask[i : i + 1], start[i : i + 1], lo[None], hi[None]
        )
        assert np.array_equal(one.q[0], batch.q[i]) and one.error_mm[0] == batch.error_mm[i], i
