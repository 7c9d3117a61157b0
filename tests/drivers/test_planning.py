"""Campaign planning: valid poses, move times, ordering, observability choice and its payoff."""

import numpy as np
import pytest

from robocal.drivers.cell import PosesTooConstrained, VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.planning import (
    candidate_jacobians,
    move_time,
    order_poses,
    plan_campaign,
    plan_poses,
    total_move_time,
)
from robocal.drivers.world import ACCEL_S, SimulatedWorld
from robocal.solver.calibrate import calibrate
from robocal.solver.kinematics import Layout, flange_frames, predict, rot, translation
from robocal.solver.observability import observability_indices, select_poses, unit_columns
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

T = np.array(list(TARGETS.values()))
BOUNDS = ((-400.0, -2000.0, 150.0), (2000.0, 2000.0, 1700.0))  # mm, base frame


def cell(seed=1):
    return VirtualCell.random(IRB2600, TARGETS, seed=seed)


def approximate(base):
    """The tracker placement as a rough registration knows it: a few mm and a few tenths off."""
    return base @ translation(4.0, -3.0, 2.0) @ rot(2, np.deg2rad(0.3))


def assert_constraints(robot, base, q, bounds=None, acceptance_deg=60.0, floor_mm=150.0):
    """Every pose constraint, recomputed from the kinematics rather than from the planner."""
    names = tuple(TARGETS)
    assert np.all(robot.within_limits(q, np.deg2rad(2.0) - 1e-12))
    lay = Layout(robot, base, names)
    x = lay.initial(T)
    p = predict(lay, x, q)  # tracker frame; the tracker sits at its origin
    dist = np.linalg.norm(p, axis=-1)
    assert np.all(dist >= 1000.0)
    R, _ = flange_frames(lay, x, q)
    facing = np.einsum("mj,mkj->mk", R[:, :, 2], -p) / dist
    assert np.all(facing >= np.cos(np.deg2rad(acceptance_deg)))
    base_lay = Layout(robot, np.eye(4), names)
    p_base = predict(base_lay, base_lay.initial(T), q)
    assert np.all(p_base[..., 2] >= floor_mm)
    _, o_base = flange_frames(base_lay, base_lay.initial(T), q)
    assert np.all(np.hypot(o_base[:, 0], o_base[:, 1]) >= 300.0)
    # IRB 2600: axes 4 and 6 are parallel when sin(q5) = 0
    assert np.all(np.abs(np.sin(q[:, 4])) >= np.sin(np.deg2rad(10.0)) - 1e-9)
    if bounds is not None:
        assert np.all((p_base >= bounds[0]) & (p_base <= bounds[1]))


def test_planned_poses_meet_every_constraint():
    base = approximate(cell().base)
    q = plan_poses(IRB2600, base, T, 300, np.random.default_rng(0), bounds=BOUNDS)
    assert q.shape == (300, 6)
    assert_constraints(IRB2600, base, q, BOUNDS)
    # the box does bite: poses planned without it leave it
    free = plan_poses(IRB2600, base, T, 300, np.random.default_rng(0))
    assert_constraints(IRB2600, base, free)
    with pytest.raises(AssertionError):
        assert_constraints(IRB2600, base, free, BOUNDS)


def test_narrow_acceptance_and_high_floor_are_honoured():
    base = cell(2).base
    q = plan_poses(
        IRB2600, base, T, 100, np.random.default_rng(1), acceptance_deg=40.0, floor_mm=600.0
    )
    assert_constraints(IRB2600, base, q, acceptance_deg=40.0, floor_mm=600.0)


def test_planning_is_deterministic():
    base = cell().base
    a = plan_poses(IRB2600, base, T, 50, np.random.default_rng(5))
    b = plan_poses(IRB2600, base, T, 50, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)


def test_too_tight_constraints_raise_with_pass_rates():
    tiny = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    # a ValueError (422 in the API, one line in the CLI) naming the check and what to change
    with pytest.raises(
        PosesTooConstrained, match=r"only 0 of 10 poses valid.*bounds 0\.0%.*bounds: widen"
    ):
        plan_poses(
            IRB2600, cell().base, T, 10, np.random.default_rng(0), bounds=tiny, max_batches=2
        )


def test_move_time_matches_the_simulated_world():
    c = cell()
    q = plan_poses(IRB2600, c.base, T, 6, np.random.default_rng(2))
    world = SimulatedWorld(c, VirtualClock(), q_home=q[0])
    for qb in q[1:]:
        assert move_time(q[0], qb) == pytest.approx(world.move_duration(qb))
    assert move_time(q[0], q[0]) == pytest.approx(ACCEL_S)
    np.testing.assert_allclose(move_time(q[:1], q[1:]), [move_time(q[0], b) for b in q[1:]])


