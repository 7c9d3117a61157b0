"""Faults of the disk are the service's, not the user's: a store that cannot write answers 503
with the reason, a campaign whose reading cannot be stored stops the arm, its campaigns still
show (reads never write), and once the disk is fixed the campaign resumes with every reading
stored once. Faults injected at the driver (both backends), then a real full tmpfs and a real
read-only ext4 (root only; skipped with the reason where mounting is not permitted)."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine, event

from robocal.server import store
from tests.backends import execute
from tests.server.api.conftest import free_port, serve, settings_for, wait_for
from tests.server.api.test_real_devices import RUN, cell_json, devices, finished  # noqa: F401
from tests.server.api.test_sigterm import ROOT

PROBLEM = "application/problem+json"
TARGETS = 3  # the default cell's SMRs


class WriteFault:
    """While armed, every statement that writes fails as the driver fails on a full or
    read-only disk (or the OS under it)."""

    def __init__(self, kind: str):
        self.kind, self.armed = kind, threading.Event()

    def __enter__(self) -> WriteFault:
        event.listen(Engine, "before_cursor_execute", self._check)
        return self

    def __exit__(self, *exc) -> None:
        event.remove(Engine, "before_cursor_execute", self._check)

    def _check(self, conn, cursor, statement, parameters, context, executemany):
        words = statement.split(None, 1)
        if self.armed.is_set() and words and words[0].upper() in ("INSERT", "UPDATE", "DELETE"):
            raise self.error(conn.dialect.name)
        return statement, parameters

    def error(self, dialect: str) -> Exception:
        if self.kind == "oserror":
            return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        if dialect == "postgresql":
            import psycopg.errors

            if self.kind == "full":
                return psycopg.errors.DiskFull("could not extend file: No space left on device")
            return psycopg.errors.ReadOnlySqlTransaction("cannot execute INSERT in a read-only")
        return sqlite3.OperationalError(
            "database or disk is full" if self.kind == "full" else self.kind
        )


def on_measure(devices, pose: int, action) -> list[str]:
    """Call action() once, as the tracker measures the pose'th move's (1-based) second SMR,
    before it answers: the reading is taken, then the service must store it. The engine picks a
    pose's order of SMRs (its farthest first): the list returned fills with that pose's SMRs in
    the order measured, the first of them stored before the fault."""
    device = devices.tracker_server.device
    real, done = device.measure, threading.Event()
    order: list[str] = []

    def measure(*args):
        moves = len(devices.controller.moves)
        target = device.locked_target
        if not done.is_set() and moves == pose and target is not None:
            if target not in order:
                order.append(target)
            if len(order) == 2:
                done.set()
                action()
        return real(*args)

    device.measure = measure
    return order


def controller_lines(devices) -> list[str]:
    """The commands the controller received, in order (STOP, MOVEJ, ...)."""
    return [line.split()[1] for line in list(devices.controller.received) if len(line.split()) > 1]


def stopped_after_fault(lines: list[str]) -> None:
    """A STOP came after the last MOVEJ: the arm was halted and nothing moved it again."""
    assert "STOP" in lines, lines
    last_move = max(i for i, c in enumerate(lines) if c == "MOVEJ")
    assert lines.index("STOP", last_move) > last_move, lines[last_move:]


def readings(database: str, cid: int) -> list[tuple]:
    """(pose, target, x, time_s) of every stored reading, in (pose, target) order."""
    return execute(
        database,
        "select pose_index, target, x, time_s from reading where campaign_id = :cid "
        "order by pose_index, target",
        cid=cid,
    )


def complete_once(database: str, cid: int, poses: int) -> None:
    """Every pose closed, every target of every pose stored exactly once."""
    rows = readings(database, cid)
    keys = [(p, t) for p, t, *_ in rows]
    assert len(keys) == len(set(keys)), "a reading stored twice"
    assert sorted(keys) == [(p, t) for p in range(poses) for t in "ABC"]
    outcomes = execute(database, "select count(*) from pose_outcome where campaign_id = :c", c=cid)
    assert outcomes[0][0] == poses


def refused_503(r: httpx.Response, reason: str) -> None:
    assert r.status_code == 503, r.text
    assert r.headers["content-type"] == PROBLEM and int(r.headers["retry-after"]) > 0
    assert reason in r.json()["reason"] and reason in r.json()["detail"], r.text


def start_campaign(c, devices, name: str) -> tuple[int, str]:
    """(campaign, cell): a campaign on the devices' cell, started."""
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    r = c.post("/api/campaigns", json={"name": name, "cell_id": cell_id, **RUN})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    return cid, cell_id


