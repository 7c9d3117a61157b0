"""Both real campaigns, in process: joint 2's compliance named with its held-out gain, no
per-dataset setting (tests/server/test_diagnose_real.py runs them through the command line;
moved from tests/solver, since the campaign files are read as the commands read them)."""

import pytest

from robocal.server.calibration import workflow
from robocal.solver.diagnose import diagnose
from tests.real import CAMPAIGNS, campaign_files


@pytest.mark.parametrize("name", CAMPAIGNS)
def test_real_campaign_names_joint_2_compliance(name):
    meas_path, cell_path = campaign_files(name)
    cell, meas = workflow.load_data(meas_path, cell_path)
    r = diagnose(workflow.cell_problem(cell, meas)).report.to_json()  # as report.json has it
    first = r["effects"][0]
    assert (first["name"], first["joint"]) == ("joint_compliance", 2), r["effects"]
    before, after = first["holdout_rmse_before_mm"], first["holdout_rmse_after_mm"]
    assert after < 0.8 * before
    lo, hi = first["holdout_gain_interval_mm"]
    assert 0 < lo <= before - after <= hi
    assert first["significance"]["p_value"] < 0.005 and first["uncertainty"]
    # the one-stiffness model of the physics, not the masses fitted one by one
    assert first["parameters"]["gravity_terms"] == 1
    for alt in first["alternatives"]:  # named beside it when the data cannot tell them apart
        # a richer variant may score a little better on these poses: the data cannot tell
        assert alt["holdout_rmse_mm"] > after or alt["label"].endswith("masses fitted)")
    # and it holds off the training region: no region fold worse than geometry
    assert r["extrapolation"]["refused"] == []
    for fold in r["extrapolation"]["folds"]:
        assert fold["final_rmse_mm"] <= fold["geometric_rmse_mm"], fold
    assert r["outliers"] == []
