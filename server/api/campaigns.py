"""Campaigns: plan one on a cell (simulated or real), follow its progress, start, abort, e-stop."""

from __future__ import annotations


from fastapi import APIRouter

from server import store
from server.acquire import AcquireOptions
from server.campaign_planning import check_plan_size, plan_in_worker, plans_long

from . import ops
from .deps import AcquisitionsDep, Authorized, DbDep, JobsDep, SettingsDep
from .schemas import (CampaignCreate, CampaignDetail, CampaignPublic, EstopPublic, RunPublic,
                      StopPublic)
from .worker_calls import CALL_PROBLEMS, run_call

router = APIRouter(prefix="/campaigns", tags=["campaigns"])
ABORT_NOTE = ("a running acquisition ends after the pose in progress, whose readings are kept; "
              "one not running is marked aborted at once")
ESTOP_NOTE = ("STOP sent to the controller (the arm halts where it is) and the campaign aborted; "
              "one not running is just marked aborted; the cell's hardware e-stop still rules")


def _public(info: store.CampaignInfo, acquisitions, cls=CampaignPublic, run=...):
    """The campaign as the API shows it; run: its run state read before info (default: now)."""
    run = acquisitions.get(info.id) if run is ... else run
    extra = {"settings": info.settings} if cls is CampaignDetail else {}
    return cls(id=info.id, name=info.name, created_at=info.created_at, status=info.status,
               simulated=info.simulated, notes=info.notes, poses_total=info.n_poses,
               poses_done=info.n_done, run=None if run is None else RunPublic(
                   state=run.state, stop_requested=run.stop_requested, detail=run.detail,
                   summary=run.summary), **extra)


@router.post("", status_code=201, dependencies=[Authorized], responses=CALL_PROBLEMS)
def create_campaign(body: CampaignCreate, db: DbDep, settings: SettingsDep,
                    acquisitions: AcquisitionsDep, jobs: JobsDep) -> CampaignDetail:
    """Plan a campaign on the cell (stored `planned`; POST .../start runs it): on its real devices
    if the cell has `devices`, else on the simulated ones. A D-optimal choice beyond the
    planning bounds is refused at once (422); a long planning (D-optimal choice, long tour) runs
    in a worker process under the request limit (504 past it)."""
    cell = ops.load_cell(cells_dir=settings.cells_dir, cell_id=body.cell_id)
    opts = AcquireOptions(**body.model_dump(exclude={"cell_id"}))
    check_plan_size(opts)
    if plans_long(opts):
        cid = run_call(jobs, plan_in_worker, db.engine.url.render_as_string(hide_password=False),
                       cell, opts)
    else:
        cid = ops.plan_campaign(db, cell=cell, opts=opts)
    return _public(store.get_campaign(db, campaign_id=cid), acquisitions, CampaignDetail)


@router.get("")
def list_campaigns(db: DbDep, acquisitions: AcquisitionsDep,
                   status: str | None = None) -> list[CampaignPublic]:
    """Every campaign, oldest first (or those with this status)."""
    return [_public(c, acquisitions) for c in store.list_campaigns(db, status=status)]


@router.get("/{campaign_id}")
def get_campaign(campaign_id: int, db: DbDep, acquisitions: AcquisitionsDep) -> CampaignDetail:
    """One campaign with its live state: status and poses done of total, from the store."""
    # the run first: a run that ends in between then shows with the status it left behind
    run = acquisitions.get(campaign_id)
    return _public(store.get_campaign(db, campaign_id=campaign_id), acquisitions, CampaignDetail,
                   run=run)


@router.post("/{campaign_id}/start", status_code=202, dependencies=[Authorized])
def start_campaign(campaign_id: int, db: DbDep,
                   acquisitions: AcquisitionsDep) -> CampaignPublic:
    """Run (or resume) the acquisition on the worker thread; poll GET for progress."""
    acquisitions.start(campaign_id=campaign_id)
    return _public(store.get_campaign(db, campaign_id=campaign_id), acquisitions)


@router.post("/{campaign_id}/pause", dependencies=[Authorized])
def pause_campaign(campaign_id: int, acquisitions: AcquisitionsDep) -> StopPublic:
    """Pause the running acquisition after its current pose (409 if it is not running here)."""
    was = acquisitions.pause(campaign_id=campaign_id)
    return StopPublic(id=campaign_id, status="paused", was=was,
                      note="the engine pauses after the pose in progress; POST .../resume")


@router.post("/{campaign_id}/resume", status_code=202, dependencies=[Authorized])
def resume_campaign(campaign_id: int, acquisitions: AcquisitionsDep) -> StopPublic:
    """Resume a paused campaign (the live engine, or a new run from its next unmeasured pose)."""
    was = acquisitions.resume(campaign_id=campaign_id)
    return StopPublic(id=campaign_id, status="running", was=was, note="resumed")


@router.post("/{campaign_id}/abort", dependencies=[Authorized])
def abort_campaign(campaign_id: int, acquisitions: AcquisitionsDep) -> StopPublic:
    """Abort the campaign after the pose in progress (final: readings stay, no resume)."""
    was = acquisitions.stop(campaign_id=campaign_id, how="abort")
    return StopPublic(id=campaign_id, status="aborted", was=was, note=ABORT_NOTE)


@router.post("/{campaign_id}/estop", dependencies=[Authorized])
def estop_campaign(campaign_id: int, acquisitions: AcquisitionsDep) -> StopPublic:
    """Emergency stop: the controller halts the arm now and the campaign is aborted."""
    was = acquisitions.stop(campaign_id=campaign_id, how="estop")
    return StopPublic(id=campaign_id, status="aborted", was=was, note=ESTOP_NOTE)


estop_router = APIRouter(tags=["campaigns"])


@estop_router.post("/estop", dependencies=[Authorized])
def estop_all(acquisitions: AcquisitionsDep) -> EstopPublic:
    """Emergency stop whatever campaign runs (none: nothing to do); the cell's hardware e-stop
    still rules."""
    cid = acquisitions.emergency_stop_all()
    return EstopPublic(campaign_id=cid, note=ESTOP_NOTE if cid is not None else "nothing runs")


__all__ = ["estop_router", "router"]
