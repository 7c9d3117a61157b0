"""One SMR on a SCARA: the nominal model's registration frees base z and the SMR's z, one
direction to the readings (every axis vertical). Its covariance's inverse failed ('Singular
matrix'), read as 'no pose can be held out': the summary lost the nominal held-out figure and
the guard 'worse than the nominal arm' went silently off. The redundant coordinate is now held."""

import json

import numpy as np

from robocal.server.cli import main
from robocal.solver.fit_errors import independent

from .test_simulate_unseen import SCARA

BASE = [[1, 0, 0, 300.0], [0, -1, 0, 0.0], [0, 0, -1, 2000.0], [0, 0, 0, 1]]


def calibrated(tmp_path):
    """model.json of a 40-pose one-SMR SCARA campaign hung from the ceiling (seed 3)."""
    cell, meas, model = tmp_path / "cell.json", tmp_path / "m.csv", tmp_path / "model.json"
    cell.write_text(json.dumps({"robot": SCARA, "targets": {"A": [0, 0, 30]}, "base": BASE}))
    sim = ["simulate", "--cell", str(cell), "--poses", "40", "--seed", "3", "--out", str(meas)]
    assert main(sim) == 0
    assert main(["calibrate", str(meas), "--cell", str(cell), "--out", str(model)]) == 0
    return model


def test_one_smr_scara_has_a_nominal_held_out_figure(tmp_path, capsys):
    model = calibrated(tmp_path)
    out = capsys.readouterr().out
    v = json.loads(model.read_text())["validation"]
    print(out, v["nominal_rms_mm"], v["nominal_holdout_rms_mm"], v["holdout_rms_mm"])
    # the nominal arm misses by ~0.36 mm on the readings; held out it misses by more
    assert v["nominal_holdout_rms_mm"] is not None
    assert v["nominal_rms_mm"] <= v["nominal_holdout_rms_mm"] < 2 * v["nominal_rms_mm"]
    assert v["holdout_rms_mm"] < v["nominal_holdout_rms_mm"]


def test_redundant_columns_are_held_in_order_and_independent_ones_kept():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(60, 4))
    assert independent(J.T @ J).all()
    J = np.column_stack([J, -2.0 * J[:, 1], np.zeros(60)])  # a copy of column 1, a dead column
    assert independent(J.T @ J).tolist() == [True, True, True, True, False, False]


def test_an_upside_down_base_changes_the_short_way_round(tmp_path, capsys):
    model = calibrated(tmp_path)
    rows = json.loads(model.read_text())["identified"]["rows"]
    rx = next(r for r in rows if r["parameter"] == "base_rx")
    print(capsys.readouterr().out.count("+359.9998"), rx)
    # rx 180 deg nominal (hung from the ceiling), identified at 179.9998: a change of -0.0002
    assert abs(rx["calibrated"]) > 179.9 and abs(rx["change"]) < 0.01
    assert all(-180 <= r["change"] < 180 for r in rows if r["unit"] == "deg" and r["change"])
