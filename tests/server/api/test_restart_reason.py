"""Kill -9 the service mid-campaign and start it again: the campaign showed `failed` with
`run: null`, no word of why; it now says the process running it stopped and where a resume
continues."""

import signal

import httpx

from tests.server.api.conftest import free_port
from tests.server.api.test_restart import start, started


def test_a_campaign_left_running_by_a_killed_service_says_why(tmp_path):
    port = free_port()
    proc, token = start(tmp_path, port)
    url = f"http://127.0.0.1:{port}/api"
    auth = {"Authorization": f"Bearer {token}"}
    body = {"poses": 60, "seed": 3, "name": "k", "pause_s": 0.0, "samples": 5}
    cid = started(url, auth, body, 3)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc2, _ = start(tmp_path, port)
    try:
        with httpx.Client(headers=auth, timeout=30) as c:
            left = c.get(f"{url}/campaigns/{cid}").json()
            assert left["status"] == "failed" and left["poses_done"] < 60, left
            run = left["run"]
            assert run is not None and run["active"] is False, left
            assert "stopped while it was running" in run["detail"], run
            assert f"resume continues at pose {left['poses_done'] + 1}" in run["detail"], run
            listed = [x for x in c.get(f"{url}/campaigns").json() if x["id"] == cid]
            assert listed[0]["run"] == run, listed
    finally:
        proc2.send_signal(signal.SIGTERM)
        proc2.wait(timeout=30)
