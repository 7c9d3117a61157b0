"""A backlash model used where a pose's approach direction is unknown (a targets file of one
pose, the first pose of a file without prev_q): the backlash is not applied there, and the
commands say so instead of promising the model's full correction."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import write_model
from tests.server.test_cli import robocal

SEED, POSES, BACKLASH = 4, 80, "joint_backlash:2=0.05"


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    """model.json diagnosed from an untimed campaign with 0.05 deg of backlash on joint 2, and
    its last pose with the joints the arm came from."""
    d = tmp_path_factory.mktemp("backlash")
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects([BACKLASH], vc, SEED))
    meas = replace(vc.campaign(POSES, seed=SEED), time_s=None, temp_c=None)
    _, model = workflow.diagnose(cell, meas, screen=False)
    assert [e.label() for e in model.extensions] == ["joint_backlash(2)"]
    write_model(d / "model.json", model)
    return d, meas


def _one_pose(path, meas, k, prev):
    """targets.csv of pose k's readings, its joints as the start, prev_q columns if prev."""
    n = meas.q.shape[1]
    head = ["pose", "target", "x", "y", "z", *[f"q{i}" for i in range(1, n + 1)]]
    head += [f"prev_q{i}" for i in range(1, n + 1)] if prev else []
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        for t, name in enumerate(meas.target_names):
            row = [meas.pose_ids[k], name, *meas.xyz[k, t], *np.degrees(meas.q[k])]
            w.writerow(row + (list(np.degrees(meas.q[k - 1])) if prev else []))


def test_one_pose_without_its_approach_is_said_and_with_it_not(model_dir):
    """One pose to compensate (a production line asks per target), no prev_q: the backlash of
    joint 2 was dropped without a word (its direction 0), predicted error 0.000 mm."""
    d, meas = model_dir
    k = 40
    _one_pose(d / "t.csv", meas, k, prev=False)
    _one_pose(d / "tp.csv", meas, k, prev=True)
    for cmd in (("compensate", "model.json", "t.csv"), ("predict", "model.json", "t.csv")):
        r = robocal(*cmd, "--out", "o.csv", cwd=d)
        assert r.returncode == 0, r.stderr
        warn = [ln for ln in r.stderr.splitlines() if "last motion" in ln]
        assert len(warn) == 1, (cmd, r.stderr)
        assert f"pose {meas.pose_ids[k]!r}" in warn[0] and "joint_backlash(2)" in warn[0], warn
        assert "prev_q" in warn[0], warn
        r = robocal(cmd[0], "model.json", "tp.csv", "--out", "o.csv", cwd=d)
        assert r.returncode == 0 and "last motion" not in r.stderr, r.stderr


ORDER = "the rows' order is taken as the order of motion"


def test_the_row_order_taken_as_the_order_of_motion_is_said_where_backlash_needs_it(model_dir):
    """A backlash model on a file with neither time_s nor prev_q: `predict`, `evaluate`,
    `compensate` and `check` (which said nothing) say in one warning line that the rows' order is the order of motion (a file
    sorted after the fact, here by q1, is named as such); with times or prev_q they do not."""
    from robocal.server.formats.campaign_csv import write_campaign

    d, meas = model_dir
    part = meas.subset(np.arange(20))
    by_q1 = part.subset(np.argsort(part.q[:, 0]))
    prev = np.vstack([np.full((1, part.q.shape[1]), np.nan), part.q[:-1]])
    files = {
        "rows.csv": (part, False),
        "sorted.csv": (by_q1, True),
        "timed.csv": (replace(part, time_s=np.arange(20.0)[:, None].repeat(3, axis=1)), None),
        "prev.csv": (replace(part, prev_q=prev), None),
    }
    for name, (m, is_sorted) in files.items():
        write_campaign(d / name, m)
        for cmd in (
            ("predict", "model.json", name, "--out", "o.csv"),
            ("evaluate", "model.json", name),
            ("compensate", "model.json", name, "--out", "o.csv"),
            ("check", "model.json", name, "--db", f"{name}.db"),
        ):
            r = robocal(*cmd, cwd=d)
            assert r.returncode in ((0, 3) if cmd[0] == "check" else (0,)), (cmd, r.stderr)
            said = [ln for ln in r.stderr.splitlines() if ORDER in ln]
            if is_sorted is None:
                assert not said, (cmd, r.stderr)
                continue
            assert len(said) == 1 and "joint_backlash(2)" in said[0], (cmd, r.stderr)
            assert len([ln for ln in r.stderr.splitlines() if "last motion" in ln]) <= 1
            assert ("q1 only rises down the rows" in said[0]) == is_sorted, said


def test_diagnose_says_the_row_order_only_where_backlash_is_involved(model_dir, tmp_path):
    """`diagnose` without time_s or prev_q: said when it names backlash or when the rows look
    sorted by a joint (the backlash it tests reads scrambled directions), not for a campaign in
    its order whose diagnosis names none; `calibrate` (geometry, no motion order) never says it."""
    from robocal.server.formats.campaign_csv import write_campaign

    d, meas = model_dir
    write_campaign(tmp_path / "rows.csv", meas)
    write_campaign(tmp_path / "sorted.csv", meas.subset(np.argsort(meas.q[:, 0])))
    r = robocal("simulate", "--poses", 40, "--seed", 3, "--out", "clean.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "clean.csv").read_text().splitlines()
    head = text[0].split(",")
    keep = [i for i, c in enumerate(head) if c not in ("time_s", "temp_c")]
    (tmp_path / "clean.csv").write_text(
        "\n".join(",".join(ln.split(",")[i] for i in keep) for ln in text) + "\n"
    )
    for name, said in (("rows.csv", True), ("sorted.csv", True), ("clean.csv", False)):
        r = robocal("diagnose", name, "--out", "r.json", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        lines = [ln for ln in r.stderr.splitlines() if ORDER in ln]
        assert len(lines) == int(said), (name, r.stderr)
        assert ("q1 only rises" in r.stderr) == (name == "sorted.csv"), r.stderr
    r = robocal("calibrate", "sorted.csv", "--out", "m.json", cwd=tmp_path)
    assert r.returncode == 0 and ORDER not in r.stderr, r.stderr
