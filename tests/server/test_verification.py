"""`robocal acquire --verify`: an ISO 9283 run on the simulated cell with hidden geometry and
compliance, after a calibration campaign through the same acquisition, diagnosed in process."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import write_model
from robocal.server.verify.run import VerifyOptions, verify
from tests import cli_process

EFFECT = "joint_compliance:2=1.0"


@pytest.fixture(scope="module", params=[6, 17])
def verified(request, tmp_path_factory):
    """(verification report, the model's held-out RMS mm, folder) for a cell drawn from the seed."""
    seed = request.param
    d = tmp_path_factory.mktemp(f"verify{seed}")
    report, model = calibrated_and_verified(d, seed)
    return report.to_json(), model.diagnosis.final.holdout_rmse_mm, d  # as verification.json


def calibrated_and_verified(d, seed: int):
    """(verification report, model) of a simulated cell: a 100-pose campaign diagnosed, its
    model written to d/model.json, then verified on the cube (database d/cell.db)."""
    db_path, cell = d / "cell.db", default_cell()
    s = acquire(db_path, cell, AcquireOptions(poses=100, seed=seed, effects=(EFFECT,), name="cal"))
    db = store.open_database(db_path)
    meas = store.campaign_measurements(
        db, campaign_id=s.campaign, targets=tuple(sorted(cell.targets))
    )
    _, model = workflow.diagnose(cell, meas, screen=False)
    write_model(d / "model.json", model)
    report = verify(db_path, cell, d / "model.json", VerifyOptions(seed=seed, effects=(EFFECT,)))
    return report, model


def test_compensation_brings_accuracy_to_the_models_own_and_keeps_repeatability(verified):
    report, holdout, _ = verified
    before, after = report["before"], report["after"]
    assert [p["point"] for p in after["points"]] == ["P1", "P2", "P3", "P4", "P5"]
    ap_after = after["AP_max_mm"]
    assert ap_after <= 1.5 * holdout, f"AP after {ap_after:.4f} mm, held-out RMS {holdout:.4f}"
    assert before["AP_max_mm"] >= 10 * ap_after
    # the tracker's maximum permissible error some 2 m out: what one reading may be off
    tracker = report["instrument"]
    noise = 1e-3 * (tracker["mpe_um"] + 2.0 * tracker["mpe_um_per_m"])
    for b, a in zip(before["points"], after["points"]):
        assert abs(a["RP_mm"] - b["RP_mm"]) <= max(0.5 * b["RP_mm"], 2 * noise), (b, a)
        # every visit was measured: cycles x directions attained positions per point
        assert np.isfinite(a["attained_mm"]).all() and len(a["attained_mm"]) == 9
    for b, a in zip(before["distances"], after["distances"]):
        assert abs(a["AD_mm"]) <= abs(b["AD_mm"]) + 2 * noise
    assert report["simulated_s"]["compensated"] > 0


def test_acquire_verify_writes_the_figures_and_refuses_bad_points(verified, tmp_path):
    _, _, d = verified
    seed = 6 if d.name.startswith("verify6") else 17
    pts = tmp_path / "points.csv"
    pts.write_text("point,x_mm,y_mm,z_mm\nA,1,2,3\nB,4,oops,6\n")

    def robocal(*args):  # its own process, forked from one that has imported the program
        return cli_process.run(
            "acquire", "--db", d / "cell.db", "--seed", seed, "--effect", EFFECT,
            "--verify", d / "model.json", *args, cwd=tmp_path, timeout=600,
        )  # fmt: skip

    r = robocal("--points", str(pts))
    assert r.returncode == 1 and r.stderr.count("\n") == 1, r.stderr
    assert "points.csv:3:3: y_mm" in r.stderr
    assert not (tmp_path / "verification.json").exists()
    r = robocal("--cycles", "1", "--directions", "1")
    assert r.returncode == 1 and "repeatability" in r.stderr, r.stderr
    r = robocal("--cycles", "2", "--directions", "2", "--out", "v.json", "--certificate", "c.html")
    assert r.returncode == 0, r.stderr
    out = json.loads((tmp_path / "v.json").read_text())
    assert out["cycles"] == 2 and len(out["after"]["points"][0]["attained_mm"]) == 4
    assert out["model"]["sha256"] and "AP after" in r.stdout
    assert "AP: no pass or fail (the cell gives no tolerance_mm)" in r.stdout, r.stdout
    assert "RP: no pass or fail (the cell gives no repeatability_mm)" in r.stdout
    html = (tmp_path / "c.html").read_text()
    assert out["model"]["sha256"] in html and f"{out['after']['AP_max_mm']:.4f}" in html


def test_a_users_points_are_verified_like_the_cube(verified, tmp_path):
    report, holdout, d = verified
    seed = 6 if d.name.startswith("verify6") else 17
    cube = {p["point"]: p["commanded_mm"] for p in report["after"]["points"]}
    pts = tmp_path / "points.csv"
    rows = [f"{n},{x:.3f},{y:.3f},{z:.3f}" for n, (x, y, z) in
            (("centre", cube["P1"]), ("low", cube["P4"]), ("high", cube["P2"]))]  # fmt: skip
    pts.write_text("point,x_mm,y_mm,z_mm\n" + "\n".join(rows) + "\n")
    opts = VerifyOptions(cycles=1, directions=2, points_path=str(pts), seed=seed, effects=(EFFECT,))
    r = verify(d / "cell.db", default_cell(), d / "model.json", opts).to_json()
    assert r["points"] == ["centre", "low", "high"]
    np.testing.assert_allclose(r["after"]["points"][1]["commanded_mm"], cube["P4"], atol=1e-3)
    assert [x["pair"] for x in r["after"]["distances"]] == [["centre", "low"], ["centre", "high"]]
    assert r["after"]["AP_max_mm"] <= 1.5 * holdout < r["before"]["AP_max_mm"] / 10


def test_a_point_beyond_the_arms_reach_is_refused_before_any_solve(verified, monkeypatch):
    from robocal.server.formats.model_json import read_model
    from robocal.server.verify import run as verification

    _, _, d = verified
    model = read_model(d / "model.json")
    solved = []
    real = verification.compensate
    monkeypatch.setattr(verification, "compensate", lambda *a: solved.append(1) or real(*a))
    base = np.asarray(model.base)[:3, 3]
    far = base + [model.robot.reach_mm + 500.0, 0.0, 0.0]
    opts = VerifyOptions(points=(["near", "far"], [base + [900.0, 0.0, 600.0], far]))
    with pytest.raises(ValueError, match=r"test point far is unreachable: \d+ mm from the arm's"):
        verification.make_plan(model, opts)
    assert solved == []  # refused by the bound (it took 60 solves, 3 s of CPU, before)
