"""`robocal export`: the URDF, the parameter table and the RAPID module, each read back."""

import csv
import re

import numpy as np
import pytest
from pytransform3d.urdf import UrdfTransformManager

from robocal.drivers.cell import VirtualCell
from robocal.server.calibration import workflow
from robocal.server.cli import main
from robocal.server.exports.frames import matrix_from_rpy, rpy_from_matrix
from robocal.server.exports.params import apply_params, params_text, read_params
from robocal.server.exports.rapid import NAME_MAX, module_text, read_module
from robocal.server.exports.urdf import urdf_text
from robocal.server.formats.cell_json import Cell, default_cell
from robocal.server.formats.model_json import ModelFile, read_model, write_model
from robocal.solver.effects import Extension
from robocal.solver.kinematics import Layout, predict, rot, translation
from robocal.solver.robot import IRB2600
from tests import cli_process
from tests.robots import KUKA_LIKE, PUMA_LIKE, TARGETS

TOL_MM = 1e-6


def random_model(robot, seed) -> ModelFile:
    """A model of this robot with every parameter (beta too) off nominal, a base anywhere."""
    rng = np.random.default_rng(seed)
    names = robot.param_names()
    scale = np.array([1e-2 if n.startswith(("theta", "alpha", "beta")) else 2.0 for n in names])
    calibrated = robot.with_params(robot.param_vector() + scale * rng.normal(size=len(names)))
    base = translation(*rng.uniform(-4000, 4000, 3)) @ rot(2, rng.uniform(-3, 3))
    base = base @ rot(1, rng.uniform(-1.5, 1.5)) @ rot(0, rng.uniform(-3, 3))
    targets = {t: np.array(p) + rng.normal(scale=3.0, size=3) for t, p in TARGETS.items()}
    return ModelFile(calibrated, base, targets, nominal=robot, meta={"method": "test"})


def through_file(model: ModelFile, path) -> ModelFile:
    write_model(path, model)
    return read_model(path)


def random_joints(robot, n, seed) -> np.ndarray:
    return np.random.default_rng(seed).uniform(robot.lower, robot.upper, (n, robot.n_joints))


def urdf_points(text: str, q: np.ndarray, targets) -> np.ndarray:
    """SMR centres (m, K, 3), mm, in the URDF's root frame, by pytransform3d's URDF reader."""
    tm = UrdfTransformManager()
    tm.load_urdf(text)
    out = np.empty((len(q), len(targets), 3))
    for i, qi in enumerate(q):
        for j, v in enumerate(qi, start=1):
            tm.set_joint(f"joint_{j}", v)
        for k, t in enumerate(targets):
            out[i, k] = 1000.0 * tm.get_transform(f"smr_{t}", "tracker")[:3, 3]
    return out


def model_points(model: ModelFile, q) -> np.ndarray:
    lay, x = model.layout()
    return predict(lay, x, q)


def simulated_calibration(robot, seed) -> ModelFile:
    cell = Cell(robot, {k: np.array(v) for k, v in TARGETS.items()})
    meas = VirtualCell.random(robot, cell.targets, seed=seed).campaign(40, seed=seed)
    return workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """model.json files of a simulated campaign calibrated in-process: DH (IRB 2600) and MDH."""
    d = tmp_path_factory.mktemp("exports")
    out = {}
    for robot, seed in ((IRB2600, 3), (PUMA_LIKE, 4)):
        path = d / f"{robot.name}.json"
        write_model(path, simulated_calibration(robot, seed))
        out[robot.convention] = path
    return out


def test_rpy_rebuilds_any_rotation_also_at_gimbal_lock():
    rng = np.random.default_rng(0)
    cases = [rot(1, s * np.pi / 2) @ rot(0, rng.uniform(-3, 3)) for s in (1, -1)]
    cases += [rot(2, 0.3) @ rot(1, np.pi / 2 - 1e-9) @ rot(0, -1.1)]
    cases += [rot(2, a) @ rot(1, b) @ rot(0, c) for a, b, c in rng.uniform(-3.2, 3.2, (200, 3))]
    for R in cases:
        np.testing.assert_allclose(matrix_from_rpy(*rpy_from_matrix(R)), R, atol=2e-15)


