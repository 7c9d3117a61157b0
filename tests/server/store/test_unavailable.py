"""Which errors are faults of the disk (the service's: 503) and which are not."""

import errno
import sqlite3

import psycopg.errors as pg
import pytest
from sqlalchemy import event
from sqlalchemy.exc import IntegrityError, OperationalError

from robocal.server import store
from robocal.server.store.errors import unavailable

CELL = {
    "robot": "irb2600",
    "targets": {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]},
}


def wrapped(error: Exception) -> OperationalError:
    return OperationalError("INSERT INTO reading ...", {}, error)


@pytest.mark.parametrize(
    "error, says",
    [
        (wrapped(sqlite3.OperationalError("database or disk is full")), "disk is full"),
        (wrapped(sqlite3.OperationalError("attempt to write a readonly database")), "read-only"),
        (wrapped(sqlite3.OperationalError("disk I/O error")), "I/O error"),
        (wrapped(pg.DiskFull("could not extend file")), "disk is full"),
        (wrapped(pg.ReadOnlySqlTransaction("cannot execute INSERT")), "read-only"),
        (wrapped(pg.IoError("could not write block 7")), "I/O error"),
        (OSError(errno.ENOSPC, "No space left on device"), "disk is full"),
        (OSError(errno.EROFS, "Read-only file system"), "read-only"),
        (OSError(errno.EIO, "Input/output error"), "I/O error"),
    ],
)
def test_faults_of_the_disk_say_which(error, says):
    fault = unavailable(error)
    assert isinstance(fault, store.StoreUnavailable) and says in fault.reason
    assert str(fault).startswith("the service's storage failed: ")


@pytest.mark.parametrize(
    "error",
    [
        wrapped(sqlite3.OperationalError("no such table: reading")),  # a bug, not the disk
        IntegrityError("INSERT", {}, sqlite3.IntegrityError("UNIQUE constraint failed")),
        FileNotFoundError(errno.ENOENT, "No such file or directory"),
        ValueError("bad argument"),
    ],
)
def test_other_errors_are_not_faults_of_the_disk(error):
    assert unavailable(error) is None


def test_a_store_that_cannot_write_raises_store_unavailable(tmp_path):
    """The session turns the driver's error into StoreUnavailable; reads still work."""
    with store.open_database(tmp_path / "s.db") as db:
        cid = store.create_campaign(db, name="c", cell_json=CELL, poses_deg=[[0.0] * 6])

        def full(conn, cursor, statement, *rest):
            if statement.startswith("UPDATE"):
                raise sqlite3.OperationalError("database or disk is full")

        event.listen(db.engine, "before_cursor_execute", full)
        with pytest.raises(store.StoreUnavailable, match="disk is full"):
            store.set_status(db, campaign_id=cid, status="running")
        assert store.get_campaign(db, campaign_id=cid).status == "planned"
