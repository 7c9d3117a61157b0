"""model.json's validation block on the arm: its held-out RMS is what refitting without each
pose gives (ls-sum to 0.1%, minimax to 5%), and its identified block names every parameter."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import TrackerSpec, VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.calibration import workflow
from robocal.solver.kinematics import predict
from robocal.solver.measurements import Measurements


def campaign(poses, seed, effects=()):
    cell = workflow.load_cell(None)
    vc = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec(**cell.tracker)
    )
    vc.effects.extend(make_effects(list(effects), vc, seed))
    return cell, vc.campaign(poses, seed=seed)


def refit_holdout(cell, meas, method) -> float:
    """3-D RMS per reading of each pose predicted by a model refitted without it."""
    errs = []
    for p in range(meas.n_poses):
        keep = np.arange(meas.n_poses) != p
        sub = Measurements(
            [meas.pose_ids[i] for i in np.flatnonzero(keep)], meas.q[keep], meas.target_names,
            meas.xyz[keep],
        )  # fmt: skip
        cal = workflow.run_method(cell, sub, method, screening=False)
        e = np.linalg.norm(predict(cal.layout, cal.x, meas.q[[p]]) - meas.xyz[[p]], axis=-1)
        errs.append(e[np.isfinite(e)])
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e * e)))


@pytest.mark.parametrize("method, rel", [("ls-sum", 1e-3), ("minimax", 0.05)])
def test_the_held_out_rms_is_that_of_refits(method, rel):
    cell, meas = campaign(20, seed=4, effects=["joint_compliance:2"])
    cal = workflow.run_method(cell, meas, method, screening=False)
    v = workflow.model_file(cal, cell, meas).validation.to_json()
    assert v["holdout_rms_mm"] == pytest.approx(refit_holdout(cell, meas, method), rel=rel)
    assert v["holdout_rms_mm"] > v["fit_rms_mm"]


def test_the_identified_block_names_every_parameter():
    cell, meas = campaign(40, seed=6)
    cal = workflow.run_method(cell, meas, "ls-pose")
    model = workflow.model_file(cal, cell, meas)
    ident = model.identified.to_json()
    names = [r["parameter"] for r in ident["rows"]]
    assert set(names) == set(cal.layout.names())
    assert {f["parameter"] for f in ident["fixed"]} == set(cal.fixed)
    assert model.validation.deployable is True, model.validation.reasons


def test_a_model_without_an_identified_block_still_has_its_table():
    from robocal.server.api.model_schemas import ModelParameters
    from robocal.server.calibration.identified import parameters_of

    cell, meas = campaign(30, seed=7)
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    full = parameters_of(model).to_json()
    del model.meta["identified"]  # as a diagnosis's model, or one written before
    table = parameters_of(model).to_json()
    ModelParameters.model_validate(
        {"job_id": 1, "method": "ls-sum", "identified": table, "validation": None}
    )
    ModelParameters.model_validate(
        {
            "job_id": 1,
            "method": "ls-sum",
            "identified": full,
            "validation": model.validation,
        }
    )
    rows = {r["parameter"]: r for r in table["rows"]}
    assert rows["a2"] == {r["parameter"]: r for r in full["rows"]}["a2"]
    assert rows["base_x"]["standard_error"] is None and table["correlations"] == []


def test_the_params_table_gives_the_base_standard_errors_and_smr_nominals():
    import csv
    import io

    from robocal.server.exports.params import params_text

    cell, meas = campaign(30, seed=8)
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    rows = {r["parameter"]: r for r in csv.DictReader(io.StringIO(params_text(model)))}
    ident = {r["parameter"]: r for r in model.identified.to_json()["rows"]}
    for n in ("base_x", "base_rz"):
        assert float(rows[n]["standard_error"]) == pytest.approx(ident[n]["standard_error"], 1e-2)
    assert float(rows["B_y"]["nominal"]) == cell.targets["B"][1]
    assert float(rows["B_y"]["difference"]) == pytest.approx(ident["B_y"]["change"])


def test_the_base_standard_errors_are_those_of_the_tracker_frame():
    from robocal.server.calibration.identified import base_standard_errors
    from robocal.solver.fit_errors import calibration_errors

    cell, meas = campaign(30, seed=9)
    cal = workflow.run_method(cell, meas, "ls-sum", screening=False)
    errors = calibration_errors(cal, meas.q, meas.xyz)
    se = base_standard_errors(cal.base, errors)
    R = cal.base[:3, :3]  # the base's translation moves along its own axes
    C = R @ errors.block(["base_x", "base_y", "base_z"]) @ R.T
    want = np.sqrt(np.diag(C))
    assert [se["base_x"], se["base_y"], se["base_z"]] == pytest.approx(want.tolist(), rel=1e-4)
    assert all(se[n] > 0 for n in ("base_rz", "base_ry", "base_rx"))


@pytest.mark.parametrize(
    ("poses", "effects", "deployable"), [(8, (), False), (60, ("joint_compliance:2",), True)]
)
def test_a_diagnosis_model_is_judged_on_its_own_cross_validation(poses, effects, deployable):
    cell, meas = campaign(poses, 21, effects)
    d, model = workflow.diagnose(cell, meas, screen=False)
    v = model.validation.to_json()
    assert v["deployable"] is deployable, v["reasons"]
    assert v["holdout"].startswith("5-fold cross-validation")
    assert v["holdout_rms_mm"] == pytest.approx(d.report.final.holdout_rmse_mm)
    if not deployable:
        assert any(r.startswith("too few poses") for r in v["reasons"])


def test_the_noise_floor_is_measured_once(monkeypatch):
    """run_method measures the tracker's noise on the fit's readings; the verdict reuses it."""
    cell, meas = campaign(20, seed=4)
    measured = []

    def counted(cell, meas):
        measured.append(meas)
        return floor(cell, meas)

    floor = workflow.noise_floor
    monkeypatch.setattr(workflow, "noise_floor", counted)
    cal = workflow.run_method(cell, meas, "ls-sum")
    v = workflow.model_file(cal, cell, meas).validation
    assert len(measured) == 1
    assert (v.noise_floor_mm, v.noise_floor_source) == (cal.noise_floor.mm, cal.noise_floor.source)
    # a calibration made elsewhere has none: the verdict measures it
    del cal["noise_floor"]
    again = workflow.model_file(cal, cell, meas).validation
    assert len(measured) == 2 and again.noise_floor_mm == v.noise_floor_mm
    # compare: one data, one measurement for all its methods
    rows = workflow.compare(cell, meas, ["nominal", "ls-sum"], screen=False)
    assert len(measured) == 3
    assert {c.noise_floor for c, _ in rows.values()} == {floor(cell, meas)}
