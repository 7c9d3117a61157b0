"""A service starting on a database another live service uses leaves that service's unfinished
jobs alone: it fails only those whose service is gone (before, it failed every queued or running
job: a second `robocal serve` on a shared store killed the first one's calibration in flight)."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from robocal.server import store
from robocal.server.service.settings import Settings
from tests.real import import_real
from tests.server.api.conftest import free_port, serve


def _owner(pid: int) -> str:
    """A job owner id of a process of this host, as the job queue writes it."""
    return f"{socket.gethostname()}:{pid}:0123abcd"


@pytest.mark.sqlite_only  # the owners are the store's; both backends keep them alike
def test_a_starting_service_fails_only_the_jobs_of_services_gone(tmp_path):
    db_path = str(tmp_path / "robocal.db")
    first = serve(Settings(database=db_path, data_dir=tmp_path / "a", port=free_port()))
    cid = import_real(next(first).client, "irb120_wu")  # its jobs are never run
    next(first, None)  # that service stopped

    alive = subprocess.Popen(
        [sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE
    )
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    db = store.open_database(db_path)
    try:
        kept = store.create_job(
            db, kind="calibration", campaign_id=cid, method="ls-sum", owner=_owner(alive.pid)
        ).id
        failed = store.create_job(
            db, kind="calibration", campaign_id=cid, method="minimax", owner=_owner(gone.pid)
        ).id
        unknown = store.create_job(db, kind="diagnosis", campaign_id=cid, method="diagnose").id
    finally:
        db.close()
    try:
        second = serve(Settings(database=db_path, data_dir=tmp_path / "b", port=free_port()))
        b = next(second)
        states = {j["id"]: (j["state"], j["reason"]) for j in b.client.get("/api/jobs").json()}
        next(second, None)
    finally:
        alive.stdin.close()
        alive.wait()
    assert states[kept] == ("queued", None), states
    assert states[failed][0] == "failed" and states[unknown][0] == "failed", states
