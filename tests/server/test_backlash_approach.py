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
