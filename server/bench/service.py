"""Service benchmark: `robocal demo` end to end, the live-state endpoint's latency under load, the
emergency stop's latency against a stalled controller, and with large request bodies in flight."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .stop_bodies import estop_with_bodies

DEMO_TARGET_S = 60.0


def _serve(settings):
    """A real uvicorn on 127.0.0.1 in a thread; returns (server, thread, app)."""
    import uvicorn

    from robocal.server.service.app import create_app

    app = create_app(settings)
    server = uvicorn.Server(
        uvicorn.Config(app, host="127.0.0.1", port=settings.port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.02)
    return server, thread, app


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(client, url, done, timeout=600.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        body = client.get(url).json()
        if done(body):
            return body
        time.sleep(0.1)
    raise TimeoutError(url)


def _timed_get(client, url) -> float:
    t0 = time.perf_counter()
    client.get(url).raise_for_status()
    return time.perf_counter() - t0


def _stats(seconds) -> dict:
    ms = np.array(seconds) * 1000
    return {
        "requests": len(ms),
        "p25_ms": float(np.percentile(ms, 25)),
        "p50_ms": float(np.percentile(ms, 50)),
        "p75_ms": float(np.percentile(ms, 75)),
        "p99_ms": float(np.percentile(ms, 99)),
        "max_ms": float(ms.max()),
    }


def _job_samples(c, url: str, campaign_id: int, cap: int) -> tuple[list[float], float, str]:
    """Latencies of GET url while one diagnosis of campaign_id runs: (seconds, job's wall, state)."""
    job = c.post("/api/jobs", json={"campaign_id": campaign_id, "kind": "diagnosis"}).json()
    _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] != "queued")
    lat: list[float] = []
    t0 = time.perf_counter()
    while len(lat) < cap:
        lat.append(_timed_get(c, url))
        # One job poll per 20 reads keeps the measured traffic the live-state endpoint's.
        if len(lat) % 20 == 0 and c.get(f"/api/jobs/{job['id']}").json()["state"] != "running":
            break
    job = _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] in ("done", "failed"))
    return lat, time.perf_counter() - t0, job["state"]


def _during_job(c, campaign_id: int, rounds: int = 3, idle: int = 100, cap: int = 5000) -> dict:
    """Latency of the live-state endpoint while only a diagnosis of `campaign_id` runs, and idle.

    The two are taken in turns (idle samples, a job, idle samples, a job, ... idle samples), so
    both see the same machine: a slow spell on a shared host shows on both sides, not on one.
    """
    url = f"/api/campaigns/{campaign_id}"
    spells: list[list[float]] = []
    jobs: list[list[float]] = []
    walls, states = [], []
    load = [os.getloadavg()[0]]
    for _ in range(rounds):
        spells.append([_timed_get(c, url) for _ in range(idle)])
        lat, wall, state = _job_samples(c, url, campaign_id, cap)
        jobs.append(lat)
        walls.append(wall)
        states.append(state)
        load.append(os.getloadavg()[0])
    spells.append([_timed_get(c, url) for _ in range(idle)])
    quiet = [t for spell in spells for t in spell]
    busy = [t for job in jobs for t in job]
    return {
        "rounds": rounds,
        "timing": f"{idle} idle reads, then reads during one diagnosis job, in turns "
        f"({rounds} jobs, {rounds + 1} idle spells)",
        "idle": _stats(quiet),
        **_stats(busy),
        "job_s": float(np.median(walls)),
        "job_s_min_max": [float(min(walls)), float(max(walls))],
        "job": states[-1] if len(set(states)) == 1 else ",".join(states),
        "p50_ms_by_turn": {
            "idle": [float(np.median(x)) * 1000 for x in spells],
            "job": [float(np.median(x)) * 1000 for x in jobs],
        },
        "load_average_1min": load,
    }


