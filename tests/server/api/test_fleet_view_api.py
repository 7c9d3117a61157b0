"""GET /api/fleet on each backend: the models, one model's arms with the bent one alone flagged,
404 for an unknown model, the token required; an arm imported and calibrated through the API
joins the fleet with the parameters its job stored."""

from __future__ import annotations

from robocal.drivers.cell import VirtualCell
from robocal.server import store
from robocal.server.formats import default_cell
from robocal.server.formats.campaign_csv import write_campaign
from tests.server.api.conftest import wait_for
from tests.server.fleet.arms import ARMS, BENT, POSES, SPREAD, build_fleet

PROBLEM = "application/problem+json"


def test_the_fleet_over_rest(live, tmp_path):
    with store.open_database(live.settings.database) as db:
        build_fleet(db, tmp_path)
    c = live.client
    assert c.get("/api/fleet").json() == [
        {"robot_model": "irb2600", "arms": ARMS, "calibrations": ARMS + 3}
    ]
    view = c.get("/api/fleet/IRB-2600").json()
    assert [a["arm"] for a in view["arms"] if a["flagged"] or a["jumped"]] == [BENT]
    assert view["family_rate"] == 0.01 and all(p["limit"] for p in view["parameters"])
    r = c.get("/api/fleet/irb120")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM, r.text
    assert "no calibrated arm of robot model 'irb120'" in r.json()["detail"]
    assert live.anonymous.get("/api/fleet").status_code == 401

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=2000, errors=SPREAD)
    write_campaign(tmp_path / "new.csv", vc.campaign(POSES, seed=2000))
    r = c.post("/api/measurements/import?arm=SN-2000", content=(tmp_path / "new.csv").read_bytes())
    assert r.status_code == 201 and r.json()["arm"] == "SN-2000", r.text
    job = c.post("/api/jobs", json={"campaign_id": r.json()["id"], "method": "ls-pose"}).json()
    done = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert done["state"] == "done", done
    view = c.get("/api/fleet/irb2600").json()
    new = next(a for a in view["arms"] if a["arm"] == "SN-2000")
    assert len(new["parameters"]) == len(view["parameters"]) and not new["flagged"]
    assert all(p["standard_error"] > 0 for p in new["parameters"])
    r = c.post("/api/measurements/import?arm=%0A", content=b"pose,target\n")
    assert r.status_code == 422 and "arm" in r.text, r.text
