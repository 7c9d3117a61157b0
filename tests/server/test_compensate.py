"""`robocal compensate` end to end: a simulated cell with hidden geometry and compliance, its
campaign diagnosed through the command line, joint commands solved for targets and sent to the
same cell's true arm (rebuilt in process from the seed, as `simulate` builds it); and the
refusals of bad targets, with nothing written."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from robocal.drivers.cell import TrackerSpec, VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.exports.rapid import read_module
from robocal.server.formats.cell_json import default_cell
from robocal.solver.configuration import CF_COLUMNS, confdata
from robocal.solver.kinematics import Layout, flange_frames
from robocal.solver.rigid import kabsch
from tests.server.test_cli import robocal

SEED, EFFECT = 6, "joint_compliance:2=1.0"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """(folder with model.json, the virtual cell whose campaign it was fitted on)."""
    d = tmp_path_factory.mktemp("compensate")
    r = robocal(
        "simulate", "--seed", SEED, "--effect", EFFECT, "--out", "meas.csv",
        "--truth-out", "truth.json", cwd=d,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = robocal("diagnose", "meas.csv", "--out", "report.json", "--model-out", "model.json", cwd=d)
    assert r.returncode == 0, r.stderr
    c = default_cell()
    vc = VirtualCell.random(c.robot, c.targets, seed=SEED, tracker=TrackerSpec(**c.tracker))
    vc.effects.extend(make_effects([EFFECT], vc, SEED))
    truth = json.loads((d / "truth.json").read_text())
    assert truth["true_params"] == vc.truth()["true_params"]  # the same hidden arm
    return d, vc


JOINTS_HEADER = ("pose", "target", "x", "y", "z", *[f"q{i}" for i in range(1, 7)])


def write_targets(path, rows, header=JOINTS_HEADER):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def read_joints(path):
    rows = list(csv.DictReader(open(path)))
    q = np.deg2rad([[float(r[f"q{i}"]) for i in range(1, 7)] for r in rows])
    return [r["pose"] for r in rows], q, np.array([float(r["predicted_error_mm"]) for r in rows])


def test_compensated_joints_reach_the_targets_on_the_true_arm(cell, tmp_path):
    d, vc = cell
    q_want = vc.sample_poses(30, np.random.default_rng(99))
    desired = vc.true_points(q_want)
    program = np.round(np.degrees(q_want), 1)  # the robot program's joints: a starting guess
    cf = confdata(default_cell().robot, q_want)  # the configurations the program was taught in
    rows = []
    for i in range(30):
        if i < 20:  # three SMRs and a guess
            for k, name in enumerate(vc.target_names):
                rows.append([f"P{i}", name, *desired[i, k], *program[i], *[""] * 4])
        else:  # one SMR, no guess: the joints are left blank, the configuration given
            k = i % 3
            rows.append([f"P{i}", vc.target_names[k], *desired[i, k], *[""] * 6, *cf[i]])
    write_targets(tmp_path / "targets.csv", rows, (*JOINTS_HEADER, *CF_COLUMNS))
    r = robocal("compensate", d / "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "compensated 30 poses" in r.stdout
    # one SMR leaves the orientation to the configuration's search: said, once
    assert r.stderr.count("warning") == 1 and "10 poses (first 'P20')" in r.stderr, r.stderr
    assert open(tmp_path / "joints.csv").readline().strip() == (
        "pose,q1,q2,q3,q4,q5,q6,predicted_error_mm"
    )
    ids, q, err = read_joints(tmp_path / "joints.csv")
    assert ids == [f"P{i}" for i in range(30)]
    assert np.all((q >= vc.true_robot.lower) & (q <= vc.true_robot.upper))
    assert (confdata(default_cell().robot, q) == cf).all()
    reached = vc.true_points(q)
    floor = vc.noise_floor_mm(q_want)
    three = reached[:20] - desired[:20]
    assert np.sqrt(np.mean(np.sum(three**2, -1))) <= 2 * floor
    one = np.array([reached[i, i % 3] - desired[i, i % 3] for i in range(20, 30)])
    assert np.sqrt(np.mean(np.sum(one**2, -1))) <= 2 * floor
    # the program's own joints miss by more than the noise: there was something to compensate
    miss = vc.true_points(np.deg2rad(program[:20])) - desired[:20]
    assert np.sqrt(np.mean(np.sum(miss**2, -1))) > 10 * floor
    assert err.max() < 0.05


def test_tool_centre_point(cell, tmp_path):
    """A tool 150 mm out: its point is known in the true flange frame and, as a user would
    measure it, relative to the SMR fixture; the model's flange frame is where its SMRs are."""
    d, vc = cell
    tcp = np.array([10.0, -20.0, 150.0])
    model = json.loads((d / "model.json").read_text())
    smrs = np.array([model["targets"][n] for n in vc.target_names])
    T = kabsch(vc.true_targets, smrs)  # true flange frame -> the model's
    tcp_model = T[:3, :3] @ tcp + T[:3, 3]
    q_want = vc.sample_poses(10, np.random.default_rng(3))

    def true_tcp(q):  # the true arm, its compliance included, carrying the tool
        dq = sum(e.joint_offsets(vc, q, None, None) for e in vc.effects)
        lay = Layout(vc.true_robot, vc.base, ("TCP",))
        R, o = flange_frames(lay, lay.initial(tcp[None]), q, dq)
        return np.einsum("mij,j->mi", R, tcp) + o

    want = true_tcp(q_want)
    program = np.round(np.degrees(q_want), 1)
    write_targets(tmp_path / "t.csv", [[i, "TCP", *want[i], *program[i]] for i in range(10)])
    r = robocal(
        "compensate", d / "model.json", "t.csv", "--tcp", ",".join(map(str, tcp_model)),
        "--out", "j.csv",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    _, q, err = read_joints(tmp_path / "j.csv")
    floor = vc.noise_floor_mm(q_want)
    assert np.sqrt(np.mean(np.sum((true_tcp(q) - want) ** 2, -1))) <= 2 * floor
    assert err.max() < 1e-4  # one point: the model reaches it exactly


def refused(cell, tmp_path, rows, *extra, header=None):
    d, _ = cell
    write_targets(tmp_path / "targets.csv", rows, *([header] if header else []))
    r = robocal(
        "compensate", d / "model.json", "targets.csv", "--out", "joints.csv", *extra, cwd=tmp_path
    )
    assert r.returncode == 1
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "joints.csv").exists()
    return r.stderr.strip()


