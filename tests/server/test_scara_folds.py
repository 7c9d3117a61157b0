"""A SCARA (every axis vertical) has no gravity-loaded joint to split a campaign at: diagnose on
40 poses said 'not tested off its training poses: too few poses to split' where 36 poses of an
IRB 120 gave 10 folds. Region folds now split at the joints that move an SMR when gravity loads
none; the joints turning the SMR on their axis give no fold."""

import json

from robocal.server.cli import main

from .test_scara_nominal import BASE
from .test_simulate_unseen import SCARA


def _diagnose(tmp_path, capsys, effect=()):
    cell, meas, report = tmp_path / "cell.json", tmp_path / "m.csv", tmp_path / "r.json"
    cell.write_text(json.dumps({"robot": SCARA, "targets": {"A": [0, 0, 30]}, "base": BASE}))
    sim = ["simulate", "--cell", str(cell), "--poses", "40", "--seed", "3", "--out", str(meas)]
    assert main([*sim, *effect]) == 0
    assert main(["diagnose", str(meas), "--cell", str(cell), "--out", str(report)]) == 0
    out = capsys.readouterr().out
    return out, json.loads(report.read_text())


def test_a_40_pose_scara_is_tested_off_its_training_poses(tmp_path, capsys):
    out, report = _diagnose(tmp_path, capsys)
    folds = report["extrapolation"]["folds"]
    print([(f["test"], f["beyond_training_deg"]) for f in folds])
    assert "too few poses to split" not in out
    # q1 and q2 carry the SMR round; q3 and q4 turn it on their own axis
    assert sorted({f["test"][:2] for f in folds}) == ["q1", "q2"]
    assert all(f["test_poses"] == 20 and f["beyond_training_deg"] > 50 for f in folds)


def test_a_true_scara_effect_holds_on_the_new_folds(tmp_path, capsys):
    out, report = _diagnose(tmp_path, capsys, ["--effect", "joint_periodic:2:1=0.02"])
    names = [e["name"] for e in report["effects"]]
    print(names, report["extrapolation"]["refused"])
    assert names == ["joint_periodic"] and not report["extrapolation"]["refused"]
    assert len(report["extrapolation"]["folds"]) >= 4
