"""The virtual cell: determinism, pose constraints, tracker noise, nominal-model error, effects."""

import json

import numpy as np
import pytest
from scipy.optimize import least_squares

from robocal.drivers.cell import GeometricErrors, TrackerSpec, VirtualCell
from robocal.solver.kinematics import (
    Layout,
    flange_frames,
    predict,
    predict_with_jacobian,
    translation,
)
from robocal.solver.robot import IRB2600
from tests.robots import KUKA_LIKE, PUMA_LIKE, TARGETS


def irb_cell(seed=1, **kw):
    return VirtualCell.random(IRB2600, TARGETS, seed=seed, **kw)


def assert_constraints(cell, q):
    """Every pose constraint, recomputed here from the kinematics rather than from the cell."""
    robot = cell.true_robot
    assert np.all(robot.within_limits(q, np.deg2rad(2.0) - 1e-12))
    lay = Layout(robot, cell.base, cell.target_names)
    x = lay.initial(cell.true_targets)
    p = predict(lay, x, q)
    np.testing.assert_allclose(p, cell.true_points(q), atol=1e-9)
    base_lay = Layout(robot, np.eye(4), cell.target_names)
    p_base = predict(base_lay, base_lay.initial(cell.true_targets), q)
    assert np.all(p_base[..., 2] >= cell.floor_clearance_mm)
    R, _ = flange_frames(lay, x, q)
    dist = np.linalg.norm(p, axis=-1)
    assert np.all(dist >= 1000.0)
    cos_to_tracker = np.einsum("mj,mkj->mk", R[:, :, 2], -p) / dist
    assert np.all(cos_to_tracker >= np.cos(cell.acceptance_rad))
    _, o_base = flange_frames(base_lay, base_lay.initial(cell.true_targets), q)
    assert np.all(np.hypot(o_base[:, 0], o_base[:, 1]) >= 300.0)
    # the true geometry moves the singularity by hundredths of a degree
    assert np.all(np.abs(np.sin(q[:, 4])) >= np.sin(np.deg2rad(10.0)) - 1e-3)


def nominal_model_ap(cell, meas, fit_targets=True):
    """Per-reading AP (mm) of the nominal geometry with a best-fit base (and SMR positions)."""
    lay = Layout(cell.nominal_robot, cell.base, cell.target_names)
    x0 = lay.initial(cell.nominal_targets)
    free = list(range(lay.base_slice.start, lay.base_slice.stop))
    if fit_targets:
        free += list(range(lay.target_slice.start, lay.target_slice.stop))

    def fun(z):
        x = x0.copy()
        x[free] = z
        p, J, _ = predict_with_jacobian(lay, x, meas.q)
        return (p - meas.xyz).ravel(), J[..., free].reshape(-1, len(free))

    sol = least_squares(lambda z: fun(z)[0], x0[free], jac=lambda z: fun(z)[1])
    return np.linalg.norm(sol.fun.reshape(-1, 3), axis=1)


def test_tracker_sigma_is_half_the_mpe():
    spec = TrackerSpec()
    assert spec.sigma_mm(0.0) == pytest.approx(0.005)
    np.testing.assert_allclose(spec.sigma_mm([2000.0, 4000.0]), [0.0075, 0.010])


def test_geometric_error_sigmas_follow_parameter_names():
    s = GeometricErrors().sigmas(IRB2600.param_names())
    named = dict(zip(IRB2600.param_names(), s))
    assert named["a2"] == named["d4"] == 0.5
    assert named["theta3"] == pytest.approx(np.deg2rad(0.05))
    assert named["alpha1"] == pytest.approx(np.deg2rad(0.03))
    assert named["beta2"] == pytest.approx(np.deg2rad(0.03))
    assert sum(n.startswith("beta") for n in named) == sum(IRB2600.parallel)


def test_same_seed_same_cell_and_campaign():
    a, b = irb_cell(7), irb_cell(7)
    np.testing.assert_array_equal(a.base, b.base)
    np.testing.assert_array_equal(a.true_robot.param_vector(), b.true_robot.param_vector())
    np.testing.assert_array_equal(a.true_targets, b.true_targets)
    ma = a.campaign(30, seed=3, beam_break_rate=0.1)
    mb = b.campaign(30, seed=3, beam_break_rate=0.1)
    for f in ("q", "xyz", "time_s", "temp_c"):
        np.testing.assert_array_equal(getattr(ma, f), getattr(mb, f))
    assert not np.array_equal(irb_cell(8).base, a.base)
    assert not np.array_equal(a.campaign(30, seed=4).q, ma.q)


def test_true_geometry_differs_from_nominal_by_the_error_model():
    cell = irb_cell(2)
    diff = cell.true_robot.param_vector() - IRB2600.param_vector()
    z = diff / GeometricErrors().sigmas(IRB2600.param_names())
    assert 0.4 < np.std(z) < 2.0
    assert 0.2 < np.std(cell.true_targets - cell.nominal_targets) < 3.0


