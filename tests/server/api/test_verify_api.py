"""A verification run over the API: planned from a done job's model on the cell its campaign was
measured on, run by the acquisition runner as any campaign (one at a time, e-stop, reset,
resume), its ISO 9283 figures and certificate read back once it is done."""

from __future__ import annotations

import pytest

from tests.server.api.conftest import wait_for
from tests.server.api.test_compensate_api import model_job  # noqa: F401 - a fixture
from tests.server.api.test_live import readings

PROBLEM = "application/problem+json"


def run_campaign(c, **body) -> int:
    r = c.post("/api/campaigns", json=body)
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["status"] == "done")
    return cid


def calibrate(c, cid, method="ls-sum") -> int:
    r = c.post("/api/jobs", json={"campaign_id": cid, "method": method})
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    return job["id"]


@pytest.mark.sqlite_only  # the store's part (campaigns, readings) runs on both backends elsewhere
def test_verify_a_model_estop_reset_resume_and_read_the_certificate(live):
    c = live.client
    seed = 23
    job = calibrate(c, run_campaign(c, name="cal", poses=60, seed=seed, pause_s=0, arm="SN-23"))
    url = f"/api/models/{job}/verify"
    body = {"cycles": 2, "directions": 2, "pause_s": 0}
    assert live.anonymous.post(url, json=body).status_code == 401

    r = c.post(url, json=body)
    assert r.status_code == 201, r.text
    v = r.json()
    vid = v["id"]
    assert v["kind"] == "verification" and v["poses_total"] == 2 * 5 * 2 * 2 * 2, v
    assert v["settings"]["options"]["seed"] == seed  # the calibration's simulated arm
    assert v["arm"] == "SN-23", v  # and its serial number
    # the arm runs one campaign at a time: a second verification is refused while this one runs
    r = c.post(url, json=body)
    assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, r.text
    assert c.get(f"/api/campaigns/{vid}/verification").status_code == 409  # not done yet

    wait_for(lambda: c.get(f"/api/campaigns/{vid}").json(), lambda j: j["poses_done"] >= 5)
    r = c.post(f"/api/campaigns/{vid}/estop")
    assert r.status_code == 200 and r.json()["status"] == "estopped", r.text
    stopped = wait_for(
        lambda: c.get(f"/api/campaigns/{vid}").json(),
        lambda j: j["status"] == "estopped" and not (j["run"] or {}).get("active"),
    )
    assert stopped["poses_done"] < stopped["poses_total"]
    before = readings(live, vid)
    assert c.post(f"/api/campaigns/{vid}/reset").json()["status"] == "paused"
    assert c.post(f"/api/campaigns/{vid}/resume").status_code == 202
    done = wait_for(lambda: c.get(f"/api/campaigns/{vid}").json(), lambda j: j["status"] == "done")
    after = readings(live, vid)
    assert set(after.values()) == {1} and set(before) <= set(after)  # none lost or duplicated
    assert len({i for i, _ in after}) == done["poses_total"]

    r = c.get(f"/api/campaigns/{vid}/verification")
    assert r.status_code == 200, r.text
    rep = r.json()
    assert rep["campaign"] == vid and rep["model"]["path"] == f"job-{job}.model.json"
    assert [p["point"] for p in rep["after"]["points"]] == ["P1", "P2", "P3", "P4", "P5"]
    for p in rep["after"]["points"]:
        assert len(p["attained_mm"]) == 4  # 2 cycles x 2 directions
    # geometry only (no hidden effects): compensation brings AP to the tracker's noise
    assert rep["before"]["AP_max_mm"] >= 10 * rep["after"]["AP_max_mm"], rep
    assert rep["after"]["AP_max_mm"] < 0.1
    assert live.anonymous.get(f"/api/campaigns/{vid}/verification").status_code == 401

    r = c.get(f"/api/campaigns/{vid}/certificate")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html"), r.text
    html = r.text
    assert "Accuracy certificate" in html and f"job-{job}.model.json" in html
    assert f"{rep['after']['AP_max_mm']:.4f}" in html

    # a measurement campaign has no figures
    cal = [x for x in c.get("/api/campaigns").json() if x["name"] == "cal"][0]
    assert cal["kind"] == "measurement"
    r = c.get(f"/api/campaigns/{cal['id']}/verification")
    assert r.status_code == 404 and "not a verification run" in r.json()["detail"], r.text


