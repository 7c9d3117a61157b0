"""Calibration, diagnosis and planning jobs kept in the store."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import Session

from . import checks
from .campaigns import _campaign
from .db import Database
from .errors import Conflict, NotFound
from .models import JOB_KINDS, JOB_STATES, Job, utcnow

# queued -> running -> done | failed; a queued job may fail without running (a restart).
JOB_TRANSITIONS = {
    "queued": {"running", "failed"},
    "running": {"done", "failed"},
    "done": set(),
    "failed": set(),
}


JOB_FIELDS = ("progress", "reason", "results", "campaign_id")  # campaign: a planning job's


@dataclass(frozen=True)
class JobInfo:
    """A job as the store holds it."""

    id: int
    kind: str
    campaign_id: int | None  # None for a planning job until it planned its campaign
    method: str
    state: str
    reason: str | None
    progress: float
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    results: dict
    holdout_campaign_id: int | None = None  # a calibration's held-out campaign, if it has one
    tolerance_mm: float | None = None  # the accuracy asked for, over the cell's; None: the cell's


class ActiveJob(Conflict):
    """The same job is already queued or running (`job`): create_job(unique=True) refused."""

    def __init__(self, job: JobInfo):
        super().__init__(f"job {job.id} is the same and {job.state}")
        self.job = job

    def __reduce__(self):
        return type(self), (self.job,)


def create_job(
    db: Database,
    *,
    kind: str,
    campaign_id: int | None,
    method: str,
    holdout_campaign_id: int | None = None,
    tolerance_mm: float | None = None,
    unique: bool = False,
    owner: str | None = None,
) -> JobInfo:
    """Store a queued job on an existing campaign (none for a planning job); the job. unique:
    ActiveJob if the same job (kind, campaign, method, held-out campaign, tolerance) is queued or
    running, looked for in the insert's own write transaction, so that two services on one
    database cannot both queue it. owner: the process that runs it (fail_unfinished_jobs)."""
    checks.one_of(kind, JOB_KINDS, "kind")
    if (campaign_id is None) != (kind == "planning"):
        raise ValueError("a planning job has no campaign yet; every other job has one")
    tol = None if tolerance_mm is None else float(tolerance_mm)
    with db.session(write=True) as s:
        for cid in (campaign_id, holdout_campaign_id):
            if cid is not None:
                _campaign(s, cid)
        if unique:
            _refuse_active(s, (kind, campaign_id, str(method), holdout_campaign_id, tol))
        job = Job(
            kind=kind,
            campaign_id=campaign_id,
            holdout_campaign_id=holdout_campaign_id,
            tolerance_mm=tol,
            owner=owner,
            method=str(method),
            state="queued",
            progress=0.0,
            results={},
            created_at=utcnow(),
        )
        s.add(job)
        s.flush()
        return _job_info(job)


def _refuse_active(s: Session, same: tuple) -> None:
    """ActiveJob if a queued or running job is `same` (kind, campaign, method, held-out
    campaign, tolerance), running ones first."""
    kind, campaign_id, method = same[:3]
    query = select(Job).where(
        Job.kind == kind,
        Job.campaign_id == campaign_id,
        Job.method == method,
        Job.state.in_(("running", "queued")),
    )
    for job in sorted(s.scalars(query), key=lambda j: (j.state != "running", j.id)):
        if (
            job.kind,
            job.campaign_id,
            job.method,
            job.holdout_campaign_id,
            job.tolerance_mm,
        ) == same:
            raise ActiveJob(_job_info(job))


def get_job(db: Database, *, job_id: int) -> JobInfo:
    """The job with this id; NotFound if there is none."""
    with db.session() as s:
        return _job_info(_job(s, job_id))


def list_jobs(db: Database, *, state: str | None = None) -> list[JobInfo]:
    """Every job (or those in this state), oldest first."""
    with db.session() as s:
        query = select(Job).order_by(Job.id)
        if state is not None:
            query = query.where(Job.state == checks.one_of(state, JOB_STATES, "state"))
        return [_job_info(j) for j in s.scalars(query)]


def update_job(db: Database, *, job_id: int, state: str | None = None, **changes) -> JobInfo:
    """Move a job along (see JOB_TRANSITIONS) and/or set progress, reason, results; the job."""
    unknown = set(changes) - set(JOB_FIELDS)
    if unknown:
        raise ValueError(f"cannot set {', '.join(sorted(unknown))} of a job")
    if "progress" in changes and not 0.0 <= float(changes["progress"]) <= 1.0:
        raise ValueError("progress is a fraction in [0, 1]")
    with db.session(write=True) as s:
        job = _job(s, job_id)
        if state is not None and state != job.state:
            checks.one_of(state, JOB_STATES, "state")
            if state not in JOB_TRANSITIONS[job.state]:
                raise Conflict(f"job {job_id} is {job.state}; it cannot go to {state}")
            job.state = state
            if state == "running":
                job.started_at = utcnow()
            if state in ("done", "failed"):
                job.finished_at = utcnow()
                if state == "done":
                    job.progress = 1.0
        for key, value in changes.items():
            setattr(job, key, dict(value) if key == "results" else value)
        s.flush()
        return _job_info(job)


def fail_unfinished_jobs(
    db: Database, *, reason: str, gone: Callable[[str | None], bool] = lambda owner: True
) -> list[int]:
    """Mark failed with `reason` every queued or running job whose owner is `gone` (nothing runs
    them any more; another live service's jobs are its own); ids."""
    with db.session(write=True) as s:
        unfinished = s.scalars(select(Job).where(Job.state.in_(("queued", "running"))))
        jobs = [j for j in unfinished if gone(j.owner)]
        for job in jobs:
            job.state, job.reason, job.finished_at = "failed", reason, utcnow()
        return [j.id for j in jobs]


def _job(s: Session, job_id: int) -> Job:
    job = s.get(Job, job_id)
    if job is None:
        raise NotFound(f"no job {job_id}")
    return job


def _job_info(j: Job) -> JobInfo:
    return JobInfo(
        j.id,
        j.kind,
        j.campaign_id,
        j.method,
        j.state,
        j.reason,
        j.progress,
        j.created_at,
        j.started_at,
        j.finished_at,
        dict(j.results or {}),
        j.holdout_campaign_id,
        j.tolerance_mm,
    )
