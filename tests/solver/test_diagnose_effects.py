"""The diagnosis finds hidden effects, in process: each test draws an effect at random from its
seed, simulates a campaign with it and checks the diagnosis names it, models it down to the noise
floor and (for a backlash) predicts in visit order. tests/server/test_diagnose.py checks the same
through the command line's files on a few of these draws."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import TrackerSpec, VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import metrics
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnose import diagnose
from robocal.solver.effects import Inputs, prepare
from robocal.solver.extended import predict_extended
from robocal.solver.kinematics import Layout, predict
from robocal.solver.problem import Problem
from tests.robots import KUKA_LIKE
from tests.sim import SimCell, default_cell

EFFECTS = ("joint_compliance", "joint_periodic", "joint_scale", "thermal_drift", "base_shift")
GRAVITY_JOINTS = (2, 3, 5)  # joints that carry a gravity torque on a floor-mounted 6R arm
POSES = 100


def cell_of(robot: str) -> SimCell:
    irb = default_cell()
    return irb if robot == "irb2600" else SimCell(KUKA_LIKE, irb.targets)


def robot_for(seed: int) -> str:
    return ("irb2600", "kuka-like")[seed % 2]


def geometric_ratio(cell, spec, seed):
    """Held-out RMS of a geometric-only calibration over the noise floor, for this effect spec."""
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    vc.effects.extend(make_effects([spec], vc, seed))
    meas = vc.campaign(150, seed=seed)
    names = meas.target_names
    targets = np.array([cell.targets[t] for t in names])
    fit = calibrate(Problem(cell.robot, targets, names, meas.q[:100], meas.xyz[:100]), "ls-sum")
    hold = slice(100, 150)
    err = predict(fit.layout, fit.x, meas.q[hold]) - meas.xyz[hold]
    return np.sqrt(np.nanmean(np.sum(err**2, axis=-1))) / vc.noise_floor_mm(meas.q[hold])


def aim(cell, spec, name, seed, target):
    """The magnitude whose geometric-only held-out error is `target` times the noise floor.

    The effect's share of the error grows linearly with its magnitude, so one probe where the
    effect dominates (ratio above 3) fixes the scale.
    """
    from robocal.drivers.effects import EFFECTS as FX

    m0 = FX[name].default
    for _ in range(6):
        probe = geometric_ratio(cell, f"{spec}={m0:.6g}", seed)
        if probe > 3.0:
            break
        m0 *= 4.0
    return m0 * np.sqrt(target**2 - 1.0) / np.sqrt(probe**2 - 1.0)


def draw(seed):
    """Effect, joint, harmonic and a magnitude giving 4-25x the noise floor, all from the seed.

    Seeds below 20 take the effect types in turn, so that every type meets both robots twice;
    the others draw it at random like everything else.
    """
    rng = np.random.default_rng(seed)
    name = str(rng.choice(EFFECTS))
    if seed < 20:
        name = EFFECTS[(seed // 2) % len(EFFECTS)]
    joint = harmonic = None
    if name == "joint_compliance":
        joint = int(rng.choice(GRAVITY_JOINTS))
    elif name in ("joint_periodic", "joint_scale"):
        joint = int(rng.integers(1, 7))
    if name == "joint_periodic":
        harmonic = int(rng.integers(1, 3))
    target = float(np.exp(rng.uniform(np.log(4.0), np.log(25.0))))
    spec = name + "".join(f":{v}" for v in (joint, harmonic) if v is not None)
    return spec, name, joint, harmonic, target


def draw_backlash(seed):
    """A backlash joint and a magnitude multiple (4-25x the floor) from the seed; the generator
    goes on to shuffle the poses."""
    rng = np.random.default_rng(seed)
    joint = int(rng.integers(1, 7))
    target = float(np.exp(rng.uniform(np.log(4.0), np.log(25.0))))
    return joint, target, rng


def simulated(cell, seed, specs, poses=POSES):
    """The campaign `robocal simulate --cell C --poses N --seed S --effect ...` makes, and its
    truth (with the noise floor), without the file."""
    vc = VirtualCell.random(
        cell.robot,
        cell.targets,
        seed=seed,
        tracker=TrackerSpec(),  # the cell's default spec
    )
    vc.effects.extend(make_effects(specs, vc, seed))
    meas = vc.campaign(poses, seed=seed)
    truth = vc.truth()
    truth["noise_floor_mm"] = vc.noise_floor_mm(meas.q)
    return meas, truth


def diagnosed(cell, meas):
    """The diagnosis `robocal diagnose` runs on a campaign."""
    return diagnose(cell.problem(meas))


def figure_of(d, effect):
    """The figure data the diagnosis keeps for a named effect (written as a PNG by the server)."""
    labels = [f.label for f in d.figures]
    ext = next(e for e in d.extensions if e.name == effect["name"])
    return d.figures[labels.index(ext.label())] if ext.label() in labels else None


def predict_poses(cell, d, q, time_s=None, temp_c=None):
    """SMR centres (m, K, 3) the diagnosis's extended model predicts for poses visited in order
    (by time_s when given, else as listed)."""
    lay, x = d.layout, d.x
    K = len(lay.target_names)
    inputs = Inputs(q, time_s, temp_c)
    nominal = Layout(cell.robot, np.eye(4), lay.target_names)
    nx = nominal.initial(np.zeros((K, 3)))
    bases = [prepare(e, nominal, nx, inputs) for e in d.extensions]
    return predict_extended(lay, x, d.extensions, inputs, bases)


@pytest.mark.parametrize("seed", range(24))
def test_hidden_effect_is_found(seed):
    robot = robot_for(seed)
    spec, name, joint, harmonic, target = draw(seed)
    cell = cell_of(robot)
    magnitude = aim(cell, spec, name, seed, target)
    meas, truth = simulated(cell, seed, [f"{spec}={magnitude:.6g}"])
    d = diagnosed(cell, meas)
    report = d.report.to_json()  # as report.json has it
    floor = truth["noise_floor_mm"]
    ratio = report["baseline"]["holdout_rmse_mm"] / floor
    assert 3.0 <= ratio <= 30.0, f"premise: geometric-only held-out error {ratio:.1f}x the floor"
    assert report["effects"], f"{spec}: nothing found ({ratio:.1f}x floor)"
    found = report["effects"][0]
    assert found["name"] == name, (spec, [e["name"] for e in report["effects"]])
    if joint is not None:
        assert found["joint"] == joint
    if harmonic is not None:
        assert found["harmonic"] == harmonic
    assert len(report["effects"]) == 1, [(e["name"], e.get("joint")) for e in report["effects"]]
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * floor
    assert figure_of(d, found) is not None, f"no figure for {found['name']}"
    if name == "base_shift":
        at = next(e for e in truth["effects"] if e["name"] == "base_shift")["at_s"]
        assert abs(found["at_s"] - at) < 40.0


@pytest.mark.parametrize("seed", range(200, 206))
def test_clean_campaign_has_no_effect(seed):
    meas, truth = simulated(cell_of(robot_for(seed)), seed, [])
    report = diagnosed(cell_of(robot_for(seed)), meas).report.to_json()  # as report.json has it
    assert report["effects"] == []
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * truth["noise_floor_mm"]
    assert report["noise_floor_mm"] == pytest.approx(truth["noise_floor_mm"], rel=0.25)


def test_two_effects_are_both_found():
    cell = cell_of("irb2600")
    meas, truth = simulated(cell, 300, ["joint_periodic:4:2=0.015", "thermal_drift=25"])
    report = diagnosed(cell, meas).report.to_json()  # as report.json has it
    names = {(e["name"], e.get("joint"), e.get("harmonic")) for e in report["effects"]}
    assert names == {("joint_periodic", 4, 2), ("thermal_drift", None, None)}
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * truth["noise_floor_mm"]


def test_extended_model_predicts_with_time_and_temperature():
    """The thermal model, evaluated on its own campaign with each pose's time and temperature,
    is at the noise floor (what `robocal evaluate` reports for it)."""
    cell = cell_of("irb2600")
    meas, truth = simulated(cell, 301, ["thermal_drift=30"])
    d = diagnosed(cell, meas)
    assert [e.name for e in d.report.effects] == ["thermal_drift"]
    assert [e.name for e in d.extensions] == ["thermal_drift"]
    pred = predict_poses(cell, d, meas.q, meas.time_s, meas.temp_c)
    acc = metrics.accuracy(pred, meas.xyz, meas.target_names)
    assert acc.rmse <= 1.3 * truth["noise_floor_mm"]


def rms(pred, xyz):
    return float(np.sqrt(np.nanmean(np.sum((pred - xyz) ** 2, axis=-1))))


@pytest.mark.parametrize("seed", range(400, 406))
def test_backlash_is_found_and_predicted_in_visit_order(seed):
    """A backlash on a joint drawn from the seed is named; prediction takes the visit order from
    time_s, else from the order the poses are given in."""
    robot = robot_for(seed)
    cell = cell_of(robot)
    joint, target, rng = draw_backlash(seed)
    spec = f"joint_backlash:{joint}"
    magnitude = aim(cell, spec, "joint_backlash", seed, target)
    meas, truth = simulated(cell, seed, [f"{spec}={magnitude:.6g}"])
    d = diagnosed(cell, meas)
    report = d.report.to_json()  # as report.json has it
    floor = truth["noise_floor_mm"]
    ratio = report["baseline"]["holdout_rmse_mm"] / floor
    assert 3.0 <= ratio <= 30.0, f"premise: geometric-only held-out error {ratio:.1f}x the floor"
    assert [(e["name"], e.get("joint")) for e in report["effects"]] == [
        ("joint_backlash", joint)
    ], (spec, magnitude, ratio, report["effects"])
    found = report["effects"][0]
    assert found["parameters"]["backlash_deg"] == pytest.approx(magnitude, rel=0.2)
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * floor
    assert figure_of(d, found) is not None

    shuffled = rng.permutation(meas.n_poses)  # listed order != visit order
    timed = predict_poses(cell, d, meas.q[shuffled], meas.time_s[shuffled])
    untimed = predict_poses(cell, d, meas.q)  # listed order = visit order
    wrong = predict_poses(cell, d, meas.q[shuffled])
    np.testing.assert_allclose(timed, untimed[shuffled], atol=2e-6)
    assert rms(timed, meas.xyz[shuffled]) <= 1.3 * floor
    assert rms(wrong, meas.xyz[shuffled]) > 2.0 * floor  # a shuffle without times is wrong