def test_ordering_is_a_permutation_that_never_lengthens_the_campaign():
    base = cell().base
    q = plan_poses(IRB2600, base, T, 100, np.random.default_rng(3))
    order = order_poses(q)
    np.testing.assert_array_equal(np.sort(order), np.arange(100))
    before, after = total_move_time(q), total_move_time(q, order)
    assert after < 0.75 * before  # random order wastes a lot of motion
    np.testing.assert_array_equal(order_poses(q), order)  # deterministic
    home = np.zeros(6)
    from_home = order_poses(q, start=home)
    assert total_move_time(q, from_home, home) <= total_move_time(q, None, home)
    # already short orders are kept at least as short
    for m in (1, 2, 3, 7):
        o = order_poses(q[order][:m])
        assert total_move_time(q[order][:m], o) <= total_move_time(q[order][:m]) + 1e-9


def test_ordering_finds_the_straight_sweep():
    q = np.zeros((30, 6))
    q[:, 0] = np.random.default_rng(4).permutation(np.linspace(-2.0, 2.0, 30))
    best = 4.0 / np.deg2rad(175.0) + 29 * ACCEL_S
    assert total_move_time(q, order_poses(q)) == pytest.approx(best)


def test_plan_campaign_chooses_and_orders():
    base = cell().base
    q, s = plan_campaign(IRB2600, base, TARGETS, 400, np.random.default_rng(6), k=40)
    assert q.shape == (40, 6) and s["n_poses"] == 40 and s["criterion"] == "D"
    assert_constraints(IRB2600, base, q)
    assert s["move_time_s"]["after"] <= s["move_time_s"]["before"]
    assert s["move_time_s"]["after"] == pytest.approx(total_move_time(q))
    chosen, random_ = s["observability"]["chosen"], s["observability"]["random"]
    assert chosen["log_det"] > random_["log_det"] and chosen["condition"] < random_["condition"]
    q_all, s_all = plan_campaign(IRB2600, base, T, 30, np.random.default_rng(6))
    assert q_all.shape == (30, 6) and s_all["criterion"] is None


def test_the_planning_reports_rising_progress_and_plans_the_same():
    base = cell().base
    seen = []
    q, _ = plan_campaign(
        IRB2600, base, TARGETS, 200, np.random.default_rng(6), k=20, progress=seen.append
    )
    q_quiet, _ = plan_campaign(IRB2600, base, TARGETS, 200, np.random.default_rng(6), k=20)
    np.testing.assert_array_equal(q, q_quiet)  # reporting changes nothing
    assert seen == sorted(seen) and 0 < seen[0] and seen[-1] < 1  # done is the caller's to say
    assert len([f for f in seen if 0.1 < f < 0.9]) >= 20  # each greedy pick and sweep
    J = candidate_jacobians(IRB2600, base, T, q_quiet)
    picks = []
    select_poses(J, 5, progress=picks.append)
    assert picks[:5] == [0.1, 0.2, 0.3, 0.4, 0.5] and picks[-1] < 1


def held_out_rms(c, q, idx, held, draws):
    """RMS (mm) over noise draws of an ls-sum calibration from poses q[idx] predicting `held`."""
    true = c.true_points(held)
    err = []
    for d in range(draws):
        meas = c.measure(q[idx], np.random.default_rng(100 + d))
        cal = calibrate(Problem(IRB2600, T, tuple(TARGETS), q[idx], meas), "ls-sum")
        err.append(np.mean(np.sum((predict(cal.layout, cal.x, held) - true) ** 2, axis=-1)))
    return float(np.sqrt(np.mean(err)))


def test_d_optimal_40_of_400_beats_a_random_40():
    c = cell(1)
    base = approximate(c.base)
    cand = plan_poses(IRB2600, base, T, 400, np.random.default_rng(10))
    J = unit_columns(candidate_jacobians(IRB2600, base, T, cand))
    d_opt = select_poses(J, 40, "D")
    rand = np.random.default_rng(11).choice(400, 40, replace=False)
    d_ind, r_ind = observability_indices(J[d_opt]), observability_indices(J[rand])
    assert d_ind["log_det"] > r_ind["log_det"] + 3.0
    assert d_ind["condition"] < r_ind["condition"]
    # the payoff: the model from the D-optimal poses predicts unseen poses at least as well.
    # Tracker noise dominates a single campaign, so compare over 20 noise draws; held-out
    # errors are against the true SMR centres, which a noisy reading would hide.
    held = c.sample_poses(100, np.random.default_rng(12))
    rms_d = held_out_rms(c, cand, d_opt, held, draws=20)
    rms_r = held_out_rms(c, cand, rand, held, draws=20)
    assert rms_d <= 1.05 * rms_r
