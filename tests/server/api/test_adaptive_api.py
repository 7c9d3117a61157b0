"""An adaptive campaign over the API: `target_accuracy_mm` in the plan, each step's prediction in
the campaign's settings and sent as an event; a bad target is a 422 naming the field."""

from __future__ import annotations

import json

import jsonschema_rs
import pytest

from tests.server.api.conftest import wait_for
from tests.server.api.test_events_doc import sse_events

RUN = {"seed": 3, "pause_s": 0, "settle": "adaptive", "order": True}


def test_an_adaptive_campaign_runs_to_its_target_with_its_steps_kept(live):
    c = live.client
    r = c.post("/api/campaigns", json={"name": "a", "poses": 40, "target_accuracy_mm": 0.05, **RUN})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    plan = r.json()["settings"]["plan"]["adaptive"]
    assert plan["target_accuracy_mm"] == 0.05 and r.json()["poses_total"] == plan["seed_poses"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    done = wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["status"] == "done" and j["run"] is not None and not j["run"]["active"],
    )
    steps = done["settings"]["adaptive_steps"]
    assert steps[-1]["stop"] and steps[-1]["reason"] == "target", steps
    assert steps[-1]["predicted_mm"] <= 0.05
    assert done["poses_total"] == done["poses_done"] == steps[-1]["poses"] > plan["seed_poses"]
    assert done["run"]["summary"]["adaptive"]["stopped"] == "target"


def test_a_bad_target_is_a_422_naming_the_field(live):
    c = live.client
    for bad in (0, -1.0, "0.1", True, 1e9):
        r = c.post("/api/campaigns", json={"name": "b", "poses": 20, "target_accuracy_mm": bad})
        assert r.status_code == 422, (bad, r.text)
        assert "target_accuracy_mm" in r.json()["detail"], (bad, r.text)
    assert c.get("/api/campaigns").json() == []


@pytest.mark.sqlite_only  # the stream is the service's, not the store's
def test_each_step_is_an_event_holding_to_the_documented_schema(live):
    c = live.client
    item = c.get("/openapi.json").json()["paths"]["/api/events"]["get"]["responses"]["200"]
    schema = item["content"]["text/event-stream"]["itemSchema"]
    assert "campaign.adaptive" in schema["properties"]["event"]["enum"]
    data = jsonschema_rs.validator_for(schema["properties"]["data"]["contentSchema"])
    steps, totals = [], []
    with c.stream("GET", "/api/events") as stream:
        body = {"name": "e", "poses": 30, "target_accuracy_mm": 0.05, **RUN}
        cid = c.post("/api/campaigns", json=body).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
        for event, _, text in sse_events(stream.iter_lines()):
            ev = json.loads(text)
            if event == "campaign.adaptive":
                assert data.is_valid(ev), [e.message for e in data.iter_errors(ev)]
                steps.append(ev)
            if event == "campaign.pose":
                totals.append(ev["poses_total"])
            if event == "campaign.run" and ev["campaign_id"] == cid:
                break
    assert steps and steps[-1]["stop"] and not any(s["stop"] for s in steps[:-1])
    # the live progress counts against the plan as it grows
    assert totals == sorted(totals) and totals[-1] == steps[-1]["poses"] > totals[0]
