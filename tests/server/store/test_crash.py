"""Kill -9 mid-campaign, open again, resume: nothing lost, nothing duplicated."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
from sqlalchemy import text

from robocal.server.store import (
    campaign_measurements,
    create_campaign,
    get_campaign,
    next_unmeasured_pose,
    open_database,
)

from .crash_writer import TARGETS, beam_broken, fake_reading

ROOT = Path(__file__).resolve().parents[3]
N_POSES = 120
KILL_AFTER = 40  # readings reported committed


def writer(path, cid, delay_s, **kwargs):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tests.server.store.crash_writer",
            str(path),
            str(cid),
            str(delay_s),
        ],
        cwd=ROOT,
        env=env,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        **kwargs,
    )


def stored_readings(path) -> list[tuple]:
    con = sqlite3.connect(path)
    try:
        return con.execute(
            "SELECT pose_index, target, status, x, y, z, std_x, std_y, std_z, "
            "samples, time_s, temp_c FROM reading ORDER BY id"
        ).fetchall()
    finally:
        con.close()


def expected(pose: int, target: str) -> tuple:
    if beam_broken(pose, target):
        return (pose, target, "missing", None, None, None, None, None, None, None, None, None)
    r = fake_reading(pose, target)
    return (pose, target, "ok", *r["xyz"], *r["std"], r["samples"], r["time_s"], r["temp_c"])


def test_kill_9_mid_campaign_then_resume(tmp_path, cell_json):
    path = tmp_path / "store.db"
    q = np.zeros((N_POSES, 6))
    q[:, 0] = np.linspace(-90.0, 90.0, N_POSES)
    with open_database(path) as db:
        cid = create_campaign(db, name="killed", cell_json=cell_json, poses_deg=q)

    proc = writer(path, cid, 0.002)
    reported = []
    for line in proc.stdout:
        word, *rest = line.split()
        if word == "reading":
            reported.append((int(rest[0]), rest[1]))
            if len(reported) == KILL_AFTER:
                os.kill(proc.pid, signal.SIGKILL)
                break
    proc.wait(timeout=60)
    print(f"killed after {len(reported)} readings reported")
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    proc.stdout.close()
    proc.stderr.close()

    # Every reading reported committed is there, intact; nothing else is torn or doubled.
    rows = stored_readings(path)
    keys = [r[:2] for r in rows]
    assert len(set(keys)) == len(keys)
    assert set(reported) <= set(keys)
    assert all(row == expected(*row[:2]) for row in rows)

    with open_database(path) as db:  # opens fine after the kill: WAL replayed, schema current
        with db.session() as s:
            assert s.execute(text("PRAGMA integrity_check")).scalar() == "ok"
            assert s.execute(text("PRAGMA foreign_key_check")).all() == []
        resume = next_unmeasured_pose(db, campaign_id=cid)
        info = get_campaign(db, campaign_id=cid)
    assert resume is not None and resume == info.n_done  # killed mid-way, poses done in order
    assert info.status == "running"  # as the killed run left it

    proc = writer(path, cid, 0.0)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    lines = [line.split() for line in out.splitlines()]
    kept = [(int(w[1]), w[2]) for w in lines if w[0] == "kept"]
    assert {k for k in keys if k[0] == resume} == set(kept)  # the partial pose's readings kept
    assert all(int(w[1]) >= resume for w in lines if w[0] == "reading")
    assert lines[-1] == ["done"]

    rows = stored_readings(path)
    keys = [r[:2] for r in rows]
    assert keys == [(i, t) for i in range(N_POSES) for t in TARGETS]  # each once, in plan order
    assert rows == [expected(*k) for k in keys]
    with open_database(path) as db:
        info = get_campaign(db, campaign_id=cid)
        assert (info.status, info.n_done) == ("done", N_POSES)
        assert next_unmeasured_pose(db, campaign_id=cid) is None
        meas = campaign_measurements(db, campaign_id=cid)
    assert meas.n_poses == N_POSES
    assert meas.n_readings == 3 * N_POSES - sum(beam_broken(i, "C") for i in range(N_POSES))