@pytest.mark.parametrize("seed", range(20))
def test_tracker_placement(seed):
    tracker_in_base = np.linalg.inv(irb_cell(seed).base)
    x, y, z = tracker_in_base[:3, 3]
    assert 2500.0 <= np.hypot(x, y) <= 4500.0
    assert abs(np.arctan2(y, x)) <= np.deg2rad(60.0)
    assert 300.0 <= z <= 1200.0
    assert tracker_in_base[2, 2] >= np.cos(np.deg2rad(0.1))  # level within 0.1 deg


def test_sampled_poses_meet_every_constraint():
    cell = irb_cell(3)
    q = cell.sample_poses(300, np.random.default_rng(0))
    assert q.shape == (300, 6)
    assert_constraints(cell, q)
    assert all(ok.all() for ok in cell.pose_checks(q).values())


def test_impossible_constraints_raise():
    cell = irb_cell(3, floor_clearance_mm=5000.0)
    with pytest.raises(ValueError, match="floor: keep the SMRs above the floor"):
        cell.sample_poses(10, np.random.default_rng(0), max_batches=3)


def test_noise_statistics_match_the_spec():
    cell = irb_cell(4)
    rng = np.random.default_rng(5)
    q = cell.sample_poses(1700, rng)  # 5100 readings
    p = cell.true_points(q)
    d = cell.measure(q, rng) - p
    sigma = cell.tracker.sigma_mm(np.linalg.norm(p, axis=-1))
    expected = np.sqrt(np.mean(sigma**2))
    for axis in range(3):
        assert np.sqrt(np.mean(d[..., axis] ** 2)) == pytest.approx(expected, rel=0.1)
        assert np.std(d[..., axis] / sigma) == pytest.approx(1.0, rel=0.1)
    floor = cell.noise_floor_mm(q)
    assert np.sqrt(np.mean(np.sum(d**2, axis=-1))) == pytest.approx(floor, rel=0.1)
    assert 0.01 < floor < 0.03  # 3-5 m from a 10 um + 2.5 um/m tracker


@pytest.mark.parametrize("seed", range(5))
def test_nominal_model_error_is_like_the_paper(seed):
    cell = irb_cell(seed)
    ap = nominal_model_ap(cell, cell.campaign(100, seed=100 + seed))
    assert 0.5 <= ap.mean() <= 3.0
    assert ap.max() < 7.0


def test_campaign_timing_temperature_and_ids():
    cell = irb_cell(5)
    m = cell.campaign(60, seed=1)
    assert m.pose_ids == [str(i) for i in range(1, 61)]
    assert m.xyz.shape == (60, 3, 3) and m.time_s.shape == m.temp_c.shape == (60, 3)
    step = np.diff(m.time_s[:, 0])
    assert 16.0 < step.mean() < 20.0 and step.min() > 12.0
    gaps = np.diff(m.time_s, axis=1)
    assert np.all((gaps > 1.0) & (gaps < 3.0))
    assert abs(m.temp_c[0, 0] - 20.0) < 1.5
    trend = np.polyval(np.polyfit(m.time_s.ravel(), m.temp_c.ravel(), 1), m.time_s.ravel())
    assert 0.1 < abs(trend.max() - trend.min()) < 1.0
    assert np.std(m.temp_c.ravel() - trend) == pytest.approx(0.02, rel=0.3)


def test_beam_breaks_drop_the_expected_fraction():
    cell = irb_cell(6)
    m = cell.campaign(1000, seed=2, beam_break_rate=0.2)
    missing = ~m.mask
    assert missing.mean() == pytest.approx(0.2, abs=0.03)  # about 4 binomial sigmas
    assert np.all(np.isnan(m.xyz[missing])) and np.all(np.isfinite(m.xyz[~missing]))
    assert np.all(np.isnan(m.time_s[missing])) and np.all(np.isnan(m.temp_c[missing]))
    assert cell.campaign(50, seed=2).n_readings == 150


def test_truth_is_json_and_complete():
    cell = irb_cell(9)
    assert cell.truth()["noise_floor_mm"] is None
    m = cell.campaign(20, seed=1)
    truth = json.loads(json.dumps(cell.truth()))
    assert truth["seed"] == 9 and truth["robot"] == "irb2600"
    assert set(truth["true_params"]) == set(IRB2600.param_names())
    assert truth["nominal_params"]["alpha1"] == pytest.approx(-90.0)
    assert truth["true_params"]["theta2"] == pytest.approx(-90.0, abs=0.3)  # degrees
    np.testing.assert_allclose(truth["true_targets"]["B"], cell.true_targets[1])
    np.testing.assert_allclose(truth["base"], cell.base)
    assert truth["tracker"] == {"mpe_um": 10.0, "mpe_um_per_m": 2.5}
    assert truth["noise_floor_mm"] == pytest.approx(cell.noise_floor_mm(m.q))


class KickAndShift:
    """Test-only effect: joint 2 reads 1 mrad short; the base rises 2 mm at t = 100 s."""

    def joint_offsets(self, cell, q, time_s, temp_c):
        dq = np.zeros_like(q)
        dq[:, 1] = 1e-3
        return dq

    def base_motion(self, cell, time_s, temp_c):
        if time_s is None:
            return None
        after = (np.asarray(time_s) >= 100.0)[:, None, None]
        return np.where(after, translation(0, 0, 2.0), np.eye(4))