def latency_under_load(poses: int = 100, requests: int = 400) -> dict:
    """p50/p99 of GET /api/campaigns/{id} while a campaign and a calibration job run, then while
    only a diagnosis job runs (`during_job`, with the job pool's kind)."""
    import httpx

    from robocal.server.service.security import ensure_token
    from robocal.server.service.settings import Settings

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(
            database=str(Path(tmp) / "b.db"), data_dir=Path(tmp) / "data", port=_free_port()
        )
        token = ensure_token(settings.token_file)
        server, thread, app = _serve(settings)
        auth = {"Authorization": f"Bearer {token}"}
        try:
            with httpx.Client(
                base_url=f"http://127.0.0.1:{settings.port}", headers=auth, timeout=30.0
            ) as c:
                # a finished campaign to calibrate while the next one runs
                first = c.post(
                    "/api/campaigns", json={"poses": 60, "seed": 1, "name": "done"}
                ).json()
                c.post(f"/api/campaigns/{first['id']}/start")
                _wait(c, f"/api/campaigns/{first['id']}", lambda b: b["status"] == "done")
                live = c.post(
                    "/api/campaigns", json={"poses": poses, "seed": 2, "name": "live"}
                ).json()
                c.post(f"/api/campaigns/{live['id']}/start")
                job = c.post(
                    "/api/jobs", json={"campaign_id": first["id"], "method": "minimax"}
                ).json()
                lat, busy = [], 0
                for _ in range(requests):
                    t0 = time.perf_counter()
                    body = c.get(f"/api/campaigns/{live['id']}").json()
                    lat.append(time.perf_counter() - t0)
                    busy += body["status"] == "running"
                _wait(c, f"/api/campaigns/{live['id']}", lambda b: b["status"] == "done")
                job = _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] in ("done", "failed"))
                during = {
                    "pool": app.state.jobs.pool_kind,
                    "workers": settings.job_workers,
                    **_during_job(c, live["id"]),
                }
        finally:
            server.should_exit = True
            thread.join(timeout=10)
    ms = np.array(lat) * 1000
    return {
        "requests": requests,
        "while_running": busy,
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "max_ms": float(ms.max()),
        "calibration_job": job["state"],
        "during_job": during,
    }


STOP_BOUND_MS = 100.0  # issue 11: stop request to STOP on the wire


def _until(predicate, what: str, timeout: float = 10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value is not None:
            return value
        time.sleep(0.001)
    raise TimeoutError(what)


def stop_latency(stops: int = 100) -> dict:
    """Time from emergency_stop() to STOP received by the simulated controller on 127.0.0.1, each
    stop against a controller stalled mid-move while a STATUS waits for its reply on another
    thread: p50 and max of `stops`, and how long emergency_stop took to return."""
    from robocal.drivers.abb.client import ControllerClient, ControllerError
    from robocal.drivers.abb.sim import SimulatedController, serve_controller
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.clock import VirtualClock
    from robocal.drivers.world import SimulatedWorld

    from ..formats import default_cell

    cell, clock = default_cell(), VirtualClock()
    targets = {k: v.tolist() for k, v in cell.targets.items()}
    world = SimulatedWorld(VirtualCell.random(cell.robot, targets, seed=1), clock)
    device = SimulatedController(world, cell.robot, clock)
    on_wire, returned, confirmed = [], [], 0
    quiet = logging.getLogger("robocal.drivers.abb.client")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)  # the 100 STATUS that fail are the design here
    with (
        _restore_level(quiet, level),
        serve_controller(device) as server,
        ControllerClient(server.url, cell.robot, timeout_s=2.0, retries=0) as client,
    ):
        for i in range(stops):
            server.resume()
            client.clear_stop()
            client.move_abs_j([60.0 if i % 2 else -60.0, 0, 0, 0, 0, 0])  # the arm is moving
            since = time.monotonic()
            server.stall()
            stuck = threading.Thread(target=_swallow(client.status, ControllerError), daemon=True)
            stuck.start()
            _until(lambda: device.first_arrival("STATUS", since), "STATUS in flight")  # noqa: B023 (awaited here)
            t0 = time.monotonic()
            confirmed += client.emergency_stop(confirm_s=1.0)
            returned.append(time.monotonic() - t0)
            on_wire.append(_until(lambda: device.first_arrival("STOP", t0), "STOP") - t0)  # noqa: B023
            server.drop_connections()  # frees the stalled STATUS (it fails; the next reconnects)
            stuck.join(timeout=10)
    wire_ms, back_ms = np.array(on_wire) * 1000, np.array(returned) * 1000
    return {
        "stops": stops,
        "controller": "simulated, stalled mid-move, STATUS in flight, 127.0.0.1",
        "p50_ms": float(np.percentile(wire_ms, 50)),
        "max_ms": float(wire_ms.max()),
        "bound_ms": STOP_BOUND_MS,
        "met": bool(wire_ms.max() <= STOP_BOUND_MS),
        "confirmed": confirmed,
        "returned_p50_ms": float(np.percentile(back_ms, 50)),
        "returned_max_ms": float(back_ms.max()),
    }


