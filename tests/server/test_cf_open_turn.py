"""Compensation by confdata alone on an arm whose joints 2 and 3 turn +-360 deg (a UR-like arm):
cf1, cf4, cf6, cfx leave their turn open, and the turn taken (nearest zero) is said in a warning,
not chosen silently (a UR10-like campaign's q2 -248.5 deg came back as +111.5)."""

import csv
import json

import numpy as np

from robocal.server.cli import main
from robocal.server.formats.cell_doc import CellDoc
from robocal.solver.configuration import confdata, open_turns
from robocal.solver.robot import IRB2600

TABLE = [
    (0, 127.3, 90),
    (-612, 0, 0),
    (-572.3, 0, 0),
    (0, 163.941, 90),
    (0, 115.7, -90),
    (0, 92.2, 0),
]
RING = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}


def _cell(limits) -> dict:
    joints = [
        {"a": a, "d": d, "theta": 0.0, "alpha": al, "limits": list(lim)}
        for (a, d, al), lim in zip(TABLE, limits)
    ]
    return {"robot": {"name": "ur10-like", "convention": "dh", "joints": joints}, "targets": RING}


def _confdata_targets(cell: dict, meas, out, poses: int) -> None:
    robot = CellDoc.model_validate(cell).robot_model
    rows = [r for r in csv.DictReader(open(meas)) if int(r["pose"]) <= poses]
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", "cf1", "cf4", "cf6", "cfx"])
        for r in rows:
            q = np.radians([float(r[f"q{i}"]) for i in range(1, 7)])
            cf = np.asarray(confdata(robot, q)).reshape(-1)
            w.writerow([r["pose"], r["target"], r["x"], r["y"], r["z"], *map(int, cf)])


def test_which_joints_confdata_leaves_a_turn_open():
    assert open_turns(IRB2600) == []
    ur = CellDoc.model_validate(_cell([(-360, 360)] * 6)).robot_model
    assert open_turns(ur) == [1, 2]
    wrist = CellDoc.model_validate(_cell([(-180, 180)] * 4 + [(-400, 400), (-180, 180)]))
    assert open_turns(wrist.robot_model) == [4]  # more than a turn on one side of zero


def test_a_turn_confdata_leaves_open_is_said(tmp_path, capsys):
    cell = _cell([(-360, 360)] * 6)
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    p = {n: str(tmp_path / n) for n in ("cell.json", "meas.csv", "model.json", "t.csv", "j.csv")}
    assert (
        main(
            [
                "simulate",
                "--cell",
                p["cell.json"],
                "--poses",
                "30",
                "--seed",
                "5",
                "--out",
                p["meas.csv"],
            ]
        )
        == 0
    )
    args = ["calibrate", p["meas.csv"], "--cell", p["cell.json"], "--method", "ls-sum"]
    assert main([*args, "--out", p["model.json"]]) == 0
    _confdata_targets(cell, p["meas.csv"], p["t.csv"], 6)
    capsys.readouterr()
    assert main(["compensate", p["model.json"], p["t.csv"], "--out", p["j.csv"]]) == 0
    err = capsys.readouterr().err
    assert "6 poses (first '1') give a configuration (cf1, cf4, cf6, cfx) alone" in err, err
    assert "joints 2 and 3 can turn more than a full turn" in err, err
    got = list(csv.DictReader(open(p["j.csv"])))
    assert all(abs(float(r[f"q{j}"])) <= 180.0 for r in got for j in (2, 3))
