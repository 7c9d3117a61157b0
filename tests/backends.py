"""The store's two backends for tests: a SQLite file, or a fresh database on a PostgreSQL server.

ROBOCAL_TEST_POSTGRES is a URL of the test server's admin database (tests/postgres.sh sets it);
each PostgreSQL test gets its own database made from it and dropped after, so pytest-xdist's
workers never share one. Without the variable the PostgreSQL params skip, except in CI (CI=true)
where they fail: CI must run them.
"""

from __future__ import annotations

import os
import sqlite3
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

BACKENDS = ("sqlite", "postgresql")
ENV = "ROBOCAL_TEST_POSTGRES"


def admin_url() -> str:
    """The test server's admin URL; skips (fails in CI) without one."""
    url = os.environ.get(ENV)
    if url:
        return url
    reason = f"{ENV} is not set (run the tests under tests/postgres.sh for a PostgreSQL server)"
    if os.environ.get("CI", "").lower() in ("true", "1"):
        pytest.fail(f"CI runs the PostgreSQL tests but {reason}", pytrace=False)
    pytest.skip(reason)


@contextmanager
def fresh_postgres() -> Iterator[str]:
    """A new, empty database on the test server, its URL; dropped afterwards."""
    admin = make_url(admin_url())
    name = f"robocal_test_{uuid.uuid4().hex}"
    engine = create_engine(admin, isolation_level="AUTOCOMMIT")
    try:
        with engine.connect() as c:
            c.execute(text(f'CREATE DATABASE "{name}"'))
        yield admin.set(database=name).render_as_string(hide_password=False)
        with engine.connect() as c:
            # FORCE: a service under test may still hold pooled connections.
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    finally:
        engine.dispose()


@contextmanager
def store_url_for(backend: str, tmp_path) -> Iterator[str]:
    """A URL of an empty store on `backend`: a SQLite file under tmp_path, or a fresh database."""
    if backend == "sqlite":
        yield f"sqlite:///{tmp_path / 'store.db'}"
    else:
        with fresh_postgres() as url:
            yield url


def execute(database: str, sql: str, **params) -> list[tuple]:
    """One statement on a store (a path or a URL) from outside the service, committed; its rows."""
    from robocal.server.store.db import make_engine

    engine = make_engine(database)
    try:
        with engine.begin() as c:
            result = c.execute(text(sql), params)
            return [tuple(row) for row in result] if result.returns_rows else []
    finally:
        engine.dispose()


def replace_sqlite_file(path: Path) -> None:
    """Swap another SQLite database in for the file at `path`, as a restore or a copy would."""
    other = path.with_name("other.db")
    with sqlite3.connect(other) as o:
        o.execute("CREATE TABLE note (text TEXT)")
    o.close()
    os.replace(other, path)
