"""API jobs screen gross outliers the way the command line does: the model and the report list
them by pose and target."""

import numpy as np

from robocal.drivers.cell import VirtualCell, displace
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell
from tests.server.api.conftest import wait_for


def test_jobs_exclude_and_list_gross_outliers(live, tmp_path):
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=8)
    meas = vc.campaign(30, seed=8)
    meas.xyz[:], moved = displace(meas.xyz, 8, 3 / 90)
    bad = {(int(meas.pose_ids[p]), meas.target_names[k]) for p, k in np.argwhere(moved)}
    write_campaign(tmp_path / "meas.csv", meas)
    c = live.client
    r = c.post(
        "/api/measurements/import?name=outliers", content=(tmp_path / "meas.csv").read_text()
    )
    assert r.status_code == 201, r.text
    cid = r.json()["id"]

    def run(**job):
        j = c.post("/api/jobs", json={"campaign_id": cid, **job}).json()
        j = wait_for(
            lambda: c.get(f"/api/jobs/{j['id']}").json(), lambda s: s["state"] in ("done", "failed")
        )
        assert j["state"] == "done", j
        return j

    model = c.get(run(method="minimax")["model_url"]).json()
    assert {(o["pose"], o["target"]) for o in model["fit"]["excluded_readings"]} == bad
    report = c.get(run(kind="diagnosis")["report_url"]).json()
    assert {(o["pose"], o["target"]) for o in report["outliers"]} == bad
