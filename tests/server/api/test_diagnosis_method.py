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
