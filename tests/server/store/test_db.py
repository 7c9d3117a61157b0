"""Opening the store: migrations make the schema, pragmas on every connection, commits shared."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import inspect, text

from robocal.server.store import open_database, record_reading
from robocal.server.store.db import alembic_config, database_url
from robocal.server.store.models import Base
from tests.server.store.conftest import POSES_DEG

ROOT = Path(__file__).resolve().parents[3]
TABLES = {
    "alembic_version",
    "campaign",
    "planned_pose",
    "reading",
    "pose_outcome",
    "job",
    "model_check",
}


@pytest.mark.sqlite_only
def test_migrations_create_the_schema(tmp_path):
    db = open_database(tmp_path / "deep" / "er" / "store.db")  # the folder is created
    insp = inspect(db.engine)
    assert set(insp.get_table_names()) == TABLES
    columns = {c["name"] for c in insp.get_columns("reading")}
    assert {
        "campaign_id",
        "pose_index",
        "target",
        "x",
        "y",
        "z",
        "std_x",
        "std_y",
        "std_z",
        "samples",
        "time_s",
        "temp_c",
        "pressure_hpa",
        "humidity_pct",
        "status",
    } <= columns
    uniques = {tuple(u["column_names"]) for u in insp.get_unique_constraints("reading")}
    assert ("campaign_id", "pose_index", "target") in uniques
    with db.engine.connect() as c:
        assert c.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0012"
        # The migration and the models describe the same schema.
        assert (
            compare_metadata(
                MigrationContext.configure(c, opts={"compare_type": True}), Base.metadata
            )
            == []
        )
    db.close()


def test_the_migrated_schema_is_the_models(store_url):
    """On each backend, head's tables, types and constraints are what the models declare."""
    with open_database(store_url) as db, db.engine.connect() as c:
        context = MigrationContext.configure(c, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
        assert c.execute(text("SELECT count(*) FROM alembic_version")).scalar() == 1


@pytest.mark.sqlite_only
def test_reopening_keeps_data_and_migrates_once(tmp_path, running, db):
    record_reading(db, campaign_id=running, pose_index=0, target="A", xyz=[1, 2, 3])
    again = open_database(db.engine.url.database)
    with again.engine.connect() as c:
        assert c.execute(text("SELECT count(*) FROM reading")).scalar() == 1
        assert c.execute(text("SELECT count(*) FROM alembic_version")).scalar() == 1
    again.close()


@pytest.mark.sqlite_only
def test_pragmas_on_every_connection(db):
    a, b = db.engine.raw_connection(), db.engine.raw_connection()  # two pooled connections
    try:
        for conn in (a, b):
            cur = conn.cursor()
            assert cur.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
            assert cur.execute("PRAGMA foreign_keys").fetchone()[0] == 1
            assert cur.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
            assert cur.execute("PRAGMA busy_timeout").fetchone()[0] > 0
    finally:
        a.close()
        b.close()


@pytest.mark.sqlite_only
def test_a_commit_is_visible_to_an_independent_connection(running, db):
    """What crash safety rests on: once record_reading returns, the row is in the file."""
    other = open_database(db.engine.url.database)
    raw = sqlite3.connect(db.engine.url.database)
    try:
        record_reading(db, campaign_id=running, pose_index=0, target="B", xyz=[4.0, 5.0, 6.0])
        with other.session() as s:
            assert s.execute(text("SELECT x, y, z FROM reading")).one() == (4.0, 5.0, 6.0)
        assert raw.execute("SELECT target FROM reading").fetchall() == [("B",)]
    finally:
        raw.close()
        other.close()


@pytest.mark.sqlite_only
def test_readers_are_not_blocked_by_an_open_write(running, db):
    other = open_database(db.engine.url.database)
    try:
        with db.session(write=True) as s:
            s.execute(text("UPDATE campaign SET notes = 'uncommitted'"))
            with other.session() as r:  # WAL: the reader sees the last commit, at once
                assert r.execute(text("SELECT notes FROM campaign")).scalar() == ""
        with other.session() as r:
            assert r.execute(text("SELECT notes FROM campaign")).scalar() == "uncommitted"
    finally:
        other.close()


def test_urls_and_paths(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert database_url("rel.db").database == str(tmp_path / "rel.db")
    url = f"sqlite:///{tmp_path / 'by-url.db'}"
    assert str(database_url(url)) == url
    open_database(url).close()
    assert (tmp_path / "by-url.db").exists()
    with pytest.raises(ValueError, match="in-memory"):
        open_database("sqlite://")


def test_migrations_in_code_down_and_up(store_url):
    path = store_url
    config = alembic_config(path)
    command.upgrade(config, "head")  # env.py's own engine, no alembic.ini
    command.downgrade(config, "base")
    assert set(inspect(open_database(path).engine).get_table_names()) == TABLES


@pytest.mark.sqlite_only
def test_alembic_command_line_with_database_url(tmp_path):
    path = tmp_path / "cli.db"
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{path}")
    done = subprocess.run(
        [sys.executable, "-m", "alembic", "upgrade", "head"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    con = sqlite3.connect(path)
    assert con.execute("SELECT version_num FROM alembic_version").fetchone() == ("0012",)
    assert con.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    con.close()


def test_two_writers_wait_for_each_other(store_url, cell_json):
    """Write transactions take the lock up front, so a second writer waits instead of failing."""
    from concurrent.futures import ThreadPoolExecutor

    from robocal.server.store import create_campaign, set_status

    path = store_url
    with open_database(path) as db:
        cids = [
            create_campaign(db, name=f"c{i}", cell_json=cell_json, poses_deg=POSES_DEG)
            for i in range(2)
        ]
        for cid in cids:
            set_status(db, campaign_id=cid, status="running")

    def write(cid):
        with open_database(path) as db:  # its own engine, as another process would have
            for i in range(len(POSES_DEG)):
                for t in ("A", "B", "C"):
                    record_reading(db, campaign_id=cid, pose_index=i, target=t, xyz=[i, cid, 0])
        return cid

    with ThreadPoolExecutor(2) as pool:
        assert sorted(pool.map(write, cids)) == cids
    with open_database(path) as db, db.engine.connect() as c:
        assert c.execute(text("SELECT count(*) FROM reading")).scalar() == 18


def test_opening_a_new_store_from_many_places_at_once(store_url):
    """Threads and processes that open a new store together: one migrates, the others wait."""
    from concurrent.futures import ThreadPoolExecutor

    path = store_url
    code = "import sys; from robocal.server.store import open_database; open_database(sys.argv[1])"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code, str(path)],
            cwd=ROOT,
            env=env,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(3)
    ]

    def version(_):
        with open_database(path) as db, db.engine.connect() as c:
            return c.execute(text("SELECT version_num FROM alembic_version")).all()

    with ThreadPoolExecutor(4) as pool:
        assert list(pool.map(version, range(4))) == [[("0012",)]] * 4
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err


@pytest.mark.sqlite_only
def test_migration_0003_widens_the_status_and_keeps_campaigns(tmp_path):
    """A 0002 store keeps its campaigns through 0003 and back (in-between states mapped)."""
    path = tmp_path / "old.db"
    config = alembic_config(path)
    command.upgrade(config, "0002")
    con = sqlite3.connect(path)
    con.execute(
        "INSERT INTO campaign (id, name, created_at, status, cell_json, settings_json, "
        "simulated, notes) VALUES (1, 'a', '2026-01-01 00:00:00', 'paused', '{}', '{}', "
        "0, '')"
    )
    con.commit()
    with pytest.raises(sqlite3.IntegrityError):
        con.execute("UPDATE campaign SET status = 'estopped'")
    con.close()
    command.upgrade(config, "head")
    con = sqlite3.connect(path)
    assert con.execute("SELECT status, lease_owner FROM campaign").fetchall() == [("paused", None)]
    con.execute("UPDATE campaign SET status = 'estopped'")  # allowed now
    con.commit()
    con.close()
    command.downgrade(config, "0002")
    con = sqlite3.connect(path)
    assert con.execute("SELECT status FROM campaign").fetchall() == [("paused",)]
    con.close()


@pytest.mark.sqlite_only
def test_migration_0004_adds_planning_jobs_and_keeps_jobs(tmp_path):
    """A 0003 store keeps its jobs through 0004 (planning jobs, no campaign until planned) and
    back (the planning jobs dropped, the others kept)."""
    path = tmp_path / "old.db"
    config = alembic_config(path)
    command.upgrade(config, "0003")
    con = sqlite3.connect(path)
    con.execute(
        "INSERT INTO campaign (id, name, created_at, status, cell_json, settings_json, "
        "simulated, notes) VALUES (1, 'a', '2026-01-01 00:00:00', 'done', '{}', '{}', "
        "0, '')"
    )
    job = (
        "INSERT INTO job (kind, campaign_id, method, state, progress, created_at, results) "
        "VALUES (?, ?, 'm', 'done', 1.0, '2026-01-01 00:00:00', '{}')"
    )
    con.execute(job, ("diagnosis", 1))
    con.commit()
    for kind, campaign in (("planning", None), ("diagnosis", None)):
        with pytest.raises(sqlite3.IntegrityError):
            con.execute(job, (kind, campaign))
    con.close()
    command.upgrade(config, "head")
    con = sqlite3.connect(path)
    con.execute(job, ("planning", None))  # allowed now
    con.commit()
    with pytest.raises(sqlite3.IntegrityError):
        con.execute(job, ("survey", 1))
    assert con.execute("SELECT kind, campaign_id FROM job ORDER BY id").fetchall() == [
        ("diagnosis", 1),
        ("planning", None),
    ]
    con.close()
    command.downgrade(config, "0003")
    con = sqlite3.connect(path)
    assert con.execute("SELECT kind, campaign_id FROM job").fetchall() == [("diagnosis", 1)]
    con.close()


@pytest.mark.sqlite_only
def test_a_planning_job_has_no_campaign_until_it_planned_one(tmp_path, cell_json):
    from robocal.server import store

    db = open_database(tmp_path / "store.db")
    job = store.create_job(db, kind="planning", campaign_id=None, method="20 of 2000")
    assert (job.kind, job.campaign_id, job.state) == ("planning", None, "queued")
    with pytest.raises(ValueError, match="planning job has no campaign"):
        store.create_job(db, kind="diagnosis", campaign_id=None, method="diagnose")
    cid = store.create_campaign(db, name="p", cell_json=cell_json, poses_deg=POSES_DEG)
    store.update_job(db, job_id=job.id, state="running")
    done = store.update_job(
        db, job_id=job.id, state="done", campaign_id=cid, results={"campaign": cid}
    )
    assert (done.campaign_id, done.results, done.progress) == (cid, {"campaign": cid}, 1.0)
    db.close()
