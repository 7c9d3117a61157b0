"""A cell with real devices: the simulated tracker and controller run as separate servers on
loopback on the wall clock, and the API reaches them only through the addresses of the cell."""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass

import httpx
import pytest

from robocal.drivers.abb.sim import SimulatedController, serve_controller
from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import RealClock
from robocal.drivers.lifecycle import MOVING
from robocal.drivers.tracker.sim import SimulatedTracker, serve_tracker
from robocal.drivers.world import SimulatedWorld
from robocal.server.formats import cell_to_json, default_cell
from tests.server.api.conftest import free_port, wait_for

PROBLEM = "application/problem+json"
# A fast arm (10x an IRB 2600) so that the real-time campaign takes seconds, not minutes.
FAST_DEG_S = (1750.0,) * 6
# Few, short poses: the handshake runs in real time (moves, a 50 ms pause, 20 samples).
RUN = {"poses": 8, "pause_s": 0.05, "samples": 20, "order": True, "seed": 2}


@dataclass
class Devices:
    """The devices of the cell: a world on the wall clock and its two servers."""

    cell: VirtualCell
    world: SimulatedWorld
    controller: SimulatedController
    tracker_server: object
    controller_server: object = None

    def serve_controller(self, port: int = 0) -> None:
        """(Re)start the controller's server, on `port` if given."""
        self.controller_server = serve_controller(self.controller, port=port)


@pytest.fixture
def devices():
    robot_cell = default_cell()
    clock = RealClock()
    cell = VirtualCell.random(robot_cell.robot, robot_cell.targets, seed=11)
    world = SimulatedWorld(cell, clock, speeds_deg_s=FAST_DEG_S)
    tracker = serve_tracker(SimulatedTracker(world, clock, seed=11))
    controller = SimulatedController(world, robot_cell.robot, clock)
    d = Devices(cell, world, controller, tracker)
    d.serve_controller()
    yield d
    d.controller_server.close()
    d.tracker_server.close()


def cell_json(devices: Devices, *, tracker_port=None, controller_port=None) -> dict:
    """The cell.json of the real cell: the surveyed base and the devices' addresses."""
    doc = cell_to_json(default_cell())
    doc["base"] = devices.cell.base.tolist()  # a good survey: the first poses need no search
    doc["devices"] = {
        "tracker": {"host": "127.0.0.1", "port": tracker_port or devices.tracker_server.port},
        "controller": {
            "url": f"socket://127.0.0.1:{controller_port or devices.controller_server.port}",
            "timeout_s": 2,
        },
    }
    return doc


class FailedEvents:
    """Reads /api/events on a thread until `count` runs have ended with a detail; those."""

    def __init__(self, url, count, token):
        self.details: dict[int, str] = {}
        self.count = count
        self._client = httpx.Client(
            base_url=url,
            timeout=httpx.Timeout(30, read=None),
            headers={"Authorization": f"Bearer {token}"},
        )
        self._connected = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()
        assert self._connected.wait(10), "no event stream"

    def _read(self):
        try:
            with self._client.stream("GET", "/api/events") as r:
                self._connected.set()
                for line in r.iter_lines():
                    event = json.loads(line[5:]) if line.startswith("data:") else {}
                    if event.get("type") == "campaign.run" and event.get("detail"):
                        self.details[event["campaign_id"]] = event["detail"]
                    if len(self.details) == self.count:
                        return  # hang up: an open stream would hold the server's shutdown
        except httpx.HTTPError:
            pass  # closed

    def close(self):
        self._client.close()


def finished(c, cid, timeout=90.0) -> dict:
    """The campaign once its run has ended (status and run are read apart: wait for both)."""
    return wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["run"] is not None and not j["run"]["active"] and j["status"] not in MOVING,
        timeout=timeout,
        interval=0.05,
    )


def calibrated(c, cid) -> dict:
    """The done ls-sum calibration job of the campaign."""
    job = c.post("/api/jobs", json={"campaign_id": cid, "method": "ls-sum"}).json()
    job = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
        timeout=60,
    )
    assert job["state"] == "done", job
    return job