def fault_then_resume(
    c, devices, database: str, *, fault, fix, reason: str, files: bool = False
) -> None:
    """Run a campaign; the disk fails as pose 3's second SMR is measured: the run stops the arm
    and fails saying why, reads work, actions answer 503; once fixed, resume completes it with
    every reading stored once and pose 3's first SMR not measured again."""
    failed_at: list[float] = []

    def fail():
        failed_at.append(time.monotonic())
        fault()

    order = on_measure(devices, 3, fail)
    cid, cell_id = start_campaign(c, devices, "disk")
    shown = finished(c, cid)
    stop_at = devices.controller.first_arrival("STOP", since=failed_at[0])
    assert stop_at is not None, "no STOP reached the controller after the fault"
    # a figure, not a bound: the disk failed as the reading was taken, then it was stored
    print(json.dumps({"disk_fault_to_stop_on_the_wire_ms": round(1000 * (stop_at - failed_at[0]))}))
    assert shown["status"] == "failed" and shown["actions"] == ["resume", "abort", "reset"]
    assert reason in shown["run"]["detail"], shown["run"]
    stopped_after_fault(controller_lines(devices))
    moves = len(devices.controller.moves)
    before = readings(database, cid)
    # cut off mid-pose: its first SMR stored, the second measured as the disk failed
    assert [(p, t) for p, t, *_ in before if p == 2] == [(2, order[0])], (order, before)
    # reads work and never write; actions and new campaigns answer 503 with the reason
    assert c.get(f"/api/campaigns/{cid}").status_code == 200
    assert c.get("/api/campaigns").status_code == 200
    assert c.get(f"/api/campaigns/{cid}/measurements").status_code == 200
    refused_503(c.post(f"/api/campaigns/{cid}/resume"), reason)
    refused_503(c.post("/api/campaigns", json={"cell_id": cell_id, **RUN}), reason)
    if files:  # the data dir on the same disk: a new cell's file cannot be written either
        other = cell_json(devices)
        other["targets"]["A"][2] += 1.0
        refused_503(c.post("/api/cells", json=other), reason)
    assert len(devices.controller.moves) == moves  # nothing moved the arm meanwhile
    fix()
    assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202
    done = wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["status"] == "done",
        timeout=90,
        interval=0.05,
    )
    assert done["poses_done"] == RUN["poses"]
    complete_once(database, cid, RUN["poses"])
    after = readings(database, cid)
    assert [r for r in after if r[:2] in {x[:2] for x in before}] == before  # kept, not redone


# The driver's full disk and the OS's (a campaign each per backend); the other faults' words
# are tests/server/store/test_unavailable.py's, a real read-only disk is the last test here.
@pytest.mark.parametrize("kind", ["full", "oserror"])
def test_write_fault_mid_campaign_stops_the_arm_and_resume_loses_nothing(live, devices, kind):
    with WriteFault(kind) as fault:
        fault_then_resume(
            live.client,
            devices,
            live.settings.database,
            fault=fault.armed.set,
            fix=fault.armed.clear,
            reason="full",
        )


def test_an_estop_the_store_cannot_take_stays_an_estop(live, devices):
    """E-stopped while the store cannot write: the arm stops (the STOP needs no store), the
    campaign shows estopped, not the paused the store still holds, and once the store writes
    again it must be reset before it resumes, as after any e-stop."""
    c, database = live.client, live.settings.database
    cid, _ = start_campaign(c, devices, "estop")
    wait_for(lambda: len(devices.controller.moves), lambda n: n >= 2, timeout=60, interval=0.02)
    assert c.post(f"/api/campaigns/{cid}/pause").status_code == 200
    # paused in the store itself (the API shows the engine's state before the store has it)
    wait_for(
        lambda: execute(database, "select status from campaign where id = :c", c=cid),
        lambda rows: rows == [("paused",)],
        timeout=60,
    )
    with WriteFault("full") as fault:
        fault.armed.set()
        r = c.post(f"/api/campaigns/{cid}/estop")
        assert r.status_code == 200 and r.json()["confirmed"] is True, r.text
        shown = finished(c, cid)
        assert shown["status"] == "estopped" and "resume" not in shown["actions"], shown
        stopped_after_fault(controller_lines(devices))
        stored = execute(database, "select status from campaign where id = :c", c=cid)
        assert stored == [("paused",)]  # the store could not take the e-stop
        refused_503(c.post(f"/api/campaigns/{cid}/resume"), "full")
        fault.armed.clear()
    r = c.post(f"/api/campaigns/{cid}/resume")
    assert r.status_code == 409 and r.json()["state"] == "estopped", r.text
    assert c.post(f"/api/campaigns/{cid}/reset").status_code == 200
    assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json()["status"], lambda s: s == "done", timeout=90
    )
    complete_once(database, cid, RUN["poses"])


