"""Physics effects of the virtual cell: each one's law, spec parsing, determinism, the CLI."""

import json

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import EFFECTS, make_effect, make_effects
from robocal.solver.calibrate import calibrate
from robocal.solver.kinematics import Layout, predict
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600, Robot
from tests import cli_process
from tests.robots import PUMA_LIKE, TARGETS


def cell_with(spec, seed=1, robot=IRB2600, rng_seed=0):
    cell = VirtualCell.random(robot, TARGETS, seed=seed)
    effect = make_effect(spec, cell, np.random.default_rng(rng_seed))
    cell.effects.append(effect)
    return cell, effect


def poses(cell, n=40, seed=2):
    return cell.sample_poses(n, np.random.default_rng(seed))


def true_arm(cell, q, dq=None):
    """SMR centres of the true geometry, without any effect, with joint corrections dq."""
    lay = Layout(cell.true_robot, cell.base, cell.target_names)
    return predict(lay, lay.initial(cell.true_targets), q, dq)


def to_base(cell, p):
    inv = np.linalg.inv(cell.base)
    return p @ inv[:3, :3].T + inv[:3, 3]


def test_periodic_is_a_sine_of_k_times_the_joint():
    cell, eff = cell_with("joint_periodic:3:2=0.02")
    q = poses(cell)
    phase = np.deg2rad(eff.describe()["phase_deg"])
    dq = np.zeros_like(q)
    dq[:, 2] = np.deg2rad(0.02) * np.sin(2 * q[:, 2] + phase)
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q, dq), atol=1e-9)
    assert np.abs(cell.true_points(q) - true_arm(cell, q)).max() > 0.1


def test_periodic_draws_its_harmonic_when_not_given():
    drawn = {
        make_effect(
            "joint_periodic:2", cell_with("joint_scale:1")[0], np.random.default_rng(s)
        ).harmonic
        for s in range(20)
    }
    assert drawn == {1, 2}


@pytest.mark.parametrize(
    "spec, joint, driver",
    [
        ("joint_scale:2=250", 1, 1),  # scale: the joint's own angle
        ("joint_coupling:5=250", 4, 3),  # wrist coupling: the joint before it
    ],
)
def test_linear_effects_grow_with_their_joint_angle(spec, joint, driver):
    cell, _ = cell_with(spec)
    q = poses(cell)
    dq = np.zeros_like(q)
    dq[:, joint] = 250e-6 * q[:, driver]
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q, dq), atol=1e-9)


def test_backlash_lags_behind_the_last_move_in_visit_order():
    cell, eff = cell_with("joint_backlash:3=0.02")
    q = poses(cell)
    q[5, 2] = q[4, 2]  # joint 3 stands still: it keeps the direction of its previous move
    step = np.sign(np.diff(q[:, 2]))
    d = np.concatenate(
        [[0.0], np.where(step == 0, np.roll(step, 1), step)]
    )  # first pose: no move yet
    dq = np.zeros_like(q)
    dq[:, 2] = -np.deg2rad(0.02) * d
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q, dq), atol=1e-9)
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q, dq), atol=1e-9)  # read again


def test_backlash_is_the_same_campaign_at_once_or_pose_by_pose():
    """The batch campaign and the socket-driven world (moves, then one read per SMR, some twice)."""
    from robocal.drivers.clock import VirtualClock
    from robocal.drivers.world import SimulatedWorld

    rng = np.random.default_rng(11)
    joint = int(rng.integers(1, 7))
    spec = f"joint_backlash:{joint}={rng.uniform(0.005, 0.05):.4f}"

    def fresh():
        cell = VirtualCell.random(IRB2600, TARGETS, seed=3)
        cell.effects.extend(make_effects([spec], cell, 3))
        return cell

    batch = fresh()
    m = batch.campaign(25, seed=4)
    at_once = batch.true_points(m.q)
    world_cell = fresh()
    clock = VirtualClock()
    world = SimulatedWorld(world_cell, clock)
    by_pose = []
    for i, q in enumerate(m.q):
        clock.sleep(world.command_move(q) + 1.0)
        reads = [world.smr_positions() for _ in range(2 + i % 2)]
        np.testing.assert_array_equal(reads[0], reads[-1])
        by_pose.append(reads[0])
    np.testing.assert_allclose(np.array(by_pose), at_once, atol=1e-9)
    d = np.linalg.norm(at_once - cell_without_effects(batch).true_points(m.q), axis=-1)
    assert d[1:].min() > 1e-3  # the effect is on from the second pose


