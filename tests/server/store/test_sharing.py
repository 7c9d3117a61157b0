"""One SQLite file, several users (issue 20): opening the store again keeps this process's locks,
a keeper connection holds them while the store is open, so no other process deletes the
write-ahead log under it; a file or log deleted or replaced under an open store is told."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from robocal.server.store import (
    DatabaseGone,
    StoreError,
    create_campaign,
    list_campaigns,
    open_database,
    set_status,
)
from tests.backends import replace_sqlite_file

from .conftest import POSES_DEG


def shared_locks(pid: int, path: Path) -> list[str]:
    """The READ (SQLite SHARED) locks process `pid` holds on the file, from /proc/locks."""
    ino = os.stat(path).st_ino
    with open("/proc/locks") as f:  # a proc file, not the database
        rows = [line.split() for line in f]
    return [
        " ".join(r)
        for r in rows
        if len(r) >= 6 and r[3] == "READ" and r[4] == str(pid) and r[5].endswith(f":{ino}")
    ]


def other_process_opens_and_closes(path: Path) -> None:
    """A plain sqlite3 reader in its own process: it opens, reads and closes the file."""
    code = (
        "import sqlite3, sys; c = sqlite3.connect(sys.argv[1]); "
        "c.execute('SELECT count(*) FROM sqlite_master').fetchall(); c.close()"
    )
    subprocess.run([sys.executable, "-c", code, str(path)], check=True, timeout=60)


def wal(path: Path) -> Path:
    return path.with_name(path.name + "-wal")


def test_opening_the_store_again_keeps_this_process_lock(tmp_path, cell_json):
    """What every campaign start did in the service: open the store a second time. The first
    keeps its SHARED lock; another process's close leaves the log; writes go on and last."""
    path = tmp_path / "s.db"
    with open_database(path) as db:
        assert shared_locks(os.getpid(), path)
        open_database(path).close()
        assert shared_locks(os.getpid(), path), "opening the store again dropped the lock"
        other_process_opens_and_closes(path)
        assert wal(path).exists(), "another process deleted the open store's log"
        cid = create_campaign(db, name="after", cell_json=cell_json, poses_deg=POSES_DEG)
        with sqlite3.connect(path) as other:  # an independent connection sees the commit
            assert other.execute("SELECT name FROM campaign WHERE id = ?", (cid,)).fetchone()
        other.close()
    with open_database(path) as db:
        assert [c.name for c in list_campaigns(db)] == ["after"]


def test_the_keeper_holds_the_lock_with_the_pool_empty(tmp_path):
    """The pool may close every connection it has; the store's keeper still holds the lock, so
    the process never looks like the file's last user while the store is open."""
    path = tmp_path / "s.db"
    with open_database(path) as db:
        db.engine.dispose()  # every pooled connection closed
        assert shared_locks(os.getpid(), path), "no connection holds the lock"
        other_process_opens_and_closes(path)
        assert wal(path).exists()
    other_process_opens_and_closes(path)  # closed: the last user checkpoints and tidies up
    assert not wal(path).exists()


@pytest.mark.parametrize(
    ("fault", "told"),
    [
        (lambda p: p.unlink(), "the database file was deleted while"),
        (replace_sqlite_file, "the database file was deleted or replaced by another file"),
        (lambda p: wal(p).unlink(), "its write-ahead log was deleted"),
    ],
    ids=["file deleted", "file replaced", "log deleted"],
)
def test_a_file_gone_under_an_open_store_is_told(tmp_path, fault, told):
    path = tmp_path / "s.db"
    with open_database(path) as db:
        db.check_file()
        fault(path)
        with pytest.raises(DatabaseGone) as e:
            db.check_file()
    assert str(e.value).startswith(f"{path}: {told}"), e.value
    assert "restart the service" in str(e.value) and isinstance(e.value, StoreError)


def test_an_open_store_checks_its_file_on_every_backend(db):
    """PostgreSQL has no file to lose: the check passes; a SQLite file in place passes too."""
    db.check_file()


def test_the_header_is_read_through_sqlite(tmp_path):
    """An empty file is a new store; text named .db is one line; neither is opened by hand."""
    (tmp_path / "empty.db").write_bytes(b"")
    with open_database(tmp_path / "empty.db") as db:
        assert list_campaigns(db) == []
    (tmp_path / "text.db").write_text("pose,q1\n1,0\n" * 100)
    with pytest.raises(StoreError, match=r"text\.db: not a SQLite database"):
        open_database(tmp_path / "text.db")


@pytest.mark.parametrize("pooled", [True, False], ids=["old connection", "new connection"])
def test_a_run_storing_into_a_replaced_file_is_told_why(tmp_path, cell_json, pooled):
    """The campaign's sink after the file was replaced: whether its write still reaches the old
    file (a pooled connection) or a new connection's (what is at the path now, read through the
    old log: neither file's data), DatabaseGone."""
    from types import SimpleNamespace

    from robocal.server.acquisition.acquire import StoreSink

    path = tmp_path / "s.db"
    with open_database(path) as db:
        cid = create_campaign(db, name="r", cell_json=cell_json, poses_deg=POSES_DEG)
        set_status(db, campaign_id=cid, status="running")
        sink = StoreSink(db, cid)
        m = SimpleNamespace(mean_mm=[1.0, 2.0, 3.0], std_mm=[0.01] * 3, samples=20)
        sink.reading(pose_index=0, target="A", measurement=m, time_s=0.0, weather=None)
        replace_sqlite_file(path)
        if not pooled:
            db.engine.dispose()  # the next write opens the file now at the path
        with pytest.raises(DatabaseGone, match="was deleted or replaced"):
            sink.reading(pose_index=0, target="B", measurement=m, time_s=1.0, weather=None)


def test_no_new_connection_to_whatever_is_at_the_path_now(tmp_path):
    """The pool's next new connection, after the file was deleted: DatabaseGone, and no empty
    database made where it was (a restart would have opened that as an empty store)."""
    path = tmp_path / "s.db"
    with open_database(path) as db:
        path.unlink()
        db.engine.dispose()  # the next session needs a new connection
        with pytest.raises(DatabaseGone, match="the database file was deleted"):
            list_campaigns(db)
        assert not path.exists()