@contextmanager
def _restore_level(logger, level):
    try:
        yield
    finally:
        logger.setLevel(level)


def _swallow(call, errors):
    def run():
        try:
            call()
        except errors:
            pass

    return run


def deleted_database(repeats: int = 3) -> dict:
    """Time from deleting the database files (`rm robocal.db*`) under a running campaign to its
    run ending failed, and the poses it measured after; a fresh service on 127.0.0.1 with the
    simulated cell (virtual clock) each time."""
    import httpx

    from robocal.server.service.security import ensure_token
    from robocal.server.service.settings import Settings

    runs = []
    for i in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            db = Path(tmp) / "b.db"
            settings = Settings(database=str(db), data_dir=Path(tmp) / "data", port=_free_port())
            token = ensure_token(settings.token_file)
            server, thread, app = _serve(settings)
            try:
                with httpx.Client(
                    base_url=f"http://127.0.0.1:{settings.port}",
                    headers={"Authorization": f"Bearer {token}"},
                    timeout=30.0,
                ) as c:
                    runs.append(_delete_under_a_run(c, app.state.acquisitions, db, seed=i))
            finally:
                server.should_exit = True
                thread.join(timeout=10)
    ms = np.array([r["detect_ms"] for r in runs])
    return {
        "repeats": repeats,
        "cell": "simulated, virtual clock, 127.0.0.1",
        "detect_p50_ms": float(np.percentile(ms, 50)),
        "detect_max_ms": float(ms.max()),
        "poses_after_max": max(r["poses_after"] for r in runs),
        "all_failed_with_reason": all(r["told"] for r in runs),
        "runs": runs,
    }


def _delete_under_a_run(c, acquisitions, db: Path, seed: int) -> dict:
    cid = c.post("/api/campaigns", json={"poses": 40, "seed": seed, "name": "gone"}).json()["id"]
    c.post(f"/api/campaigns/{cid}/start").raise_for_status()
    _wait(c, f"/api/campaigns/{cid}", lambda b: b["poses_done"] >= 3, timeout=120)
    before = c.get(f"/api/campaigns/{cid}").json()["poses_done"]
    for f in (db, db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")):
        f.unlink()
    t0 = time.perf_counter()
    run = _until(lambda: r if not (r := acquisitions.get(cid)).active else None, "run end", 120)
    took = time.perf_counter() - t0
    # read on a connection the service opened before the file went (a new one answers 503)
    end = _until(lambda: _json_if_ok(c.get(f"/api/campaigns/{cid}")), "campaign read", 30)
    return {
        "detect_ms": took * 1000,
        "poses_after": end["poses_done"] - before,
        "status": end["status"],
        "told": end["status"] == "failed" and "was deleted" in (run.detail or ""),
    }


def _json_if_ok(response):
    return response.json() if response.status_code == 200 else None


def demo_time() -> dict:
    """Wall time of `robocal demo` in a fresh folder (a subprocess, as a user runs it)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = subprocess.run(
            [sys.executable, "-m", "robocal.server.cli", "demo", "--out", "demo"],
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=900,
        )
        wall = time.perf_counter() - t0
    return {
        "seconds": wall,
        "exit": r.returncode,
        "target_s": DEMO_TARGET_S,
        "met": r.returncode == 0 and wall <= DEMO_TARGET_S,
    }


def run_service_bench() -> dict:
    print("[bench] robocal demo", file=sys.stderr, flush=True)
    demo = demo_time()
    print("[bench] live-state latency under load", file=sys.stderr, flush=True)
    live = latency_under_load()
    print("[bench] stop latency against a stalled controller", file=sys.stderr, flush=True)
    stop = stop_latency()
    print("[bench] e-stop latency with large request bodies in flight", file=sys.stderr, flush=True)
    return {
        "benchmark": "service",
        "demo": demo,
        "live_state_latency": live,
        "stop_latency": stop,
        "estop_with_bodies": estop_with_bodies(),
        "deleted_database": _deleted_database_figure(),
    }


def _deleted_database_figure() -> dict:
    print("[bench] time to detect a deleted database", file=sys.stderr, flush=True)
    return deleted_database()
