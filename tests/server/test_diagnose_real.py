"""Both real campaigns through the command line: joint 2's compliance named with its held-out gain,
no per-dataset setting."""

import json

import pytest

from tests.real import CAMPAIGNS, campaign_files
from tests.server.test_diagnose import robocal


@pytest.mark.parametrize("name", CAMPAIGNS)
def test_real_campaign_names_joint_2_compliance(name, tmp_path):
    meas, cell = campaign_files(name)
    report = tmp_path / "report.json"
    out = robocal(
        "diagnose",
        meas,
        "--cell",
        cell,
        "--out",
        report,
        "--model-out",
        tmp_path / "model.json",
        cwd=tmp_path,
    ).stdout
    r = json.loads(report.read_text())
    first = r["effects"][0]
    assert (first["name"], first["joint"]) == ("joint_compliance", 2), out
    before, after = first["holdout_rmse_before_mm"], first["holdout_rmse_after_mm"]
    assert after < 0.8 * before
    lo, hi = first["holdout_gain_interval_mm"]
    assert 0 < lo <= before - after <= hi
    assert first["significance"]["p_value"] < 0.005 and first["uncertainty"]
    for alt in first["alternatives"]:  # named beside it when the data cannot tell them apart
        assert alt["holdout_rmse_mm"] > after
    assert "joint_compliance joint 2" in out and "held-out gain" in out and "interval" in out
    assert r["outliers"] == []
