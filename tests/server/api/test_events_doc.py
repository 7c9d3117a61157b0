"""The event stream as its OpenAPI says: every event a campaign and a job send holds to the
documented text/event-stream item schema (issue 20: it was documented as a bare string)."""

from __future__ import annotations

import json

import jsonschema_rs
import pytest


def sse_events(lines):
    """(event, id, data text) of each server-sent event in an iterator of lines."""
    fields: dict[str, str] = {}
    for line in lines:
        if not line:
            if fields:
                yield fields.get("event"), fields.get("id"), fields.get("data")
            fields = {}
        elif not line.startswith(":"):  # a comment (ping) otherwise
            name, _, value = line.partition(":")
            fields[name] = value.removeprefix(" ")


@pytest.mark.sqlite_only  # the stream is the service's, not the store's
def test_campaign_and_job_events_hold_to_the_documented_schema(live):
    c = live.client
    item = c.get("/openapi.json").json()["paths"]["/api/events"]["get"]["responses"]["200"]
    item = item["content"]["text/event-stream"]["itemSchema"]
    envelope = jsonschema_rs.validator_for(item)
    data = jsonschema_rs.validator_for(item["properties"]["data"]["contentSchema"])
    seen: dict[str, int] = {}
    with c.stream("GET", "/api/events") as stream:
        cid = c.post("/api/campaigns", json={"poses": 3, "seed": 1, "pause_s": 0}).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start").status_code in (200, 202)
        job = None
        for event, event_id, text in sse_events(stream.iter_lines()):
            body = json.loads(text)
            envelope.validate({"event": event, "id": event_id, "data": text})
            errors = [e.message for e in data.iter_errors(body)]
            assert data.is_valid(body), (event, body, errors)
            assert body["type"] == event
            seen[event] = seen.get(event, 0) + 1
            if event == "campaign.run" and body["campaign_id"] == cid:
                # 3 poses are too few to calibrate: the job fails, which is an event too
                job = c.post("/api/jobs", json={"campaign_id": cid}).json()["id"]
            if event == "job" and body["job_id"] == job and body["state"] == "failed":
                break
    assert seen["campaign.pose"] == 3 and seen["campaign.state"] >= 2, seen
    assert seen["job"] >= 2, seen
