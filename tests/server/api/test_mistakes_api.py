"""Bad requests answered in one clear line over a real server (issue 14, item 7)."""

import pytest

from tests.server.api.test_compensate_api import PROBLEM, model_job  # noqa: F401 - a fixture

from .conftest import wait_for


@pytest.mark.sqlite_only
def test_a_three_pose_campaign_runs_and_reads_back(live):
    """Was "Out of range float values are not JSON compliant": 3 poses measured, then read."""
    c = live.client
    r = c.post("/api/campaigns", json={"poses": 3, "seed": 1, "pause_s": 0})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code in (200, 202), r.text
    done = wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["status"] == "done")
    assert done["poses_done"] == 3
    for path in ("", "/measurements", "/measurements.csv"):
        r = c.get(f"/api/campaigns/{cid}{path}")
        assert r.status_code == 200, (path, r.text)
    assert c.get("/api/campaigns").status_code == 200
    # Too few poses for the geometric model: the job fails, saying so in one line.
    r = c.post("/api/jobs", json={"campaign_id": cid})
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    j = wait_for(
        lambda: c.get(f"/api/jobs/{job}").json(), lambda j: j["state"] in ("done", "failed")
    )
    assert j["state"] == "failed" and "measure at least" in j["reason"], j
    assert "\n" not in j["reason"]


@pytest.mark.sqlite_only
def test_a_misspelt_method_is_answered_with_a_suggestion(live):
    r = live.client.post("/api/jobs", json={"campaign_id": 1, "method": "minmax"})
    assert r.status_code == 422, r.text
    assert "did you mean 'minimax'?" in r.text and "Traceback" not in r.text
    # the OpenAPI still documents the methods as a pattern
    spec = live.client.get("/openapi.json").json()
    method = spec["components"]["schemas"]["JobCreate"]["properties"]["method"]
    assert "minimax" in method["pattern"]


@pytest.mark.sqlite_only  # the store's part runs on both backends in test_flow
def test_evaluating_on_a_planned_campaign_says_it_has_no_measured_pose(live, model_job):
    """Was 422 "slice step cannot be zero": a campaign planned but never run has no reading."""
    job, _ = model_job
    c = live.client
    planned = c.post("/api/campaigns", json={"poses": 5, "name": "later"})
    assert planned.status_code == 201, planned.text
    cid = planned.json()["id"]
    r = c.get(f"/api/models/{job}/evaluate", params={"campaign_id": cid})
    assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, r.text
    detail = r.json()["detail"]
    assert detail.startswith(f"campaign {cid} (later) has no measured pose yet (it is planned)")
    assert f"/api/campaigns/{cid}/start" in detail and "\n" not in detail
    # forcing does not make readings appear
    r = c.get(f"/api/models/{job}/evaluate", params={"campaign_id": cid, "force": "true"})
    assert r.status_code == 409, r.text
    # run, but every beam broken: no reading either
    body = {"poses": 3, "name": "dark", "pause_s": 0, "beam_break_rate": 0.9999}
    dark = c.post("/api/campaigns", json=body).json()["id"]
    assert c.post(f"/api/campaigns/{dark}/start").status_code in (200, 202)
    # a run that stores no reading fails, saying so
    ended = wait_for(
        lambda: c.get(f"/api/campaigns/{dark}").json(), lambda j: j["status"] == "failed"
    )
    assert "no reading stored" in ended["run"]["detail"], ended
    r = c.get(f"/api/models/{job}/evaluate", params={"campaign_id": dark})
    assert r.status_code == 409, r.text
    assert r.json()["detail"] == f"campaign {dark} (dark) has no reading: every target was missing"