@pytest.mark.sqlite_only
def test_verify_refuses_what_it_cannot_run(live, tmp_path):
    c = live.client
    job = calibrate(c, run_campaign(c, name="cal", poses=40, seed=3, pause_s=0))
    url = f"/api/models/{job}/verify"
    # a point the arm cannot reach: 422 naming it; nothing stored
    far = {"point": "far", "x_mm": 90000, "y_mm": 0, "z_mm": 0}
    r = c.post(url, json={"points": [far, {**far, "point": "farther"}], "pause_s": 0})
    assert r.status_code == 422 and "unreachable" in r.json()["detail"], r.text
    assert len(c.get("/api/campaigns").json()) == 1
    # bounds of the body: 422 naming the field
    for bad in ({"cycles": 0}, {"directions": 7}, {"points": []}, {"name": "a\x00b"}):
        r = c.post(url, json=bad)
        assert r.status_code == 422, (bad, r.text)
    # planned only, then started as any campaign
    r = c.post(url, json={"cycles": 1, "directions": 2, "pause_s": 0, "start": False})
    assert r.status_code == 201 and r.json()["status"] == "planned", r.text
    assert "start" in r.json()["actions"]
    assert c.post("/api/models/999/verify", json={}).status_code == 404


@pytest.mark.sqlite_only
def test_imported_readings_on_a_simulated_cell_have_no_arm_to_verify_on(live, model_job):
    r = live.client.post(f"/api/models/{model_job[0]}/verify", json={})
    assert r.status_code == 409 and "imported" in r.json()["detail"], r.text


@pytest.mark.sqlite_only
def test_a_thermal_models_compensated_poses_are_solved_as_due_and_resumed_over_the_api(live):
    """A model with a temperature term: its compensated poses are stored one by one as the run
    reaches them; e-stopped among them, reset and resumed over the API, the run replays the
    stored joints, solves the rest at the temperature then read, and is done."""
    import json
    from pathlib import Path

    import numpy as np

    from robocal.server import store
    from robocal.server.acquisition.compensated import KEY, TEMPS
    from robocal.server.formats.model_json import extension_to_json
    from robocal.solver.effects import Extension

    c = live.client
    job = calibrate(c, run_campaign(c, name="cal", poses=40, seed=5, pause_s=0))
    db = store.open_database(live.settings.database)
    path = Path(store.get_job(db, job_id=job).results["model"])
    doc = json.loads(path.read_text())
    growth = Extension("thermal_drift", variable="temp_c", t_ref=20.0, coef=np.array([1e-6]))
    doc["extensions"] = [extension_to_json(growth)]
    doc.pop("uncertainty", None)  # its block has no row for the term: U not stated
    path.write_text(json.dumps(doc))

    r = c.post(f"/api/models/{job}/verify", json={"cycles": 2, "directions": 2, "pause_s": 0})
    assert r.status_code == 201, r.text
    v = r.json()
    vid, total = v["id"], 2 * 5 * 2 * 2 * 2
    assert v["poses_total"] == total and KEY in v["settings"], v["poses_total"]
    half = total // 2
    wait_for(lambda: c.get(f"/api/campaigns/{vid}").json(), lambda j: j["poses_done"] >= half + 3)
    assert c.post(f"/api/campaigns/{vid}/estop").json()["status"] == "estopped"
    stopped = wait_for(
        lambda: c.get(f"/api/campaigns/{vid}").json(),
        lambda j: j["status"] == "estopped" and not (j["run"] or {}).get("active"),
    )
    assert stopped["poses_total"] == total and stopped["poses_done"] < total, stopped
    stored = store.planned_poses(db, campaign_id=vid)
    assert half + 3 <= len(stored) < total  # the compensated poses stored only as reached
    assert c.post(f"/api/campaigns/{vid}/reset").json()["status"] == "paused"
    assert c.post(f"/api/campaigns/{vid}/resume").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{vid}").json(), lambda j: j["status"] == "done")
    after = store.planned_poses(db, campaign_id=vid)
    assert len(after) == total
    assert [p.joints_deg for p in after[: len(stored)]] == [p.joints_deg for p in stored]
    temps = store.get_campaign(db, campaign_id=vid).settings[TEMPS]
    assert len(temps) == half and all(t is not None for t in temps)
    rep = c.get(f"/api/campaigns/{vid}/verification").json()
    assert rep["after"]["AP_max_mm"] < 0.1 and "compensation_note" not in rep["uncertainty"], rep