def cell_without_effects(cell):
    from dataclasses import replace

    return replace(cell, effects=[])


def body_positions(robot, mass, q):
    """Centres of gravity (m, bodies, 3) from the described mass model, through `predict`."""
    bodies = mass["links"] + [
        {"link": robot.n_joints, "mass_kg": mass["payload_kg"], "cog_mm": mass["payload_cog_mm"]}
    ]
    out = []
    for b in bodies:
        j = b["link"]
        sub = Robot(robot.name, robot.convention, robot.joints[:j], robot.parallel[:j])
        lay = Layout(sub, np.eye(4), ("g",))
        out.append(predict(lay, lay.initial([b["cog_mm"]]), q[:, :j])[:, 0])
    return np.stack(out, axis=1), np.array([b["mass_kg"] for b in bodies])


@pytest.mark.parametrize("robot", [IRB2600, PUMA_LIKE], ids=lambda r: r.name)
def test_compliance_torque_is_minus_the_gradient_of_the_potential_energy(robot):
    cell, eff = cell_with("joint_compliance:2", robot=robot)
    q = poses(cell, 20)
    mass = eff.describe()

    def energy(q):  # J, with g along -z of the base frame
        r, m = body_positions(cell.true_robot, mass, q)
        return 9.81 * np.sum(m * r[..., 2] / 1000.0, axis=1)

    tau = eff.mass.torques(cell.true_robot, q)
    h = 1e-6
    for j in range(robot.n_joints):
        step = np.zeros_like(q)
        step[:, j] = h
        fd = -(energy(q + step) - energy(q - step)) / (2 * h)
        np.testing.assert_allclose(tau[:, j], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
    if robot.convention == "dh":  # its first axis is exactly the base z (mdh tilts it by alpha1)
        assert np.abs(tau[:, 0]).max() < 1e-9  # a vertical axis carries no gravity torque
    assert np.abs(tau[:, 1]).max() > 100.0  # the shoulder carries the arm


def test_compliance_deflects_in_proportion_to_the_torque():
    cell, eff = cell_with("joint_compliance:2=0.5")
    q = poses(cell)
    tau = eff.mass.torques(cell.true_robot, q)[:, 1]
    dq = np.zeros_like(q)
    dq[:, 1] = 0.5e-6 * tau
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q, dq), atol=1e-9)
    twice = make_effect("joint_compliance:2=1.0", cell, np.random.default_rng(0))
    np.testing.assert_allclose(twice.joint_offsets(cell, q, None, None), 2 * dq, atol=1e-15)


def test_compliance_of_the_vertical_first_joint_does_nothing():
    cell, _ = cell_with("joint_compliance:1=5")
    q = poses(cell)
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q), atol=1e-9)


def test_mass_model_follows_its_recipe():
    for seed in range(10):
        _, eff = cell_with("joint_compliance:3", rng_seed=seed)
        d = eff.describe()
        masses = [b["mass_kg"] for b in d["links"]]
        assert len(masses) == 6 and all(2.5 <= m <= 1.5 * (5 + 25 * 1.4) for m in masses)
        assert 2.0 <= d["payload_kg"] <= 20.0
        assert np.linalg.norm(d["payload_cog_mm"]) <= 150.0


def test_thermal_scales_distances_from_the_base_origin():
    cell, eff = cell_with("thermal_drift=30")
    q = poses(cell, 10)
    eff.t0_c = 20.0
    temp = 20.0 + np.linspace(-1.0, 4.0, 30).reshape(10, 3)
    plain = np.linalg.norm(to_base(cell, true_arm(cell, q)), axis=-1)
    grown = np.linalg.norm(to_base(cell, cell.true_points(q, temp_c=temp)), axis=-1)
    np.testing.assert_allclose(grown / plain, 1 + 30e-6 * (temp - 20.0), rtol=1e-12)
    np.testing.assert_allclose(cell.true_points(q), true_arm(cell, q), atol=1e-9)  # no temperature


