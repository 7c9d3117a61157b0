"""A campaign whose run stored no reading (the tracker never saw an SMR) ended `done`, the CLI
exit 0 ("campaign 1 done: 6 poses measured now, 0 readings, 6 missing"); it now fails, the reason
said: `robocal acquire` exits non-zero naming it, the API's campaign is failed with it."""

from __future__ import annotations

import json

from robocal.server import store
from robocal.server.cli import main
from tests.backends import execute
from tests.server.api.conftest import wait_for

# one SMR and a beam that (nearly) never holds: every pose ends with its target missing
BLIND = {"beam_break_rate": 0.999, "seed": 0}


def test_acquire_of_no_reading_fails(tmp_path, capsys):
    cell, db = tmp_path / "cell.json", tmp_path / "acq.db"
    cell.write_text(json.dumps({"robot": "irb2600", "targets": {"A": [60.0, 0.0, 35.0]}}))
    args = ["acquire", "--db", str(db), "--poses", "6", "--cell", str(cell)]
    assert main([*args, "--beam-break-rate", "0.999"]) == 1
    err = capsys.readouterr().err
    assert "campaign 1 (campaign-seed0) failed: no reading stored" in " ".join(err.split()), err
    with store.open_database(str(db)) as d:
        assert store.get_campaign(d, campaign_id=1).status == "failed"


def test_a_measured_campaign_left_failed_at_its_end_resumes_to_done(tmp_path, capsys):
    """A campaign killed after its last pose's outcome (every pose measured, the state not yet
    done) resumes with nothing left to measure: done, its readings counted, not "no reading"."""
    cell, db = tmp_path / "cell.json", tmp_path / "acq.db"
    cell.write_text(json.dumps({"robot": "irb2600", "targets": {"A": [60.0, 0.0, 35.0]}}))
    args = ["acquire", "--db", str(db), "--poses", "4", "--cell", str(cell), "--name", "k"]
    assert main(args) == 0
    execute(str(db), "UPDATE campaign SET status = 'running' WHERE id = 1")  # as a kill leaves it
    capsys.readouterr()
    assert main(args) == 0, capsys.readouterr().err
    with store.open_database(str(db)) as d:
        assert store.get_campaign(d, campaign_id=1).status == "done"


def test_api_campaign_of_no_reading_fails_with_the_reason(live):
    body = {"name": "blind", "poses": 4, "pause_s": 0.0, "samples": 5, **BLIND}
    r = live.client.post("/api/campaigns", json=body)
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert live.client.post(f"/api/campaigns/{cid}/start").status_code == 202
    c = wait_for(
        lambda: live.client.get(f"/api/campaigns/{cid}").json(),
        lambda j: not (j["run"] or {}).get("active", True),
        timeout=120,
    )
    assert c["status"] == "failed", c
    assert "no reading stored" in c["run"]["detail"], c
