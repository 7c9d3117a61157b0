"""diagnose finds hidden effects: each test draws an effect at random from its seed and checks the
report names it, through the command line."""

import json
import subprocess
import sys

import numpy as np
import pytest
from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.formats.cell_json import Cell, cell_to_json, default_cell
from robocal.solver.calibrate import calibrate
from robocal.solver.kinematics import predict

from tests.robots import KUKA_LIKE

EFFECTS = ("joint_compliance", "joint_periodic", "joint_scale", "thermal_drift", "base_shift")
GRAVITY_JOINTS = (2, 3, 5)  # joints that carry a gravity torque on a floor-mounted 6R arm


def cells(tmp_path):
    irb = default_cell()
    kuka = Cell(KUKA_LIKE, irb.targets)
    out = {}
    for name, cell in (("irb2600", irb), ("kuka-like", kuka)):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(cell_to_json(cell)))
        out[name] = (cell, path)
    return out


def robocal(*args, cwd):
    r = subprocess.run(
        [sys.executable, "-m", "robocal.server.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    return r


def geometric_ratio(cell, spec, seed):
    """Held-out RMS of a geometric-only calibration over the noise floor, for this effect spec."""
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    vc.effects.extend(make_effects([spec], vc, seed))
    meas = vc.campaign(150, seed=seed)
    names = meas.target_names
    targets = np.array([cell.targets[t] for t in names])
    fit = calibrate(cell.robot, targets, names, meas.q[:100], meas.xyz[:100], method="ls-sum")
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


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("diagnose")
    return d, cells(d)


def run(workdir, robot, seed, specs):
    d, cs = workdir
    cell, path = cs[robot]
    stem = f"{robot}-{seed}"
    args = [
        "simulate",
        "--cell",
        path,
        "--poses",
        100,
        "--seed",
        seed,
        "--out",
        f"{stem}.csv",
        "--truth-out",
        f"{stem}-truth.json",
    ]
    for s in specs:
        args += ["--effect", s]
    robocal(*args, cwd=d)
    robocal(
        "diagnose",
        f"{stem}.csv",
        "--cell",
        path,
        "--out",
        f"{stem}/report.json",
        "--model-out",
        f"{stem}/model.json",
        cwd=d,
    )
    report = json.loads((d / stem / "report.json").read_text())
    truth = json.loads((d / f"{stem}-truth.json").read_text())
    return report, truth, d / stem


@pytest.mark.parametrize("seed", range(24))
def test_hidden_effect_is_found(workdir, seed):
    robot = ("irb2600", "kuka-like")[seed % 2]
    spec, name, joint, harmonic, target = draw(seed)
    cell = workdir[1][robot][0]
    magnitude = aim(cell, spec, name, seed, target)
    report, truth, out = run(workdir, robot, seed, [f"{spec}={magnitude:.6g}"])
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
    assert (out / found["figure"]).stat().st_size > 10_000
    if name == "base_shift":
        at = next(e for e in truth["effects"] if e["name"] == "base_shift")["at_s"]
        assert abs(found["at_s"] - at) < 40.0


@pytest.mark.parametrize("seed", range(200, 206))
def test_clean_campaign_has_no_effect(workdir, seed):
    robot = ("irb2600", "kuka-like")[seed % 2]
    report, truth, _ = run(workdir, robot, seed, [])
    assert report["effects"] == []
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * truth["noise_floor_mm"]
    assert report["noise_floor_mm"] == pytest.approx(truth["noise_floor_mm"], rel=0.25)


def test_two_effects_are_both_found(workdir):
    report, truth, _ = run(
        workdir, "irb2600", 300, ["joint_periodic:4:2=0.015", "thermal_drift=25"]
    )
    names = {(e["name"], e.get("joint"), e.get("harmonic")) for e in report["effects"]}
    assert names == {("joint_periodic", 4, 2), ("thermal_drift", None, None)}
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * truth["noise_floor_mm"]


def test_extended_model_predicts_with_time_and_temperature(workdir):
    d, cs = workdir
    report, truth, out = run(workdir, "irb2600", 301, ["thermal_drift=30"])
    assert [e["name"] for e in report["effects"]] == ["thermal_drift"]
    model = json.loads((out / "model.json").read_text())
    assert model["extensions"][0]["name"] == "thermal_drift"
    r = robocal(
        "evaluate", out / "model.json", "irb2600-301.csv", "--json", out / "eval.json", cwd=d
    )
    ev = json.loads((out / "eval.json").read_text())
    assert ev["model"]["rmse"] <= 1.3 * truth["noise_floor_mm"]
    assert "improvement over nominal" in r.stdout


def read_predictions(path):
    rows = [line.split(",") for line in path.read_text().splitlines()[1:]]
    return {(r[0], r[1]): np.array([float(v) for v in r[2:5]]) for r in rows}


def write_poses(src, dst, order, keep_time):
    """A poses file from a meas.csv: its poses in `order`, with or without the time_s column."""
    lines = src.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, h in enumerate(head) if keep_time or h not in ("time_s", "temp_c")]
    by_pose = {}
    for line in lines[1:]:
        by_pose.setdefault(line.split(",")[0], []).append(line.split(","))
    ids = list(by_pose)
    out = [",".join(head[i] for i in keep)]
    out += [",".join(r[i] for i in keep) for k in order for r in by_pose[ids[k]]]
    dst.write_text("\n".join(out) + "\n")


@pytest.mark.parametrize("seed", range(400, 406))
def test_backlash_is_found_and_predicted_in_visit_order(workdir, seed):
    """A backlash on a joint drawn from the seed is named; predict takes the visit order from
    time_s, else from the file's order."""
    d, cs = workdir
    robot = ("irb2600", "kuka-like")[seed % 2]
    rng = np.random.default_rng(seed)
    joint = int(rng.integers(1, 7))
    target = float(np.exp(rng.uniform(np.log(4.0), np.log(25.0))))
    spec = f"joint_backlash:{joint}"
    magnitude = aim(cs[robot][0], spec, "joint_backlash", seed, target)
    report, truth, out = run(workdir, robot, seed, [f"{spec}={magnitude:.6g}"])
    floor = truth["noise_floor_mm"]
    ratio = report["baseline"]["holdout_rmse_mm"] / floor
    assert 3.0 <= ratio <= 30.0, f"premise: geometric-only held-out error {ratio:.1f}x the floor"
    assert [(e["name"], e.get("joint")) for e in report["effects"]] == [
        ("joint_backlash", joint)
    ], (spec, magnitude, ratio, report["effects"])
    found = report["effects"][0]
    assert found["parameters"]["backlash_deg"] == pytest.approx(magnitude, rel=0.2)
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * floor
    assert (out / found["figure"]).stat().st_size > 10_000

    meas = d / f"{robot}-{seed}.csv"
    m = 100
    shuffled = rng.permutation(m)
    write_poses(meas, out / "timed.csv", shuffled, keep_time=True)  # file order != visit order
    write_poses(meas, out / "untimed.csv", range(m), keep_time=False)  # file order = visit order
    write_poses(meas, out / "wrong.csv", shuffled, keep_time=False)
    pred = {}
    for name in ("timed", "untimed", "wrong"):
        robocal(
            "predict",
            out / "model.json",
            out / f"{name}.csv",
            "--out",
            out / f"{name}-pred.csv",
            cwd=d,
        )
        pred[name] = read_predictions(out / f"{name}-pred.csv")
    truth_xyz = read_predictions(write_measured(meas, out / "measured.csv"))

    def rms(p):
        return np.sqrt(np.mean([np.sum((p[k] - v) ** 2) for k, v in truth_xyz.items()]))

    keys = sorted(pred["timed"])
    np.testing.assert_allclose(
        [pred["timed"][k] for k in keys], [pred["untimed"][k] for k in keys], atol=2e-6
    )
    assert rms(pred["timed"]) <= 1.3 * floor
    assert rms(pred["wrong"]) > 2.0 * floor  # the order matters: a shuffle without times is wrong


def write_measured(src, dst):
    """The measured readings of a meas.csv in pred.csv's columns (pose, target, x, y, z)."""
    lines = src.read_text().splitlines()
    head = lines[0].split(",")
    cols = [head.index(c) for c in ("pose", "target", "x", "y", "z")]
    dst.write_text("\n".join(",".join(line.split(",")[i] for i in cols) for line in lines) + "\n")
    return dst
