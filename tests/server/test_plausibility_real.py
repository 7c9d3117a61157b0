"""Every real campaign's files pass the unit check, read as the commands read them (moved from
tests/solver/test_plausibility.py, which keeps the checks on simulated campaigns)."""

import numpy as np
import pytest

from robocal.server.calibration import workflow
from robocal.server.formats.campaign_csv import read_campaign
from robocal.solver.plausibility import RATIO_BAND, check_cell_angles, check_units
from tests.real import REAL

# Every real campaign's files, read as the commands read them.
REAL_FILES = sorted(
    (d.name, str(f.relative_to(d))) for d in REAL.iterdir() for f in d.rglob("*.csv")
)


@pytest.mark.parametrize(("name", "file"), REAL_FILES)
def test_real_campaigns_pass_the_unit_check(name, file):
    cell = workflow.load_cell(REAL / name / "cell.json")
    meas = read_campaign(REAL / name / file, cell.robot)
    # irb120_wu's test.csv measures an SMR its cell does not name, a few cm from the flange:
    # taken at the flange's origin it moves the predicted spread by far less than the bound
    targets = np.array([cell.targets.get(t, [0.0, 0.0, 0.0]) for t in meas.target_names])
    if all(t in cell.targets for t in meas.target_names):
        workflow.load_campaign(REAL / name / file, cell)  # refused here on a unit mistake
    c = check_units(cell.robot, targets, meas.q, meas.xyz)
    print(f"{name}/{file}: spread ratio {c.ratio:.4f} (band 1/{RATIO_BAND:g}..{RATIO_BAND:g})")
    assert c.plausible and 1 / RATIO_BAND < c.ratio < RATIO_BAND
    assert check_cell_angles(cell.robot, targets, meas.q, meas.xyz) is None
    assert check_units(cell.robot, targets, meas.q, meas.xyz / 1000.0).likely[0] == "metres"
