"""The service and other processes on one SQLite file (issue 20, point 1): `robocal calibrate` or
a second service beside a running service cost it neither its lock nor its write-ahead log, and
every reading the API showed survives a kill -9; a database file deleted or replaced under a
running campaign stops it within a pose, the arm halted, the reason in the run's detail."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from robocal.drivers.lifecycle import MOVING
from tests.backends import replace_sqlite_file
from tests.server.api.conftest import free_port, wait_for
from tests.server.api.test_real_devices import cell_json, devices, finished  # noqa: F401 - a fixture
from tests.server.api.test_sigterm import Wire, start_service
from tests.server.store.test_sharing import other_process_opens_and_closes, shared_locks

ROOT = Path(__file__).resolve().parents[3]
# Simulated devices on the virtual clock: a campaign takes seconds of wall time.
QUICK = {"poses": 30, "pause_s": 0.0, "samples": 20}
# The campaign the service writes while the other process runs: long enough to overlap it.
SECOND = 200
# The cell's devices on the wall clock: poses slow enough to delete the file mid-campaign.
LIVE = {"poses": 30, "pause_s": 0.1, "samples": 20, "seed": 2}


def client(port, token) -> httpx.Client:
    return httpx.Client(
        base_url=f"http://127.0.0.1:{port}",
        headers={"Authorization": f"Bearer {token}"},
        timeout=60,
    )


def started_campaign(c, name: str, seed: int, poses: int = QUICK["poses"]) -> int:
    """A simulated campaign created and started through the API; its id."""
    r = c.post("/api/campaigns", json={"name": name, "seed": seed, **QUICK, "poses": poses})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    r = c.post(f"/api/campaigns/{cid}/start")
    assert r.status_code == 202, r.text
    return cid


def done(c, cid: int) -> int:
    """The campaign, once its run has ended done; its id."""
    last = finished(c, cid, timeout=180)
    assert last["status"] == "done", last
    return cid


def done_campaign(c, name: str, seed: int) -> int:
    """A simulated campaign created, started and done through the API; its id."""
    return done(c, started_campaign(c, name, seed))


def ended(campaign: dict) -> bool:
    """The campaign's run has ended and stored its last state."""
    run = campaign["run"]
    return run is not None and not run["active"] and campaign["status"] not in MOVING


def readings(c, cid) -> list[dict]:
    """Every reading of the campaign as the API answers it."""
    r = c.get(f"/api/campaigns/{cid}/measurements", params={"limit": 10_000})
    assert r.status_code == 200, r.text
    assert len(r.json()) == int(r.headers["X-Total-Count"]) > 0
    return r.json()


def kill_dash_nine(proc) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)


def stop(proc) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            kill_dash_nine(proc)


def nothing_lost(tmp_path, token, acknowledged: dict[int, list[dict]]) -> None:
    """After a kill -9, a new service on the file answers every acknowledged reading."""
    port = free_port()
    proc, again, out = start_service(tmp_path, port)
    assert again is None  # the same service's data folder: its token stands
    try:
        with client(port, token) as c:
            for cid, rows in acknowledged.items():
                assert c.get(f"/api/campaigns/{cid}").json()["status"] == "done", "".join(out)
                assert readings(c, cid) == rows, f"campaign {cid}: readings differ"
    finally:
        stop(proc)


# The command lines run beside the service on its file: a reader, and a writer of its own.
COMMANDS = {
    "calibrate": ["calibrate", "{db}", "--campaign", "{first}", "--out", "model.json"],
    "acquire": ["acquire", "--db", "{db}", "--name", "cli", "--poses", "30", "--seed", "5"],
}


