"""A calibration job with a held-out campaign over the API: the model's error on the campaign it
was not fitted on is in the job and the model's validation block, its poses are the held-out ones
of the job's recording (read back with `rerun rrd print`), and a held-out campaign that cannot
validate the calibration is refused with the field named."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.server.api.conftest import wait_for
from tests.server.api.test_verify_api import run_campaign
from tests.server.test_recording import _chunks, _cli, _static

PROBLEM = "application/problem+json"
JSON = {"content-type": "application/json"}
REAL = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "real"


def _planned(c, **body) -> int:
    """A campaign chosen among candidates (a planning job), run to done; its id."""
    r = c.post("/api/campaigns", json=body)
    assert r.status_code == 202, r.text
    cid = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(), lambda j: j["state"] == "done"
    )["campaign_id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["status"] == "done")
    return cid


@pytest.mark.sqlite_only  # the store's part (campaigns, jobs) runs on both backends elsewhere
def test_a_calibration_validated_on_a_held_out_campaign(live, tmp_path):
    c = live.client
    seed = 31  # the seed makes the simulated arm: both campaigns are of the same one
    fit = run_campaign(c, name="fit", poses=40, seed=seed, pause_s=0)
    held = _planned(c, name="held", poses=15, seed=seed, pause_s=0, choose_from=300)

    r = c.post("/api/jobs", json={"campaign_id": fit, "holdout_campaign_id": held})
    assert r.status_code == 202, r.text
    assert r.json()["holdout_campaign_id"] == held
    job = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    h = job["holdout"]
    assert (h["campaign_id"], h["poses"], h["warning"]) == (held, 15, None), h
    assert 0 < h["rms_mm"] <= h["max_mm"]
    # poses it did not see: near the leave-one-out estimate, far below the nominal arm's error
    loo = job["validation"]["holdout_rms_mm"]
    assert loo / 3 < h["rms_mm"] < 3 * loo, (h, loo)
    assert h["rms_mm"] < h["nominal_rms_mm"] / 10, h
    model = c.get(f"/api/models/{job['id']}").json()
    assert model["validation"]["held_out"].items() <= h.items()  # the job's, less `file`

    rrd = tmp_path / "job.rrd"
    rrd.write_bytes(c.get(job["recording_url"]).content)
    assert _cli("verify", str(rrd)).returncode == 0
    text = _cli("print", str(rrd)).stdout
    assert "/world/poses/held_out/error/after" in text and "/world/poses/calibration" in text
    summary = _static(_chunks(rrd), "/summary", "TextDocument:text")[0]
    assert "| held_out: 15 |" in summary, summary

    # refused, naming what is wrong: nothing queued
    irb120 = (REAL / "irb120_wu" / "cell.json").read_text()
    cell_id = c.post("/api/cells", content=irb120, headers=JSON).json()["id"]
    other = run_campaign(c, name="other", poses=5, seed=seed, pause_s=0, cell_id=cell_id)
    before = len(c.get("/api/jobs").json())
    for body, status, words in (
        ({"campaign_id": fit, "holdout_campaign_id": fit}, 422, "another than the one fitted"),
        ({"campaign_id": fit, "holdout_campaign_id": 999}, 404, "held-out campaign"),
        ({"campaign_id": fit, "holdout_campaign_id": 0}, 422, "holdout_campaign_id"),
        ({"campaign_id": fit, "holdout_campaign_id": other}, 422, "the data is of robot"),
        (
            {"campaign_id": fit, "holdout_campaign_id": held, "kind": "diagnosis"},
            422,
            "holdout_campaign_id: only a calibration takes a held-out campaign",
        ),
    ):
        r = c.post("/api/jobs", json=body)
        assert r.status_code == status and r.headers["content-type"] == PROBLEM, r.text
        assert words in r.text, r.text
    planned = c.post("/api/campaigns", json={"poses": 5, "seed": seed}).json()["id"]
    r = c.post("/api/jobs", json={"campaign_id": fit, "holdout_campaign_id": planned})
    assert r.status_code == 409 and f"held-out campaign {planned} is planned" in r.text, r.text
    assert len(c.get("/api/jobs").json()) == before
