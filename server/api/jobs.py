"""Jobs: calibrations and diagnoses of done campaigns, and the planning of new ones (POST
/api/campaigns answers 202 with one), queued -> running -> done | failed."""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, JSONResponse
from pydantic import BaseModel, ConfigDict

from robocal.server import store
from robocal.server.formats.blocks import HeldOut, Validation
from robocal.server.service.job_queue import DuplicateJob, Job
from robocal.solver.calibrate import MethodDataError

from . import problems
from .bodies import json_body, read_json
from .deps import Authorized, DbDep, JobId, JobsDep
from .schemas import FigurePublic, JobCreate, JobPublic, RecordingPosePublic

router = APIRouter(prefix="/jobs", tags=["jobs"])
JobBody = Annotated[JobCreate, Depends(read_json(JobCreate))]


class JobResults(BaseModel):
    """A done job's results as the store keeps them: the files it wrote, the campaign it
    planned, a calibration's verdict and held-out figures (formats.blocks)."""

    model_config = ConfigDict(extra="allow")
    model: str | None = None
    recording: str | None = None
    report: str | None = None
    campaign: int | None = None
    validation: Validation | None = None
    holdout: HeldOut | None = None


def public_job(job: Job) -> JobPublic:
    done = job.state == "done"
    urls = {}
    if done:
        base = f"/api/jobs/{job.id}"
        res = JobResults.model_validate(job.results)
        has_model = res.model is not None
        urls = dict(
            model_url=f"/api/models/{job.id}" if has_model else None,
            recording_url=f"{base}/recording" if res.recording is not None else None,
            report_url=f"{base}/report" if res.report is not None else None,
            figures_url=f"{base}/figures" if res.report is not None else None,
            campaign_url=f"/api/campaigns/{res.campaign}" if res.campaign is not None else None,
            parameters_url=f"/api/models/{job.id}/parameters" if has_model else None,
            validation=res.validation,
            holdout=res.holdout,
        )
    return JobPublic(
        id=job.id,
        kind=job.kind,
        campaign_id=job.campaign_id,
        method=job.method,
        state=job.state,
        reason=job.reason,
        progress=job.progress,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
        holdout_campaign_id=job.holdout_campaign_id,
        tolerance_mm=job.tolerance_mm,
        **urls,
    )


PROBLEM: dict[str, Any] = {"content": {"application/problem+json": {}}}


@router.post(
    "",
    status_code=202,
    dependencies=[Authorized],
    response_model=JobPublic,
    responses={
        409: {
            "description": "The campaign is not done, or the same "
            "calibration (campaign and method) is queued or running; "
            "`job_id` names that job",
            **PROBLEM,
        }
    },
    openapi_extra=json_body(JobCreate),
)
def create_job(body: JobBody, jobs: JobsDep, request: Request) -> JobPublic | JSONResponse:
    """Queue a calibration or diagnosis of a done campaign; poll GET /jobs/{id} or /api/events.
    A second calibration of a campaign with the same method while one is queued or running is
    refused (409); another method is accepted. A diagnosis takes no method (422 naming it)."""
    if body.kind == "diagnosis" and "method" in body.model_fields_set:
        # else a calibration's body with only its kind changed would be run as something else
        raise ValueError(
            f"method: a diagnosis takes none (it fits the geometry by ls-sum, then the "
            f"extensions), not {body.method!r}; leave method out, or ask a calibration"
        )
    try:
        return public_job(
            jobs.submit(
                campaign_id=body.campaign_id,
                method=body.method,
                kind=body.kind,
                holdout_campaign_id=body.holdout_campaign_id,
                tolerance_mm=body.tolerance_mm,
            )
        )
    except DuplicateJob as e:
        return problems.problem(request, 409, str(e), job_id=e.job_id)
    except MethodDataError as e:  # the campaign's SMRs cannot serve the method: its field named
        error = {"loc": ["body", "method"], "msg": str(e), "type": "value_error"}
        return problems.problem(request, 422, f"method: {e}", errors=[error])


@router.post(
    "/{job_id}/cancel",
    dependencies=[Authorized],
    responses={409: {"description": "The job is already done or failed", **PROBLEM}},
)
def cancel_job(job_id: JobId, jobs: JobsDep) -> JobPublic:
    """Cancel a job: a queued one leaves the queue, a running one's worker process is killed;
    either ends failed with reason "cancelled" (409 if it already ended)."""
    return public_job(jobs.cancel(job_id))


@router.get("")
def list_jobs(jobs: JobsDep) -> list[JobPublic]:
    """Every job in the store, oldest first."""
    return [public_job(j) for j in jobs.list()]


@router.get("/{job_id}")
def get_job(job_id: JobId, jobs: JobsDep) -> JobPublic:
    """One job's state and progress, and the reason if it failed."""
    return public_job(jobs.get(job_id))


@router.get(
    "/{job_id}/recording",
    response_class=FileResponse,
    responses={200: {"content": {"application/octet-stream": {}}}},
)
def get_recording(job_id: JobId, jobs: JobsDep) -> FileResponse:
    """The Rerun recording (.rrd) of a done calibration or diagnosis (404 none, 409 not done)."""
    return FileResponse(
        jobs.result_path(job_id, "recording"),
        media_type="application/octet-stream",
        filename=f"job-{job_id}.rrd",
    )


@router.get("/{job_id}/recording/poses")
def get_recording_poses(job_id: JobId, jobs: JobsDep, db: DbDep) -> list[RecordingPosePublic]:
    """The recording's timeline "pose", index by index: the calibration's poses (those with a
    reading, in plan order), then the held-out campaign's; what the page's tables link to."""
    jobs.result_path(job_id, "recording")  # 404 none, 409 not done
    job = jobs.get(job_id)
    sets = [("calibration", job.campaign_id), ("held_out", job.holdout_campaign_id)]
    out: list[RecordingPosePublic] = []
    for name, cid in sets:
        if cid is None:
            continue
        # the poses as the worker read them for the recording (store.campaign_measurements)
        labels = store.campaign_measurements(db, campaign_id=cid).pose_ids
        out += [
            RecordingPosePublic(index=len(out) + i, label=p, set=name) for i, p in enumerate(labels)
        ]
    return out


@router.get("/{job_id}/report")
def get_report(job_id: JobId, jobs: JobsDep) -> dict:
    """The report.json of a done diagnosis (404 none, 409 not done)."""
    return json.loads(jobs.result_path(job_id, "report").read_text())


@router.get("/{job_id}/figures")
def list_figures(job_id: JobId, jobs: JobsDep) -> list[FigurePublic]:
    """The figures of a done diagnosis, one PNG per effect found."""
    jobs.result_path(job_id, "report")
    names = [p.rsplit("/", 1)[-1] for p in jobs.get(job_id).results.get("figures", [])]
    return [FigurePublic(name=n, url=f"/api/jobs/{job_id}/figures/{n}") for n in names]


@router.get(
    "/{job_id}/figures/{name}",
    response_class=FileResponse,
    responses={200: {"content": {"image/png": {}}}},
)
def get_figure(job_id: JobId, name: str, jobs: JobsDep) -> FileResponse:
    """One figure of a done diagnosis, by the name the list gives."""
    return FileResponse(jobs.figure_path(job_id, name), media_type="image/png")
