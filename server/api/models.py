"""Models: the model.json a done calibration job wrote, its accuracy on a campaign, the joint
commands it compensates for a targets.csv, its exports (RAPID, parameter table, URDF), and a
verification run of it on the cell."""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from robocal.server import store
from robocal.server.acquisition import campaigns
from robocal.server.calibration.identified import parameters_of
from robocal.server.calibration.validation import absurd_errors, cell_mismatch, file_refusal
from robocal.server.compensate import model_files
from robocal.server.compensate.compensation import (
    MAX_ERROR_MM,
    MAX_JUMP_DEG,
    MAX_MOVE_DEG,
    Limits,
    parse_tcp,
)
from robocal.server.figures import charts
from robocal.server.formats.cell_json import parse_cell
from robocal.server.formats.model_json import approach_unknown, read_model
from robocal.server.verify import run as verification
from robocal.solver.finite import require_inputs

from .bodies import json_body, read_json
from .campaigns import public_campaign
from .deps import AcquisitionsDep, Authorized, CampaignQuery, DbDep, JobId, JobsDep
from .model_schemas import ModelParameters
from .problems import Responses
from .schemas import PRINTABLE, CampaignDetail, VerifyCreate
from .worker_calls import CALL_PROBLEMS, PROBLEM, call_slot, run_call

router = APIRouter(prefix="/models", tags=["models"])
VerifyBody = Annotated[VerifyCreate, Depends(read_json(VerifyCreate))]


@router.get(
    "/{job_id}", response_class=FileResponse, responses={200: {"content": {"application/json": {}}}}
)
def get_model(job_id: JobId, jobs: JobsDep) -> FileResponse:
    """The model.json of a done job (404 no job, 409 not done)."""
    path = jobs.model_path(job_id)
    name = model_files.download_name(path, job_id, "model.json")
    return FileResponse(path, media_type="application/json", filename=name)


@router.get(
    "/{job_id}/parameters",
    response_model=ModelParameters,
    responses={409: {"description": "the job is not done", "content": PROBLEM}},
)
def model_parameters(job_id: JobId, jobs: JobsDep) -> dict:
    """The identified parameters of a done job's model: per joint the change of theta, d, a,
    alpha (and beta) from nominal, the base (tracker frame) and SMR (flange frame) frames, each
    with its standard error (mm, degrees); the parameters held fixed and why; the condition
    number; the strongest correlations. With the model's validation: whether it is deployable,
    why not, and its held-out RMS (the headline) beside the fit RMS."""
    model = read_model(jobs.model_path(job_id))
    return {
        "job_id": job_id,
        "method": model.method,
        "identified": parameters_of(model),
        "validation": model.validation,
    }


Force = Annotated[
    bool,
    Query(description="go on although the model is not deployable or the data not of its cell"),
]


@router.get(
    "/{job_id}/evaluate",
    responses={
        409: {"description": "the campaign has no measured pose (reading) yet", "content": PROBLEM},
        422: {
            "description": "the campaign is not of the model's cell (another robot, or "
            "errors of metres); force=true evaluates anyway",
            "content": PROBLEM,
        },
        **CALL_PROBLEMS,
    },
)
def evaluate_model(
    job_id: JobId, campaign_id: CampaignQuery, jobs: JobsDep, db: DbDep, force: Force = False
) -> dict:
    """Accuracy of a job's model on a campaign's readings, next to the nominal model (computed
    in a worker process under a wall-clock limit: 504 past it). A campaign of another cell
    (another robot, other SMRs, or model errors past 100 mm RMS) is refused (422) unless
    force=true, which answers with the reason in `warnings`; one without a reading yet (planned)
    is 409."""
    path = jobs.model_path(job_id)
    warnings = []
    with call_slot(jobs):  # loading the readings is heavy too: at most call_workers at once
        info = store.get_campaign(db, campaign_id=campaign_id)
        cell = parse_cell(info.cell_json)
        model = read_model(path)
        why = cell_mismatch(model, cell)
        if why:
            if not force:
                raise HTTPException(422, f"campaign {campaign_id}: {why}; force=true to go on")
            warnings.append(why)
        meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
        if meas.n_poses == 0:  # nothing to compare with: the statistics would divide by zero
            raise store.Conflict(unmeasured(info))
        require_inputs(meas.q, meas.xyz)  # a non-finite campaign: 422 at once, no worker
        result = run_call(jobs, charts.evaluation, path, meas)
    why = absurd_errors(result, model.verdict)
    if why:
        if not force:
            raise HTTPException(422, f"campaign {campaign_id}: {why}; force=true to go on")
        warnings.append(why)
    # a backlash model's approach directions from the rows' order (as `robocal evaluate` says)
    if order := approach_unknown(model, meas.q, meas.time_s, meas.prev_q, meas.pose_ids):
        warnings.append(order)
    body = result.to_json()
    return {**body, "warnings": warnings} if warnings else body


