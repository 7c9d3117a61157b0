"""Driving a running campaign (pause, resume, e-stop), live events over SSE, persisted jobs."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time

import httpx

from robocal.server import store
from robocal.server.formats import cell_to_json, default_cell
from tests.backends import execute
from tests.server.api.conftest import serve, settings_for, wait_for

PROBLEM = "application/problem+json"


class EventReader:
    """Reads /api/events on a thread over a real socket; the events seen so far."""

    def __init__(self, url, token):
        self.events: list[tuple[str, dict]] = []
        self.connected = threading.Event()
        self._client = httpx.Client(
            base_url=url,
            timeout=httpx.Timeout(30, read=None),
            headers={"Authorization": f"Bearer {token}"},
        )
        self._socket: socket.socket | None = None
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()
        assert self.connected.wait(10), "no event stream"

    def _read(self):
        try:
            with self._client.stream("GET", "/api/events") as r:
                assert r.headers["content-type"].startswith("text/event-stream")
                self._socket = r.extensions["network_stream"].get_extra_info("socket")
                self.connected.set()
                kind = None
                for line in r.iter_lines():
                    if line.startswith("event:"):
                        kind = line.split(":", 1)[1].strip()
                    elif line.startswith("data:") and kind:
                        self.events.append((kind, json.loads(line.split(":", 1)[1])))
        except httpx.HTTPError:
            pass  # closed by close()

    def wait(self, pred, timeout=120.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [e for e in list(self.events) if pred(*e)]
            if found:
                return found[0]
            time.sleep(0.02)
        raise AssertionError(f"no such event; seen {self.events[-10:]}")

    def close(self):
        # Hang up at once (closing the client would not wake the read): an open stream holds
        # the server's stop for its whole grace period.
        if self._socket is not None:
            with contextlib.suppress(OSError):
                self._socket.shutdown(socket.SHUT_RDWR)
        self._thread.join(10)
        self._client.close()


def readings(live, cid):
    """(pose_index, target) of every stored reading, and how many rows each has."""
    rows = execute(
        live.settings.database,
        "SELECT pose_index, target, count(*) FROM reading WHERE campaign_id = :c "
        "GROUP BY pose_index, target",
        c=cid,
    )
    return {(i, t): n for i, t, n in rows}


def test_pause_resume_estop_reset_resume_completes(live):
    """Events carry the engine's states; e-stop mid-campaign, reset, resume: the campaign
    completes with every reading once, those before the e-stop kept."""
    c = live.client
    reader = EventReader(live.url, live.token)
    try:
        cid = c.post("/api/campaigns", json={"name": "live", "poses": 40, "seed": 1}).json()["id"]
        r = c.post(f"/api/campaigns/{cid}/start")
        assert r.status_code == 202 and r.json()["was"] == "planned", r.text
        pose = reader.wait(lambda k, e: k == "campaign.pose" and e["campaign_id"] == cid)[1]
        assert pose["poses_total"] == 40 and pose["poses_done"] >= 1 and pose["readings"] >= 1
        reader.wait(lambda k, e: k == "campaign.state" and e["state"] == "running")

        r = c.post(f"/api/campaigns/{cid}/pause")
        assert r.status_code == 200 and r.json()["status"] in ("pausing", "paused"), r.text
        # The engine finishes the pose in progress, then holds; the store says what it says.
        reader.wait(lambda k, e: k == "campaign.state" and e["state"] == "paused")
        shown = c.get(f"/api/campaigns/{cid}").json()
        assert shown["status"] == "paused" and "resume" in shown["actions"], shown
        held = shown["poses_done"]
        time.sleep(0.5)
        assert c.get(f"/api/campaigns/{cid}").json()["poses_done"] == held < 40

        r = c.post(f"/api/campaigns/{cid}/resume")
        assert r.status_code == 202 and r.json()["status"] == "running", r.text
        reader.wait(lambda k, e: k == "campaign.pose" and e["poses_done"] > held)

        assert live.anonymous.post(f"/api/campaigns/{cid}/estop").status_code == 401
        r = c.post(f"/api/campaigns/{cid}/estop")
        assert r.status_code == 200, r.text
        body = r.json()
        assert (body["was"], body["status"], body["confirmed"]) == ("running", "estopped", True)
        assert body["actions"] == ["abort", "estop", "reset"], body
        reader.wait(lambda k, e: k == "campaign.run" and e["campaign_id"] == cid)
        stopped = c.get(f"/api/campaigns/{cid}").json()
        assert stopped["status"] == "estopped" and stopped["poses_done"] < 40, stopped
        before = readings(live, cid)
        assert before and set(before.values()) == {1}
        # Nothing moves: pause and resume are refused with the state and what it allows.
        for action in ("pause", "resume"):
            r = c.post(f"/api/campaigns/{cid}/{action}")
            assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, r.text
            assert r.json()["state"] == "estopped"
            assert r.json()["allowed_actions"] == ["abort", "estop", "reset"]
        assert c.post("/api/estop").json()["campaign_id"] is None  # nothing runs here

        r = c.post(f"/api/campaigns/{cid}/reset")
        assert r.status_code == 200 and r.json()["status"] == "paused", r.text
        assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202
        # The stream tells a state once the store has it; GET shows the engine's at once, so a
        # GET saying done is no sign that the stream has said it yet: wait for the stream's.
        reader.wait(lambda k, e: k == "campaign.state" and e["state"] == "done", timeout=180)
        done = c.get(f"/api/campaigns/{cid}").json()
        assert done["status"] == "done", done
        assert done["poses_done"] == 40 and done["actions"] == []
        after = readings(live, cid)
        assert set(after.values()) == {1}  # none duplicated
        assert set(before) <= set(after)  # none lost
        assert len({i for i, _ in after}) == 40  # every pose measured
        states = [
            e["state"]
            for k, e in reader.events
            if k == "campaign.state" and e["campaign_id"] == cid
        ]
        assert states[-1] == "done" and "estopped" in states and "pausing" in states, states
        assert set(states) <= {"running", "pausing", "paused", "estopped", "done"}, states
    finally:
        reader.close()


def test_abort_a_running_campaign_ends_after_the_pose(live):
    c = live.client
    cid = c.post("/api/campaigns", json={"name": "ab", "poses": 40, "seed": 2}).json()["id"]
    c.post(f"/api/campaigns/{cid}/start")
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: j["poses_done"] >= 1, interval=0.02
    )
    r = c.post(f"/api/campaigns/{cid}/abort")
    assert r.status_code == 200 and r.json()["status"] in ("stopping", "aborted"), r.text
    done = wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(), lambda j: not (j["run"] or {}).get("active")
    )
    assert done["status"] == "aborted" and done["actions"] == [], done
    assert done["poses_done"] < 40


def test_jobs_left_running_fail_when_the_service_starts(tmp_path):
    settings = settings_for(tmp_path)
    db = store.open_database(settings.database)
    cid = store.create_campaign(
        db, name="old", cell_json=cell_to_json(default_cell()), poses_deg=[[0, 0, 0, 0, 30, 0]]
    )
    running = store.create_job(db, kind="calibration", campaign_id=cid, method="minimax")
    store.update_job(db, job_id=running.id, state="running", progress=0.5)
    queued = store.create_job(db, kind="diagnosis", campaign_id=cid, method="diagnose")
    db.close()
    server = serve(settings)
    live = next(server)
    try:
        for job_id in (running.id, queued.id):
            job = live.client.get(f"/api/jobs/{job_id}").json()
            assert job["state"] == "failed", job
            assert job["reason"] == "service stopped while running"
            assert job["finished_at"] is not None
        r = live.client.get(f"/api/jobs/{running.id}/recording")
        assert r.status_code == 409 and r.headers["content-type"] == PROBLEM
    finally:
        server.close()
