"""A campaign in metres, inches or with joints in radians is refused in one line naming the
file and the likely units by every command that reads it for a cell; a geometry changed beyond
what the arm can have makes the model undeployable, naming the parameter; the nominal model's
own error stands beside the calibrated one (issue 21, point 5)."""

import csv
import json
import math

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.server.calibration import workflow
from robocal.server.cli import main
from robocal.server.formats.cell_json import default_cell
from robocal.solver.measurements import Measurements
from robocal.solver.robot import IRB2600

TARGETS = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}
UNITS = {
    "metres.csv": ("xyz", lambda v: v / 1000.0, "x, y, z look like metres; give them in mm"),
    "inches.csv": ("xyz", lambda v: v / 25.4, "x, y, z look like inches; give them in mm"),
    "radians.csv": ("q", math.radians, "q1..q6 look like radians; give them in degrees"),
}


def converted(src, dst, columns: str, f) -> None:
    """src's rows with the columns (x, y, z or every joint q1..) passed through f."""
    with open(src, newline="") as fh:
        rows = list(csv.DictReader(fh))
    pick = (lambda k: k in "xyz") if columns == "xyz" else (lambda k: k[0] == "q")
    with open(dst, "w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: repr(f(float(v))) if pick(k) else v for k, v in r.items()})


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("units")
    assert main(["simulate", "--poses", "40", "--seed", "7", "--out", str(d / "meas.csv")]) == 0
    for name, (columns, f, _) in UNITS.items():
        converted(d / "meas.csv", d / name, columns, f)
    return d


@pytest.fixture(scope="module")
def model(folder):
    """The untouched campaign's calibration (ls-sum: quick) and what calibrate printed."""
    out = folder / "model.json"
    args = ["calibrate", str(folder / "meas.csv"), "--method", "ls-sum", "--out", str(out)]
    assert main(args) == 0
    return json.loads(out.read_text())


COMMANDS = {
    "calibrate": lambda d, f: ["calibrate", f, "--method", "ls-sum", "--out", str(d / "m.json")],
    "diagnose": lambda d, f: ["diagnose", f, "--out", str(d / "r.json")],
    "compare": lambda d, f: ["compare", f],
    "evaluate": lambda d, f: ["evaluate", str(d / "model.json"), f],
    "check": lambda d, f: ["check", str(d / "model.json"), f, "--db", str(d / "checks.db")],
}


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("name", UNITS)
def test_wrong_units_refused_in_one_line(folder, model, capsys, name, command):
    capsys.readouterr()
    path = str(folder / name)
    assert main(COMMANDS[command](folder, path)) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"robocal: error: {path}: the readings span ")
    assert err.endswith(UNITS[name][2]), err


def test_right_units_calibrate_with_the_nominal_error_beside(folder, model, capsys):
    v = model["validation"]
    assert v["deployable"], v["reasons"]
    # the nominal robot registered on the data errs by mm; the calibration by the noise
    assert v["nominal_rms_mm"] > 20 * v["fit_rms_mm"]
    capsys.readouterr()
    args = ["calibrate", str(folder / "meas.csv"), "--method", "ls-sum", "--out"]
    assert main([*args, str(folder / "again.json")]) == 0
    said = f"(nominal {v['nominal_rms_mm']:.4f} mm, {v['nominal_holdout_rms_mm']:.4f} mm held out)"
    assert said in capsys.readouterr().out


def test_wrong_nominal_geometry_not_deployable(folder, capsys):
    """The cell's nominal a2 30 mm longer than the arm (a drawing of another variant): the
    calibration finds the arm, and the verdict says the change is more than an arm can have."""
    joints = [
        {
            "a": j.a + (30.0 if i == 1 else 0.0),
            "d": j.d,
            "theta": math.degrees(j.theta),
            "alpha": math.degrees(j.alpha),
            "limits": [math.degrees(x) for x in j.limits],
        }
        for i, j in enumerate(IRB2600.joints)
    ]
    cell = {"robot": {"name": "irb2600", "convention": "dh", "joints": joints}, "targets": TARGETS}
    (folder / "long.json").write_text(json.dumps(cell))
    out = folder / "long_model.json"
    args = ["calibrate", str(folder / "meas.csv"), "--cell", str(folder / "long.json")]
    assert main([*args, "--method", "ls-sum", "--out", str(out)]) == 0
    v = json.loads(out.read_text())["validation"]
    assert not v["deployable"]
    reach = IRB2600.reach_mm + 30.0
    (why,) = [r for r in v["reasons"] if "changed by" in r]
    assert why.startswith(
        f"a2 changed by -30.0 mm from nominal (more than {0.005 * reach:.3g} mm for an arm of "
        f"{reach:,.0f} mm reach)"
    ), why
    assert "NOT DEPLOYABLE" in capsys.readouterr().out


def test_cell_angles_in_radians_refused_naming_the_cell(folder, capsys):
    joints = [
        {"a": j.a, "d": j.d, "theta": j.theta, "alpha": j.alpha, "limits": [-400, 400]}
        for j in IRB2600.joints  # radians, as a user converting from a datasheet might
    ]
    cell = {"robot": {"name": "irb2600", "convention": "dh", "joints": joints}, "targets": TARGETS}
    (folder / "radians_cell.json").write_text(json.dumps(cell))
    capsys.readouterr()
    args = ["calibrate", str(folder / "meas.csv"), "--cell", str(folder / "radians_cell.json")]
    assert main([*args, "--out", str(folder / "rc.json")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robocal: error: {folder / 'radians_cell.json'}: the nominal arm errs ")
    assert err.endswith("read as radians: give the robot's angles in degrees") and "\n" not in err


def test_a_verdict_on_readings_in_metres_names_them():
    """Where no file is read (a campaign measured by the service), the verdict says it: the
    readings' units and the links shrunk a thousandfold."""
    cell = default_cell()
    meas = VirtualCell.random(cell.robot, cell.targets, seed=7).campaign(30, seed=7)
    metres = Measurements(meas.pose_ids, meas.q, meas.target_names, meas.xyz / 1000.0)
    v = workflow.model_file(workflow.run_method(cell, metres, "ls-sum"), cell, metres)
    v = v.validation.to_json()
    assert not v["deployable"]
    assert any(r.endswith("x, y, z look like metres; give them in mm") for r in v["reasons"])
    (change,) = [r for r in v["reasons"] if "changed by" in r]
    assert "a2 by -899" in change or change.startswith("a2 changed by -899"), change
    assert np.isfinite(v["nominal_rms_mm"]) and v["nominal_rms_mm"] > 1000.0