def test_reads_never_write_an_orphan_shows_failed_and_its_action_stores_it(live, devices):
    """A campaign left running by a process that is gone shows failed on a store that cannot
    write (its reads take no lease); resuming it answers 503 until the store writes again."""
    c, database = live.client, live.settings.database
    cell_id = c.post("/api/cells", json=cell_json(devices)).json()["id"]
    cid = c.post("/api/campaigns", json={"name": "orphan", "cell_id": cell_id, **RUN}).json()["id"]
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    dead = f"{socket.gethostname()}:{gone.pid}:deadbeef"
    with store.open_database(database) as db:
        store.take_lease(db, campaign_id=cid, owner=dead, ttl_s=600)
        store.set_status(db, campaign_id=cid, status="running")
    with WriteFault("attempt to write a readonly database") as fault:
        fault.armed.set()
        for _ in range(2):  # and again: the first read wrote nothing
            r = c.get(f"/api/campaigns/{cid}")
            assert r.status_code == 200, r.text
            assert r.json()["status"] == "failed", r.json()
            assert r.json()["actions"] == ["resume", "abort", "reset"]
        listed = c.get("/api/campaigns", params={"status": "failed"})
        assert [j["id"] for j in listed.json()] == [cid], listed.text
        assert c.get("/api/campaigns", params={"status": "running"}).json() == []
        refused_503(c.post(f"/api/campaigns/{cid}/resume"), "read-only")
        stored = execute(database, "select status, lease_owner from campaign where id = :c", c=cid)
        assert stored == [("running", dead)]  # nothing was written
        fault.armed.clear()
        assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json()["status"], lambda s: s == "done", timeout=90
    )
    complete_once(database, cid, RUN["poses"])


# -- real disks ----------------------------------------------------------------------------------


def start_service(database: Path, data_dir: Path, port: int):
    """`robocal serve` in its own process; (process, token shown at its first start, output)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "robocal.server.cli", "serve", "--port", str(port)]
        + ["--db", str(database), "--data-dir", str(data_dir)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    out: list[str] = []
    for line in proc.stdout:
        out.append(line)
        if "Uvicorn running" in line:
            threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True).start()
            token = re.search(r"API token \(shown once, keep it\): (\S+)", "".join(out))
            return proc, token and token.group(1), out
    proc.wait()
    raise RuntimeError("service did not start: " + "".join(out))


def mount(*args: str) -> None:
    """Run mount(8); skip the test with its reason where this machine does not allow it."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small disk needs root")
    r = subprocess.run(["mount", *args], capture_output=True, text=True)
    if r.returncode:
        pytest.skip(f"mount {' '.join(args)} is not permitted here: {r.stderr.strip()}")


def fill(folder: Path) -> None:
    """Write a file until the disk has no space left."""
    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\0" * 65536)
    except OSError as e:
        assert e.errno == errno.ENOSPC, e
    finally:
        os.close(fd)


def test_full_tmpfs_stops_the_arm_and_resumes_once_space_returns(tmp_path, devices):
    disk = tmp_path / "disk"
    disk.mkdir()
    mount("-t", "tmpfs", "-o", "size=16m", "tmpfs", str(disk))
    try:
        database = str(disk / "robocal.db")
        settings = settings_for(tmp_path, database).model_copy(update={"data_dir": disk / "data"})
        running = serve(settings)
        live = next(running)
        try:
            fault_then_resume(
                live.client,
                devices,
                database,
                fault=lambda: fill(disk),
                fix=lambda: (disk / "filler").unlink(),
                reason="full",
                files=True,
            )
        finally:
            running.close()
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


