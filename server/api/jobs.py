"""Calibration jobs: queued -> running -> done | failed, on the worker pool."""

from __future__ import annotations

from fastapi import APIRouter

from server.jobs import Job

from .deps import Authorized, JobsDep
from .schemas import JobCreate, JobPublic

router = APIRouter(prefix="/jobs", tags=["jobs"])


def _public(job: Job) -> JobPublic:
    return JobPublic(id=job.id, campaign_id=job.campaign_id, method=job.method, state=job.state,
                     reason=job.reason, created_at=job.created_at, started_at=job.started_at,
                     finished_at=job.finished_at,
                     model_url=f"/api/models/{job.id}" if job.state == "done" else None)


@router.post("", status_code=202, dependencies=[Authorized])
def create_job(body: JobCreate, jobs: JobsDep) -> JobPublic:
    """Queue a calibration of a done campaign; poll GET /jobs/{id}."""
    return _public(jobs.submit(campaign_id=body.campaign_id, method=body.method))


@router.get("")
def list_jobs(jobs: JobsDep) -> list[JobPublic]:
    """Jobs since the server started."""
    return [_public(j) for j in jobs.list()]


@router.get("/{job_id}")
def get_job(job_id: int, jobs: JobsDep) -> JobPublic:
    """One job's state, and the reason if it failed."""
    return _public(jobs.get(job_id))
