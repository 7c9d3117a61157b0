"""Plan, run, calibrate, fetch the model; import and export meas.csv; the schema is served."""

import subprocess
import sys
from pathlib import Path

import pytest

from tests.server.api.conftest import wait_for

PROBLEM = "application/problem+json"


def test_simulated_campaign_runs_then_calibrates_to_a_model(live):
    c = live.client
    r = c.post("/api/campaigns", json={"name": "api-20", "poses": 20, "seed": 3})
    assert r.status_code == 201, r.text
    campaign = r.json()
    cid = campaign["id"]
    assert campaign["status"] == "planned"
    assert (campaign["poses_total"], campaign["poses_done"]) == (20, 0)
    assert campaign["settings"]["options"]["poses"] == 20

    r = c.post(f"/api/campaigns/{cid}/start")
    assert r.status_code == 202, r.text
    done = wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["status"] not in ("planned", "running") and not (j["run"] or {}).get("active"),
    )
    assert done["status"] == "done" and done["actions"] == [], done
    assert done["poses_done"] == 20 and done["run"]["detail"] == "the run ended done"
    assert done["run"]["summary"]["measured_poses"] == 20

    readings = c.get(f"/api/campaigns/{cid}/measurements").json()
    assert len(readings) == 60 and {r["target"] for r in readings} == {"A", "B", "C"}
    csv_text = c.get(f"/api/campaigns/{cid}/measurements.csv").text
    assert csv_text.startswith("pose,") and len(csv_text.strip().splitlines()) == 61

    # A finished campaign cannot be started again.
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 409

    r = c.post("/api/jobs", json={"campaign_id": cid, "method": "minimax"})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["state"] in ("queued", "running", "done")
    job = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(), lambda j: j["state"] in ("done", "failed")
    )
    assert job["state"] == "done", job
    model = c.get(job["model_url"]).json()
    assert model["method"] == "minimax" and model["data"]["poses"] == 20
    assert model["data"]["campaign"] == cid and set(model["targets"]) == {"A", "B", "C"}
    assert (live.settings.models_dir / f"job-{job['id']}.model.json").exists()
    assert job["kind"] == "calibration" and job["progress"] == 1.0
    r = c.get(job["recording_url"])
    assert r.status_code == 200 and len(r.content) > 1000, r.text
    assert r.headers["content-type"] == "application/octet-stream"
    rrd = live.settings.data_dir / "downloaded.rrd"
    rrd.write_bytes(r.content)
    rerun = Path(sys.executable).parent / "rerun"
    v = subprocess.run(
        [str(rerun), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120
    )
    assert v.returncode == 0, v.stderr
    ev = c.get(f"/api/models/{job['id']}/evaluate", params={"campaign_id": cid}).json()
    assert ev["model"]["rmse"] < 0.05 and ev["improvement_pct"]["ap_mean"] > 90

    # A diagnosis of the same campaign: a report, its figures and the extended model.
    r = c.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis"})
    assert r.status_code == 202, r.text
    diag = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert diag["state"] == "done" and diag["kind"] == "diagnosis", diag
    report = c.get(diag["report_url"]).json()
    assert "final" in report and "effects" in report
    figures = c.get(diag["figures_url"]).json()
    assert [f["name"] for f in figures] == report["figures"]
    for f in figures:
        png = c.get(f["url"])
        assert png.status_code == 200 and png.content.startswith(b"\x89PNG")
    assert c.get(f"/api/jobs/{diag['id']}/figures/..%2Fsecret.png").status_code == 404
    # its recording: "after" the final model, the geometry beside it
    rec = c.get(f"/api/jobs/{diag['id']}/recording")
    assert rec.status_code == 200, rec.text
    drrd = live.settings.data_dir / "diagnosis.rrd"
    drrd.write_bytes(rec.content)
    text = subprocess.run(
        [str(rerun), "rrd", "print", str(drrd)], capture_output=True, text=True, timeout=120
    ).stdout
    assert "/world/frames/geometric/links" in text, text[:2000]
    assert c.get(diag["model_url"]).status_code == 200


def test_job_requests_are_checked_before_queueing(live):
    c = live.client
    cid = c.post("/api/campaigns", json={"poses": 5}).json()["id"]
    assert c.post("/api/jobs", json={"campaign_id": cid}).status_code == 409  # not done
    assert c.post("/api/jobs", json={"campaign_id": 99}).status_code == 404
    r = c.get("/api/models/99")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM


def test_failed_job_reports_its_reason(live):
    c = live.client
    rows = [
        "pose,q1,q2,q3,q4,q5,q6,target,x,y,z",
        "p1,0,0,0,0,30,0,A,1000,0,1500",
        "p2,10,20,-10,45,-30,90,A,900,100,1400",
    ]
    cid = c.post("/api/measurements/import", content="\n".join(rows) + "\n").json()["id"]
    job = c.post("/api/jobs", json={"campaign_id": cid, "method": "ls-sum"}).json()
    job = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(), lambda j: j["state"] in ("done", "failed")
    )
    assert job["state"] == "failed" and job["reason"], job
    assert c.get(f"/api/models/{job['id']}").status_code == 409


