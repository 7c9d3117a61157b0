"""A job asks for the accuracy its application needs (`tolerance_mm`, over the cell's): beyond it
the model is not deployable, naming the tolerance; within it the verdict says so; the job keeps
it (on both stores); a tolerance that is not a length in mm is refused with the field named."""

from __future__ import annotations

from tests.server.api.conftest import wait_for
from tests.server.api.test_verify_api import run_campaign


def _job(c, **body) -> dict:
    r = c.post("/api/jobs", json=body)
    assert r.status_code == 202, r.text
    assert r.json()["tolerance_mm"] == body.get("tolerance_mm"), r.json()
    job = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    return job


def test_the_tolerance_of_a_job_judges_its_model(live):
    c = live.client
    cid = run_campaign(c, name="cal", poses=30, seed=5, pause_s=0)

    tight = _job(c, campaign_id=cid, method="ls-sum", tolerance_mm=0.0001)
    v = tight["validation"]
    assert v["tolerance_mm"] == 0.0001 and v["deployable"] is False, v
    assert any("exceeds the tolerance 0.0001 mm" in r for r in v["reasons"]), v
    # below the readings' noise: no model could meet it, and the verdict says why
    assert any("0.0001 mm is below the readings' noise floor" in w for w in v["warnings"]), v
    model = c.get(f"/api/models/{tight['id']}").json()
    assert model["validation"]["deployable"] is False, model["validation"]

    loose = _job(c, campaign_id=cid, method="ls-sum", tolerance_mm=5)
    v = loose["validation"]
    assert v["tolerance_mm"] == 5 and v["holdout_rms_mm"] < 5, v
    assert v["deployable"] is True and "within the tolerance 5 mm" in v["summary"], v

    plain = _job(c, campaign_id=cid, method="ls-sum")  # none asked, none in the cell
    assert plain["validation"]["tolerance_mm"] is None, plain["validation"]
    assert "no tolerance given" in plain["validation"]["summary"], plain["validation"]

    diagnosed = _job(c, campaign_id=cid, kind="diagnosis", tolerance_mm=0.0001)
    assert diagnosed["validation"]["deployable"] is False, diagnosed["validation"]
    assert c.get(f"/api/jobs/{diagnosed['id']}").json()["tolerance_mm"] == 0.0001

    before = len(c.get("/api/jobs").json())
    for bad in (0, -1, 1001, "0.1", True):
        r = c.post("/api/jobs", json={"campaign_id": cid, "tolerance_mm": bad})
        assert r.status_code == 422 and "tolerance_mm" in r.text, (bad, r.text)
    assert len(c.get("/api/jobs").json()) == before  # nothing queued
