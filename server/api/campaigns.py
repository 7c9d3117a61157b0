"""Campaigns: plan one on a cell (simulated or real), follow its progress, and move it through its
life cycle (start, pause, resume, abort, reset, e-stop), each request checked against the state."""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import HTMLResponse, JSONResponse

from robocal.server import store
from robocal.server.acquisition import campaigns, cells
from robocal.server.acquisition.acquire import AcquireOptions
from robocal.server.acquisition.compensated import total_poses
from robocal.server.acquisition.planning import check_plan_size, plans_long
from robocal.server.service.acquisitions import Run
from robocal.server.verify import run as verification

from .bodies import json_body, read_json
from .deps import (
    AcquisitionsDep,
    Authorized,
    AuthorizedNow,
    CampaignId,
    CampaignStatus,
    DbDep,
    JobsDep,
    SettingsDep,
)
from .jobs import public_job
from .problems import Responses, problem
from .schemas import (
    ActionPublic,
    CampaignCreate,
    CampaignDetail,
    CampaignPublic,
    EstopPublic,
    JobPublic,
    RunPublic,
)
from .worker_calls import CALL_PROBLEMS, call_slot, run_call

router = APIRouter(prefix="/campaigns", tags=["campaigns"])
CampaignBody = Annotated[CampaignCreate, Depends(read_json(CampaignCreate))]
ESTOP_NOTE = (
    "STOP sent to the controller (the arm halts where it is), the campaign e-stopped; "
    "POST .../reset, then .../resume, continues it; the cell's hardware e-stop rules"
)
# An e-stop is answered within this (502 "unconfirmed" past it), whatever the controller does.
ESTOP_ANSWER_S = 1.0
CONFLICT: Responses = {
    409: {
        "description": "the campaign's state does not allow this action (the body "
        "says its `state` and `allowed_actions`)"
    }
}


def public_campaign(
    info: store.CampaignInfo,
    acquisitions,
    cls=CampaignPublic,
    status: str | None = None,
    run: Run | None = None,
):
    """The campaign as the API shows it: its life-cycle state (`status` and `run` if read
    already, see Acquisitions.shown) and the actions it allows."""
    run = run or acquisitions.get(info.id)
    status = status or acquisitions.status_of(info)
    extra = {"settings": info.settings} if cls is CampaignDetail else {}
    return cls(
        id=info.id,
        name=info.name,
        kind="verification" if verification.is_verification(info) else "measurement",
        created_at=info.created_at,
        status=status,
        actions=acquisitions.actions(info, status),
        simulated=info.simulated,
        notes=info.notes,
        arm=info.arm,
        # a verification's compensated poses are stored one by one as the run reaches them
        poses_total=total_poses(info.settings, info.n_poses),
        poses_done=info.n_done,
        run=None
        if run is None
        else RunPublic(active=run.active, detail=run.detail, summary=run.summary),
        **extra,
    )


def _acted(outcome, db, acquisitions, note: str) -> ActionPublic:
    """The campaign after the request, in the state the request left it in."""
    info = store.get_campaign(db, campaign_id=outcome.campaign_id)
    now = public_campaign(info, acquisitions).model_dump()
    now.update(status=outcome.status, actions=acquisitions.actions(info, outcome.status))
    return ActionPublic(**now, was=outcome.was, note=outcome.note or note)


PLANNING_JOB: Responses = {
    202: {
        "model": JobPublic,
        "description": "A planning that may take seconds (a D-optimal choice, a long tour) is "
        "queued as a `planning` job: follow it at `Location` (GET /api/jobs/{id}, "
        "progress 0..1); it ends done with `campaign_url`, or failed with the reason",
        "headers": {"Location": {"description": "the planning job", "schema": {"type": "string"}}},
    }
}


@router.post(
    "",
    status_code=201,
    dependencies=[Authorized],
    response_model=CampaignDetail,
    responses=PLANNING_JOB,
    openapi_extra=json_body(CampaignCreate),
)
def create_campaign(
    body: CampaignBody,
    db: DbDep,
    settings: SettingsDep,
    acquisitions: AcquisitionsDep,
    jobs: JobsDep,
):
    """Plan a campaign on the cell (stored `planned`; POST .../start runs it): on its real devices
    if the cell has `devices`, else on the simulated ones. Random poses are planned at once
    (201, the campaign); a D-optimal choice or a long tour is queued as a planning job (202, the
    job); a D-optimal choice beyond the planning bounds is refused at once (422)."""
    cell = cells.load_cell(cells_dir=settings.cells_dir, cell_id=body.cell_id)
    opts = AcquireOptions(**body.model_dump(exclude={"cell_id"}))
    check_plan_size(opts)
    if plans_long(opts):
        job = public_job(jobs.submit_planning(cell=cell, opts=opts))
        return JSONResponse(
            job.model_dump(mode="json"),
            status_code=202,
            headers={"Location": f"/api/jobs/{job.id}"},
        )
    cid = campaigns.plan_campaign(db, cell=cell, opts=opts)
    return public_campaign(store.get_campaign(db, campaign_id=cid), acquisitions, CampaignDetail)


@router.get("")
def list_campaigns(
    acquisitions: AcquisitionsDep, status: CampaignStatus | None = None
) -> list[CampaignPublic]:
    """Every campaign, oldest first (or those with this status, as shown)."""
    return [
        public_campaign(info, acquisitions, status=shown, run=run)
        for info, shown, run in acquisitions.shown_all(status)
    ]