@pytest.mark.sqlite_only  # refused before the store: once is enough
def test_a_boolean_or_text_for_a_number_is_refused_naming_the_field(live):
    """Issue 20: `beam_break_rate: false` was taken as 0 (and `seed: true` as 1, `order: 1` as
    true); the body's numbers and flags are JSON's own."""
    c = live.client
    for url, body, field in (
        ("/api/campaigns", {"poses": 5, "beam_break_rate": False}, "beam_break_rate"),
        ("/api/campaigns", {"poses": 5, "seed": True}, "seed"),
        ("/api/campaigns", {"poses": 5, "pause_s": "0"}, "pause_s"),
        ("/api/campaigns", {"poses": 5, "order": 1}, "order"),
        ("/api/jobs", {"campaign_id": True}, "campaign_id"),
        ("/api/jobs", {"campaign_id": 1, "holdout_campaign_id": True}, "holdout_campaign_id"),
        ("/api/models/1/verify", {"cycles": True}, "cycles"),
        ("/api/models/1/verify", {"start": "false"}, "start"),
        (
            "/api/models/1/verify",
            {"points": [{"point": "p", "x_mm": False, "y_mm": 0, "z_mm": 0}]},
            "x_mm",
        ),
    ):
        r = c.post(url, json=body)
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, (body, r.text)
        assert r.json()["errors"][0]["loc"][-1] == field, (body, r.text)
    # numbers as JSON writes them are taken: an integer for a real, a whole real for a count
    r = c.post("/api/campaigns", json={"poses": 5.0, "pause_s": 0, "beam_break_rate": 0})
    assert r.status_code == 201, r.text
    assert c.get(f"/api/campaigns/{r.json()['id']}").json()["poses_total"] == 5


@pytest.mark.sqlite_only
def test_the_openapi_says_what_the_uploads_refuse(live):
    """Issue 20: an empty meas.csv or targets.csv was refused though the schema allowed it."""
    c = live.client
    spec = c.get("/openapi.json").json()["paths"]
    for path in ("/api/measurements/import", "/api/models/{job_id}/compensate"):
        body = spec[path]["post"]["requestBody"]
        assert body["required"] and body["content"]["text/csv"]["schema"]["minLength"] == 1
    r = c.post("/api/measurements/import", content=b"", headers={"content-type": "text/csv"})
    assert r.status_code == 422 and "empty file" in r.json()["detail"], r.text
    # an SMR the cell lacks (a lowercase 'a' for 'A'): its line and field, not stored
    body = b"pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n1,0,0,0,0,0,0,a,1,2,3\n"
    r = c.post("/api/measurements/import", content=body, headers={"content-type": "text/csv"})
    p = r.json()
    assert r.status_code == 422 and (p["line"], p["column"]) == (2, 8), r.text
    assert "case-sensitive: 'A'" in p["detail"], r.text
    # a body nested past the parser's limit is a 4xx too, not a 500
    deep = "[" * 100_000 + "]" * 100_000
    for url in ("/api/campaigns", "/api/cells"):
        r = c.post(url, content=deep, headers={"content-type": "application/json"})
        assert 400 <= r.status_code < 500 and r.headers["content-type"] == PROBLEM, r.text


@pytest.mark.sqlite_only
def test_an_import_with_prev_q_in_radians_is_refused_naming_its_line_and_field(live):
    """prev_q1..prev_q6 in radians beside q1..q6 in degrees: a 422 naming the line, the field and
    the unit, nothing stored."""
    import math

    c = live.client
    poses = [
        [10, 20, -30, 40, 50, 60],
        [-20, -10, 10, -40, 30, -60],
        [30, 40, -60, 20, -30, 90],
        [0, 5, -5, 60, 10, -30],
    ]
    head = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z," + ",".join(f"prev_q{i}" for i in range(1, 7))
    rows = [head]
    for k, q in enumerate(poses):
        prev = [math.radians(v) for v in (poses[k - 1] if k else [0] * 6)]
        rows.append(f"{k + 1},{','.join(map(str, q))},A,1,2,3,{','.join(f'{v:.6f}' for v in prev)}")
    before = len(c.get("/api/campaigns").json())
    r = c.post(
        "/api/measurements/import",
        content=("\n".join(rows) + "\n").encode(),
        headers={"content-type": "text/csv"},
    )
    p = r.json()
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    assert p["line"] == 3 and "column 'prev_q" in p["detail"], r.text
    assert "prev_q1..prev_q6 look like radians" in p["detail"], r.text
    assert len(c.get("/api/campaigns").json()) == before
