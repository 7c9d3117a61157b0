"""A route's heavy computation in a short-lived worker process (Jobs.call), its failures as
problems: 504 past the wall-clock limit, 503 when no worker frees up or one died."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Any

from fastapi import HTTPException

from robocal.server.service.job_queue import Busy, CallTimedOut, Jobs
from robocal.server.service.processes import WorkerDied

from .problems import Responses

PROBLEM: dict[str, Any] = {"application/problem+json": {}}
CALL_PROBLEMS: Responses = {
    503: {
        "description": "No worker free for the computation (Retry-After), or it died",
        "content": PROBLEM,
    },
    504: {
        "description": "The computation ran past its wall-clock limit and was stopped",
        "content": PROBLEM,
    },
}
RETRY_AFTER_S = 5


@contextmanager
def call_slot(jobs: Jobs):
    """Hold a worker slot while a route loads its inputs and computes (503 if none frees up)."""
    try:
        with jobs.call_slot():
            yield
    except Busy as e:
        raise HTTPException(503, str(e), headers={"Retry-After": str(RETRY_AFTER_S)}) from None


def run_call(jobs: Jobs, target, *args):
    """target(*args, report) in a worker: its result; its own exceptions pass through."""
    try:
        return jobs.call(target, *args)
    except CallTimedOut as e:
        raise HTTPException(504, str(e)) from None
    except Busy as e:
        raise HTTPException(503, str(e), headers={"Retry-After": str(RETRY_AFTER_S)}) from None
    except WorkerDied as e:
        raise HTTPException(503, str(e)) from None