def test_thermal_warms_the_campaign_and_starts_from_its_first_reading():
    cell, eff = cell_with("thermal_drift")
    m = cell.campaign(80, seed=3)
    assert 2.0 <= eff.temperature_rise_c <= 5.0
    assert abs(eff.t0_c - m.temp_c[0, 0]) < 0.1  # the true air, the sensor adds 0.02 degC noise
    t = m.temp_c.ravel()
    assert t[-1] - t[0] > 1.5
    smooth = np.convolve(t, np.ones(15) / 15, mode="valid")
    assert np.all(np.diff(smooth) > -0.01)  # warming, give or take the sensor noise
    plain = VirtualCell.random(IRB2600, TARGETS, seed=1).campaign(80, seed=3)
    assert abs(plain.temp_c[-1, -1] - plain.temp_c[0, 0]) < 1.0  # no effect, no warming


def test_base_shift_moves_the_base_rigidly_at_its_time():
    cell, eff = cell_with("base_shift=0.5")
    q = poses(cell, 10)
    assert eff.at_s is None  # no campaign yet: no shift scheduled
    np.testing.assert_allclose(cell.true_points(q, time_s=np.full(10, 1e6)), true_arm(cell, q))
    eff.start_campaign(cell, np.linspace(0.0, 1000.0, 30).reshape(10, 3), None)
    assert 300.0 <= eff.at_s <= 700.0
    t = np.where(np.arange(10)[:, None] < 5, eff.at_s - 1.0, eff.at_s + 1.0) * np.ones((10, 3))
    moved = to_base(cell, cell.true_points(q, time_s=t))
    plain = to_base(cell, true_arm(cell, q))
    np.testing.assert_allclose(moved[:5], plain[:5], atol=1e-9)
    M = eff.motion
    np.testing.assert_allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.norm(M[:3, 3]) == pytest.approx(0.5)
    angle = np.arccos((np.trace(M[:3, :3]) - 1) / 2)
    assert angle == pytest.approx(0.5 / 2000.0, rel=1e-6)
    np.testing.assert_allclose(moved[5:], plain[5:] @ M[:3, :3].T + M[:3, 3], atol=1e-9)


def test_base_shift_happens_mid_campaign():
    cell, eff = cell_with("base_shift")
    m = cell.campaign(60, seed=4)
    span = np.nanmax(m.time_s)
    assert 0.3 * span <= eff.at_s <= 0.7 * span
    assert eff.describe()["at_s"] == eff.at_s


@pytest.mark.parametrize(
    "spec, name, joint, harmonic, magnitude",
    [
        ("joint_periodic:3:2=0.02", "joint_periodic", 3, 2, 0.02),
        ("joint_compliance:2", "joint_compliance", 2, None, EFFECTS["joint_compliance"].default),
        (" joint_scale:6=-40 ", "joint_scale", 6, None, -40.0),
        ("thermal_drift=20", "thermal_drift", None, None, 20.0),
        ("base_shift=0.3", "base_shift", None, None, 0.3),
        ("base_shift", "base_shift", None, None, 0.2),
        ("joint_backlash:4", "joint_backlash", 4, None, EFFECTS["joint_backlash"].default),
        ("joint_coupling:5=-300", "joint_coupling", 5, None, -300.0),
    ],
)
def test_spec_parsing(spec, name, joint, harmonic, magnitude):
    d = cell_with(spec)[1].describe()
    assert (d["name"], d["joint"], d["magnitude"]) == (name, joint, magnitude)
    if harmonic is not None:
        assert d["harmonic"] == harmonic
    assert d["unit"] == EFFECTS[name].unit


@pytest.mark.parametrize(
    "spec, message",
    [
        ("gravity", "unknown effect 'gravity'; choose from joint_compliance"),
        ("joint_periodic", "needs a joint, 1 to 6"),
        ("joint_periodic:0", "joint 0 is not one of the robot's joints 1 to 6"),
        ("joint_scale:7=5", "joint 7 is not one of"),
        ("joint_scale:two", "joint 'two' is not an integer"),
        ("joint_scale:2:1", "joint_scale takes only a joint"),
        ("joint_periodic:2:1:1", "takes a joint and a harmonic"),
        ("joint_periodic:2:0", "harmonic must be a positive integer"),
        ("joint_periodic:2:1.5", "harmonic '1.5' is not an integer"),
        ("thermal_drift:1", "thermal_drift takes no joint"),
        ("base_shift=far", r"magnitude 'far' is not a number \(in mm\)"),
        ("base_shift=", "magnitude '' is not a number"),
        ("base_shift=-0.1", "must not be negative"),
        ("joint_compliance:2=inf", "must be finite"),
        ("joint_backlash:2=-0.01", "must not be negative"),
        ("joint_coupling:1", "joint_coupling acts on joints 2 to 6"),
    ],
)
def test_bad_specs_are_refused(spec, message):
    cell = VirtualCell.random(IRB2600, TARGETS, seed=1)
    with pytest.raises(ValueError, match=message):
        make_effect(spec, cell, np.random.default_rng(0))


