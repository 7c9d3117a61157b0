"""Jobs run in worker processes: progress over SSE, a killed worker, a stop with a job running."""

from __future__ import annotations

import json
import os
import signal
import time

import httpx
import pytest

from robocal.server import store
from robocal.server.cli import main as robocal
from robocal.server.service import app as app_module
from robocal.server.service.job_queue import RESTART_REASON, Jobs
from tests.server.api.conftest import serve, settings_for, wait_for


class SpiedJobs(Jobs):
    """Jobs that the test can reach (for the worker pids)."""

    made: list[Jobs] = []

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        SpiedJobs.made.append(self)


@pytest.fixture(scope="module")
def csv_text(tmp_path_factory):
    path = tmp_path_factory.mktemp("sim") / "meas.csv"
    assert robocal(["simulate", "--poses", "60", "--seed", "3", "--out", str(path)]) == 0
    return path.read_text()


def served(tmp_path):
    """A live server whose Jobs is the last of SpiedJobs.made."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(app_module, "Jobs", SpiedJobs)
        yield from serve(settings_for(tmp_path))


@pytest.fixture(scope="module")
def pooled(tmp_path_factory):
    yield from served(tmp_path_factory.mktemp("pool"))


def campaign(live, csv_text) -> int:
    r = live.client.post("/api/measurements/import", content=csv_text)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def running_pid(jobs: Jobs, job_id: int) -> int:
    return wait_for(
        lambda: jobs.worker_pid(job_id), lambda pid: pid is not None, timeout=60, interval=0.01
    )


def finished(live, job_id: int) -> dict:
    return wait_for(
        lambda: live.client.get(f"/api/jobs/{job_id}").json(),
        lambda j: j["state"] in ("done", "failed"),
        timeout=60,
    )


def job_events(live, body: dict) -> tuple[int, list[dict]]:
    """Queue a job while reading /api/events; the job's id and its events up to the last."""
    seen, kind = [], None
    # Read on this thread, so that leaving closes the stream at once (the server waits for it).
    with (
        httpx.Client(
            base_url=live.url,
            timeout=httpx.Timeout(30, read=60),
            headers={"Authorization": f"Bearer {live.token}"},
        ) as c,
        c.stream("GET", "/api/events") as stream,
    ):
        job_id = live.client.post("/api/jobs", json=body).json()["id"]
        for line in stream.iter_lines():
            if line.startswith("event:"):
                kind = line.split(":", 1)[1].strip()
            elif line.startswith("data:") and kind == "job":
                seen.append(json.loads(line.split(":", 1)[1]))
                if seen[-1]["job_id"] == job_id and seen[-1]["state"] in ("done", "failed"):
                    break
    return job_id, [e for e in seen if e["job_id"] == job_id]


def test_progress_events_arrive_from_the_worker_process(pooled, csv_text):
    job_id, events = job_events(
        pooled, {"campaign_id": campaign(pooled, csv_text), "method": "ls-sum"}
    )
    seen = [(e["state"], e["progress"]) for e in events]
    assert seen == [
        ("queued", 0.0),
        ("running", 0.0),
        ("running", 0.1),
        ("running", 0.5),
        ("done", 1.0),
    ], seen
    assert finished(pooled, job_id)["model_url"]


def test_a_killed_worker_fails_its_job_and_the_next_job_runs(pooled, csv_text):
    c, jobs = pooled.client, SpiedJobs.made[-1]
    cid = campaign(pooled, csv_text)
    job_id = c.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis"}).json()["id"]
    os.kill(running_pid(jobs, job_id), signal.SIGKILL)
    job = finished(pooled, job_id)
    assert job["state"] == "failed", job
    assert job["reason"] == "its worker process died (killed by SIGKILL)", job
    assert jobs.worker_pid(job_id) is None
    after = c.post("/api/jobs", json={"campaign_id": cid, "method": "ls-sum"}).json()
    assert finished(pooled, after["id"])["state"] == "done"


def test_stopping_the_service_with_a_running_job_does_not_hang(tmp_path, csv_text):
    live = served(tmp_path)
    client = next(live)
    cid = campaign(client, csv_text)
    job_id = client.client.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis"}).json()[
        "id"
    ]
    pid = running_pid(SpiedJobs.made[-1], job_id)
    t0 = time.monotonic()
    with pytest.raises(StopIteration):
        next(live)  # stops the server
    assert time.monotonic() - t0 < 10
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # the worker is gone (and reaped)
    with store.open_database(client.settings.database) as db:
        job = store.get_job(db, job_id=job_id)
    assert (job.state, job.reason) == ("failed", RESTART_REASON)
