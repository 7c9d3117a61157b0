"""Jobs under limits: a wall-clock limit that kills, cancel of queued and running jobs, one job
killed while another runs on, duplicate calibrations refused, heavy reads in bounded workers,
and numerics that refuse non-finite data instead of hanging the service."""

from __future__ import annotations

import logging
import os
import sqlite3
import subprocess
import sys
import time

import httpx
import pytest

from robocal.server.cli import main as robocal
from robocal.server.service import app as app_module
from robocal.server.service.job_queue import CANCELLED
from robocal.server.service.security import ensure_token
from tests.server.api.conftest import serve, settings_for, wait_for
from tests.server.api.test_job_pool import SpiedJobs, csv_text  # noqa: F401 - a fixture


def served(tmp_path, **settings):
    """A live server with these settings; its Jobs is the last of SpiedJobs.made."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(app_module, "Jobs", SpiedJobs)
        yield from serve(settings_for(tmp_path).model_copy(update=settings))


@pytest.fixture
def make_live(tmp_path):
    """make_live(**settings): a live server with these settings, stopped after the test."""
    servers = []

    def make(**settings):
        servers.append(served(tmp_path, **settings))
        return next(servers[-1])

    yield make
    for s in servers:
        next(s, None)  # runs the rest of serve(): stops the server


@pytest.fixture
def one_worker(make_live):
    return make_live(job_workers=1)


@pytest.fixture
def two_workers(make_live):
    return make_live(job_workers=2)


def campaign(live, csv_text) -> int:
    r = live.client.post("/api/measurements/import", content=csv_text)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def queue(live, cid: int, **body) -> dict:
    r = live.client.post("/api/jobs", json={"campaign_id": cid, **body})
    assert r.status_code == 202, r.text
    return r.json()


def running_pid(job_id: int) -> int:
    jobs = SpiedJobs.made[-1]
    return wait_for(
        lambda: jobs.worker_pid(job_id), lambda pid: pid is not None, timeout=60, interval=0.01
    )


def finished(live, job_id: int, timeout=120) -> dict:
    return wait_for(
        lambda: live.client.get(f"/api/jobs/{job_id}").json(),
        lambda j: j["state"] in ("done", "failed"),
        timeout=timeout,
        interval=0.02,
    )


def gone(pid: int) -> bool:
    """The process has exited (a zombie waiting for its reaper counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except (FileNotFoundError, ProcessLookupError):  # reaped before the open, or between it
        return True  # and the read (the read then fails with ESRCH)


@pytest.fixture(scope="module")
def long_csv_text(tmp_path_factory):
    path = tmp_path_factory.mktemp("sim") / "meas.csv"
    assert (
        robocal(
            [
                "simulate",
                "--poses",
                "400",
                "--seed",
                "5",
                "--effect",
                "thermal_drift",
                "--out",
                str(path),
            ]
        )
        == 0
    )
    return path.read_text()


def test_a_job_past_its_wall_clock_limit_is_killed_and_failed_with_the_reason(
    make_live, long_csv_text, caplog
):
    live = make_live(job_timeout_s=0.5)
    c = live.client
    cid = campaign(live, long_csv_text)
    caplog.set_level(logging.INFO, logger="robocal.jobs")
    job = queue(live, cid, kind="diagnosis")  # 400 poses with a drift: seconds, not 0.5 s
    pid = running_pid(job["id"])
    # The service keeps answering while the job runs: the work is in another process.
    answers = []
    while not gone(pid):
        t0 = time.perf_counter()
        assert c.get("/api/jobs").status_code == 200
        assert c.get("/api/campaigns").status_code == 200
        answers.append(time.perf_counter() - t0)
        time.sleep(0.05)
    job = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(),
        lambda j: j["state"] == "failed",
        timeout=10,
        interval=0.02,
    )
    assert job["reason"] == "exceeded its wall-clock limit of 0.5 s", job
    killed = [r.getMessage() for r in caplog.records if "after its wall-clock limit" in r.message]
    assert len(killed) == 1, killed
    print(
        f"\n{killed[0]}; {len(answers)} health+list reads while it ran, slowest "
        f"{max(answers) * 1000:.0f} ms"
    )


