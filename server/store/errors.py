"""What the store raises when it refuses a request (bad arguments raise ValueError)."""

from __future__ import annotations


class StoreError(Exception):
    """A request the store refuses; the message says why."""


class NotFound(StoreError):
    """No such campaign or planned pose."""


class Conflict(StoreError):
    """The request contradicts what is already recorded (or the campaign's status)."""


class DatabaseGone(StoreError):
    """The database file (or its log) was deleted or replaced under the running service."""
