"""Cell sizes over HTTP: an oversized or degenerate cell refused at upload in one line naming
the field, and a campaign the cell cannot have refused in one line (422), never a 500."""

from __future__ import annotations

import json

import pytest

from tests.server.test_cell_sizes import cell, joint, seven_joints

from .conftest import wait_for

PROBLEM = "application/problem+json"


def upload(live, doc: dict):
    return live.client.post(
        "/api/cells",
        content=json.dumps(doc, indent=1),
        headers={"Content-Type": "application/json"},
    )


def one_line_problem(r, *words) -> dict:
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    body = r.json()
    assert "\n" not in body["detail"], body["detail"]
    for w in words:
        assert w in body["detail"], body["detail"]
    return body


def small_arm() -> list[dict]:
    """A tenth of an IRB 2600: plausible links, but the flange never clears the base's axis."""
    six = seven_joints()[:3] + seven_joints()[4:]
    return [{**j, "a": j["a"] / 10, "d": j["d"] / 10} for j in six]


@pytest.mark.sqlite_only  # refused before the store: once is enough
@pytest.mark.parametrize(
    ("doc", "words"),
    [
        (cell(n_targets=1000), ["targets: 1000 targets; a cell has at most 16 SMRs"]),
        (cell([joint()] * 50), ["robot.joints: 50 joints; a serial arm has at most 7"]),
        (cell([joint(0.0, 0.0)] * 6), ["robot.joints: the links add up to 0 mm"]),
    ],
    ids=["1000-smrs", "50-joints", "zero-links"],
)
def test_an_oversized_or_degenerate_cell_is_refused_at_upload(live, doc, words):
    body = one_line_problem(upload(live, doc), *words)
    assert body["line"] is not None and body["column"] is not None
    assert live.client.get("/api/cells").json() == ["default"]  # nothing kept


def test_a_7_joint_cell_is_kept_and_its_campaign_refused_in_one_line(live):
    r = upload(live, cell(seven_joints()))
    assert r.status_code == 201, r.text
    cell_id = r.json()["id"]
    r = live.client.post("/api/campaigns", json={"poses": 5, "cell_id": cell_id})
    one_line_problem(r, "robot.joints: 7 joints; the controller protocol drives at most 6")
    assert live.client.get("/api/campaigns").json() == []


def test_a_cell_with_no_valid_pose_is_refused_naming_the_check_to_relax(live):
    r = upload(live, cell(small_arm()))
    assert r.status_code == 201, r.text
    cell_id = r.json()["id"]
    r = live.client.post("/api/campaigns", json={"poses": 5, "cell_id": cell_id})
    one_line_problem(r, "constraints too tight", "base_axis: keep the flange 300 mm off")
    # the same planning as a job: failed with the reason, the service answers on
    r = live.client.post("/api/campaigns", json={"poses": 5, "choose_from": 50, "cell_id": cell_id})
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: live.client.get(r.headers["Location"]).json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "failed" and "constraints too tight" in job["reason"], job
    assert "base_axis: keep the flange" in job["reason"]
    assert live.client.get("/api/campaigns").json() == []