@pytest.mark.parametrize("robot", [IRB2600, KUKA_LIKE, PUMA_LIKE], ids=lambda r: r.name)
def test_urdf_forward_kinematics_equals_the_model(robot, tmp_path):
    model = through_file(random_model(robot, seed=len(robot.name)), tmp_path / "model.json")
    assert any(model.robot.parallel) and any(j.beta != 0 for j in model.robot.joints)
    q = random_joints(model.robot, 40, seed=1)
    got = urdf_points(urdf_text(model), q, model.targets)
    assert np.abs(got - model_points(model, q)).max() < TOL_MM


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_urdf_of_a_calibrated_campaign(calibrated, convention):
    model = read_model(calibrated[convention])
    assert model.robot.convention == convention
    text = urdf_text(model)
    q = random_joints(model.robot, 60, seed=2)
    err = np.abs(urdf_points(text, q, model.targets) - model_points(model, q)).max()
    assert err < TOL_MM
    # the limits are the model's, in radians; joint values are the controller's readings
    limits = re.findall(r'<limit lower="([^"]+)" upper="([^"]+)"', text)
    np.testing.assert_array_equal(
        np.array(limits, dtype=float).T, [model.robot.lower, model.robot.upper]
    )


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_params_table_read_back_reproduces_the_parameters(calibrated, convention, tmp_path):
    model = read_model(calibrated[convention])
    path = tmp_path / "params.csv"
    path.write_text(params_text(model))
    robot, base, targets = apply_params(path, read_params(path), model.robot, tuple(model.targets))
    names = tuple(model.targets)
    lay, x = model.layout()
    back = Layout(robot, base, names)
    y = back.initial(np.array([targets[t] for t in names]))
    # geometry (mm, rad) and SMRs (mm) to the table's 1e-9, the base as a transform
    np.testing.assert_allclose(y[: lay.n_geo], x[: lay.n_geo], rtol=0, atol=1e-9)
    np.testing.assert_allclose(y[lay.target_slice], x[lay.target_slice], rtol=0, atol=1e-9)
    np.testing.assert_allclose(base, model.base, rtol=0, atol=1e-9)
    q = random_joints(model.robot, 50, seed=3)
    assert np.abs(predict(back, y, q) - predict(lay, x, q)).max() < TOL_MM


def test_params_table_says_nominal_calibrated_difference_and_status(calibrated, tmp_path):
    model = read_model(calibrated["dh"])
    rows = {r["parameter"]: r for r in csv.DictReader(params_text(model).splitlines())}
    a2 = rows["a2"]
    assert (a2["joint"], a2["convention"], a2["unit"]) == ("2", "dh", "mm")
    assert float(a2["nominal"]) == 900.0
    assert float(a2["difference"]) == pytest.approx(float(a2["calibrated"]) - 900.0, abs=2e-9)
    assert float(rows["theta2"]["nominal"]) == -90.0 and rows["theta2"]["unit"] == "deg"
    assert "beta2" in rows and "beta1" not in rows  # beta only where axes 2 and 3 are parallel
    assert rows["theta1"]["status"].startswith("held fixed: redundant with")
    assert rows["theta1"]["standard_error"] == ""
    assert float(rows["a2"]["standard_error"]) > 0 and rows["a2"]["status"] == "identified"
    assert [n for n in rows if n.startswith("base_")] == [
        "base_x",
        "base_y",
        "base_z",
        "base_rz",
        "base_ry",
        "base_rx",
    ]
    assert {f"{t}_{c}" for t in "ABC" for c in "xyz"} <= set(rows)


def write_joints(path, robot, q_deg, ids=None, error=True):
    ids = ids or [f"P{i:03d}" for i in range(len(q_deg))]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", *[f"q{j}" for j in range(1, robot.n_joints + 1)], "predicted_error_mm"])
        for pid, q in zip(ids, q_deg):
            w.writerow([pid, *[f"{v:.9f}" for v in q], "0.000123" if error else ""])


