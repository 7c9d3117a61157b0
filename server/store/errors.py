"""What the store raises when it refuses a request (bad arguments raise ValueError), or when it
cannot do its work (a full, read-only or failing disk: the service's fault, not the request's)."""

from __future__ import annotations

import errno

from sqlalchemy.exc import DBAPIError


class StoreError(Exception):
    """A request the store refuses; the message says why."""


class NotFound(StoreError):
    """No such campaign or planned pose."""


class Conflict(StoreError):
    """The request contradicts what is already recorded (or the campaign's status)."""


class DatabaseGone(StoreError):
    """The database file (or its log) was deleted or replaced under the running service."""


# How long a client waits before asking again a store that could not write (Retry-After, s).
RETRY_AFTER_S = 30


class StoreUnavailable(StoreError):
    """The store (the database, or the service's files) could not read or write: a full or
    read-only disk, an I/O error. Nothing of the request was stored; it may succeed once the
    disk is fixed. `.reason` says what failed."""

    def __init__(self, reason: str):
        super().__init__(f"the service's storage failed: {reason}")
        self.reason = reason


# SQLite's own words for a fault of the disk, then what to do about each.
_SQLITE_FAULTS = (
    ("database or disk is full", "its disk is full; free space on it, then try again"),
    ("attempt to write a readonly database", "its disk is read-only; make it writable"),
    ("readonly database", "its disk is read-only; make it writable"),
    ("disk i/o error", "the disk reported an I/O error; check it"),
    ("unable to open database file", "its file cannot be opened; check the disk"),
)
_OS_FAULTS = {
    errno.ENOSPC: "its disk is full; free space on it, then try again",
    errno.EDQUOT: "its disk quota is used up; free space, then try again",
    errno.EROFS: "its disk is read-only; make it writable",
    errno.EIO: "the disk reported an I/O error; check it",
}
# PostgreSQL's SQLSTATE classes of the same faults: 53 insufficient resources (53100 disk full), 58
# system error (I/O), 25006 read-only transaction (a standby or a read-only server), 57P
# operator intervention (shutting down, starting up).
_PG_FAULTS = (
    ("53100", "the database server's disk is full; free space on it, then try again"),
    ("53", "the database server is out of memory or connections; try again"),
    ("58", "the database server reported an I/O error"),
    ("25006", "the database server is read-only"),
    ("57P", "the database server is shutting down or starting; try again"),
)


def unavailable(exc: BaseException) -> StoreUnavailable | None:
    """The StoreUnavailable that `exc` (a driver's or the OS's error) means, if it is a fault of
    the disk or the database server; None for any other error."""
    if isinstance(exc, StoreUnavailable):
        return exc
    if isinstance(exc, OSError) and exc.errno in _OS_FAULTS:
        return StoreUnavailable(f"{_OS_FAULTS[exc.errno]} ({exc.strerror or exc})")
    if not isinstance(exc, DBAPIError):
        return None
    orig = exc.orig
    first = str(orig or exc).splitlines()[0] if str(orig or exc) else type(orig).__name__
    state = getattr(orig, "sqlstate", None) or getattr(orig, "pgcode", None) or ""
    for prefix, what in _PG_FAULTS:
        if state.startswith(prefix):
            return StoreUnavailable(f"{what} ({first})")
    text = first.lower()
    for words, what in _SQLITE_FAULTS:
        if words in text:
            return StoreUnavailable(f"{what} ({first})")
    if isinstance(orig, OSError):
        return unavailable(orig)
    return None