def test_read_only_disk_stops_the_arm_reads_work_and_resume_after_repair(tmp_path, devices):
    """The kernel makes the store's ext4 read-only under the service (errors=remount-ro, as a
    failing disk does): the arm stops, the campaign shows, resume is 503; after the disk is
    repaired and the service started again, resume completes it with nothing lost."""
    for tool in ("mkfs.ext4", "e2fsck"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    image, disk = tmp_path / "disk.img", tmp_path / "disk"
    disk.mkdir()
    with open(image, "wb") as f:
        f.truncate(64 << 20)
    subprocess.run(["mkfs.ext4", "-q", "-F", str(image)], check=True)
    mount("-o", "loop,errors=remount-ro", str(image), str(disk))
    port, proc = free_port(), None
    try:
        database = disk / "s.db"
        proc, token, out = start_service(database, tmp_path / "data", port)
        device = next(
            Path(line.split()[0]).name
            for line in Path("/proc/mounts").read_text().splitlines()
            if line.split()[1] == str(disk)
        )
        trigger = Path(f"/sys/fs/ext4/{device}/trigger_fs_error")
        if not trigger.exists():
            pytest.skip(f"{trigger} is missing: this kernel cannot fail an ext4 on demand")
        headers = {"Authorization": f"Bearer {token}"}
        url = f"http://127.0.0.1:{port}"
        with httpx.Client(base_url=url, headers=headers, timeout=30) as c:
            # No os.sync() first: every commit the store acknowledged must already be on the
            # disk (synchronous=FULL) when the kernel fails it, as at a power cut.
            failed_at: list[float] = []

            def fail_disk():
                trigger.write_text("robocal test: disk fails\n")
                failed_at.append(time.monotonic())

            on_measure(devices, 3, fail_disk)
            cid, _ = start_campaign(c, devices, "ro")
            shown = finished(c, cid)
            assert shown["status"] == "failed", shown
            detail = shown["run"]["detail"]
            assert "read-only" in detail or "I/O error" in detail, detail
            stopped_after_fault(controller_lines(devices))
            stop_at = devices.controller.first_arrival("STOP", since=failed_at[0])
            assert stop_at is not None, "no STOP reached the controller after the fault"
            print(
                json.dumps(
                    {"read_only_to_stop_on_the_wire_ms": round(1000 * (stop_at - failed_at[0]))}
                )
            )
            assert c.get(f"/api/campaigns/{cid}").status_code == 200  # reads work
            r = c.post(f"/api/campaigns/{cid}/resume")
            assert r.status_code == 503 and r.headers["content-type"] == PROBLEM, r.text
            assert "read-only" in r.json()["reason"] or "I/O" in r.json()["reason"], r.text
        proc.terminate()
        proc.wait(timeout=30)
        con = sqlite3.connect(f"file:{database}?mode=ro", uri=True)
        try:
            before = con.execute(
                "select pose_index, target, x, time_s from reading order by pose_index, target"
            ).fetchall()
        finally:
            con.close()
        # the repair: unmount, check, mount again, start the service again
        subprocess.run(["umount", str(disk)], check=True)
        subprocess.run(["e2fsck", "-fy", str(image)], capture_output=True, check=False)
        mount("-o", "loop,errors=remount-ro", str(image), str(disk))
        proc, _, out = start_service(database, tmp_path / "data", port)
        with httpx.Client(base_url=url, headers=headers, timeout=30) as c:
            assert c.get(f"/api/campaigns/{cid}").json()["status"] == "failed"
            assert c.post(f"/api/campaigns/{cid}/resume").status_code == 202, "".join(out)
            wait_for(
                lambda: c.get(f"/api/campaigns/{cid}").json()["status"],
                lambda s: s == "done",
                timeout=90,
            )
        complete_once(str(database), cid, RUN["poses"])
        after = readings(str(database), cid)
        assert [r for r in after if r[:2] in {x[:2] for x in before}] == [tuple(r) for r in before]
    finally:
        if proc is not None and proc.poll() is None:
            proc.terminate()
            proc.wait(timeout=30)
        subprocess.run(["umount", "-l", str(disk)], check=False)
