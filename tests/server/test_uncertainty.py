"""Standard errors in model.json, the diagnosis report and the command output."""

import contextlib
import io
import json

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.server.calibration import workflow
from robocal.server.cli import main
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import read_model, write_model
from robocal.solver.effects import Extension


@pytest.fixture(scope="module")
def compliance(tmp_path_factory):
    """A campaign with joint-2 compliance of a magnitude drawn from the seed, and its diagnosis."""
    d = tmp_path_factory.mktemp("uncertainty")
    assert (
        main(
            [
                "simulate",
                "--poses",
                "60",
                "--seed",
                "5",
                "--effect",
                "joint_compliance:2",
                "--out",
                str(d / "meas.csv"),
            ]
        )
        == 0
    )
    # in process (the numerics are what is checked here); the console writes to sys.stdout
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(
            [
                "diagnose",
                str(d / "meas.csv"),
                "--out",
                str(d / "report.json"),
                "--model-out",
                str(d / "model.json"),
            ]
        )
    assert code == 0
    return d, out.getvalue()


def test_diagnose_reports_each_effect_parameter_with_its_standard_error(compliance):
    d, out = compliance
    report = json.loads((d / "report.json").read_text())
    (effect,) = [e for e in report["effects"] if e["name"] == "joint_compliance"]
    unc, par = effect["uncertainty"], effect["parameters"]
    assert set(unc) == {"deflection_rms_deg", "deflection_range_deg"}  # not the term count
    for k, se in unc.items():
        assert 0 < se < 0.1 * par[k]
    assert (
        f"deflection_rms_deg {par['deflection_rms_deg']:.6f} ± {unc['deflection_rms_deg']:.6f}"
        in out
    )

    model = json.loads((d / "model.json").read_text())
    (ext,) = model["extensions"]
    assert ext["uncertainty"] == unc
    assert len(ext["coef_standard_errors"]) == len(ext["coef"])
    assert all(v > 0 for v in ext["coef_standard_errors"])
    se = model["uncertainty"]["standard_errors"]
    assert se["theta1"] is None and se["a2"] > 0 and se["A_x"] > 0 and se["base_rz"] > 0


def test_calibrate_writes_and_prints_standard_errors(compliance, capsys, monkeypatch):
    d, _ = compliance
    monkeypatch.chdir(d)
    for method in ("minimax", "ls-sum", "ls-single:B", "ls-pose"):
        assert main(["calibrate", "meas.csv", "--method", method, "--out", "cal.json"]) == 0
        out = capsys.readouterr().out
        assert "±" in out and "fixed" in out and "Identified base and SMR frames" in out
        assert "SMR C (flange)" in out
        model = json.loads((d / "cal.json").read_text())
        unc = model["uncertainty"]
        assert unc["estimator"].startswith("pose-clustered") and unc["poses"] == 60
        missing = {n for n, v in unc["standard_errors"].items() if v is None}
        smrs = {f"{t}_{c}" for t in "ABC" for c in "xyz"}
        assert missing == set(model["fit"]["fixed_parameters"]) - smrs
        assert not missing & smrs  # every SMR is identified, by the fit or afterwards


def test_model_file_round_trips_standard_errors_and_old_files_still_load(tmp_path):
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=2)
    meas = vc.campaign(40, seed=2)
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    model.extensions = [Extension("joint_scale", joint=1, coef=np.array([2e-5]))]
    model.parameters = [{"scale_ppm": 20.0}]
    model.extension_errors = [{"coef_standard_errors": [1e-6], "uncertainty": {"scale_ppm": 1.0}}]
    write_model(tmp_path / "model.json", model)
    back = read_model(tmp_path / "model.json")
    assert back.uncertainty.to_json() == json.loads(json.dumps(model.uncertainty.to_json()))
    assert back.extension_errors == model.extension_errors and back.parameters == model.parameters

    old = json.loads((tmp_path / "model.json").read_text())
    del old["uncertainty"]
    for e in old["extensions"]:
        del e["coef_standard_errors"], e["uncertainty"], e["parameters"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    back = read_model(tmp_path / "old.json")
    assert "uncertainty" not in back.meta and back.extension_errors == [{}]
    q = meas.q[:3]
    assert np.allclose(workflow.model_predict(back, q), workflow.model_predict(model, q))
