"""Opening the store (SQLite or PostgreSQL): URL, write lock, migrations to head, sessions."""

from __future__ import annotations

import os
import sqlite3
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import DBAPIError, SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from .errors import DatabaseGone, StoreError, unavailable

MIGRATIONS = Path(__file__).resolve().parents[2] / "migrations"
# How long a writer waits for another process's write lock before "database is locked".
BUSY_TIMEOUT_MS = 30_000
WRITE_OPTION = "robocal_write"
# PostgreSQL's stand-in for SQLite's write lock: a transaction-level advisory lock on this key
# (any 64-bit number no other program on the server uses; this one spells "robocal").
PG_WRITE_LOCK = 0x726F626F63616C
# Alembic keeps its running context in module globals: one migration at a time per process.
_MIGRATING = threading.Lock()


def database_url(url_or_path) -> URL:
    """A SQLAlchemy URL from a URL (`sqlite:///x.db`, `DATABASE_URL` style) or a plain file path."""
    if isinstance(url_or_path, URL):
        return url_or_path
    text = os.fspath(url_or_path)
    if "://" in text:
        return make_url(text)
    return URL.create("sqlite", database=str(Path(text).expanduser().resolve()))


def make_engine(url_or_path) -> Engine:
    """An engine whose writers lock first; SQLite connections use WAL, foreign keys, FULL sync."""
    url = database_url(url_or_path)
    if url.get_backend_name() == "postgresql":
        # pre_ping: a fleet's server restarts or drops idle connections; a service outlives that.
        engine = create_engine(url, pool_pre_ping=True)
        event.listen(engine, "begin", _postgresql_begin)
        return engine
    if url.get_backend_name() != "sqlite":
        return create_engine(url)
    if url.database in (None, "", ":memory:"):
        # Every pooled connection would get its own empty database; the store needs a file.
        raise ValueError("the store needs a database file, not an in-memory SQLite database")
    Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url)
    event.listen(engine, "connect", _sqlite_connect)
    event.listen(engine, "begin", _sqlite_begin)
    return engine


def _sqlite_connect(dbapi_connection, _record) -> None:
    # pysqlite opens transactions itself, lazily and not before SELECTs; _sqlite_begin does it.
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    # First, so that the pragmas below wait for another process's lock too.
    cursor.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
    # WAL: a commit is one append, readers never block the writer, and a killed writer leaves a
    # log that the next open replays. FULL syncs the log at every commit, so a reading once
    # acknowledged survives an OS crash, a power cut or a disk the kernel turns read-only too
    # (NORMAL, syncing at checkpoints only, lost a whole campaign that way in the disk tests);
    # about 2 ms a commit, against a pose's seconds.
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=FULL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


def _sqlite_begin(connection) -> None:
    # A writer takes the write lock up front, so its checks and inserts see no other writer in
    # between and a busy database is waited for (busy_timeout) rather than failed mid-way.
    write = connection.get_execution_options().get(WRITE_OPTION, False)
    connection.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")


def _postgresql_begin(connection) -> None:
    # The same one-writer-at-a-time as SQLite's BEGIN IMMEDIATE, across every station on the
    # server: a writer's checks and inserts see no other writer in between (READ COMMITTED reads
    # what was committed before each statement), and the lock goes with the commit or rollback.
    if connection.get_execution_options().get(WRITE_OPTION, False):
        connection.exec_driver_sql(f"SELECT pg_advisory_xact_lock({PG_WRITE_LOCK})")


def alembic_config(url_or_path=None) -> Config:
    """Alembic's configuration built in code (no alembic.ini needed), for this database if given."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    if url_or_path is not None:
        config.attributes["url"] = database_url(url_or_path)
    return config


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the database to `revision` on one of the engine's connections, in one transaction.

    The transaction holds the write lock (SQLite's file lock, PostgreSQL's advisory lock) from its
    first statement, so services starting together migrate one after the other: the first
    upgrades, the others then find the schema current and do nothing.
    """
    config = alembic_config()
    with _MIGRATING, engine.connect().execution_options(**{WRITE_OPTION: True}) as connection:
        with connection.begin():
            config.attributes["connection"] = connection
            command.upgrade(config, revision)