def test_cancel_a_queued_and_a_running_job(one_worker, csv_text):
    c = one_worker.client
    cid = campaign(one_worker, csv_text)
    first = queue(one_worker, cid, kind="diagnosis")
    second = queue(one_worker, cid, method="ls-sum")  # waits: one worker
    pid = running_pid(first["id"])
    assert one_worker.anonymous.post(f"/api/jobs/{second['id']}/cancel").status_code == 401

    r = c.post(f"/api/jobs/{second['id']}/cancel")
    assert r.status_code == 200, r.text
    assert (r.json()["state"], r.json()["reason"], r.json()["started_at"]) == (
        "failed",
        CANCELLED,
        None,
    )

    t0 = time.perf_counter()
    r = c.post(f"/api/jobs/{first['id']}/cancel")
    print(f"\ncancel of a running job answered in {(time.perf_counter() - t0) * 1000:.0f} ms")
    assert r.status_code == 200, r.text
    assert (r.json()["state"], r.json()["reason"]) == ("failed", CANCELLED)
    assert gone(pid)

    again = c.post(f"/api/jobs/{first['id']}/cancel")
    assert again.status_code == 409, again.text
    assert again.headers["content-type"] == "application/problem+json"
    assert "already failed" in again.json()["detail"]
    assert c.post("/api/jobs/999999/cancel").status_code == 404
    # The queue goes on: a new job runs to the end.
    assert finished(one_worker, queue(one_worker, cid, method="ls-sum")["id"])["state"] == "done"


def test_killing_one_job_leaves_the_other_running(two_workers, csv_text):
    cid = campaign(two_workers, csv_text)
    doomed = queue(two_workers, cid, kind="diagnosis")
    other = queue(two_workers, cid, method="minimax")
    doomed_pid, other_pid = running_pid(doomed["id"]), running_pid(other["id"])
    assert doomed_pid != other_pid
    assert two_workers.client.post(f"/api/jobs/{doomed['id']}/cancel").json()["state"] == "failed"
    assert not gone(other_pid) or finished(two_workers, other["id"])["state"] == "done"
    assert finished(two_workers, other["id"])["state"] == "done"
    assert finished(two_workers, doomed["id"])["reason"] == CANCELLED


def test_a_duplicate_calibration_is_refused_while_queued_or_running(one_worker, csv_text):
    c = one_worker.client
    cid = campaign(one_worker, csv_text)
    blocker = queue(one_worker, cid, kind="diagnosis")  # holds the one worker
    first = queue(one_worker, cid, method="minimax")  # queued behind it
    r = c.post("/api/jobs", json={"campaign_id": cid, "method": "minimax"})
    assert r.status_code == 409, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["job_id"] == first["id"] and f"job {first['id']}" in r.json()["detail"]
    other = queue(one_worker, cid, method="ls-sum")  # another method is accepted
    # another tolerance is another verdict: accepted; the same one again is refused
    tight = c.post("/api/jobs", json={"campaign_id": cid, "method": "minimax", "tolerance_mm": 0.1})
    assert tight.status_code == 202, tight.text
    again = c.post("/api/jobs", json={"campaign_id": cid, "method": "minimax", "tolerance_mm": 0.1})
    assert again.status_code == 409 and again.json()["job_id"] == tight.json()["id"], again.text
    for job in (blocker, first, other, tight.json()):
        c.post(f"/api/jobs/{job['id']}/cancel")
    # Once the first has ended, the same calibration may be asked for again.
    assert c.post("/api/jobs", json={"campaign_id": cid, "method": "minimax"}).status_code == 202


def test_a_chart_past_its_limit_answers_504_and_the_service_goes_on(make_live, csv_text):
    # Table 3 of 60 poses is every method of the paper: some 0.1 s of numerics alone on a fast
    # machine, plus starting the worker; a 20 ms limit is far below it on any machine.
    live = make_live()
    c = live.client
    job = finished(live, queue(live, campaign(live, csv_text), method="ls-sum")["id"])
    assert job["state"] == "done", job
    # the limit lowered once the campaign is in: its import is read in a worker under it too
    SpiedJobs.made[-1].call_timeout_s = 0.02
    t0 = time.perf_counter()
    r = c.get(f"/api/charts/jobs/{job['id']}/table3")
    took = time.perf_counter() - t0
    print(f"\ntable3 under a 0.02 s limit answered {r.status_code} in {took * 1000:.0f} ms")
    assert r.status_code == 504, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert "wall-clock limit of 0.02 s" in r.json()["detail"]
    assert not SpiedJobs.made[-1]._calls  # its worker is gone
    assert c.get("/api/jobs").status_code == 200


def poison(database: str, campaign_id: int) -> None:
    """Put x = 1e308 into one stored reading, as an import without bounds once let through."""
    with sqlite3.connect(database) as con:
        rid = con.execute(
            "SELECT min(id) FROM reading WHERE campaign_id = ?", (campaign_id,)
        ).fetchone()[0]
        con.execute("UPDATE reading SET x = 1e308 WHERE id = ?", (rid,))