def test_campaign_on_real_devices_survives_a_lost_controller_resumes_and_calibrates(live, devices):
    c = live.client
    r = c.post("/api/cells", json=cell_json(devices))
    assert r.status_code == 201, r.text
    cell = r.json()
    assert cell["simulated"] is False and cell["cell"]["devices"]["tracker"]["port"] > 0
    assert c.get(f"/api/cells/{cell['id']}").json()["simulated"] is False
    assert c.get("/api/cells/default").json()["simulated"] is True

    r = c.post("/api/campaigns", json={"name": "real", "cell_id": cell["id"], **RUN})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert r.json()["simulated"] is False and r.json()["settings"]["options"]["pause_s"] == 0.05

    # The controller drops off the network mid-campaign: the run fails, naming its address.
    t0 = time.monotonic()
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["poses_done"] >= 3,
        timeout=60,
        interval=0.05,
    )
    port = devices.controller_server.port
    devices.controller_server.close()
    failed = finished(c, cid)
    assert failed["status"] == "failed" and "resume" in failed["actions"], failed
    assert f"socket://127.0.0.1:{port}" in failed["run"]["detail"], failed["run"]["detail"]
    kept = len(c.get(f"/api/campaigns/{cid}/measurements").json())
    assert kept >= 9 and 3 <= failed["poses_done"] < RUN["poses"]

    # Back on the same address: the campaign resumes at its next pose and keeps what it had.
    wait_for(devices.world.moving, lambda moving: not moving, timeout=10, interval=0.02)
    devices.serve_controller(port)
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 409  # failed: resume it
    assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202
    done = finished(c, cid)
    assert done["status"] == "done" and done["run"]["detail"] == "the run ended done", done["run"]
    assert done["run"]["summary"]["simulated"] is False
    assert done["run"]["summary"]["resumed_at"] == failed["poses_done"]
    readings = c.get(f"/api/campaigns/{cid}/measurements").json()
    assert len(readings) == 3 * RUN["poses"] and all(x["status"] == "ok" for x in readings)
    # Every pose went to the controller over its socket, and the pauses really waited.
    # (the pose cut off, if the controller went while the arm was there, is moved to again)
    assert RUN["poses"] <= len(devices.controller.moves) <= RUN["poses"] + 1
    assert time.monotonic() - t0 > RUN["poses"] * RUN["pause_s"]

    job = calibrated(c, cid)
    model = c.get(job["model_url"]).json()
    assert model["method"] == "ls-sum" and model["data"]["poses"] == RUN["poses"]


def test_estop_reaches_the_real_controller(live, devices):
    c = live.client
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    cid = c.post("/api/campaigns", json={"name": "stop", "cell_id": cell_id, **RUN}).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    wait_for(lambda: len(devices.controller.moves), lambda n: n >= 2, timeout=30, interval=0.02)
    sent = len(devices.controller.received)
    r = c.post("/api/estop")
    assert r.status_code == 200 and r.json()["campaign_id"] == cid, r.text
    assert r.json()["status"] == "estopped" and r.json()["confirmed"] is True, r.text
    assert any(" STOP" in line for line in devices.controller.received[sent:])
    stopped = finished(c, cid)
    assert stopped["status"] == "estopped" and stopped["actions"] == ["abort", "estop", "reset"]
    assert len(devices.controller.moves) < RUN["poses"]


def test_unreachable_devices_fail_the_campaign_with_their_address(live, devices):
    c = live.client
    nobody = free_port()  # nothing listens there: connection refused
    events = FailedEvents(live.url, count=2, token=live.token)
    for where, doc, expect in (
        ("tracker", cell_json(devices, tracker_port=nobody), f"tracker at 127.0.0.1:{nobody}"),
        (
            "controller",
            cell_json(devices, controller_port=nobody),
            f"controller at socket://127.0.0.1:{nobody}",
        ),
    ):
        cell_id = c.post("/api/cells", json=doc).json()["id"]
        cid = c.post("/api/campaigns", json={"name": where, "cell_id": cell_id, **RUN}).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
        # nothing moved: the campaign stays planned (start it again), the run says why
        failed = wait_for(
            lambda: c.get(f"/api/campaigns/{cid}").json(),  # noqa: B023 (awaited here)
            lambda j: j["run"] is not None and not j["run"]["active"],
            timeout=30,
            interval=0.05,
        )
        assert failed["status"] == "planned" and "start" in failed["actions"], failed
        assert expect in failed["run"]["detail"] and "does not answer" in failed["run"]["detail"]
        assert failed["poses_done"] == 0 and devices.controller.moves == []
        detail = wait_for(lambda: events.details.get(cid), lambda d: d is not None, timeout=10)  # noqa: B023 (awaited here)
        assert expect in detail, detail
    events.close()


