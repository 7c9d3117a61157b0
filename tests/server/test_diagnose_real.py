"""Both real campaigns through the command line: exit 0, the report and the model written, joint
2's compliance named and printed with its held-out gain (the numerics are checked in process in
tests/server/test_diagnose_real_in_process.py)."""

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
    assert json.loads((tmp_path / "model.json").read_text())["extensions"]
    assert "joint_compliance joint 2" in out and "held-out gain" in out and "interval" in out
    assert r["outliers"] == []
