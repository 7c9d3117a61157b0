"""A calibrated model's verification states its uncertainty: U of the model at each test point
and over the working volume (from model.json's position block), each AP with the tracker's U,
and the decision against the tolerance by the guard-banded rule (pass, fail, not decided)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import read_model, write_model
from robocal.server.formats.verification_doc import VerificationDoc
from robocal.server.verify.run import VerifyOptions, verify
from robocal.server.verify.uncertainty import decision

SEED = 8


def calibrated_and_verified(d, tolerance_mm: float | None = 0.5) -> tuple[VerificationDoc, dict]:
    """(verification report, model.json's position block) of a simulated cell calibrated by
    ls-sum on 60 poses (the arm's scatter included), verified with the cell's tolerance."""
    cell = dataclasses.replace(default_cell(), tolerance_mm=tolerance_mm)
    db_path = d / "cell.db"
    s = acquire(db_path, cell, AcquireOptions(poses=60, seed=SEED, name="cal"))
    meas = store.campaign_measurements(
        store.open_database(db_path), campaign_id=s["campaign"], targets=tuple(sorted(cell.targets))
    )
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    write_model(d / "model.json", model)
    report = verify(db_path, cell, d / "model.json", VerifyOptions(seed=SEED))
    return report, read_model(d / "model.json").uncertainty.position


@pytest.fixture(scope="module")
def verified(tmp_path_factory):
    return calibrated_and_verified(tmp_path_factory.mktemp("verification-uncertainty"))


def test_model_json_keeps_the_position_uncertainty(verified):
    _, block = verified
    n = len(block["parameters"])
    cov = np.asarray(block["covariance"])
    assert cov.shape == (n, n) and np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-12)
    assert block["coverage"] == 0.95 and block["joint_scatter_deg"] >= 0.0


def test_each_point_has_its_uncertainty_and_the_volume_a_map(verified):
    report = verified[0].to_json()  # as verification.json has it
    unc = report["uncertainty"]
    model = unc["model"]
    points = report["after"]["points"]
    assert len(model["model_U_mm"]) == len(points) == len(model["reading_U_mm"])
    for p, u, r in zip(points, model["model_U_mm"], model["reading_U_mm"]):
        assert 0.0 < u < r < 1.0, (u, r)  # mm: a reading adds the tracker's error
        assert 0.005 < p["AP_U_mm"] < 0.05, p["AP_U_mm"]  # the tracker's MPE at its range
    print("\nAP after and model U per point:", [(round(p["AP_mm"], 4), round(u, 4))
          for p, u in zip(points, model["model_U_mm"])])  # fmt: skip
    m = model["map"]
    assert len(m["xyz_mm"]) == len(m["U_mm"]) == 600
    assert min(m["U_mm"]) > 0


def test_the_decision_follows_the_guard_bands(verified):
    report = verified[0].to_json()  # as verification.json has it
    dec = report["uncertainty"]["decision"]
    assert dec["verdict"] == "pass" and dec["tolerance_mm"] == 0.5, dec
    ap = np.array([p["AP_mm"] for p in report["after"]["points"]])
    u = np.array([p["AP_U_mm"] for p in report["after"]["points"]])
    worst = int(np.argmax(ap))
    assert decision(ap, u, float(ap[worst] + u[worst] * 1.01))["verdict"] == "pass"
    assert decision(ap, u, float(ap[worst]))["verdict"] == "not decided"
    assert decision(ap, u, float(ap[worst] - u[worst] * 1.01))["verdict"] == "fail"
    assert decision(ap, u, None)["verdict"] == "no tolerance"