SPECS = ["joint_compliance:2", "joint_periodic:3", "joint_scale:1", "thermal_drift", "base_shift"]


def test_same_seed_same_effects_and_campaign():
    def run(seed):
        cell = VirtualCell.random(IRB2600, TARGETS, seed=5)
        cell.effects.extend(make_effects(SPECS, cell, seed))
        return cell.campaign(30, seed=6), cell.truth()

    (ma, ta), (mb, tb) = run(8), run(8)
    np.testing.assert_array_equal(ma.xyz, mb.xyz)
    np.testing.assert_array_equal(ma.temp_c, mb.temp_c)
    assert ta == tb and json.loads(json.dumps(ta))["effects"] == ta["effects"]
    assert [e["name"] for e in ta["effects"]] == [s.split(":")[0] for s in SPECS]
    mc, tc = run(9)
    assert tc["effects"] != ta["effects"] and not np.array_equal(mc.xyz, ma.xyz)
    assert tc["true_params"] == ta["true_params"]  # effects draw from their own stream


@pytest.mark.parametrize(
    "spec",
    [
        "joint_compliance:2",
        "joint_periodic:2",
        "joint_scale:2",
        "thermal_drift",
        "base_shift",
        "joint_backlash:2",
        "joint_coupling:5",
    ],
)
def test_defaults_are_clearly_visible_to_a_geometric_calibration(spec):
    cell = VirtualCell.random(IRB2600, TARGETS, seed=0)
    cell.effects.extend(make_effects([spec], cell, 0))
    m = cell.campaign(150, seed=1000)
    held = np.arange(150) % 3 == 0  # interleaved, so time-dependent effects reach both sets
    cal, hold = m.subset(~held), m.subset(held)
    nominal = np.array([TARGETS[n] for n in m.target_names])
    c = calibrate(Problem.of(IRB2600, nominal, cal), "ls-sum")
    rms = np.sqrt(np.mean(np.sum((predict(c.layout, c.x, hold.q) - hold.xyz) ** 2, axis=-1)))
    assert 3.0 < rms / cell.noise_floor_mm(m.q) < 30.0


def robocal(*args, cwd):
    return cli_process.run(*args, cwd=cwd, timeout=300)


def test_simulate_with_an_effect_end_to_end(tmp_path):
    r = robocal(
        "simulate",
        "--poses",
        30,
        "--seed",
        2,
        "--effect",
        "joint_periodic:3:2=0.02",
        "--effect",
        "base_shift",
        "--out",
        "m.csv",
        "--truth-out",
        "t.json",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    assert "joint_periodic:3:2=0.02 deg" in r.stdout and "base_shift=0.2 mm" in r.stdout
    effects = json.loads((tmp_path / "t.json").read_text())["effects"]
    periodic, shift = effects
    assert (periodic["name"], periodic["joint"], periodic["harmonic"]) == ("joint_periodic", 3, 2)
    assert periodic["magnitude"] == 0.02 and periodic["unit"] == "deg"
    assert 0.0 <= periodic["phase_deg"] < 360.0
    assert shift["name"] == "base_shift" and shift["at_s"] > 0.0

    r = robocal("simulate", "--help", cwd=tmp_path)
    inside, _, outside = " ".join(r.stdout.split()).partition("simulator only")
    assert "joint_backlash:J" in inside and "joint_coupling:J" in outside

    r = robocal("simulate", "--effect", "joint_periodic:9", "--out", "bad.csv", cwd=tmp_path)
    assert r.returncode != 0 and not (tmp_path / "bad.csv").exists()
    assert r.stderr.count("\n") == 1 and "joint 9 is not one of the robot's joints" in r.stderr