def _good_rows(vc, n=3):
    q = vc.sample_poses(n, np.random.default_rng(8))
    p = vc.true_points(q)
    g = np.round(np.degrees(q), 1)
    return [[i, t, *p[i, k], *g[i]] for i in range(n) for k, t in enumerate(vc.target_names)]


def test_an_unreachable_target_is_refused_with_its_line(cell, tmp_path):
    _, vc = cell
    rows = _good_rows(vc)
    rows[4][2] += 3000.0  # pose 1's second SMR, on line 6, three metres off
    err = refused(cell, tmp_path, rows)
    assert "targets.csv:5:" in err and "pose '1' is unreachable" in err, err


@pytest.mark.parametrize(
    "change,where",
    [
        (lambda rows: rows[2].__setitem__(1, "Z"), "targets.csv:4:2: column 'target': 'Z'"),
        (lambda rows: rows[3].__setitem__(6, "170"), "targets.csv:5:7: column 'q2': 170"),
        (lambda rows: rows[1].__setitem__(4, "nan"), "targets.csv:3:5: column 'z'"),
        (lambda rows: rows.append(list(rows[0])), "targets.csv:11:2: column 'target'"),
        (lambda rows: rows[1].__setitem__(5, "3"), "targets.csv:3:6: column 'q1'"),
    ],
)
def test_bad_targets_are_refused_with_file_line_and_column(cell, tmp_path, change, where):
    _, vc = cell
    rows = _good_rows(vc)
    change(rows)
    assert refused(cell, tmp_path, rows).startswith(f"robocal: error: {where}")


def test_a_partial_starting_guess_is_refused_at_the_header(cell, tmp_path):
    _, vc = cell
    rows = [r[:-1] for r in _good_rows(vc)]
    header = ("pose", "target", "x", "y", "z", "q1", "q2", "q3", "q4", "q5")
    err = refused(cell, tmp_path, rows, header=header)
    assert err.startswith("robocal: error: targets.csv:1: missing column 'q6'"), err


