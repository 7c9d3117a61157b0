"""Sizes bounded where they enter: SMRs, joints and link lengths of a cell, targets of a
meas.csv; each refusal one line naming the field; 7-joint arms and the real cells still load."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robocal.server.formats.cell_json import cell_to_json, default_cell, parse_cell
from robocal.server.formats.errors import InputError
from robocal.solver.robot import IRB2600
from tests.real import REAL

from .test_cli import robocal
from .test_cli_mistakes import one_line_error

SMRS_MAX, JOINTS_MAX = 16, 7  # the bounds of server/formats/limits.py, as documented


def joint(a=100.0, d=100.0, alpha=90.0) -> dict:
    return {"a": a, "d": d, "theta": 0.0, "alpha": alpha, "limits": [-170.0, 170.0]}


def cell(joints=None, n_targets=3) -> dict:
    """The default cell's JSON with an inline robot of these joints and n_targets SMRs."""
    doc = cell_to_json(default_cell())
    if joints is not None:
        doc["robot"] = {"name": "arm", "convention": "dh", "joints": joints}
    angles = np.linspace(0.0, 2 * np.pi, n_targets, endpoint=False)
    doc["targets"] = {
        f"T{i}": [60.0 * np.cos(w), 60.0 * np.sin(w), 35.0] for i, w in enumerate(angles)
    }
    return doc


def seven_joints() -> list[dict]:
    """An IRB 2600 with a redundant elbow roll: a plausible 7-axis arm."""
    return [
        joint(150.0, 445.0, -90.0),
        joint(900.0, 0.0, 0.0),
        joint(150.0, 0.0, -90.0),
        joint(0.0, 400.0, 90.0),
        joint(0.0, 538.0, -90.0),
        joint(0.0, 0.0, 90.0),
        joint(0.0, 200.0, 0.0),
    ]


def refusal(doc: dict) -> InputError:
    with pytest.raises(InputError) as e:
        parse_cell(json.dumps(doc, indent=1), "cell.json")
    assert e.value.line is not None and e.value.column is not None
    assert "\n" not in str(e.value)
    return e.value


def test_a_cell_of_1000_smrs_is_refused_naming_targets():
    e = refusal(cell(n_targets=1000))
    assert e.message.startswith("targets: 1000 targets; a cell has at most 16 SMRs"), e.message


def test_a_cell_of_16_smrs_is_accepted():
    assert len(parse_cell(json.dumps(cell(n_targets=SMRS_MAX))).targets) == SMRS_MAX


def test_a_robot_of_50_joints_is_refused_naming_the_joints():
    e = refusal(cell([joint()] * 50))
    assert e.message == f"robot.joints: 50 joints; a serial arm has at most {JOINTS_MAX}"


@pytest.mark.parametrize("scale", [0.0, 1e-3])  # all zeros; a table given in metres
def test_zero_length_links_are_refused(scale):
    joints = [{**j, "a": j["a"] * scale, "d": j["d"] * scale} for j in seven_joints()[:6]]
    e = refusal(cell(joints))
    assert e.message.startswith("robot.joints: the links add up to"), e.message
    assert "give a and d in mm" in e.message


@pytest.mark.parametrize("field", ["a", "d"])
def test_a_link_beyond_5_m_is_refused(field):
    joints = seven_joints()[:6]
    joints[1] = {**joints[1], field: 5000.5}
    e = refusal(cell(joints))
    assert e.message.startswith(f"robot.joints[1].{field}: 5000.5 is out of range"), e.message


def test_a_7_joint_arm_is_accepted():
    parsed = parse_cell(json.dumps(cell(seven_joints())))
    assert parsed.robot.n_joints == 7


@pytest.mark.parametrize("path", sorted(REAL.glob("**/cell.json")), ids=str)
def test_the_real_cells_still_load(path):
    assert parse_cell(path.read_text(), str(path)).robot.n_joints == 6


def test_a_meas_csv_of_more_targets_than_a_cell_holds_is_refused_at_its_line(tmp_path):
    from robocal.server.formats.campaign_csv import read_campaign

    rows = [f"{i},0,0,0,0,30,0,T{i},100,200,300\n" for i in range(SMRS_MAX + 5)]
    path = tmp_path / "meas.csv"
    path.write_text("pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n" + "".join(rows))
    with pytest.raises(InputError) as e:
        read_campaign(path, IRB2600)
    assert (e.value.line, e.value.column) == (SMRS_MAX + 2, 8), e.value
    assert "at most 16" in e.value.message


@pytest.mark.parametrize(
    ("doc", "args", "words"),
    [
        (
            cell(n_targets=1000),
            ("simulate", "--poses", 5, "--out", "m.csv"),
            ["cell.json:", "targets: 1000"],
        ),
        (cell([joint()] * 50), ("acquire", "--db", "a.db", "--poses", 3), ["robot.joints: 50"]),
        (cell([joint(0.0, 0.0)] * 6), ("calibrate", "meas.csv"), ["the links add up to 0 mm"]),
    ],
    ids=["simulate-1000-smrs", "acquire-50-joints", "calibrate-zero-links"],
)
def test_commands_taking_a_cell_refuse_it_in_one_line(tmp_path, doc, args, words):
    (tmp_path / "cell.json").write_text(json.dumps(doc))
    (tmp_path / "meas.csv").write_text("pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n")
    r = robocal(*args, "--cell", "cell.json", cwd=tmp_path)
    one_line_error(r, *words)
    assert not (tmp_path / "a.db").exists()


def test_acquire_refuses_a_7_joint_cell_in_one_line_before_creating_the_database(tmp_path):
    (tmp_path / "cell.json").write_text(json.dumps(cell(seven_joints())))
    r = robocal("acquire", "--db", "a.db", "--cell", "cell.json", "--poses", 3, cwd=tmp_path)
    one_line_error(r, "robot.joints: 7 joints; the controller protocol drives at most 6")
    assert not (tmp_path / "a.db").exists()


def test_acquire_names_the_check_to_relax_when_no_pose_is_valid(tmp_path):
    # a tenth of an IRB 2600: plausible links, but the flange never clears the base's axis
    small = [
        {**j, "a": j["a"] / 10, "d": j["d"] / 10} for j in seven_joints()[:3] + seven_joints()[4:]
    ]
    (tmp_path / "cell.json").write_text(json.dumps(cell(small)))
    r = robocal("acquire", "--db", "a.db", "--cell", "cell.json", "--poses", 3, cwd=tmp_path)
    one_line_error(r, "constraints too tight", "base_axis: keep the flange 300 mm off")
