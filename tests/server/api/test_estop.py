"""The e-stop over HTTP against a cell with real devices (simulated servers on loopback, wall
clock): answered ahead of 60 heavy reads in flight (its time printed); the moving states refuse what the
table refuses; one process owns a running campaign."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

from robocal.drivers.lifecycle import allowed
from tests.server.api.conftest import free_port, serve, settings_for, wait_for
from tests.server.api.test_real_devices import cell_json, devices  # noqa: F401 - a fixture
from tests.server.api.test_sigterm import Wire, start_service

ROOT = Path(__file__).resolve().parents[3]
PROBLEM = "application/problem+json"
# Slow poses (a 1.5 s settle each): a state reached mid-pose holds long enough to be asked.
SLOW = {"poses": 12, "pause_s": 1.5, "samples": 20, "order": True, "seed": 2}


def running_campaign(c, devices, name: str, run=SLOW) -> int:
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    r = c.post("/api/campaigns", json={"name": name, "cell_id": cell_id, **run})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["status"] == "running",
        timeout=30,
        interval=0.02,
    )
    wait_for(lambda: len(devices.controller.moves), lambda n: n >= 1, timeout=30, interval=0.02)
    return cid


def refused(c, cid, action, state):
    r = c.post(f"/api/campaigns/{cid}/{action}")
    assert r.status_code == 409 and r.headers["content-type"] == PROBLEM, (state, action, r.text)
    assert r.json()["state"] == state and r.json()["allowed_actions"] == allowed(state), r.text


def test_moving_states_refuse_what_the_table_refuses(live, devices):
    """running, pausing and stopping with a live engine: every illegal action 409."""
    c = live.client
    cid = running_campaign(c, devices, "moving")
    for action in ("start", "resume", "reset"):
        refused(c, cid, action, "running")
    assert c.get(f"/api/campaigns/{cid}").json()["actions"] == ["pause", "abort", "estop"]
    r = c.post(f"/api/campaigns/{cid}/pause")
    assert r.status_code == 200 and r.json()["status"] == "pausing", r.text
    for action in ("start", "pause", "reset"):
        refused(c, cid, action, "pausing")
    r = c.post(f"/api/campaigns/{cid}/resume")  # before the pause is reached: cancels it
    assert r.status_code == 202 and r.json()["status"] == "running", r.text
    r = c.post(f"/api/campaigns/{cid}/abort")
    assert r.status_code == 200 and r.json()["status"] == "stopping", r.text
    for action in ("start", "pause", "resume", "abort", "reset"):
        refused(c, cid, action, "stopping")
    r = c.post(f"/api/campaigns/{cid}/estop")
    assert r.status_code == 200 and r.json()["status"] == "estopped", r.text
    assert r.json()["confirmed"] is True


def test_estop_answers_ahead_of_60_heavy_reads(tmp_path, devices):
    # The service in its own process, as in production: the readers and the simulated devices
    # here do not share its interpreter.
    port = free_port()
    proc, token, _ = start_service(tmp_path, port)
    try:
        _estop_under_reads(f"http://127.0.0.1:{port}", token, devices)
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _estop_under_reads(url, token, devices):
    c = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=30)
    # The heavy reads: Table 3 (every method of the paper) of a calibrated simulated campaign.
    sim = c.post("/api/campaigns", json={"name": "data", "poses": 20, "seed": 4}).json()["id"]
    c.post(f"/api/campaigns/{sim}/start")
    wait_for(
        lambda: c.get(f"/api/campaigns/{sim}").json(), lambda j: j["status"] == "done", timeout=120
    )
    job = c.post("/api/jobs", json={"campaign_id": sim, "method": "ls-sum"}).json()
    wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(), lambda j: j["state"] == "done", timeout=120
    )
    cid = running_campaign(c, devices, "stop")
    with httpx.Client(base_url=url, headers=c.headers, timeout=30) as h:
        idle = []
        for _ in range(5):  # the same route, refused (no e-stop in planned), with no load
            t0 = time.perf_counter()
            h.post(f"/api/campaigns/{sim}/estop")
            idle.append(time.perf_counter() - t0)

    answered, started = [], threading.Barrier(61, timeout=30)

    def heavy():
        with httpx.Client(base_url=url, headers=c.headers, timeout=120) as h:
            started.wait()
            t0 = time.perf_counter()
            r = h.get(f"/api/charts/jobs/{job['id']}/table3")
            answered.append((r.status_code, time.perf_counter() - t0))

    threads = [threading.Thread(target=heavy, daemon=True) for _ in range(60)]
    for t in threads:
        t.start()
    started.wait()
    time.sleep(0.3)  # the reads are in flight, the server's thread pool full
    in_flight = 60 - len(answered)
    wire = Wire(devices.controller)
    with httpx.Client(base_url=url, headers=c.headers, timeout=30) as h:
        t0, m0 = time.perf_counter(), time.monotonic()
        r = h.post(f"/api/campaigns/{cid}/estop")
        took = time.perf_counter() - t0
        still_reading = 60 - len(answered)
    on_wire = wire.first("STOP", after=m0)
    for t in threads:
        t.join(timeout=300)
    reads = sorted(s for _, s in answered)
    print(
        f"\ne-stop: STOP on the wire after {(on_wire - m0) * 1000:.1f} ms, answered in "
        f"{took * 1000:.1f} ms with {in_flight} of 60 Table 3 reads in "
        f"flight (reads took {reads[0]:.2f}-{reads[-1]:.2f} s, median {reads[30]:.2f} s); "
        f"with no load {min(idle) * 1000:.1f}-{max(idle) * 1000:.1f} ms; load average "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    assert r.status_code == 200 and r.json()["status"] == "estopped", r.text
    assert r.json()["confirmed"] is True
    assert in_flight >= 30, f"the reads were over before the e-stop: not a load test {answered[:3]}"
    # a read answers, or is refused in time (503 no chart worker free, 504 past its limit)
    assert {s for s, _ in answered} <= {200, 503, 504} and 200 in {s for s, _ in answered}
    # Load-proof: the e-stop did not queue behind the reads (most were still in flight when it
    # was answered). Its time against the 100 ms target is printed above and measured by
    # `robocal bench service`, not asserted: a loaded CI machine is no stopwatch.
    assert still_reading >= 30, (
        f"e-stop answered in {took * 1000:.1f} ms only after {60 - still_reading} reads ended"
    )


def test_one_process_owns_a_running_campaign(tmp_path, live, devices):
    """A second service on the same database, and `robocal acquire --db` on it, cannot drive a
    campaign this service runs."""
    c = live.client
    cid = running_campaign(c, devices, "owned")
    name = "owned"
    cell = tmp_path / "cell.json"
    cell.write_text(json.dumps(cell_json(devices)))
    moves = len(devices.controller.moves)
    other = settings_for(tmp_path / "other")
    other = other.model_copy(update={"database": live.settings.database})
    second = serve(other)
    live2 = next(second)
    try:
        shown = live2.client.get(f"/api/campaigns/{cid}").json()
        assert shown["status"] == "running" and shown["actions"] == [], shown
        for action in ("pause", "abort", "resume", "start", "estop"):
            r = live2.client.post(f"/api/campaigns/{cid}/{action}")
            assert r.status_code == 409, (action, r.text)
            assert "another process" in r.json()["detail"], r.text
    finally:
        second.close()
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "acquire",
            "--db",
            live.settings.database,
            "--cell",
            str(cell),
            "--name",
            name,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1, done
    err = done.stderr.strip().splitlines()
    assert len(err) == 1 and "driven by another process" in err[0], done.stderr
    # The owner drives on: still running here, moving on.
    assert c.get(f"/api/campaigns/{cid}").json()["status"] == "running"
    wait_for(lambda: len(devices.controller.moves), lambda n: n > moves, timeout=30)
    assert c.post(f"/api/campaigns/{cid}/estop").status_code == 200
