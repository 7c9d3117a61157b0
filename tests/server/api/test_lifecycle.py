"""The campaign's life cycle over HTTP: every (state, action) pair the table refuses answers 409
with the state and the allowed actions; every one it allows does not; JSON carries `actions`."""

from __future__ import annotations

import pytest

from robocal.drivers.lifecycle import ACTIONS, MOVING, STATES, allowed, next_state
from tests.backends import execute
from tests.server.api.conftest import wait_for

PROBLEM = "application/problem+json"
# States a campaign rests in with no engine running it (the moving ones need a live engine:
# test_estop.py walks them); a state set here is what the store holds after a restart.
AT_REST = [s for s in STATES if s not in MOVING]


def force_state(live, cid: int, state: str) -> None:
    """Put the campaign's stored state straight in the store, as a run would leave it."""
    execute(live.settings.database, "UPDATE campaign SET status = :s WHERE id = :c", s=state, c=cid)


def plan(live, name: str) -> int:
    r = live.client.post(
        "/api/campaigns", json={"name": name, "poses": 6, "seed": 1, "pause_s": 0.0, "samples": 5}
    )
    assert r.status_code == 201, r.text
    return r.json()["id"]


def idle(live, cid):
    """Wait until this service's worker is done with the campaign; its JSON."""
    return wait_for(
        lambda: live.client.get(f"/api/campaigns/{cid}").json(),
        lambda j: not (j["run"] or {}).get("active"),
        timeout=120,
    )


@pytest.mark.parametrize("state", AT_REST)
def test_every_action_in_every_state_at_rest(live, state):
    c = live.client
    for action in ACTIONS:
        cid = plan(live, f"{state}-{action}")
        force_state(live, cid, state)
        shown = c.get(f"/api/campaigns/{cid}").json()
        assert shown["status"] == state and shown["actions"] == allowed(state), shown
        r = c.post(f"/api/campaigns/{cid}/{action}")
        if action not in allowed(state):
            assert r.status_code == 409, (state, action, r.text)
            assert r.headers["content-type"] == PROBLEM
            body = r.json()
            assert body["state"] == state and body["allowed_actions"] == allowed(state), body
            assert c.get(f"/api/campaigns/{cid}").json()["status"] == state  # unchanged
            continue
        assert r.status_code in (200, 202), (state, action, r.text)
        body = r.json()
        assert body["was"] == state and "actions" in body, body
        after = idle(live, cid)
        if action in ("start", "resume"):  # a run began, at the next unmeasured pose
            assert after["status"] == "done" and after["poses_done"] == 6, after
        else:  # no engine: the store follows the same table
            assert after["status"] == next_state(state, action), (state, action, after)


def test_estop_after_done_is_refused_not_faked(live):
    cid = plan(live, "done")
    force_state(live, cid, "done")
    for route in (f"/api/campaigns/{cid}/estop",):
        r = live.client.post(route)
        assert r.status_code == 409 and r.json()["state"] == "done", r.text
    assert live.client.get(f"/api/campaigns/{cid}").json()["status"] == "done"
    r = live.client.post("/api/estop")  # nothing runs: nothing to do, and no campaign changed
    assert r.status_code == 200 and r.json()["campaign_id"] is None, r.text
    assert live.anonymous.post("/api/estop").status_code == 401
    assert live.anonymous.post(f"/api/campaigns/{cid}/reset").status_code == 401


def test_imported_campaign_offers_no_start(live):
    cid = plan(live, "imported")
    execute(live.settings.database, "UPDATE campaign SET settings_json = '{}' WHERE id = :c", c=cid)
    shown = live.client.get(f"/api/campaigns/{cid}").json()
    assert shown["status"] == "planned" and shown["actions"] == ["abort"], shown
    r = live.client.post(f"/api/campaigns/{cid}/start")
    assert r.status_code == 409 and "imported" in r.json()["detail"], r.text
