"""A real-device cell.json whose inline robot names a built-in model may not widen its limits."""

import json

import numpy as np
import pytest

from robocal.server.formats import InputError, cell_to_json, default_cell, read_cell
from robocal.server.formats.cell_json import robot_to_json
from robocal.solver.robot import IRB2600

DEVICES = {
    "tracker": {"host": "127.0.0.1", "port": 5000},
    "controller": {"url": "socket://127.0.0.1:1025"},
}


def cell_doc(name="irb2600", joint2=(-95.0, 155.0), devices=True):
    doc = cell_to_json(default_cell())
    robot = robot_to_json(IRB2600)
    robot["name"] = name
    robot["joints"][1]["limits"] = list(joint2)
    doc["robot"] = robot
    doc["base"] = np.eye(4).tolist()
    if devices:
        doc["devices"] = DEVICES
    return doc


def write(tmp_path, doc):
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(doc, indent=2))
    return path


@pytest.mark.parametrize("name", ["irb2600", "IRB 2600", "IRB-2600"])
def test_wider_than_the_builtin_refused_naming_file_and_field(tmp_path, name):
    path = write(tmp_path, cell_doc(name, joint2=(-720.0, 720.0)))
    with pytest.raises(InputError) as info:
        read_cell(path)
    text = str(info.value)
    assert text.startswith(f"{path}:") and "\n" not in text
    assert "robot.joints[1].limits: [-720, 720] deg" in text, text
    assert "[-720, 720]" in text and "[-95, 155]" in text


def test_missing_limits_default_wider_than_the_builtin_refused(tmp_path):
    doc = cell_doc()
    del doc["robot"]["joints"][1]["limits"]  # the default [-180, 180] exceeds [-95, 155]
    with pytest.raises(InputError, match="exceeds the built-in irb2600"):
        read_cell(write(tmp_path, doc))


def test_narrower_than_the_builtin_accepted(tmp_path):
    cell = read_cell(write(tmp_path, cell_doc(joint2=(-90.0, 150.0))))
    assert np.rad2deg(cell.robot.joints[1].limits) == pytest.approx((-90.0, 150.0))


def test_simulated_cells_and_other_names_keep_their_limits(tmp_path):
    read_cell(write(tmp_path, cell_doc(joint2=(-720.0, 720.0), devices=False)))
    read_cell(write(tmp_path, cell_doc(name="my-arm", joint2=(-720.0, 720.0))))


def test_builtin_name_with_other_joint_count_refused(tmp_path):
    doc = cell_doc()
    doc["robot"]["joints"] = doc["robot"]["joints"][:5]
    with pytest.raises(InputError, match="6 joints, not 5"):
        read_cell(write(tmp_path, doc))