@router.get("/{campaign_id}")
def get_campaign(campaign_id: CampaignId, acquisitions: AcquisitionsDep) -> CampaignDetail:
    """One campaign with its state, the actions it allows, and its poses done of total (read
    only: a campaign left moving by a process that is gone shows failed)."""
    info, status, run = acquisitions.shown(campaign_id)
    return public_campaign(info, acquisitions, CampaignDetail, status, run)


VERIFICATION_PROBLEMS: Responses = {
    404: {"description": "no such campaign, or it is no verification run"},
    409: {"description": "the verification run is not done yet"},
    422: {"description": "a test point's reading is missing"},
    **CALL_PROBLEMS,
}


def _verification(jobs, db, campaign_id: int, target):
    """target(campaign, readings) of a done verification run, in a worker."""
    with call_slot(jobs):
        info, meas = verification.readings(db, campaign_id)
        return run_call(jobs, target, info, meas)


@router.get("/{campaign_id}/verification", responses=VERIFICATION_PROBLEMS)
def get_verification(campaign_id: CampaignId, db: DbDep, jobs: JobsDep) -> dict:
    """A done verification run's ISO 9283 figures (mm), before (nominal joints) and after
    (compensated): per test point AP, RP and vAP, per pair of points AD and RD."""
    return _verification(jobs, db, campaign_id, verification.verification_json)


@router.get(
    "/{campaign_id}/certificate",
    response_class=HTMLResponse,
    responses={200: {"content": {"text/html": {}}}, **VERIFICATION_PROBLEMS},
)
def get_certificate(campaign_id: CampaignId, db: DbDep, jobs: JobsDep) -> HTMLResponse:
    """A done verification run's accuracy certificate: one HTML page with its plots and tables,
    printable to PDF (A4)."""
    return HTMLResponse(_verification(jobs, db, campaign_id, verification.certificate))


def _action(name: str, doc: str, note: str, status_code: int = 200):
    def route(campaign_id: CampaignId, db: DbDep, acquisitions: AcquisitionsDep) -> ActionPublic:
        outcome = acquisitions.request(campaign_id=campaign_id, action=name)
        return _acted(outcome, db, acquisitions, note)

    route.__name__ = f"{name}_campaign"
    route.__doc__ = doc
    router.post(
        f"/{{campaign_id}}/{name}",
        status_code=status_code,
        dependencies=[Authorized],
        responses=CONFLICT,
    )(route)


_action(
    "start",
    "Run the acquisition on the worker thread (planned); poll GET for progress.",
    "queued",
    202,
)
_action(
    "pause",
    "Pause the run after its current pose (running).",
    "the engine pauses after the pose in progress; POST .../resume",
)
_action(
    "resume",
    "Resume: the live engine (pausing, paused), or a new run from the next "
    "unmeasured pose (paused, failed).",
    "resumed",
    202,
)
_action(
    "abort",
    "Abort: a run ends after the pose in progress; final, the readings stay.",
    "aborted after the pose in progress; the readings stay",
)
_action(
    "reset",
    "Bring an e-stopped (or failed) campaign back to paused, after the cell was "
    "checked; POST .../resume then continues it at its next unmeasured pose.",
    "reset to paused; POST .../resume continues it",
)


async def _estop(request: Request, campaign_id: int | None):
    """The e-stop on the event loop: the work on the acquisitions' own stop threads (never the
    server's thread pool), answered within ESTOP_ANSWER_S."""
    acquisitions = request.app.state.acquisitions
    future = acquisitions.stops.submit(acquisitions.estop, campaign_id)
    try:
        outcome = await asyncio.wait_for(asyncio.wrap_future(future), ESTOP_ANSWER_S)
    except TimeoutError:
        return problem(
            request,
            502,
            f"unconfirmed: the controller did not confirm the stop "
            f"within {ESTOP_ANSWER_S:g} s; use the cell's hardware e-stop",
            campaign_id=campaign_id,
            confirmed=False,
        )
    if outcome.confirmed is False:
        return problem(
            request,
            502,
            "unconfirmed: the controller did not confirm the stop; use the cell's hardware e-stop",
            campaign_id=outcome.campaign_id,
            state=outcome.status,
            confirmed=False,
        )
    note = outcome.note or ESTOP_NOTE
    return EstopPublic(
        campaign_id=outcome.campaign_id,
        status=outcome.status,
        was=outcome.was,
        confirmed=outcome.confirmed,
        actions=list(outcome.actions),
        note=note,
    )


ESTOP_RESPONSES: Responses = {
    **CONFLICT,
    502: {"description": "unconfirmed: the controller did not confirm the stop within 1 s"},
}


@router.post("/{campaign_id}/estop", dependencies=[AuthorizedNow], responses=ESTOP_RESPONSES)
async def estop_campaign(campaign_id: CampaignId, request: Request) -> EstopPublic:
    """Emergency stop: the campaign is e-stopped and the controller halts the arm now (200 once
    it confirmed; 502 if it did not within 1 s)."""
    return await _estop(request, campaign_id)


estop_router = APIRouter(tags=["campaigns"])


@estop_router.post("/estop", dependencies=[AuthorizedNow], responses=ESTOP_RESPONSES)
async def estop_all(request: Request) -> EstopPublic:
    """Emergency stop whatever campaign runs here (none: nothing to do); the cell's hardware
    e-stop still rules."""
    return await _estop(request, None)


__all__ = ["estop_router", "router"]