def test_rapid_module_reads_back_to_the_joints(calibrated, tmp_path, capsys):
    model = read_model(calibrated["dh"])
    q = np.rad2deg(random_joints(model.robot, 30, seed=4))
    write_joints(tmp_path / "joints.csv", model.robot, q)
    out = tmp_path / "Robocal_Targets.mod"
    assert (
        main(
            [
                "export",
                str(calibrated["dh"]),
                "--format",
                "rapid",
                "--joints",
                str(tmp_path / "joints.csv"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert "Run_Robocal_Targets" in capsys.readouterr().out
    text = out.read_text(encoding="ascii")
    mod = read_module(text)
    assert mod.name == "Robocal_Targets" and len(mod.moves) == 30
    assert mod.moves == [f"jt_P{i:03d}" for i in range(30)]
    robax = np.array([mod.targets[n][0] for n in mod.moves])
    assert np.abs(robax - q).max() <= 0.5e-5 + 1e-9  # five decimals, as printed
    assert all((mod.targets[n][1] == 9e9).all() for n in mod.moves)
    check_rapid_text(text)


def test_rapid_from_joints_in_radians_warns(calibrated, tmp_path, capsys):
    """A joints.csv in radians was exported as degrees without a word."""
    model = read_model(calibrated["dh"])
    q = random_joints(model.robot, 10, seed=5).clip(-2 * np.pi, 2 * np.pi)
    write_joints(tmp_path / "rad.csv", model.robot, q)
    out = tmp_path / "t.mod"
    code, _, err = run_export(
        calibrated["dh"], "--joints", tmp_path / "rad.csv", "--out", out, capsys=capsys
    )
    assert code == 0 and out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("robocal: warning: "), err
    assert "rad.csv: q1..q6 of all 10 poses lie within +-6.28" in lines[0]
    assert "look like radians" in lines[0]
    write_joints(tmp_path / "deg.csv", model.robot, np.rad2deg(q))
    code, _, err = run_export(
        calibrated["dh"], "--joints", tmp_path / "deg.csv", "--out", out, capsys=capsys
    )
    assert code == 0 and "radians" not in err


def check_rapid_text(text):
    """What the controller requires of the text: lines, names, blocks, statements."""
    lines = text.splitlines()
    assert max(map(len, lines)) <= 80
    code = [line.split("!", 1)[0].strip() for line in lines]
    code = [c for c in code if c]
    assert code[0].startswith("MODULE ") and code[-1] == "ENDMODULE"
    words = re.findall(r"[A-Za-z_]\w*", " ".join(code))
    assert words.count("PROC") == words.count("ENDPROC") == 1
    for name in re.findall(r"jointtarget (\w+)", text) + re.findall(r"(?:MODULE|PROC) (\w+)", text):
        assert re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name) and len(name) <= NAME_MAX, name
    # a statement ends with ';', or goes on after a ',' or ':=' on the next line
    for line in code:
        if not line.startswith(("MODULE", "PROC", "ENDPROC", "ENDMODULE")):
            assert line.endswith((";", ",", ":=")), line
    assert re.findall(r"MoveAbsJ \w+, RC_SPEED, fine, tool0;", text)


def test_rapid_names_are_unique_valid_and_short():
    ids = ["a", "A", "1 st", "x" * 200, "x" * 200 + "y", "MODULE", "ü"]
    text = module_text("Robocal Targets", ids, np.zeros((len(ids), 6)))
    check_rapid_text(text)
    mod = read_module(text)
    assert len({n.lower() for n in mod.moves}) == len(ids)  # RAPID names ignore case
    assert mod.name == "Robocal_Targets"


def test_rapid_wraps_wide_joint_values_within_80_characters():
    q = np.full((1, 6), -1079.99999)
    text = module_text("M", ["p"], q)
    check_rapid_text(text)
    np.testing.assert_array_equal(read_module(text).targets["jt_p"][0], q[0])


def run_export(*args, capsys):
    code = main(["export", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_bad_joints_file_one_line_and_nothing_written(calibrated, tmp_path, capsys):
    model = read_model(calibrated["dh"])
    q = np.zeros((3, 6))
    q[1, 2] = 80.0  # joint 3 of the IRB 2600 stops at 75 degrees
    write_joints(tmp_path / "joints.csv", model.robot, q)
    out = tmp_path / "t.mod"
    code, _, err = run_export(
        calibrated["dh"], "--joints", tmp_path / "joints.csv", "--out", out, capsys=capsys
    )
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert re.search(r"joints\.csv:3:4: column 'q3': 80\.000000000 deg is outside the limits", err)
    assert not out.exists() and not list(tmp_path.glob(".t.mod*"))

    (tmp_path / "dup.csv").write_text("pose,q1,q2,q3,q4,q5,q6\n1,0,0,0,0,0,0\n1,0,0,0,0,0,0\n")
    code, _, err = run_export(
        calibrated["dh"], "--joints", tmp_path / "dup.csv", "--out", out, capsys=capsys
    )
    assert code == 1 and "dup.csv:3:1: column 'pose': pose '1' is already on line 2" in err
    (tmp_path / "few.csv").write_text("pose,q1,q2,q3,q4,q5\n1,0,0,0,0,0\n")
    code, _, err = run_export(
        calibrated["dh"], "--joints", tmp_path / "few.csv", "--out", out, capsys=capsys
    )
    assert code == 1 and "few.csv:1: missing required column 'q6'" in err
    code, _, err = run_export(calibrated["dh"], "--out", out, capsys=capsys)
    assert code == 1 and "--joints" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_bad_model_or_format_one_line_and_nothing_written(tmp_path, capsys):
    (tmp_path / "model.json").write_text('{"schema": 1, "robot": "irb2600"}\n')
    out = tmp_path / "robot.urdf"
    code, _, err = run_export(tmp_path / "model.json", "--out", out, capsys=capsys)
    assert code == 1 and err.startswith("robocal: error: ") and "model.json:1" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    code, _, err = run_export(tmp_path / "model.json", "--out", tmp_path / "x.txt", capsys=capsys)
    assert code == 1 and "--format" in err


def test_extended_model_exports_its_geometry_and_says_so(tmp_path, capsys):
    cell = default_cell()
    model = random_model(cell.robot, seed=5)
    model.extensions = [Extension("joint_scale", joint=1, coef=np.array([2e-5]))]
    write_model(tmp_path / "model.json", model)
    # a made-up model has no validation verdict: refused in one line, exported with --force
    code, _, err = run_export(tmp_path / "model.json", "--out", tmp_path / "r.urdf", capsys=capsys)
    assert code == 1 and len(err.strip().splitlines()) == 1, err
    assert "the model is not deployable: the model has no validation verdict" in err, err
    assert not (tmp_path / "r.urdf").exists()
    for name in ("robot.urdf", "params.csv"):
        path = tmp_path / name
        code, out, err = run_export(
            tmp_path / "model.json", "--out", path, "--force", capsys=capsys
        )
        assert code == 0 and "note: the model's extensions (" in out and "geometric part" in out
        assert err.startswith("robocal: warning: ") and "no validation verdict" in err, err
    back = read_model(tmp_path / "model.json")
    q = random_joints(back.robot, 10, seed=6)
    text = (tmp_path / "robot.urdf").read_text()
    assert np.abs(urdf_points(text, q, back.targets) - model_points(back, q)).max() < TOL_MM


def test_export_command_line(calibrated, tmp_path):
    model = read_model(calibrated["mdh"])
    write_joints(tmp_path / "joints.csv", model.robot, np.zeros((2, 6)))
    runs = [
        ("--format", "urdf", "--out", "puma.urdf"),
        ("--format", "params", "--out", "params.csv"),
        ("--joints", "joints.csv", "--out", "Cal_Run.mod"),
    ]
    for args in runs:
        r = cli_process.run("export", calibrated["mdh"], *args, cwd=tmp_path, timeout=120)
        assert r.returncode == 0 and r.stdout.startswith("wrote "), r.stderr
    assert read_module((tmp_path / "Cal_Run.mod").read_text()).moves == ["jt_P000", "jt_P001"]
    assert '<robot name="puma-like_calibrated">' in (tmp_path / "puma.urdf").read_text()
    assert (tmp_path / "params.csv").read_text().splitlines()[1].startswith("a1,1,mdh,mm,")
