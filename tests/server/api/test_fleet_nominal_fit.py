"""A `nominal` calibration (the nominal arm only registered on the data: none of the arm's
parameters identified) does not stand for its arm in the fleet view: the arm keeps its latest
identified calibration, and that one's jump is from the calibration before it."""

from __future__ import annotations

from tests.real import REAL
from tests.server.api.conftest import done_job

CSV = {"content-type": "text/csv"}


def _calibrated(c, cid: int, method: str) -> int:
    return done_job(c, campaign_id=cid, method=method)["id"]


def test_a_nominal_fit_does_not_hide_the_arms_calibration(live):
    c = live.client
    cell = (REAL / "irb120_wu" / "cell.json").read_bytes()
    cell_id = c.post("/api/cells", content=cell).json()["id"]
    r = c.post(
        "/api/measurements/import",
        params={"filename": "train.csv", "cell_id": cell_id, "arm": "IRB-7"},
        content=(REAL / "irb120_wu" / "train.csv").read_bytes(),
        headers=CSV,
    )
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    first = _calibrated(c, cid, "ls-sum")
    second = _calibrated(c, cid, "minimax")
    nominal = _calibrated(c, cid, "nominal")
    assert nominal > second > first

    fleet = c.get("/api/fleet/irb120").json()
    (arm,) = fleet["arms"]
    assert (arm["arm"], arm["job_id"], arm["method"]) == ("IRB-7", second, "minimax"), arm
    assert arm["previous_job_id"] == first, arm
    assert {p["parameter"] for p in arm["parameters"]} >= {"a2", "d4"}, arm["parameters"]
    assert arm["calibrations"] == 2, arm
    assert c.get("/api/fleet").json() == [{"robot_model": "irb120", "arms": 1, "calibrations": 2}]
