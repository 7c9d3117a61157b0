"""Gross outliers through the command line: calibrate, compare and diagnose exclude them, print
them by pose and target and record them; --keep-outliers uses every reading."""

import json

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell, displace
from robocal.drivers.effects import make_effects
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell
from tests import cli_process

SEED = 21


def robocal(*args, cwd, ok=True):
    r = cli_process.run(*args, cwd=cwd, timeout=600)
    assert (r.returncode == 0) == ok, r.stderr
    return r


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """40 poses x 3 SMRs with joint-2 compliance and 4 of 120 readings moved 0.3-2 mm (the
    issue's case); returns the folder, the moved (pose id, target) set and the true floor."""
    d = tmp_path_factory.mktemp("outliers")
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects(["joint_compliance:2=0.2"], vc, SEED))
    meas = vc.campaign(40, seed=SEED)
    meas.xyz[:], moved = displace(meas.xyz, SEED, 4 / 120)
    write_campaign(d / "meas.csv", meas)
    bad = {(int(meas.pose_ids[p]), meas.target_names[k]) for p, k in np.argwhere(moved)}
    return d, bad, vc.noise_floor_mm(meas.q)


def printed(stdout) -> set:
    """(pose, target) of the outlier lines a command printed."""
    out = set()
    for line in stdout.splitlines():
        words = line.split()
        if len(words) > 4 and words[0] == "pose" and words[2] == "target":
            out.add((int(words[1]), words[3].rstrip(":")))
    return out


def test_calibrate_excludes_prints_and_records_them(campaign):
    d, bad, _ = campaign
    r = robocal("calibrate", "meas.csv", "--out", "model.json", cwd=d)
    assert printed(r.stdout) == bad
    fit = json.loads((d / "model.json").read_text())["fit"]
    assert {(o["pose"], o["target"]) for o in fit["excluded_readings"]} == bad
    assert all(o["residual_mm"] > 0.2 for o in fit["excluded_readings"])
    assert fit["readings_used"] == 120 - len(bad)
    kept = robocal("calibrate", "meas.csv", "--keep-outliers", "--out", "kept.json", cwd=d)
    assert not printed(kept.stdout) and "screening off" in kept.stdout
    kept_fit = json.loads((d / "kept.json").read_text())["fit"]
    assert "excluded_readings" not in kept_fit


def test_compare_prints_them_once(campaign):
    d, bad, _ = campaign
    r = robocal("compare", "meas.csv", cwd=d)
    assert printed(r.stdout) == bad
    assert r.stdout.count("excluded as gross outliers") == 1


def test_diagnose_lists_them_and_keeps_the_floor(campaign):
    d, bad, floor = campaign
    r = robocal(
        "diagnose", "meas.csv", "--out", "diag/report.json", "--model-out", "diag/model.json", cwd=d
    )
    assert printed(r.stdout) == bad
    report = json.loads((d / "diag" / "report.json").read_text())
    assert {(o["pose"], o["target"]) for o in report["outliers"]} == bad
    assert abs(report["noise_floor_mm"] / floor - 1) < 0.3
    assert [(e["name"], e["joint"]) for e in report["effects"]] == [("joint_compliance", 2)]
    assert report["final"]["holdout_rmse_mm"] < 1.5 * floor
    meta = json.loads((d / "diag" / "model.json").read_text())
    assert len(meta["diagnosis"]["outliers"]) == len(bad)


def test_keep_outliers_takes_no_value(campaign):
    r = robocal("calibrate", "meas.csv", "--keep-outliers=yes", cwd=campaign[0], ok=False)
    assert "--keep-outliers" in r.stderr.strip().splitlines()[-1]