def test_malformed_csv_is_422_with_its_line_and_imports_nothing(live):
    c = live.client
    rows = [
        "pose,q1,q2,q3,q4,q5,q6,target,x,y,z",
        "p1,0,0,0,0,30,0,A,1000,0,1500",
        "p1,0,0,0,0,30,0,B,1000,oops,1500",
        "p2,10,20,-10,45,-30,90,A,900,100,1400",
    ]
    r = c.post(
        "/api/measurements/import?filename=bad.csv",
        content="\n".join(rows) + "\n",
        headers={"Content-Type": "text/csv"},
    )
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == PROBLEM
    body = r.json()
    assert body["file"] == "bad.csv" and body["line"] == 3
    assert body["detail"].startswith("bad.csv:3:")
    assert c.get("/api/campaigns").json() == []

    good = "\n".join(rows[:2] + rows[3:]) + "\n"
    r = c.post("/api/measurements/import?name=good", content=good)
    assert r.status_code == 201, r.text
    assert (r.json()["status"], r.json()["poses_total"]) == ("done", 2)


def test_abort_marks_the_campaign_and_it_cannot_start(live):
    c = live.client
    cid = c.post("/api/campaigns", json={"poses": 5}).json()["id"]
    r = c.post(f"/api/campaigns/{cid}/estop")  # nothing moves: the table has no e-stop here
    assert r.status_code == 409 and r.json()["state"] == "planned", r.text
    r = c.post(f"/api/campaigns/{cid}/abort")
    assert r.status_code == 200 and r.json()["was"] == "planned", r.text
    assert c.get(f"/api/campaigns/{cid}").json()["status"] == "aborted"
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 409
    assert c.post(f"/api/campaigns/{cid}/abort").status_code == 409  # final
    # The name is free again for a new campaign; an unfinished namesake is refused.
    assert c.post("/api/campaigns", json={"poses": 5}).status_code == 201
    assert c.post("/api/campaigns", json={"poses": 5}).status_code == 409


@pytest.mark.sqlite_only  # no store involved: once is enough
def test_cells_default_and_upload(live):
    c = live.client
    default = c.get("/api/cells/default").json()["cell"]
    assert set(default["targets"]) == {"A", "B", "C"}
    r = c.post("/api/cells", content='{"robot": "IRB2600",\n "targets": 5}')
    assert r.status_code == 422 and r.json()["line"] == 2, r.text
    default["targets"]["D"] = [0.0, 0.0, 80.0]
    r = c.post("/api/cells", json=default)
    assert r.status_code == 201, r.text
    cell_id = r.json()["id"]
    assert c.get("/api/cells").json() == ["default", cell_id]
    r = c.post("/api/campaigns", json={"poses": 5, "cell_id": cell_id})
    assert r.status_code == 201, r.text
    assert c.get("/api/cells/..%2Fsecret").status_code == 404


@pytest.mark.sqlite_only  # no store involved: once is enough
def test_validation_errors_are_problem_details(live):
    r = live.client.post("/api/campaigns", json={"poses": 1})
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM
    assert r.json()["errors"][0]["loc"] == ["body", "poses"]
    r = live.client.get("/api/campaigns/12345")
    assert r.status_code == 404 and r.json()["detail"] == "no campaign 12345"


@pytest.mark.sqlite_only  # no store involved: once is enough
def test_openapi_schema_and_docs_are_served(live):
    schema = live.anonymous.get("/openapi.json").json()
    assert schema["info"]["title"] == "robocal"
    for path in (
        "/api/campaigns",
        "/api/campaigns/{campaign_id}/start",
        "/api/jobs",
        "/api/models/{job_id}",
        "/api/measurements/import",
        "/api/cells",
    ):
        assert path in schema["paths"]
    body = schema["paths"]["/api/measurements/import"]["post"]["requestBody"]
    assert "text/csv" in body["content"]
    assert live.anonymous.get("/docs").status_code == 200


def test_abort_stops_a_running_acquisition_at_its_next_reading(live):
    c = live.client
    cid = c.post("/api/campaigns", json={"poses": 400}).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["poses_done"] >= 2)
    r = c.post(f"/api/campaigns/{cid}/abort")
    assert r.status_code == 200 and r.json()["was"] == "running", r.text
    assert r.json()["status"] in ("stopping", "aborted"), r.text
    j = wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: not j["run"]["active"])
    assert j["status"] == "aborted" and j["run"]["detail"] == "the run ended aborted", j
    assert 2 <= j["poses_done"] < 400
    assert [x["id"] for x in c.get("/api/campaigns").json()] == [cid]  # no namesake planned