class Database:
    """An open store: the engine and its sessions; on a SQLite file, a connection kept open for
    the store's life and the file's identity, to tell a file deleted or replaced under it."""

    def __init__(self, engine: Engine):
        self.engine = engine
        self._sessions = sessionmaker(engine, expire_on_commit=False)
        self._keeper: sqlite3.Connection | None = None
        self._files: tuple[tuple[Path, tuple[int, int] | None], ...] = ()
        url = engine.url
        if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
            self._keep(Path(url.database).absolute())

    def _keep(self, path: Path) -> None:
        # SQLite deletes the -wal when its last connection closes if no other process holds a
        # lock on the file: the keeper's SHARED lock means this process is never that last user
        # while the store is open, whatever the pool closes. Same library as the engine's
        # (pysqlite is the sqlite3 module), so it shares the file's locks, never drops them.
        keeper = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        try:
            keeper.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
            # a read takes the lock and opens the log; in WAL mode the lock stays after it
            keeper.execute("SELECT count(*) FROM sqlite_master").fetchall()
        except BaseException:
            keeper.close()
            raise
        self._keeper = keeper
        wal = path.with_name(path.name + "-wal")
        self._files = ((path, _identity(path)), (wal, _identity(wal)))
        # A new pooled connection would open (or create, empty) whatever is at the path now.
        event.listen(self.engine, "do_connect", self._before_connect)

    def _before_connect(self, _dialect, _record, _cargs, _cparams) -> None:
        self.check_file()

    def check_file(self) -> None:
        """DatabaseGone if the SQLite file or its log is not the one opened (deleted, replaced):
        what is written from then on is lost when the process ends. Two stat() calls."""
        for (path, opened), what in zip(self._files, ("the database file", "its write-ahead log")):
            now = _identity(path)
            if opened is not None and now != opened:
                # (a pool's new connection may have made a new empty file where it was)
                how = "deleted" if now is None else "deleted or replaced by another file"
                raise DatabaseGone(
                    f"{self._files[0][0]}: {what} was {how} while the service had it open; "
                    "what is stored since is lost when the service stops: put the file back "
                    "or restart the service"
                )

    @contextmanager
    def session(self, *, write: bool = False) -> Iterator[Session]:
        """One transaction, committed on leaving or rolled back on error; `write` locks first.
        A fault of the disk or the database server raises StoreUnavailable, a write into a file
        deleted or replaced under the store DatabaseGone (nothing stored, nothing acknowledged)."""
        if write:
            self.check_file()
        try:
            with self._sessions() as session, session.begin():
                if write:
                    session.connection(execution_options={WRITE_OPTION: True})
                yield session
        except (DBAPIError, OSError) as e:
            fault = unavailable(e)
            if fault is None:
                raise
            raise fault from e

    def close(self) -> None:
        self.engine.dispose()
        if self._keeper is not None:  # last, so the store's log is checkpointed by its owner
            self._keeper.close()
            self._keeper = None

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _identity(path: Path) -> tuple[int, int] | None:
    """The file's (device, inode), None if it is not there."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_dev, st.st_ino


def open_database(url_or_path) -> Database:
    """Open (creating it and its folder if needed) the store and migrate it to the latest schema;
    StoreError, in one line, if it is not a database (a CSV, a folder) or cannot be opened."""
    try:
        url = database_url(url_or_path)
    except SQLAlchemyError as e:
        raise StoreError(f"{url_or_path}: not a database file or URL: {e}") from None
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        _check_sqlite_file(Path(url.database), url_or_path)
    try:
        engine = make_engine(url)
    except (SQLAlchemyError, ImportError) as e:
        # e.g. mysql://: a dialect whose driver is not installed (robocal ships SQLite's and
        # PostgreSQL's)
        raise StoreError(
            f"{_shown(url_or_path)}: cannot use this database ({type(e).__name__}: {e}); "
            "robocal works with SQLite files and PostgreSQL"
        ) from None
    try:
        migrate(engine)
        return Database(engine)
    except (SQLAlchemyError, sqlite3.Error) as e:
        engine.dispose()
        # The driver's own first line names the cause; the rest is SQLAlchemy's help link.
        cause = str(getattr(e, "orig", None) or e).splitlines()[0]
        raise StoreError(f"{_shown(url_or_path)}: cannot open the database: {cause}") from None
    except Exception:
        engine.dispose()
        raise


def _check_sqlite_file(path: Path, given) -> None:
    """Refuse a folder, or a file that is something else than SQLite (a meas.csv, a model.json).

    The header is read through SQLite, never with open(): closing any descriptor of a file drops
    every POSIX lock the process holds on it, and a service that lost its SHARED lock has its
    write-ahead log checkpointed and deleted under it by the next process that closes the file.
    """
    if path.is_dir():
        raise StoreError(f"{_shown(given)}: is a folder, not a database file")
    if path.suffix.lower() in NOT_DATABASES:
        raise StoreError(
            f"{_shown(given)}: a {path.suffix} file is not a database; give a .db file "
            "(a meas.csv is read by calibrate, evaluate, compare and diagnose directly)"
        )
    if not path.exists():
        return  # created on first use
    if not os.access(path, os.R_OK):
        raise StoreError(f"{_shown(given)}: cannot read the file: permission denied")
    try:
        probe = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True)
    except sqlite3.Error:
        return  # the engine's own open says why, in one line
    try:
        probe.execute("PRAGMA schema_version").fetchall()  # reads the header
    except sqlite3.DatabaseError as e:
        if getattr(e, "sqlite_errorcode", None) == SQLITE_NOTADB:
            raise StoreError(
                f"{_shown(given)}: not a SQLite database (the file holds something else)"
            ) from None
    finally:
        probe.close()


SQLITE_NOTADB = 26  # "file is not a database"


# Suffixes of robocal's own text files: given as a database, they are a mistake, not a new store.
NOT_DATABASES = (".csv", ".json", ".txt", ".rrd", ".html", ".mod", ".urdf")


def _shown(given) -> str:
    """The database as the user wrote it, its password hidden."""
    if isinstance(given, URL):
        return given.render_as_string(hide_password=True)
    text = os.fspath(given)
    return make_url(text).render_as_string(hide_password=True) if "://" in text else text
