"""Quick checks of a done job's model (FORMATS section 8 over HTTP): post a check.csv, its history
and its chart, and the production line's single question, whether the model still holds."""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated

from fastapi import APIRouter, Depends, Request, Response
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from robocal.server import store
from robocal.server.acquisition import cells
from robocal.server.checks import charts as check_charts
from robocal.server.checks import check
from robocal.server.checks import service as check_service
from robocal.server.formats.model_json import file_digest, read_model
from robocal.server.service import uploads
from robocal.server.store.model_checks import CheckRecord, model_checks
from robocal.solver import drift

from .bodies import csv_body, json_body, read_json
from .check_schemas import (
    CheckEntry,
    CheckHistory,
    CheckPublic,
    CheckRunCreate,
    CheckRunPublic,
    ModelHealth,
)
from .deps import AcquisitionsDep, Authorized, DbDep, JobId, JobsDep, SettingsDep
from .models import Filename
from .problems import Responses
from .worker_calls import CALL_PROBLEMS, PROBLEM, call_slot, run_call

router = APIRouter(prefix="/models", tags=["checks"])
charts_router = APIRouter(prefix="/charts", tags=["charts"])
CHECK_BODY = csv_body(
    "a check.csv: a meas.csv (spec sections 1 and 8) of the few poses measured every check"
)
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
    return public_check(job_id, check.record(db, prepared, filename), path)


def public_check(job_id: int, res: check.CheckResult, model_path) -> CheckPublic:
    """A check's result as the API answers it: check.json's figures, the warning `robocal
    check` prints beside them (the same CheckResult.warning), and the model's own verdict."""
    figures = asdict(res)
    warning = figures.pop("warning")
    return CheckPublic(
        job_id=job_id, **figures, warnings=[warning] if warning else [], **_deploy(model_path)
    )


def _deploy(model_path) -> dict:
    """The model's own deployable verdict and reasons (a check does not judge that)."""
    verdict = read_model(model_path).verdict
    return {"deployable": bool(verdict.deployable), "not_deployable": list(verdict.reasons)}


CheckRunBody = Annotated[CheckRunCreate, Depends(read_json(CheckRunCreate))]
RUN_PROBLEMS: Responses = {
    409: {
        "description": "the job has no model yet, the cell runs another campaign, the "
        "model's check campaign waits for its reset after an e-stop (POST "
        "/api/campaigns/{id}/reset), or the model's readings were imported and no `seed` "
        "says which simulated arm to check",
        "content": PROBLEM,
    },
    422: {
        "description": "a model not of the cell's arm (its SMRs, its joints)",
        "content": PROBLEM,
    },
}


@router.post(
    "/{job_id}/checks/run",
    status_code=202,
    dependencies=[Authorized],
    response_model=CheckRunPublic,
    openapi_extra=json_body(CheckRunCreate),
    responses={
        201: {"model": CheckRunPublic, "description": "a check measured earlier judged now"},
        **RUN_PROBLEMS,
    },
)
def run_check(
    job_id: JobId,
    body: CheckRunBody,
    jobs: JobsDep,
    db: DbDep,
    settings: SettingsDep,
    acquisitions: AcquisitionsDep,
) -> JSONResponse:
    """Run a quick check of the job's model on the cell (as `robocal acquire --check`): its check
    poses as a campaign on the acquisition worker, with its lease, e-stop and events (202; follow
    `campaign_url`); once done, judged and appended to the model's history (GET .../checks,
    .../health). An unfinished check campaign of the model is resumed rather than planned again;
    one measured but not judged yet is judged now (201)."""
    path, campaign_id = jobs.model_path(job_id), jobs.get(job_id).campaign_id
    if campaign_id is None:  # a planning job (model_path refused it already)
        raise store.NotFound(f"job {job_id} has no model")
    source = check_service.model_source(db, campaign_id)
    same_cell = body.cell_id is None
    cell = source.cell
    if body.cell_id is not None:
        cell = cells.load_cell(cells_dir=settings.cells_dir, cell_id=body.cell_id)
    if cell.simulated and body.seed is None and not (same_cell and source.acquired):
        raise store.Conflict(
            f"campaign {campaign_id}'s readings were imported: which simulated arm to check is "
            "unknown; give `seed` (that of `robocal simulate --seed`)"
        )
    out = check_service.start_check(
        db,
        acquisitions,
        cell=cell,
        model_path=path,
        job_id=job_id,
        poses=body.poses,
        seed=source.seed if body.seed is None else body.seed,
        pause_s=body.pause_s,
        # the same simulated arm, read as the calibration read it
        effects=source.effects if same_cell else (),
        samples=source.samples,
        settle=source.settle,
        arm=source.arm,
    )
    doc = CheckRunPublic(
        job_id=job_id,
        campaign_id=out.campaign_id,
        campaign_url=f"/api/campaigns/{out.campaign_id}",
        started=out.started,
        note=out.note,
        check=None if out.result is None else public_check(job_id, out.result, path),
    )
    if out.started:
        return JSONResponse(
            doc.model_dump(mode="json"),
            status_code=202,
            headers={"Location": doc.campaign_url},
        )
    return JSONResponse(doc.model_dump(mode="json"), status_code=201)


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
    deploy = _deploy(jobs.model_path(job_id))
    if not checks:
        return ModelHealth(
            job_id=job_id,
            model_sha256=sha,
            checked=False,
            verdict=None,
            reason=f"never checked: POST a check.csv to /api/models/{job_id}/checks or run one "
            f"with POST /api/models/{job_id}/checks/run",
            checked_at=None,
            history=0,
            rms_mm=None,
            expected_rms_mm=None,
            **deploy,
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
        **deploy,
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