BAD_DEVICES = (
    (lambda d: d["devices"]["tracker"].update(port=70000), "devices.tracker.port"),
    (lambda d: d["devices"]["tracker"].update(port=50.5), "devices.tracker.port"),
    (lambda d: d["devices"]["tracker"].update(host="10.0.0.5:5000"), "devices.tracker.host"),
    (lambda d: d["devices"].update(controler=d["devices"].pop("controller")), "devices.controler"),
    (
        lambda d: d["devices"]["controller"].update(url="http://10.0.0.6:1025"),
        "devices.controller.url",
    ),
    (
        lambda d: d["devices"]["controller"].update(url="socket://10.0.0.6"),
        "devices.controller.url",
    ),
    (lambda d: d["devices"]["controller"].update(baudrate=0), "devices.controller.baudrate"),
    (lambda d: d.pop("base"), "devices"),
)


def test_bad_device_config_is_422_naming_the_field_and_its_line(live):
    for change, field in BAD_DEVICES:
        doc = {
            "robot": "irb2600",
            "targets": {"A": [60, 0, 35]},
            "base": [[1, 0, 0, 2000], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            "devices": {
                "tracker": {"host": "10.0.0.5", "port": 5000},
                "controller": {"url": "socket://10.0.0.6:1025"},
            },
        }
        change(doc)
        text = json.dumps(doc, indent=1)
        r = live.client.post("/api/cells", content=text)
        assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
        body = r.json()
        assert body["detail"].startswith(f"cell.json:{body['line']}:{body['column']}: {field}: ")
        # the line it names is the field's own
        key = field.rsplit(".", 1)[-1]
        assert text.splitlines()[body["line"] - 1].strip().startswith(f'"{key}"'), (text, body)
    assert "needs a `base` guess" in body["detail"]
    assert live.client.get("/api/cells").json() == ["default"]


def test_simulation_only_options_are_refused_on_a_real_cell(live, devices):
    c = live.client
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    r = c.post("/api/campaigns", json={"cell_id": cell_id, "beam_break_rate": 0.1, **RUN})
    assert r.status_code == 422 and "beam_break_rate" in r.json()["detail"], r.text
    # Motion needs the token, on a real cell as on the simulated one.
    assert live.anonymous.post("/api/campaigns", json={"cell_id": cell_id}).status_code == 401


@pytest.mark.sqlite_only  # a minute of wall clock; the store's part runs on both elsewhere
def test_verification_on_real_devices(live, devices):
    """A model calibrated on the real cell is verified there: both joint sets go to the
    controller over its socket on the wall clock, and compensation brings AP down tenfold."""
    c = live.client
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    run = {**RUN, "poses": 30}
    cid = c.post("/api/campaigns", json={"name": "cal", "cell_id": cell_id, **run}).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    assert finished(c, cid, timeout=120)["status"] == "done"
    job = calibrated(c, cid)

    moves = len(devices.controller.moves)
    r = c.post(
        f"/api/models/{job['id']}/verify",
        json={"cycles": 2, "directions": 1, "pause_s": run["pause_s"]},
    )
    assert r.status_code == 201, r.text
    v = r.json()
    assert v["simulated"] is False and v["settings"]["options"]["samples"] == run["samples"]
    t0 = time.monotonic()
    done = finished(c, v["id"], timeout=180)
    took = time.monotonic() - t0
    assert done["status"] == "done", done
    assert len(devices.controller.moves) - moves == v["poses_total"] == 5 * 2 * 2 * 2
    rep = c.get(f"/api/campaigns/{v['id']}/verification").json()
    assert rep["simulated"] is False and rep["instrument"]["kind"] == "laser tracker"
    print(
        f"real-device verification: {v['poses_total']} poses in {took:.1f} s; worst AP "
        f"{rep['before']['AP_max_mm']:.3f} mm nominal, {rep['after']['AP_max_mm']:.4f} mm "
        f"compensated; RP {rep['before']['RP_max_mm']:.4f} / {rep['after']['RP_max_mm']:.4f} mm"
    )
    assert rep["before"]["AP_max_mm"] >= 10 * rep["after"]["AP_max_mm"], rep
    assert c.get(f"/api/campaigns/{v['id']}/certificate").text.count("real devices") == 1