def test_a_non_finite_campaign_is_refused_quickly_everywhere(two_workers, csv_text):
    c = two_workers.client
    good = campaign(two_workers, csv_text)
    model = finished(two_workers, queue(two_workers, good, method="ls-sum")["id"])
    assert model["state"] == "done", model
    bad = campaign(two_workers, csv_text)
    poison(two_workers.settings.database, bad)

    t0 = time.perf_counter()
    r = c.get(f"/api/models/{model['id']}/evaluate", params={"campaign_id": bad})
    took = time.perf_counter() - t0
    print(f"\nevaluate of a 1e308 campaign: {r.status_code} in {took * 1000:.0f} ms")
    assert r.status_code == 422, r.text
    assert "1e+308 mm is beyond" in r.json()["detail"]
    assert took < 1.0
    ok = c.get(f"/api/models/{model['id']}/evaluate", params={"campaign_id": good})
    assert ok.status_code == 200 and ok.json()["model"]["ap"]["max"] > 0

    for body in (
        {"method": "minimax"},
        {"method": "ls-sum"},
        {"method": "ls-pose"},
        {"method": "ls-single:A"},
        {"kind": "diagnosis"},
    ):
        job = finished(two_workers, queue(two_workers, bad, **body)["id"], timeout=60)
        assert job["state"] == "failed", job
        assert "NonFinite" in job["reason"] and "beyond" in job["reason"], job


def test_an_oversized_plan_is_refused_at_once_and_a_bounded_one_plans(one_worker):
    c = one_worker.client
    t0 = time.perf_counter()
    r = c.post("/api/campaigns", json={"poses": 20, "choose_from": 12586})
    took = time.perf_counter() - t0
    print(f"\nchoose_from 12586: {r.status_code} in {took * 1000:.0f} ms")
    assert r.status_code == 422, r.text
    assert r.json()["errors"][0]["loc"] == ["body", "choose_from"], r.text  # the schema's bound
    r = c.post("/api/campaigns", json={"poses": 100, "choose_from": 2000})
    assert r.status_code == 422 and r.json()["detail"].startswith("poses x choose_from"), r.text
    assert c.get("/api/campaigns").json() == []  # nothing half-planned was stored
    r = c.post("/api/campaigns", json={"poses": 10, "choose_from": 200, "name": "chosen"})
    assert r.status_code == 202, r.text  # a planning job (tests/server/api/test_planning_jobs.py)
    job = wait_for(
        lambda: c.get(r.headers["location"]).json(),
        lambda j: j["state"] in ("done", "failed"),
        timeout=120,
    )
    assert job["state"] == "done", job
    info = c.get(job["campaign_url"]).json()
    assert (info["poses_total"], info["status"]) == (10, "planned")


def test_workers_die_with_a_killed_service(tmp_path, csv_text):
    """SIGKILL of the service: its job's worker process ends within about a second."""
    settings = settings_for(tmp_path)
    token = ensure_token(settings.token_file)
    env = {
        **os.environ,
        "ROBOCAL_DATABASE": settings.database,
        "ROBOCAL_DATA_DIR": str(settings.data_dir),
        "ROBOCAL_PORT": str(settings.port),
    }
    service = subprocess.Popen(
        [sys.executable, "-m", "robocal.server.cli", "serve"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        url = f"http://127.0.0.1:{settings.port}"
        with httpx.Client(
            base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=30
        ) as c:
            wait_for(lambda: _answers(c), bool, timeout=60, interval=0.1)
            cid = c.post("/api/measurements/import", content=csv_text).json()["id"]
            job = c.post("/api/jobs", json={"campaign_id": cid, "kind": "diagnosis"}).json()
            wait_for(
                lambda: c.get(f"/api/jobs/{job['id']}").json()["state"],
                lambda s: s != "queued",
                timeout=60,
                interval=0.02,
            )
            workers = wait_for(lambda: _grandchildren(service.pid), bool, timeout=10, interval=0.02)
        service.kill()
        t0 = time.monotonic()
        wait_for(lambda: all(gone(pid) for pid in workers), bool, timeout=10, interval=0.01)
        took = time.monotonic() - t0
        print(f"\nworker(s) {workers} gone {took * 1000:.0f} ms after SIGKILL of the service")
        assert took < 1.5
    finally:
        service.kill()
        service.wait(timeout=10)


def _answers(client) -> bool:
    try:
        return client.get("/api/jobs").status_code == 200
    except httpx.TransportError:
        return False


def _grandchildren(pid: int) -> list[int]:
    """The live processes whose parent's parent is pid (the fork server's children)."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if fields[0] != "Z":
                parents[int(entry)] = int(fields[1])
    return sorted(p for p, pp in parents.items() if parents.get(pp) == pid)
