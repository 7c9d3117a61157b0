"""Quick checks of a done job's model (FORMATS section 8 over HTTP): post a check.csv, its history
and its chart, and the production line's single question, whether the model still holds."""

from __future__ import annotations

from dataclasses import asdict

from fastapi import APIRouter, Request, Response
from starlette.concurrency import run_in_threadpool

from robocal.server import check, check_charts, uploads
from robocal.server.formats.model_json import file_digest
from robocal.server.store.model_checks import CheckRecord, model_checks
from robocal.solver import drift

from .check_schemas import CheckEntry, CheckHistory, CheckPublic, ModelHealth
from .deps import Authorized, DbDep, JobId, JobsDep
from .models import Filename
from .problems import Responses
from .worker_calls import CALL_PROBLEMS, PROBLEM, call_slot, run_call

router = APIRouter(prefix="/models", tags=["checks"])
charts_router = APIRouter(prefix="/charts", tags=["charts"])
CHECK_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "text/csv": {
                "schema": {
                    "type": "string",
                    "minLength": 1,
                    "description": "a check.csv: a meas.csv (spec sections 1 and 8) of the few "
                    "poses measured every check",
                }
            }
        },
    }
}
BAD_CHECK: Responses = {
    409: {"description": "the job is not done (it has no model yet)", "content": PROBLEM},
    422: {
        "description": "a bad check.csv (file, line and column), one not of the model's SMRs, "
        "too many poses, or a model that states no error to check against",
        "content": PROBLEM,
    },
}


@router.post(
    "/{job_id}/checks",
    status_code=201,
    dependencies=[Authorized],
    openapi_extra=CHECK_BODY,
    responses={**BAD_CHECK, **CALL_PROBLEMS},
)
async def post_check(
    job_id: JobId, request: Request, jobs: JobsDep, db: DbDep, filename: Filename = "check.csv"
) -> CheckPublic:
    """A quick check of the job's model on the uploaded check.csv, judged over the model's history
    and appended to it (as `robocal check`, whose database this may be): ok, watch or
    recalibrate, and why. A bad file is 422 naming its line and column, and nothing is stored."""
    data = await request.body()
    return await run_in_threadpool(_check, jobs, db, job_id, data, filename)


def _check(jobs, db, job_id: int, data: bytes, filename: str) -> CheckPublic:
    """The upload parsed in a worker process; judged here, in the store's write transaction, so
    two checks of one model are judged one after the other."""
    path = jobs.model_path(job_id)
    with call_slot(jobs):
        prepared = run_call(jobs, uploads.read_check, path, data, filename)
    res = check.record(db, prepared, filename)
    return CheckPublic(job_id=job_id, **asdict(res))


def _history(jobs, db, job_id: int) -> tuple[str, list[CheckRecord]]:
    """The model's digest (the history's key, as the command line's) and its checks."""
    sha = file_digest(jobs.model_path(job_id))
    return sha, model_checks(db, sha)


@router.get("/{job_id}/checks", responses=BAD_CHECK)
def list_checks(job_id: JobId, jobs: JobsDep, db: DbDep) -> CheckHistory:
    """The model's checks, oldest first: each one's figures, verdict and reason, and the limits
    they were judged by (the level's per check; the accumulated change's once)."""
    sha, checks = _history(jobs, db, job_id)
    return CheckHistory(
        job_id=job_id,
        model_sha256=sha,
        cusum_watch=drift.CUSUM_WATCH,
        cusum_recalibrate=drift.CUSUM_H,
        checks=[_entry(c) for c in checks],
    )


def _entry(c: CheckRecord) -> CheckEntry:
    watch, recalibrate = drift.level_limits(c.expected_rms_mm, c.poses)
    return CheckEntry(
        id=c.id,
        checked_at=c.checked_at,
        source=c.source,
        poses=c.poses,
        rms_mm=c.rms_mm,
        max_mm=c.max_mm,
        expected_rms_mm=c.expected_rms_mm,
        watch_rms_mm=watch,
        recalibrate_rms_mm=recalibrate,
        change_score=c.change_z,
        cusum=c.cusum,
        verdict=c.verdict,
        reason=c.reason,
    )


@router.get("/{job_id}/health", responses=BAD_CHECK)
def model_health(job_id: JobId, jobs: JobsDep, db: DbDep) -> ModelHealth:
    """Whether the deployed model still holds, for the production line: its latest check's
    verdict (ok, watch, recalibrate), reason and time, and how many checks it has; a model never
    checked says so (verdict null)."""
    sha, checks = _history(jobs, db, job_id)
    if not checks:
        return ModelHealth(
            job_id=job_id,
            model_sha256=sha,
            checked=False,
            verdict=None,
            reason=f"never checked: POST a check.csv to /api/models/{job_id}/checks",
            checked_at=None,
            history=0,
            rms_mm=None,
            expected_rms_mm=None,
        )
    last = checks[-1]
    return ModelHealth(
        job_id=job_id,
        model_sha256=sha,
        checked=True,
        verdict=last.verdict,
        reason=last.reason,
        checked_at=last.checked_at,
        history=len(checks),
        rms_mm=last.rms_mm,
        expected_rms_mm=last.expected_rms_mm,
    )


@charts_router.get(
    "/models/{job_id}/checks.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}, **BAD_CHECK, **CALL_PROBLEMS},
)
def checks_chart(job_id: JobId, jobs: JobsDep, db: DbDep) -> Response:
    """The model's checks over time: RMS against the expected error and the watch and
    recalibrate limits; below, the change accumulated over the history against its limits."""
    _, checks = _history(jobs, db, job_id)
    with call_slot(jobs):
        data = run_call(jobs, check_charts.history_png, job_id, checks)
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})


__all__ = ["charts_router", "router"]
