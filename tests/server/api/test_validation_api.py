"""The validation guard over the API: a 5-pose campaign's model is marked not deployable with its
reasons (job, parameters route), compensate and export refuse it without force=true; a healthy
campaign's is deployable and its parameter table complete; evaluating on another cell's data is
refused with the reason."""

from __future__ import annotations

import json

import pytest

from robocal.server.formats.blocks import NO_VERDICT
from tests.real import import_real
from tests.server.api.test_verify_api import calibrate, run_campaign

PROBLEM = "application/problem+json"


@pytest.mark.sqlite_only  # the store's part (campaigns, jobs) runs on both backends elsewhere
def test_a_five_pose_campaign_gives_a_model_not_to_deploy(live):
    c = live.client
    job = calibrate(c, run_campaign(c, name="five", poses=5, seed=1, pause_s=0))
    j = c.get(f"/api/jobs/{job}").json()
    v = j["validation"]
    assert v["deployable"] is False, j
    assert any(r.startswith("too few poses: 5 poses give 45 equations") for r in v["reasons"]), v
    assert j["parameters_url"] == f"/api/models/{job}/parameters"

    assert live.anonymous.get(j["parameters_url"]).status_code == 401  # reads need the token
    r = c.get(j["parameters_url"])
    assert r.status_code == 200, r.text
    p = r.json()
    assert p["validation"]["deployable"] is False and p["validation"]["reasons"] == v["reasons"]
    held_out, fit = p["validation"]["holdout_rms_mm"], p["validation"]["fit_rms_mm"]
    assert held_out is None or held_out > 2 * fit  # poses it did not see: far worse

    body = "pose,target,x,y,z\n1,A,1000,200,900\n"
    for url, params in (
        (f"/api/models/{job}/compensate", {}),
        (f"/api/models/{job}/export", {"format": "urdf"}),
    ):
        r = c.post(url, params=params, content=body, headers={"content-type": "text/csv"})
        assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, r.text
        assert "not deployable: too few poses" in r.json()["detail"], r.text
    r = c.post(f"/api/models/{job}/export", params={"format": "urdf", "force": "true"})
    assert r.status_code == 200, r.text


@pytest.mark.sqlite_only
def test_a_healthy_campaign_is_deployable_with_its_parameter_table(live):
    c = live.client
    cid = run_campaign(c, name="sixty", poses=60, seed=2, pause_s=0)
    job = calibrate(c, cid)
    j = c.get(f"/api/jobs/{job}").json()
    assert j["validation"]["deployable"] is True and j["validation"]["reasons"] == [], j
    assert j["validation"]["warnings"] == [], j  # its SMRs are where the cell says
    p = c.get(f"/api/models/{job}/parameters").json()
    v, ident = p["validation"], p["identified"]
    assert v["warnings"] == [], v
    assert v["holdout_rms_mm"] >= v["fit_rms_mm"] > 0 and v["condition_number"] < 1000
    rows = {r["parameter"]: r for r in ident["rows"]}
    for joint in range(1, 7):
        for kind in ("theta", "d", "a", "alpha"):
            r = rows[f"{kind}{joint}"]
            assert r["unit"] == ("deg" if kind in ("theta", "alpha") else "mm")
            assert r["change"] == pytest.approx(r["calibrated"] - r["nominal"])
            assert (r["standard_error"] is None) == (r["status"] == "held fixed"), r
    assert "beta2" in rows  # joints 2 and 3 are parallel: Hayati's beta
    fixed = {f["parameter"]: f["why"] for f in ident["fixed"]}
    assert fixed["theta1"].startswith("redundant with") and rows["theta1"]["status"] == "held fixed"
    for n in ("base_x", "base_rz", "A_x", "C_z"):
        assert rows[n]["standard_error"] > 0, rows[n]
    assert rows["A_x"]["nominal"] == 60.0 and rows["A_x"]["change"] is not None  # the cell's SMR
    r = [abs(x["r"]) for x in ident["correlations"]]
    assert len(r) == 5 and r == sorted(r, reverse=True) and 0 < r[-1] <= r[0] <= 1
    assert ident["condition_number"] == pytest.approx(v["condition_number"])
    r = c.post(f"/api/models/{job}/export", params={"format": "params"})
    assert r.status_code == 200, r.text
    # the job's summary carries the accuracy to expect and the floor's source
    assert j["validation"]["summary"].startswith("expected accuracy on new poses"), j
    assert j["validation"]["noise_floor_source"] == v["noise_floor_source"]
    # its own campaign is of its cell: evaluated without a warning
    e = c.get(f"/api/models/{job}/evaluate", params={"campaign_id": cid})
    assert e.status_code == 200 and "warnings" not in e.json(), e.text
    # the same model without its verdict (as written before the guard): never deployable
    path = live.settings.models_dir / f"job-{job}.model.json"
    model = json.loads(path.read_text())
    del model["validation"]
    path.write_text(json.dumps(model))
    r = c.post(f"/api/models/{job}/export", params={"format": "params"})
    assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, r.text
    assert f"the model is not deployable: {NO_VERDICT}" in r.json()["detail"], r.text


@pytest.mark.sqlite_only
def test_evaluating_on_another_cell_is_refused_with_the_reason(live):
    c = live.client
    job = calibrate(c, run_campaign(c, name="own", poses=30, seed=3, pause_s=0))
    other = import_real(c, "qkm_hl6")
    url = f"/api/models/{job}/evaluate"
    r = c.get(url, params={"campaign_id": other})
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    assert f"campaign {other}: the data is of robot" in r.json()["detail"], r.text
    # a simulated campaign of the same robot but another arm and tracker place: errors of metres
    far = run_campaign(c, name="far", poses=10, seed=11, pause_s=0)
    r = c.get(url, params={"campaign_id": far})
    assert r.status_code == 422 and "not of the model's cell" in r.json()["detail"], r.text
    r = c.get(url, params={"campaign_id": far, "force": "true"})
    assert r.status_code == 200 and "not of the model's cell" in r.json()["warnings"][0], r.text
