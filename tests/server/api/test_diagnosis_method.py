"""A diagnosis asked with a method (a calibration's body with only `kind` changed) is refused in one
line naming `method`, nothing queued; before, the method was silently dropped and a diagnosis ran."""

from __future__ import annotations

import pytest

from tests.real import import_real


@pytest.mark.sqlite_only  # the route's check, before the store
def test_a_diagnosis_with_a_method_is_refused_naming_it(live):
    c = live.client
    cid = import_real(c, "irb120_wu")
    r = c.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis", "method": "ls-pose"})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    assert r.json()["detail"].startswith("method: a diagnosis takes none"), r.json()
    assert "'ls-pose'" in r.json()["detail"]
    assert c.get("/api/jobs").json() == []
    r = c.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis"})
    assert r.status_code == 202 and r.json()["method"] == "diagnose", r.text


@pytest.mark.sqlite_only
def test_a_diagnosis_with_a_held_out_campaign_is_refused_naming_the_field(live):
    """The 422 said "only a calibration takes a held-out campaign" without naming the field."""
    c = live.client
    cid = import_real(c, "irb120_wu")
    body = {"campaign_id": cid, "kind": "diagnosis", "holdout_campaign_id": cid}
    r = c.post("/api/jobs", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    detail = r.json()["detail"]
    assert detail.startswith("holdout_campaign_id: only a calibration takes a held-out"), detail
    assert c.get("/api/jobs").json() == []
