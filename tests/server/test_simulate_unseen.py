"""A simulated compliance on a joint whose axis lies along gravity (a SCARA's) moves nothing:
simulate said 'effects: joint_compliance:2=5 urad/(N m)' and the diagnosis, rightly, found
nothing; simulate now says the data holds nothing of it."""

import json

from robocal.server.cli import main

from .test_mounted_sim import CEILING, TARGETS

# a SCARA: every axis vertical, hung from the ceiling so its SMRs face the tracker below
SCARA = {
    "name": "scara4",
    "convention": "dh",
    "joints": [
        {"a": 325, "d": 400, "theta": 0, "alpha": 0, "limits": [-130, 130]},
        {"a": 275, "d": 0, "theta": 0, "alpha": 0, "limits": [-145, 145]},
        {"a": 0, "d": -100, "theta": 0, "alpha": 0, "limits": [-180, 180]},
        {"a": 0, "d": -50, "theta": 0, "alpha": 0, "limits": [-360, 360]},
    ],
}


def test_a_compliance_gravity_cannot_load_is_said(tmp_path, capsys):
    scara, irb = tmp_path / "scara.json", tmp_path / "irb.json"
    base = [[1, 0, 0, 300.0], [0, -1, 0, 0.0], [0, 0, -1, 2000.0], [0, 0, 0, 1]]
    scara.write_text(json.dumps({"robot": SCARA, "targets": TARGETS, "base": base}))
    irb.write_text(json.dumps({"robot": "irb2600", "targets": TARGETS, "base": CEILING}))
    meas = str(tmp_path / "meas.csv")
    for cell, said in ((scara, True), (irb, False)):
        args = ["simulate", "--cell", str(cell), "--poses", "30", "--seed", "3"]
        assert main([*args, "--effect", "joint_compliance:2=5", "--out", meas]) == 0
        err = capsys.readouterr().err
        assert ("the data holds nothing of it" in err) is said, err
