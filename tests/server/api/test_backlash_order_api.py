"""The API says what `robocal diagnose` and `evaluate` say on stderr: a backlash model whose
approach directions come from the rows' order (a campaign without time_s or prev_q)."""

from dataclasses import replace

import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell
from tests.server.api.test_job_limits import finished, queue

ORDER = "the rows' order is taken as the order of motion"


@pytest.mark.sqlite_only  # the service's words, not the store's: once is enough
def test_a_diagnosis_job_and_its_evaluation_say_the_row_order(live, tmp_path):
    """A diagnosis job naming joint 2's backlash on an untimed campaign said nothing of the
    rows' order its approach directions came from; nor did evaluating the model on it."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=4)
    vc.effects.extend(make_effects(["joint_backlash:2=0.05"], vc, 4))
    write_campaign(
        tmp_path / "meas.csv", replace(vc.campaign(80, seed=4), time_s=None, temp_c=None)
    )
    c = live.client
    r = c.post("/api/measurements/import?name=untimed", content=(tmp_path / "meas.csv").read_text())
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    job = finished(live, queue(live, cid, kind="diagnosis")["id"])
    assert job["state"] == "done", job
    said = [w for w in job["validation"]["warnings"] if ORDER in w]
    assert len(said) == 1 and "joint_backlash(2)" in said[0], job["validation"]
    r = c.get(f"/api/models/{job['id']}/evaluate", params={"campaign_id": cid})
    assert r.status_code == 200, r.text
    said = [w for w in r.json().get("warnings", []) if ORDER in w]
    assert len(said) == 1 and "joint_backlash(2)" in said[0], r.json().get("warnings")
