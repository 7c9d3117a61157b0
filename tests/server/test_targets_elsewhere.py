"""Targets in another tracker frame (another campaign's, the tracker moved since) were 'unreachable
... no closer than 3831 mm' pose by pose; every pose missed by metres says where to look."""

from robocal.server.cli import main


def test_targets_from_another_tracker_frame_are_named(tmp_path, capsys):
    d = {n: str(tmp_path / n) for n in ("a.csv", "b.csv", "model.json", "t.csv", "j.csv")}
    assert main(["simulate", "--poses", "30", "--seed", "3", "--out", d["a.csv"]]) == 0
    assert main(["calibrate", d["a.csv"], "--method", "ls-sum", "--out", d["model.json"]]) == 0
    # seed 4 stands the tracker elsewhere: its readings, with their joints, as targets
    assert main(["simulate", "--poses", "5", "--seed", "4", "--out", d["b.csv"]]) == 0
    capsys.readouterr()
    assert main(["compensate", d["model.json"], d["b.csv"], "--out", d["j.csv"]]) == 1
    err = capsys.readouterr().err.strip()
    assert "is unreachable within the joint limits" in err, err
    assert "are the targets in this model's tracker frame" in err, err
    # the campaign's own poses are reached: no such clause
    assert main(["compensate", d["model.json"], d["a.csv"], "--out", d["j.csv"]]) == 0