@pytest.mark.parametrize("beside", ["calibrate", "acquire", "second service"])
def test_another_process_beside_the_service_loses_nothing(tmp_path, beside):
    """Serve, run a campaign; while the service writes a second one, `robocal calibrate DB
    --campaign 1` (or `robocal acquire --db DB`, or a second service on the same file, started
    and stopped); the service keeps its lock and log, its second and third campaigns complete;
    kill -9 and restart: every reading the API answered is there."""
    db = tmp_path / "s.db"
    port = free_port()
    proc, token, out = start_service(tmp_path, port)
    assert token
    try:
        with client(port, token) as c:
            first = done_campaign(c, "first", seed=1)
            # a campaign start opened the store again in the service: its lock must survive it
            assert shared_locks(proc.pid, db), "the service lost its SHARED lock on the file"
            second = started_campaign(c, "second", seed=2, poses=SECOND)  # written meanwhile
            own = []  # the campaigns the other process wrote itself
            if beside in COMMANDS:
                r = subprocess.run(
                    [sys.executable, "-m", "robocal.server.cli"]
                    + [a.format(db=db, first=first) for a in COMMANDS[beside]],
                    cwd=tmp_path,
                    capture_output=True,
                    text=True,
                    timeout=300,
                )
                assert r.returncode == 0, r.stderr
                own = [x["id"] for x in c.get("/api/campaigns").json() if x["name"] == "cli"]
            else:
                port2 = free_port()
                proc2, again, _ = start_service(tmp_path, port2)
                assert again is None
                try:
                    with client(port2, token) as c2:
                        seen = c2.get(f"/api/campaigns/{first}").json()
                        assert seen["status"] == "done", seen
                        assert readings(c2, first) == readings(c, first)
                finally:
                    stop(proc2)
            meanwhile = c.get(f"/api/campaigns/{second}").json()
            print(
                f"\n{beside} done with the second campaign {meanwhile['status']} at pose "
                f"{meanwhile['poses_done']} of {SECOND}"
            )
            # the other process closed the file last but one: the service's log stays
            assert Path(f"{db}-wal").exists(), "the service's write-ahead log was deleted"
            assert shared_locks(proc.pid, db)
            done(c, second)
            third = done_campaign(c, "third", seed=3)
            acknowledged = {cid: readings(c, cid) for cid in (first, second, third, *own)}
            assert len(own) == (beside == "acquire") and len(acknowledged) == 3 + len(own)
    except BaseException:
        kill_dash_nine(proc)
        print("".join(out))
        raise
    kill_dash_nine(proc)
    nothing_lost(tmp_path, token, acknowledged)


def test_a_reader_closing_the_file_leaves_the_service_its_log(tmp_path):
    """After campaign starts, a plain sqlite3 reader's open and close in its own process neither
    deletes the log nor stops the service writing (old code: the log went, writes failed)."""
    db = tmp_path / "s.db"
    port = free_port()
    proc, token, out = start_service(tmp_path, port)
    try:
        with client(port, token) as c:
            first = done_campaign(c, "first", seed=1)
            assert shared_locks(proc.pid, db)
            other_process_opens_and_closes(db)
            assert Path(f"{db}-wal").exists(), "the service's write-ahead log was deleted"
            second = done_campaign(c, "second", seed=2)
            assert len(readings(c, second)) == len(readings(c, first))
    finally:
        stop(proc)


@pytest.mark.parametrize("fault", ["deleted", "replaced"])
def test_a_database_file_gone_mid_campaign_stops_it_within_a_pose(tmp_path, devices, fault):
    """The file deleted (as `rm s.db*` does) or replaced under a running campaign on a real
    cell: at most one more move, then STOP on the wire, the campaign failed with the reason in
    the API's answer; a new start is refused (503) with it."""
    db = tmp_path / "s.db"
    port = free_port()
    proc, token, out = start_service(tmp_path, port)
    wire = Wire(devices.controller)
    try:
        with client(port, token) as c:
            cell = c.post("/api/cells", json=cell_json(devices))
            assert cell.is_success, cell.text
            r = c.post(
                "/api/campaigns", json={"name": "live", "cell_id": cell.json()["id"], **LIVE}
            )
            assert r.status_code == 201, r.text
            cid = r.json()["id"]
            assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
            wait_for(
                lambda: c.get(f"/api/campaigns/{cid}").json(),
                lambda j: j["poses_done"] >= 2 or j["status"] not in ("planned", "running"),
                interval=0.02,
            )
            if fault == "deleted":
                for suffix in ("", "-wal", "-shm"):
                    Path(f"{db}{suffix}").unlink()
            else:
                replace_sqlite_file(db)
            gone_at = time.monotonic()
            # polled with the service's connections to a file that is gone: a new one it opens
            # finds an empty file there, and that read may fail; the next is read again
            end = wait_for(
                lambda: c.get(f"/api/campaigns/{cid}"),
                lambda r: r.status_code == 200 and ended(r.json()),
                interval=0.05,
            ).json()
            moves_after = [t for t, line in wire.lines if " MOVEJ" in line and t > gone_at]
            stop_at = wire.first("STOP", after=gone_at)
            assert end["status"] == "failed", end
            assert end["poses_done"] < LIVE["poses"], "the campaign ended before the fault"
            detail = end["run"]["detail"]
            assert f"{db}: the database file was deleted" in detail, detail
            assert fault == "deleted" or "or replaced" in detail, detail
            assert "the arm halted" in detail, detail
            assert len(moves_after) <= 1, f"{len(moves_after)} moves after the file went"
            # nor did a new connection make an empty database where the file was
            assert fault == "replaced" or not db.exists()
            assert stop_at is not None, "no STOP reached the controller"
            assert all(t < stop_at for t in moves_after)
            # the service's own log says it too (read from its output on another thread)
            wait_for(lambda: any(detail in line for line in out), bool, timeout=30)
            again = c.post(f"/api/campaigns/{cid}/resume")
            assert again.status_code == 503, again.text
            assert "the database file was deleted" in again.json()["detail"], again.text
    except BaseException:
        print("".join(out))
        raise
    finally:
        stop(proc)
