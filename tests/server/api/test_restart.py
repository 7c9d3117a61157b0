"""Kill -9 the service mid-campaign, start it again, resume: nothing lost or duplicated."""

import re
import signal
import sqlite3
import subprocess
import sys
import time

import httpx

from tests.server.api.conftest import free_port


def start(tmp_path, port):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "serve",
            "--port",
            str(port),
            "--db",
            str(tmp_path / "s.db"),
            "--data-dir",
            str(tmp_path / "data"),
        ],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    token, deadline = None, time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        m = re.search(r"API token \(shown once, keep it\): (\S+)", line)
        token = token or (m.group(1) if m else None)
        if "Uvicorn running" in line:
            return proc, token
    raise RuntimeError("service did not start")


def started(url, auth, body: dict, poses_done: int) -> int:
    """A campaign of this body started, once it has `poses_done` poses measured; its id."""
    with httpx.Client(headers=auth, timeout=30) as c:
        cid = c.post(f"{url}/campaigns", json=body).json()["id"]
        assert c.post(f"{url}/campaigns/{cid}/start").status_code == 202
        deadline = time.monotonic() + 120
        while c.get(f"{url}/campaigns/{cid}").json()["poses_done"] < poses_done:
            assert time.monotonic() < deadline
            time.sleep(0.05)
    return cid


def test_kill_dash_nine_mid_campaign_then_resume(tmp_path):
    port = free_port()
    proc, token = start(tmp_path, port)
    assert token
    url = f"http://127.0.0.1:{port}/api"
    auth = {"Authorization": f"Bearer {token}"}
    cid = started(url, auth, {"poses": 150, "seed": 3, "name": "k"}, 20)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc2, again = start(tmp_path, port)
    assert again is None  # the token is shown once, at the very first start
    try:
        with httpx.Client(headers=auth, timeout=30) as c:
            left = c.get(f"{url}/campaigns/{cid}").json()
            # the killed process is gone: its running campaign is failed, resumable
            assert 20 <= left["poses_done"] < 150 and left["status"] == "failed", left
            assert left["actions"] == ["resume", "abort", "reset"]
            assert c.post(f"{url}/campaigns/{cid}/resume").status_code == 202
            deadline = time.monotonic() + 300
            while c.get(f"{url}/campaigns/{cid}").json()["status"] != "done":
                assert time.monotonic() < deadline
                time.sleep(0.1)
    finally:
        proc2.send_signal(signal.SIGTERM)
        proc2.wait(timeout=30)
    con = sqlite3.connect(tmp_path / "s.db")
    rows = con.execute("select count(*) from reading").fetchone()[0]
    dup = con.execute(
        "select count(*) from (select count(*) c from reading group by campaign_id, "
        "pose_index, target having c > 1)"
    ).fetchone()[0]
    outcomes = con.execute("select count(*) from pose_outcome").fetchone()[0]
    con.close()
    assert (rows, dup, outcomes) == (450, 0, 150)