def unmeasured(info: store.CampaignInfo) -> str:
    """Why a campaign without a single reading cannot be evaluated, and what to do."""
    if info.n_done == 0:
        return (
            f"campaign {info.id} ({info.name}) has no measured pose yet (it is {info.status}): "
            f"run it (POST /api/campaigns/{info.id}/start), then evaluate"
        )
    return f"campaign {info.id} ({info.name}) has no reading: every target was missing"


def _deployable(path, force: bool) -> None:
    """409 with the reasons when the model is not deployable, unless forced."""
    why = file_refusal(path)
    if why and not force:
        raise HTTPException(409, f"{why}; force=true to use it anyway")


TARGETS_BODY = {
    "requestBody": {
        "content": {
            "text/csv": {
                # a header row at least: an empty body is no targets.csv
                "schema": {
                    "type": "string",
                    "minLength": 1,
                    "description": "a targets.csv (spec section 7)",
                }
            }
        },
    }
}
BAD_FILE: Responses = {
    422: {"description": "A bad targets.csv (its line) or query", "content": PROBLEM}
}
NOT_DEPLOYABLE: Responses = {
    409: {
        "description": "The model is not deployable (its validation's reasons); force=true "
        "uses it anyway",
        "content": PROBLEM,
    }
}
# the compensation's warnings (orientation from the starting joints, jumps): a JSON list of lines
WARNINGS_HEADER = "X-Robocal-Warnings"
CSV_ANSWER: Responses = {
    200: {
        "content": {"text/csv": {"schema": {"type": "string"}}},
        "headers": {
            WARNINGS_HEADER: {
                "description": "the compensation's warnings, a JSON list of one-line strings "
                "(absent without any)",
                "schema": {"type": "string"},
            }
        },
    }
}
EXPORT_ANSWER: Responses = {
    200: {"content": {m: {"schema": {"type": "string"}} for m in model_files.MEDIA.values()}}
}
Filename = Annotated[
    str, Query(max_length=255, pattern=PRINTABLE, description="the upload's name, for errors")
]
Tcp = Annotated[
    str | None,
    Query(
        max_length=200,
        pattern=r"^[-+0-9.eE]+(,[-+0-9.eE]+){2}(,[-+0-9.eE]+,[-+0-9.eE]+,[-+0-9.eE]+)?$",
        description="x,y,z[,rx,ry,rz]: a tool centre point in the flange frame (mm, degrees); "
        "targets.csv then names the target TCP",
    ),
]


def _tcp(text: str | None) -> list[float] | None:
    try:
        return None if text is None else parse_tcp(text)
    except ValueError as e:
        raise HTTPException(422, str(e)) from None


@router.post(
    "/{job_id}/compensate",
    dependencies=[Authorized],
    openapi_extra={"requestBody": {**TARGETS_BODY["requestBody"], "required": True}},
    response_class=Response,
    responses={**CSV_ANSWER, **BAD_FILE, **NOT_DEPLOYABLE, **CALL_PROBLEMS},
)
async def compensate(
    job_id: JobId,
    request: Request,
    jobs: JobsDep,
    tcp: Tcp = None,
    max_error_mm: Annotated[float, Query(gt=0, le=1000)] = MAX_ERROR_MM,
    max_move_deg: Annotated[
        float,
        Query(
            ge=0,
            le=3600,
            description="refuse a pose whose joints move further than this from its starting "
            "joints: another configuration",
        ),
    ] = MAX_MOVE_DEG,
    max_jump_deg: Annotated[
        float,
        Query(ge=0, le=3600, description="warn of consecutive poses whose joints turn more"),
    ] = MAX_JUMP_DEG,
    filename: Filename = "targets.csv",
    force: Force = False,
) -> Response:
    """The joint commands (joints.csv) that put the SMRs (or the tool) where the uploaded
    targets.csv wants them, by this job's model; an unreachable pose, or one whose joints would
    leave its starting configuration, is 422 with its line; jumps between consecutive poses are
    warnings. A model its validation marks not deployable is refused (409 with the reasons)
    unless force=true."""
    data = await request.body()
    limits = Limits(max_error_mm, max_move_deg, max_jump_deg)
    out = await run_in_threadpool(
        _with_model,
        jobs,
        job_id,
        force,
        model_files.compensated_csv,
        data,
        filename,
        _tcp(tcp),
        limits,
    )
    name = model_files.download_name(jobs.model_path(job_id), job_id, "joints.csv")
    headers = {"Content-Disposition": f'attachment; filename="{name}"'}
    if out.warnings:  # JSON with ASCII escapes: a header carries no other text safely
        headers[WARNINGS_HEADER] = json.dumps([f"{filename}: {w}" for w in out.warnings])
    return Response(out.csv, media_type="text/csv", headers=headers)


