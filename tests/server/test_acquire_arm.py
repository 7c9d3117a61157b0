"""`robocal acquire --arm SERIAL`: the arm measured stored with the campaign (campaign.arm, as
the fleet view reads it); a bad serial, or a resume naming another arm, is one line naming
--arm / the arm and a non-zero exit."""

from __future__ import annotations

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions
from robocal.server.acquisition.campaigns import plan_campaign
from robocal.server.formats.cell_json import default_cell
from tests.server.test_cli import robocal

QUICK = ("--poses", 3, "--pause", 0, "--db", "a.db")


def arms(path) -> dict:
    db = store.open_database(path)
    try:
        return {c.name: (c.arm, c.status) for c in store.list_campaigns(db)}
    finally:
        db.close()


def test_acquire_stores_the_arm_and_refuses_a_bad_one(tmp_path):
    r = robocal("acquire", *QUICK, "--name", "x", "--arm", "SN-4711", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert arms(tmp_path / "a.db") == {"x": ("SN-4711", "done")}
    for bad in ("", "x" * 65, "SN\x07"):
        r = robocal("acquire", *QUICK, "--name", "z", "--arm", bad, cwd=tmp_path)
        assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
        line = r.stderr.strip().splitlines()[-1]
        assert "argument --arm" in line and ("printable" in line or "non-empty" in line), line
    assert set(arms(tmp_path / "a.db")) == {"x"}  # nothing stored


def test_a_resume_naming_another_arm_is_refused(tmp_path):
    db = store.open_database(tmp_path / "a.db")
    try:
        plan_campaign(db, cell=default_cell(), opts=AcquireOptions(poses=3, name="y", arm="SN-1"))
    finally:
        db.close()
    r = robocal("acquire", *QUICK, "--name", "y", "--arm", "SN-2", cwd=tmp_path)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "arm: campaign 1 (y) measures arm 'SN-1', not 'SN-2'" in r.stderr, r.stderr
    assert arms(tmp_path / "a.db") == {"y": ("SN-1", "planned")}
    r = robocal("acquire", *QUICK, "--name", "y", "--arm", "SN-1", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert arms(tmp_path / "a.db") == {"y": ("SN-1", "done")}
