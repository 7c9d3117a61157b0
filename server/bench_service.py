"""Service benchmark: `robocal demo` end to end, and the live-state endpoint's latency under load."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

DEMO_TARGET_S = 60.0


def _serve(settings):
    """A real uvicorn on 127.0.0.1 in a thread; returns (server, thread, app)."""
    import uvicorn

    from .app import create_app

    app = create_app(settings)
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=settings.port,
                                           log_level="warning"))
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
    return {"requests": len(ms), "p50_ms": float(np.percentile(ms, 50)),
            "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max())}


def _during_job(c, campaign_id: int, cap: int = 5000) -> dict:
    """Latency of the live-state endpoint while only a diagnosis of `campaign_id` runs."""
    url = f"/api/campaigns/{campaign_id}"
    idle = [_timed_get(c, url) for _ in range(100)]
    job = c.post("/api/jobs", json={"campaign_id": campaign_id, "kind": "diagnosis"}).json()
    _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] != "queued")
    t0, lat = time.perf_counter(), []
    while len(lat) < cap:
        lat.append(_timed_get(c, url))
        # One job poll per 20 reads keeps the measured traffic the live-state endpoint's.
        if len(lat) % 20 == 0 and c.get(f"/api/jobs/{job['id']}").json()["state"] != "running":
            break
    job = _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] in ("done", "failed"))
    return {"idle": _stats(idle), **_stats(lat), "job_s": time.perf_counter() - t0,
            "job": job["state"]}


def latency_under_load(poses: int = 100, requests: int = 400) -> dict:
    """p50/p99 of GET /api/campaigns/{id} while a campaign and a calibration job run, then while
    only a diagnosis job runs (`during_job`, with the job pool's kind)."""
    import httpx

    from .security import ensure_token
    from .settings import Settings

    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(database=str(Path(tmp) / "b.db"), data_dir=Path(tmp) / "data",
                            port=_free_port())
        token = ensure_token(settings.token_file)
        server, thread, app = _serve(settings)
        auth = {"Authorization": f"Bearer {token}"}
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{settings.port}", headers=auth,
                              timeout=30.0) as c:
                # a finished campaign to calibrate while the next one runs
                first = c.post("/api/campaigns", json={"poses": 60, "seed": 1, "name": "done"}).json()
                c.post(f"/api/campaigns/{first['id']}/start")
                _wait(c, f"/api/campaigns/{first['id']}", lambda b: b["status"] == "done")
                live = c.post("/api/campaigns", json={"poses": poses, "seed": 2, "name": "live"}).json()
                c.post(f"/api/campaigns/{live['id']}/start")
                job = c.post("/api/jobs", json={"campaign_id": first["id"], "method": "minimax"}).json()
                lat, busy = [], 0
                for _ in range(requests):
                    t0 = time.perf_counter()
                    body = c.get(f"/api/campaigns/{live['id']}").json()
                    lat.append(time.perf_counter() - t0)
                    busy += body["status"] == "running"
                _wait(c, f"/api/campaigns/{live['id']}", lambda b: b["status"] == "done")
                job = _wait(c, f"/api/jobs/{job['id']}", lambda b: b["state"] in ("done", "failed"))
                during = {"pool": app.state.jobs.pool_kind, "workers": settings.job_workers,
                          **_during_job(c, live["id"])}
        finally:
            server.should_exit = True
            thread.join(timeout=10)
    ms = np.array(lat) * 1000
    return {"requests": requests, "while_running": busy, "p50_ms": float(np.percentile(ms, 50)),
            "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
            "calibration_job": job["state"], "during_job": during}


def demo_time() -> dict:
    """Wall time of `robocal demo` in a fresh folder (a subprocess, as a user runs it)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "server.cli", "demo", "--out", "demo"], cwd=tmp,
                           capture_output=True, text=True, timeout=900)
        wall = time.perf_counter() - t0
    return {"seconds": wall, "exit": r.returncode, "target_s": DEMO_TARGET_S,
            "met": r.returncode == 0 and wall <= DEMO_TARGET_S}


def run_service_bench() -> dict:
    print("[bench] robocal demo", file=sys.stderr, flush=True)
    demo = demo_time()
    print("[bench] live-state latency under load", file=sys.stderr, flush=True)
    return {"benchmark": "service", "demo": demo, "live_state_latency": latency_under_load()}