def test_a_refusal_leaves_an_earlier_output_alone(cell, tmp_path):
    d, vc = cell
    (tmp_path / "joints.csv").write_text("earlier\n")
    rows = _good_rows(vc)
    rows[0][2] = "far"
    write_targets(tmp_path / "targets.csv", rows)
    r = robocal("compensate", d / "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 1 and "targets.csv:2:3: column 'x'" in r.stderr
    assert (tmp_path / "joints.csv").read_text() == "earlier\n"


def euler(R):
    """rx, ry, rz (deg) with R = Rz Ry Rx."""
    return np.degrees(
        [np.arctan2(R[2, 1], R[2, 2]), -np.arcsin(R[2, 0]), np.arctan2(R[1, 0], R[0, 0])]
    )


def test_an_oriented_tool(cell, tmp_path):
    """A tool tilted 30 degrees with its orientation wanted at every pose: position and
    orientation of the true arm's tool on target."""
    from robocal.server.compensate.compensation import rotation

    d, vc = cell
    tcp, R_tool = np.array([0.0, 40.0, 180.0]), rotation(0.0, 30.0, 10.0)
    model = json.loads((d / "model.json").read_text())
    smrs = np.array([model["targets"][n] for n in vc.target_names])
    T = kabsch(vc.true_targets, smrs)
    tcp_model, R_model = T[:3, :3] @ tcp + T[:3, 3], T[:3, :3] @ R_tool
    q_want = vc.sample_poses(10, np.random.default_rng(4))

    def true_tool(q):
        dq = sum(e.joint_offsets(vc, q, None, None) for e in vc.effects)
        lay = Layout(vc.true_robot, vc.base, ("TCP",))
        R, o = flange_frames(lay, lay.initial(tcp[None]), q, dq)
        return np.einsum("mij,j->mi", R, tcp) + o, R @ R_tool

    p, R = true_tool(q_want)
    program = np.round(np.degrees(q_want), 1)
    rows = [[i, "TCP", *p[i], *program[i], *euler(R[i])] for i in range(10)]
    header = ("pose", "target", "x", "y", "z", *[f"q{i}" for i in range(1, 7)], "rx", "ry", "rz")
    write_targets(tmp_path / "t.csv", rows, header)
    spec = ",".join(map(str, [*tcp_model, *euler(R_model)]))
    r = robocal(
        "compensate", d / "model.json", "t.csv", "--tcp", spec, "--out", "j.csv", cwd=tmp_path
    )
    assert r.returncode == 0, r.stderr
    _, q, _ = read_joints(tmp_path / "j.csv")
    p2, R2 = true_tool(q)
    floor = vc.noise_floor_mm(q_want)
    assert np.sqrt(np.mean(np.sum((p2 - p) ** 2, -1))) <= 2 * floor
    assert angle_deg(R2, R).max() < 0.01
    # the program's rounded joints turn the tool by about a tenth of a degree
    assert angle_deg(true_tool(np.deg2rad(program))[1], R).max() > 5 * angle_deg(R2, R).max()


def angle_deg(A, B):
    """Per pose, the angle of the rotation between A and B (m, 3, 3)."""
    c = (np.trace(np.swapaxes(A, 1, 2) @ B, axis1=1, axis2=2) - 1) / 2
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def test_a_model_with_thermal_growth_needs_the_temperature(tmp_path):
    """In process: a model whose thermal term reads temp_c refuses targets without it, at the
    header, or at the pose whose temperature is blank; with it, the joints are found."""
    from robocal.server.compensate.compensation import compensate_file
    from robocal.server.formats.errors import InputError
    from robocal.server.formats.model_json import ModelFile, write_model
    from robocal.solver.effects import Extension

    c = default_cell()
    vc = VirtualCell.random(c.robot, c.targets, seed=2)
    growth = Extension("thermal_drift", variable="temp_c", t_ref=20.0, coef=np.array([20e-6]))
    model = ModelFile(
        vc.true_robot, vc.base, dict(zip(vc.target_names, vc.true_targets)), c.robot, [growth]
    )
    write_model(tmp_path / "model.json", model)
    q = vc.sample_poses(2, np.random.default_rng(0))
    p = vc.true_points(q)
    g = np.degrees(q)
    rows = [[i, t, *p[i, k], *g[i]] for i in range(2) for k, t in enumerate(vc.target_names)]
    write_targets(tmp_path / "a.csv", rows)
    with pytest.raises(InputError, match=r"a.csv:1: the model's thermal_drift needs a temp_c"):
        compensate_file(tmp_path / "model.json", tmp_path / "a.csv")
    temps = [[*r, "" if r[0] == 1 else 21.5] for r in rows]
    write_targets(tmp_path / "b.csv", temps, (*JOINTS_HEADER, "temp_c"))
    with pytest.raises(InputError, match=r"b.csv:5: pose '1'"):
        compensate_file(tmp_path / "model.json", tmp_path / "b.csv")
    temps = [[*r, 21.5] for r in rows]
    write_targets(tmp_path / "c.csv", temps, (*JOINTS_HEADER, "temp_c"))
    c = compensate_file(tmp_path / "model.json", tmp_path / "c.csv")
    assert c.pose_ids == ["0", "1"] and c.error_mm.max() < 0.01


def test_a_rapid_module_of_compensated_targets_reaches_them_on_the_true_arm(cell, tmp_path):
    """targets.csv -> export --targets (compensated on the way) -> the module's jointtargets,
    parsed back: the same joints as compensate's joints.csv, and the true arm lands on target."""
    d, vc = cell
    q_want = vc.sample_poses(8, np.random.default_rng(7))
    desired = vc.true_points(q_want)
    program = np.round(np.degrees(q_want), 1)
    rows = [
        [f"P{i}", name, *desired[i, k], *program[i]]
        for i in range(8)
        for k, name in enumerate(vc.target_names)
    ]
    write_targets(tmp_path / "targets.csv", rows)
    model = d / "model.json"
    r = robocal("compensate", model, "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    for source, out in (("--targets", "T.mod"), ("--joints", "J.mod")):
        path = "targets.csv" if source == "--targets" else "joints.csv"
        r = robocal("export", model, "--format", "rapid", source, path, "--out", out, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    ids, q, _ = read_joints(tmp_path / "joints.csv")
    for out in ("T.mod", "J.mod"):
        mod = read_module((tmp_path / out).read_text(encoding="ascii"))
        robax = np.array([mod.targets[n][0] for n in mod.moves])
        assert len(mod.moves) == len(ids) == 8
        assert np.abs(robax - np.degrees(q)).max() <= 0.5e-5 + 1e-9  # as printed
        reached = vc.true_points(np.deg2rad(robax))
        rms = np.sqrt(np.mean(np.sum((reached - desired) ** 2, -1)))
        assert rms <= 2 * vc.noise_floor_mm(q_want), rms
    # both flags at once: argparse refuses, one line, nothing written
    r = robocal(
        "export", model, "--format", "rapid", "--joints", "joints.csv", "--targets",
        "targets.csv", "--out", "X.mod", cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode != 0 and not (tmp_path / "X.mod").exists()


def test_a_pose_without_joints_or_configuration_is_refused_naming_it(cell, tmp_path):
    _, vc = cell
    rows = _good_rows(vc)
    for r in rows[3:6]:  # pose 1, lines 5 to 7, without its joints
        r[5:] = [""] * 6
    err = refused(cell, tmp_path, rows)
    assert err.startswith(
        "robocal: error: targets.csv:5: pose '1' has neither starting joints (q1 ... qN) nor a "
        "configuration (cf1, cf4, cf6, cfx)"
    ), err
    assert "\n" not in err


def test_a_guess_two_degrees_off_stays_in_its_configuration(cell, tmp_path):
    """The program's joints 2 degrees off on every joint: the joints found are the true ones to
    within 3 degrees, on target to within twice the floor; the jumps between poses reported."""
    d, vc = cell
    rng = np.random.default_rng(12)
    q_want = vc.sample_poses(15, rng)
    desired = vc.true_points(q_want)
    lo, hi = np.degrees(vc.true_robot.lower), np.degrees(vc.true_robot.upper)
    guess = np.clip(np.degrees(q_want) + rng.choice([-2.0, 2.0], size=q_want.shape), lo, hi)
    rows = [
        [f"P{i}", name, *desired[i, k], *guess[i]]
        for i in range(15)
        for k, name in enumerate(vc.target_names)
    ]
    write_targets(tmp_path / "targets.csv", rows)
    r = robocal(
        "compensate", d / "model.json", "targets.csv", "--out", "joints.csv",
        "--max-jump-deg", "60", cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    _, q, err = read_joints(tmp_path / "joints.csv")
    assert np.degrees(np.abs(q - q_want)).max() <= 3.0
    floor = vc.noise_floor_mm(q_want)
    assert err.max() <= 2 * floor
    reached = vc.true_points(q) - desired
    assert np.sqrt(np.mean(np.sum(reached**2, -1))) <= 2 * floor
    big = int(np.sum(np.abs(np.diff(np.degrees(q), axis=0)).max(axis=1) > 60))
    assert big > 0 and f"{big} jumps of more than 60 deg between consecutive poses" in r.stdout


def test_a_guess_in_another_configuration_is_refused(cell, tmp_path):
    """Joint 1's starting value 40 degrees off: the solve would turn it there, which no
    correction needs; refused with the pose and the joint, nothing written."""
    _, vc = cell
    rows = _good_rows(vc)
    for r in rows[3:6]:
        r[5] = float(r[5]) + (40.0 if float(r[5]) < 0 else -40.0)
    err = refused(cell, tmp_path, rows)
    assert "targets.csv:5: pose '1' would leave its starting joints' configuration: joint 1 " in err


def test_one_pose_with_starting_joints_in_radians_is_told_so(cell, tmp_path):
    """A single pose (no spread for the units check) whose starting joints are radians: it was
    refused as a configuration move, 'check the starting joints'; now the unit is named. A pose
    whose guess is 40 deg off in degrees is not called radians."""
    _, vc = cell
    rows = _good_rows(vc, 1)
    for r in rows:
        r[5:] = [float(np.radians(v)) for v in r[5:]]
    err = refused(cell, tmp_path, rows)
    assert "targets.csv:2: pose '0' would leave its starting joints' configuration" in err, err
    assert "q1..q6 look like radians: give them in degrees" in err, err
    rows = _good_rows(vc, 1)
    for r in rows:
        r[5] = float(r[5]) + (40.0 if float(r[5]) < 0 else -40.0)
    err = refused(cell, tmp_path, rows)
    assert "would leave its starting joints' configuration" in err and "radians" not in err, err


def test_a_configuration_contradicting_the_joints_is_refused(cell, tmp_path):
    _, vc = cell
    rows = _good_rows(vc)
    q = np.deg2rad([[float(v) for v in r[5:11]] for r in rows])
    cf = confdata(default_cell().robot, q)
    cf[4, 3] ^= 1  # pose 1's second row, joint 5's sign flipped
    rows = [[*r, *c] for r, c in zip(rows, cf)]
    err = refused(cell, tmp_path, rows, header=(*JOINTS_HEADER, *CF_COLUMNS))
    assert "targets.csv:6:" in err and "configuration differs from line 5" in err, err
    cf[4, 3] ^= 1
    cf[3:6, 3] ^= 1
    rows = [[*r[:11], *c] for r, c in zip(rows, cf)]
    err = refused(cell, tmp_path, rows, header=(*JOINTS_HEADER, *CF_COLUMNS))
    assert "targets.csv:5: pose '1' has starting joints in configuration" in err, err


@pytest.mark.parametrize(
    "value,why",
    [("8", "is not an arm configuration number"), ("1.5", "is not an arm"), ("x", "not a number")],
)
def test_bad_configuration_values_are_refused(cell, tmp_path, value, why):
    _, vc = cell
    rows = [[*r[:5], *[""] * 6, 0, 0, 0, value] for r in _good_rows(vc)]
    err = refused(cell, tmp_path, rows, header=(*JOINTS_HEADER, *CF_COLUMNS))
    assert err.startswith("robocal: error: targets.csv:2:15: column 'cfx'") and why in err, err


def test_one_smr_a_pose_in_a_configuration_and_the_models_own_prediction():
    """One SMR a pose and only its configuration: joints in that configuration that the model
    puts there, and the reported miss is the model file's own prediction's
    (workflow.model_predict). (From tests/solver/test_compensate.py: it reads the model file.)"""
    from robocal.server.calibration import workflow
    from robocal.server.compensate.compensation import solver_model
    from robocal.solver.compensate import compensate
    from tests.solver.test_compensate import campaign

    _, vc, meas = campaign("irb2600", 21)
    cell = default_cell()
    _, model = workflow.diagnose(cell, meas, screen=False)
    q_want = vc.sample_poses(40, np.random.default_rng(5))
    desired = vc.true_points(q_want)
    mask = np.zeros(desired.shape[:2], dtype=bool)
    mask[np.arange(40), np.arange(40) % 3] = True
    cf = confdata(cell.robot, q_want)
    res = compensate(solver_model(model), desired, mask, cf=cf)
    assert res.converged.all() and res.error_mm.max() < 1e-6
    assert (confdata(cell.robot, res.q) == cf).all()
    pred = workflow.model_predict(model, res.q)
    assert np.abs(pred[mask] - desired[mask]).max() < 1e-6
    assert np.all((res.q >= vc.true_robot.lower) & (res.q <= vc.true_robot.upper))
