"""Compensation by confdata alone on an arm whose joints 2 and 3 turn +-360 deg (a UR-like arm):
cf1, cf4, cf6, cfx leave their turn open, and the turn taken (nearest zero) is said in a warning,
not chosen silently (a UR10-like campaign's q2 -248.5 deg came back as +111.5)."""

import csv
import json

from robocal.server.cli import main
from robocal.server.formats.cell_doc import CellDoc
from robocal.solver.configuration import open_turns
from robocal.solver.robot import IRB2600

from .test_outside_cells import _confdata_targets

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
    _confdata_targets(tmp_path, tmp_path / "cell.json", "meas.csv", "t.csv")
    capsys.readouterr()
    assert main(["compensate", p["model.json"], p["t.csv"], "--out", p["j.csv"]]) == 0
    err = capsys.readouterr().err
    assert "30 poses (first '1') give a configuration (cf1, cf4, cf6, cfx) alone" in err, err
    assert "joints 2 and 3 can turn more than a full turn" in err, err
    got = list(csv.DictReader(open(p["j.csv"])))
    assert all(abs(float(r[f"q{j}"])) <= 180.0 for r in got for j in (2, 3))
