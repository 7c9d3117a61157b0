"""A pose whose every reading repeats another pose's to the last digit (a block of rows copied
under a new pose id) is said: the real IRB 120 with pose 5 copied as pose 1005 calibrated as 37
poses with nothing said, its leave-one-pose-out predicting each copy from its twin. A pose
measured again (the same joints, readings of their own) is a repeat, not a copy: nothing said."""

import csv
import json

from robocal.server.cli import main
from tests.real import REAL

IRB = REAL / "irb120_wu"


def _calibrated(tmp_path, rows, columns) -> list[str]:
    meas, model = tmp_path / "meas.csv", tmp_path / "model.json"
    with open(meas, "w", newline="") as f:
        w = csv.DictWriter(f, columns)
        w.writeheader()
        w.writerows(rows)
    args = ["calibrate", str(meas), "--cell", str(IRB / "cell.json"), "--method", "ls-sum"]
    assert main([*args, "--out", str(model)]) == 0
    return json.loads(model.read_text())["validation"]["warnings"]


def test_a_copied_pose_is_said(tmp_path):
    with open(IRB / "train.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    columns = list(rows[0])
    assert not any("repeats every reading" in w for w in _calibrated(tmp_path, rows, columns))
    copied = rows + [{**r, "pose": "1005"} for r in rows if r["pose"] == "5"]
    said = [w for w in _calibrated(tmp_path, copied, columns) if "repeats every reading" in w]
    assert said == [
        "pose '1005' repeats every reading of pose '5' to the last digit: a copied block of "
        "rows? Each copy counts as a pose of its own, and the held-out figures predict it from "
        "its twin; remove the copies"
    ], said
    again = rows + [
        {**r, "pose": "1005", "x": repr(float(r["x"]) + 0.01)} for r in rows if r["pose"] == "5"
    ]
    assert not any("repeats every reading" in w for w in _calibrated(tmp_path, again, columns))
