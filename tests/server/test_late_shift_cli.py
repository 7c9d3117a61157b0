"""A tracker bumped before a campaign's last two poses: too late for the diagnosis's base
shift (five poses on either side of it), so calibrate and diagnose warn, naming the poses and
the shift; a clean campaign gets no such warning."""

import csv
import json

import numpy as np

from .test_cli import robocal

PHRASE = "a bumped tracker or moved base?"


def _bump(src, dst, k, shift, turn_urad):
    """The readings of the last k poses (time order) moved rigidly: a turn about the tracker's
    z axis, then a shift (mm)."""
    rows = list(csv.DictReader(open(src)))
    first: dict = {}
    for r in rows:
        first.setdefault(r["pose"], float(r["time_s"]))
    last = sorted(first, key=first.get)[-k:]
    a = turn_urad * 1e-6
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    for r in rows:
        if r["pose"] in last:
            p = R @ np.array([float(r[c]) for c in "xyz"]) + shift
            r.update({c: f"{v:.5f}" for c, v in zip("xyz", p)})
    with open(dst, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return last


def test_a_tracker_bumped_before_the_last_two_poses_is_said(tmp_path):
    """IRB 2600, 60 poses, the last two moved 0.37 mm and 50 urad: no effect named (the
    base shift needs five poses after it), the model 'not deployable' for an effect it lacks,
    and nothing said of the end of the campaign. Now the warning names poses 59 and 60."""
    r = robocal("simulate", "--poses", 60, "--seed", 3, "--out", "m.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    last = _bump(tmp_path / "m.csv", tmp_path / "b.csv", 2, [0.3, -0.2, 0.1], 50.0)
    for data, bumped in (("m.csv", False), ("b.csv", True)):
        r = robocal("calibrate", data, "--out", "c.json", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        said = [w for w in json.loads((tmp_path / "c.json").read_text())["validation"]["warnings"]]
        late = [w for w in said if PHRASE in w]
        assert len(late) == bumped, (data, said)
        r = robocal("diagnose", data, "--out", "r.json", "--model-out", "d.json", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        report = json.loads((tmp_path / "r.json").read_text())
        late = [w for w in report["validation"]["warnings"] if PHRASE in w]
        assert len(late) == bumped, (data, report["validation"]["warnings"])
        assert (PHRASE in " ".join(r.stdout.split())) == bumped
        if bumped:
            assert f"the last 2 poses in time order ({', '.join(last)})" in late[0], late
            miss = float(late[0].split(" miss by ")[1].split(" mm")[0])
            assert 0.15 < miss < 0.5, late