def _with_model(jobs, job_id, force, target, *args) -> Any:
    """target(model path, *args) in a worker, once a worker slot is free; 409 if the model is
    not deployable, unless forced."""
    path = jobs.model_path(job_id)
    _deployable(path, force)
    with call_slot(jobs):
        return run_call(jobs, target, path, *args)


@router.post(
    "/{job_id}/export",
    dependencies=[Authorized],
    openapi_extra=TARGETS_BODY,
    response_class=Response,
    responses={**EXPORT_ANSWER, **BAD_FILE, **NOT_DEPLOYABLE, **CALL_PROBLEMS},
)
async def export(
    job_id: JobId,
    request: Request,
    jobs: JobsDep,
    format: Annotated[Literal["rapid", "params", "urdf"], Query(description="the export")],
    filename: Filename = "targets.csv",
    force: Force = False,
) -> Response:
    """The model for the controller and other tools: `rapid`, a RAPID module of the joint
    targets compensated for the uploaded targets.csv; `params`, the identified parameters in the
    robot's convention (CSV); `urdf`, calibrated joint origins (no body for these two). A model
    its validation marks not deployable is refused (409 with the reasons) unless force=true."""
    data = await request.body()
    if format == "rapid" and not data:
        raise HTTPException(422, "a RAPID export needs a targets.csv as the request body")
    text = await run_in_threadpool(
        _with_model,
        jobs,
        job_id,
        force,
        model_files.exported,
        format,
        data if format == "rapid" else None,
        filename,
    )
    name = model_files.download_name(jobs.model_path(job_id), job_id, model_files.ENDING[format])
    return Response(
        text,
        media_type=model_files.MEDIA[format],
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


@router.post(
    "/{job_id}/verify",
    status_code=201,
    dependencies=[Authorized],
    response_model=CampaignDetail,
    responses={
        409: {"description": "the arm runs another campaign, or no cell to verify on"},
        422: {"description": "a test point the arm cannot reach, or bad options"},
        **CALL_PROBLEMS,
    },
    openapi_extra=json_body(VerifyCreate),
)
def verify_model(
    job_id: JobId, body: VerifyBody, jobs: JobsDep, db: DbDep, acquisitions: AcquisitionsDep
):
    """Plan an ISO 9283 verification run of the job's model on the cell its campaign was measured
    on (the same simulated arm, on a simulated cell), store it as a campaign and start it (unless
    `start` is false): follow it as any campaign (pause, e-stop, reset, resume); once done, its
    figures are at GET /api/campaigns/{id}/verification and its certificate at .../certificate."""
    path, job = jobs.model_path(job_id), store.get_job(db, job_id=job_id)
    if job.campaign_id is None:  # a planning job (model_path refused it already)
        raise store.NotFound(f"job {job_id} has no model")
    source = store.get_campaign(db, campaign_id=job.campaign_id)
    cell = parse_cell(source.cell_json, f"<campaign {source.id} cell>")
    was = (source.settings or {}).get("options") or {}  # how the campaign was acquired
    if cell.simulated and not was:
        raise store.Conflict(
            f"campaign {source.id}'s readings were imported on a simulated cell: there is no "
            "simulated arm to verify this model on"
        )
    busy = acquisitions.running()
    if body.start and busy is not None:
        raise store.Conflict(f"campaign {busy} is running; one at a time")
    opts = verification.VerifyOptions(
        cycles=body.cycles,
        directions=body.directions,
        points=None
        if body.points is None
        else ([p.point for p in body.points], [[p.x_mm, p.y_mm, p.z_mm] for p in body.points]),
        side_mm=body.side_mm,
        seed=was.get("seed", 0),
        name=body.name,
        effects=tuple(was.get("effects", ())),
        pause_s=body.pause_s,
        # the tracker reads the SMRs as it did for the calibration
        samples=was.get("samples", verification.VerifyOptions.samples),
        settle=was.get("settle", verification.VerifyOptions.settle),
        arm=source.arm,  # the arm the model is of
    )
    with call_slot(jobs):
        q_deg, labels, settings = run_call(
            jobs, verification.prepare, cell, path, opts, f"job-{job_id}.model.json"
        )
    cid = campaigns.plan_given(
        db,
        cell=cell,
        opts=verification.acquire_options(cell, opts, verification.run_poses(q_deg, settings)),
        poses_deg=q_deg,
        labels=labels,
        settings={**settings, "model_job": job_id},
    )
    if body.start:
        acquisitions.request(campaign_id=cid, action="start")
    return public_campaign(store.get_campaign(db, campaign_id=cid), acquisitions, CampaignDetail)