def test_effects_hook_applies_joint_offsets_and_base_motion():
    cell = irb_cell(10)
    q = cell.sample_poses(10, np.random.default_rng(1))
    plain = cell.true_points(q)
    cell.effects.append(KickAndShift())
    lay = Layout(cell.true_robot, cell.base, cell.target_names)
    dq = np.zeros_like(q)
    dq[:, 1] = 1e-3
    kicked = predict(lay, lay.initial(cell.true_targets), q, dq)
    assert np.abs(kicked - plain).max() > 0.5
    np.testing.assert_allclose(cell.true_points(q), kicked, atol=1e-9)
    # per-reading times: the shift applies only to readings taken after it
    t = np.full((10, 3), 50.0)
    t[5:, 1:] = 150.0
    up = cell.base[:3, :3] @ [0.0, 0.0, 2.0]
    expected = kicked.copy()
    expected[5:, 1:] += up
    np.testing.assert_allclose(cell.true_points(q, time_s=t), expected, atol=1e-9)
    late = cell.true_points(q, time_s=np.full(10, 150.0))
    np.testing.assert_allclose(late, kicked + up, atol=1e-9)


@pytest.mark.parametrize("robot", [KUKA_LIKE, PUMA_LIKE], ids=lambda r: r.name)
def test_other_arms(robot):
    assert any(robot.parallel)
    cell = VirtualCell.random(robot, TARGETS, seed=11)
    m = cell.campaign(100, seed=12)
    assert_constraints(cell, m.q)
    ap = nominal_model_ap(cell, m)
    assert 0.2 <= ap.mean() <= 3.0
    json.dumps(cell.truth())


def test_campaign_options_draw_apart_from_the_default_campaign():
    """Scatter, absent SMRs and outliers leave poses, times and tracker noise draws as they were."""
    cell = irb_cell(11)
    plain = cell.campaign(40, seed=3)
    noisy = cell.campaign(40, seed=3, noise_scale=3.0)
    other = cell.campaign(40, seed=3, arm_scatter_deg=0.004, targets_per_pose=2, outlier_rate=0.02)
    for m in (noisy, other):
        np.testing.assert_array_equal(m.q, plain.q)
    true = cell.true_points(plain.q)
    np.testing.assert_allclose(noisy.xyz - true, 3.0 * (plain.xyz - true), atol=1e-9)
    assert cell.campaign(40, seed=3, noise_scale=2.5).n_readings == 120
    assert cell.last_campaign["noise_floor_mm"] == pytest.approx(2.5 * cell.noise_floor_mm(plain.q))


def test_arm_scatter_moves_each_pose_rigidly_and_afresh():
    """A joint error per pose moves the flange: SMR-to-SMR distances hold, the SMRs do not."""
    cell = irb_cell(12)
    still = cell.campaign(200, seed=4, noise_scale=0.0)
    moved = cell.campaign(200, seed=4, noise_scale=0.0, arm_scatter_deg=0.004)
    d = moved.xyz - still.xyz
    rms = np.sqrt(np.mean(np.sum(d**2, axis=-1)))
    assert rms == pytest.approx(cell.last_campaign["arm_scatter_rms_mm"])
    assert 0.05 < rms < 0.5  # 0.004 deg at a reach of 1-3 m
    for i, j in ((0, 1), (0, 2), (1, 2)):
        gap = [np.linalg.norm(m.xyz[:, i] - m.xyz[:, j], axis=-1) for m in (still, moved)]
        np.testing.assert_allclose(gap[1], gap[0], atol=1e-6)
    # consecutive poses share nothing: a per-pose draw, not a drift
    assert abs(np.corrcoef(d[1:, 0, 0], d[:-1, 0, 0])[0, 1]) < 0.25


def test_one_target_per_pose():
    cell = irb_cell(13)
    m = cell.campaign(90, seed=5, targets_per_pose=1)
    assert np.all(m.mask.sum(axis=1) == 1)
    assert np.all(m.mask.sum(axis=0) > 15)  # each SMR in turn, at random
    assert cell.truth()["campaign"]["targets_per_pose"] == 1


def test_outliers_are_displaced_and_listed():
    cell = irb_cell(14)
    clean = cell.campaign(100, seed=6, beam_break_rate=0.1)
    m = cell.campaign(100, seed=6, beam_break_rate=0.1, outlier_rate=0.02)
    listed = cell.truth()["campaign"]["outliers"]
    assert len(listed) == round(0.02 * clean.n_readings)
    d = np.linalg.norm(np.nan_to_num(m.xyz - clean.xyz), axis=-1)
    assert np.count_nonzero(d) == len(listed)
    for o in listed:
        i, k = int(o["pose"]) - 1, m.target_names.index(o["target"])
        assert 0.3 <= o["displacement_mm"] <= 2.0
        np.testing.assert_allclose(m.xyz[i, k] - clean.xyz[i, k], o["offset_mm"], atol=1e-9)
    json.dumps(cell.truth())
