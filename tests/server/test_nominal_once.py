"""A calibration by the `nominal` method fits the nominal arm once: its verdict's nominal
figures are the model's own, not a second registration of the same arm."""

import pytest

from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.solver import calibrate as solver_calibrate


@pytest.fixture(scope="module")
def campaign():
    from robocal.drivers.cell import VirtualCell

    cell = default_cell()
    return cell, VirtualCell.random(cell.robot, cell.targets, seed=2).campaign(20, seed=2)


def _counted(monkeypatch):
    calls: list[str] = []
    fit = solver_calibrate.calibrate

    def counting(problem, method, *a, **k):
        calls.append(method)
        return fit(problem, method, *a, **k)

    monkeypatch.setattr(solver_calibrate, "calibrate", counting)
    return calls


@pytest.mark.parametrize("method,nominal_fits", [("nominal", 1), ("ls-sum", 1)])
def test_the_nominal_arm_is_fitted_once(campaign, monkeypatch, method, nominal_fits):
    """Before, `nominal` fitted the nominal arm twice: the calibration, then its verdict's
    nominal figures (validation.nominal_errors) on the same readings."""
    cell, meas = campaign
    calls = _counted(monkeypatch)
    model = workflow.model_file(workflow.run_method(cell, meas, method), cell, meas)
    print(f"\n{method}: {calls}")
    assert calls.count("nominal") == nominal_fits, calls
    v = model.validation
    assert v.nominal_rms_mm is not None and v.nominal_holdout_rms_mm is not None
    if method == "nominal":  # the nominal model's figures are its own
        assert v.nominal_rms_mm == v.fit_rms_mm and v.nominal_holdout_rms_mm == v.holdout_rms_mm
        assert not v.deployable
