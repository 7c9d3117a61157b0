"""A calibrated model's verification states its uncertainty: U of the model at each test point
and over the working volume (from model.json's position block), each AP with the tracker's U,
each RP with its U below and above (its visits and the tracker's noise), and the decisions
against the tolerance and the arm's stated repeatability by the guard-banded rule (pass, fail,
not decided). The simulated arm, over the devices' sockets, scatters by the cell's
repeatability_mm, so that RP is the arm's and not the tracker's alone."""

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


def calibrated_and_verified(
    d, tolerance_mm: float | None = 0.5, repeatability_mm: float | None = None
) -> tuple[VerificationDoc, dict]:
    """(verification report, model.json's position block) of a simulated cell calibrated by
    ls-sum on 60 poses, verified with the cell's tolerance (and the arm's repeatability, by
    which it scatters)."""
    cell = dataclasses.replace(
        default_cell(), tolerance_mm=tolerance_mm, repeatability_mm=repeatability_mm
    )
    db_path = d / "cell.db"
    s = acquire(db_path, cell, AcquireOptions(poses=60, seed=SEED, name="cal"))
    meas = store.campaign_measurements(
        store.open_database(db_path), campaign_id=s.campaign, targets=tuple(sorted(cell.targets))
    )
    model = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    write_model(d / "model.json", model)
    report = verify(db_path, cell, d / "model.json", VerifyOptions(seed=SEED))
    return report, read_model(d / "model.json").uncertainty.position


@pytest.fixture(scope="module")
def verified(tmp_path_factory):
    return calibrated_and_verified(tmp_path_factory.mktemp("verification-uncertainty"))


@pytest.fixture(scope="module")
def scattering(tmp_path_factory):
    """The same cell whose arm's data sheet states an RP of 0.04 mm."""
    return calibrated_and_verified(tmp_path_factory.mktemp("scattering"), repeatability_mm=0.04)[0]


def rp_table(report: VerificationDoc) -> np.ndarray:
    """(p, 3): each compensated point's RP, U below and U above (mm)."""
    return np.array([[p.RP_mm, p.RP_U_below_mm, p.RP_U_above_mm] for p in report.after.points])


def test_a_still_arms_rp_is_the_trackers_noise_and_its_u_says_so(verified):
    report, _ = verified
    rp, below, above = rp_table(report).T
    assert np.all(above > 0) and np.all(below >= 0)
    # no arm scatter: the tracker's noise (sigma MPE / 2) accounts for the whole spread
    assert np.allclose(rp - below, 0.0), (rp, below)
    assert report.uncertainty.rp_decision.verdict == "no tolerance"


def test_the_simulated_arm_scatters_by_its_stated_repeatability(verified, scattering):
    still, moving = rp_table(verified[0]), rp_table(scattering)
    print(f"\nRP after (mm), still arm {np.round(still[:, 0], 4)}, RP 0.04 arm "
          f"{np.round(moving[:, 0], 4)} (-U {np.round(moving[:, 1], 4)}, +U "
          f"{np.round(moving[:, 2], 4)})")  # fmt: skip
    assert moving[:, 0].mean() > 1.3 * still[:, 0].mean()
    # beyond what the tracker's noise explains at some point: the arm's own scatter is seen
    assert np.any(moving[:, 0] - moving[:, 1] > 0.0)
    # its true RP (0.04) within [RP - U-, RP + U+] at most points
    assert (
        np.mean((moving[:, 0] - moving[:, 1] <= 0.04) & (0.04 <= moving[:, 0] + moving[:, 2]))
        >= 0.8
    )
    dec = scattering.uncertainty.rp_decision
    assert dec.tolerance_mm == 0.04 and dec.verdict in ("not decided", "pass", "fail")
    assert dec.verdict == decision(*moving[:, [0, 2]].T, 0.04, below=moving[:, 1])["verdict"]


def test_the_rp_decision_guards_each_side_by_its_own_u(scattering):
    rp, below, above = rp_table(scattering).T
    worst = int(np.argmax(rp + above))
    assert (
        decision(rp, above, float(rp[worst] + above[worst]) * 1.001, below=below)["verdict"]
        == "pass"
    )
    low = int(np.argmax(rp - below))
    beyond = float(rp[low] - below[low]) * 0.999
    assert decision(rp, above, beyond, below=below)["verdict"] == "fail"
    # between the two sides: not decided
    assert decision(rp, above, float(np.max(rp)), below=below)["verdict"] == "not decided"


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


def test_a_verification_written_before_rps_u_still_reads(verified):
    """verification.json without RP's U (written before it) parses, and the table and the
    certificate show its RPs bare, with no RP decision."""
    from robocal.server.cli.tables import verification_decisions
    from robocal.server.verify.certificate import render

    written = verified[0].to_json()
    for run in ("before", "after"):
        for p in written[run]["points"]:
            del p["RP_U_below_mm"], p["RP_U_above_mm"]
    del written["uncertainty"]["rp_u"], written["uncertainty"]["rp_decision"]
    old = VerificationDoc.model_validate(written)
    assert old.to_json() == written  # read back as written: nothing added
    assert old.after.points[0].RP_U_above_mm is None and old.uncertainty.rp_decision is None
    assert [line[:3] for line in verification_decisions(old)] == ["AP:"]
    html = render(old)
    assert f"<td>{old.after.points[0].RP_mm:.4f}</td>" in html
    assert "95 % interval" not in html and "U of an RP" not in html
