"""The arm measured (its serial number) named where a campaign is created over the API, stored
with it (campaign.arm, as the fleet view reads it), on both store backends; a bad one is a 422
naming the field."""

from __future__ import annotations

from robocal.server import store
from tests.server.api.conftest import wait_for

PROBLEM = "application/problem+json"
RUN = {"poses": 3, "seed": 1, "pause_s": 0}


def test_arm_stored_with_a_planned_and_a_job_planned_campaign(live, store_url):
    c = live.client
    r = c.post("/api/campaigns", json={"name": "a", "arm": " SN-4711 ", **RUN})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert (
        r.json()["arm"] == "SN-4711" and c.get(f"/api/campaigns/{cid}").json()["arm"] == "SN-4711"
    )
    # a D-optimal choice is planned by a job: the arm reaches the campaign it stores
    r = c.post("/api/campaigns", json={"name": "b", "arm": "SN-0815", "choose_from": 6, **RUN})
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: c.get(r.headers["location"]).json(), lambda j: j["state"] in ("done", "failed")
    )
    assert job["state"] == "done", job
    planned = c.get(job["campaign_url"]).json()
    assert planned["arm"] == "SN-0815", planned
    # the run keeps it: started and done, the stored campaign still names its arm
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["status"] == "done")
    db = store.open_database(store_url)
    try:
        arms = {i.name: i.arm for i in store.list_campaigns(db)}
    finally:
        db.close()
    assert arms == {"a": "SN-4711", "b": "SN-0815"}, arms
    r = c.post("/api/campaigns", json={"name": "c", **RUN})
    assert r.status_code == 201 and r.json()["arm"] is None, r.text


def test_a_bad_arm_is_a_422_naming_the_field(live):
    c = live.client
    for arm in ("", "   ", "x" * 65, "SN\x07", 42, "a\nb"):
        r = c.post("/api/campaigns", json={"name": "bad", "arm": arm, **RUN})
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, (arm, r.text)
        detail = r.json()["detail"]
        assert ": arm: " in detail and "\n" not in detail, (arm, detail)
    assert c.get("/api/campaigns").json() == []
    assert live.anonymous.post("/api/campaigns", json={"arm": "SN-1", **RUN}).status_code == 401
