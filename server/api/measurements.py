"""Measurements: a campaign's readings as JSON or meas.csv, and meas.csv import."""

from __future__ import annotations

from fastapi import APIRouter, Query, Request
from fastapi.responses import PlainTextResponse
from starlette.concurrency import run_in_threadpool

from server import store

from . import ops
from .deps import Authorized, DbDep, SettingsDep
from drivers.lifecycle import allowed

from .schemas import CampaignPublic, ReadingPublic

router = APIRouter(tags=["measurements"])
CSV_BODY = {"requestBody": {"required": True, "content": {"text/csv": {
    "schema": {"type": "string", "description": "a meas.csv (spec section 1)"}}}}}


@router.get("/campaigns/{campaign_id}/measurements")
def list_readings(campaign_id: int, db: DbDep) -> list[ReadingPublic]:
    """Every reading of the campaign (missing targets included), in plan order."""
    return [ReadingPublic(pose=label, pose_index=r.pose_index, target=r.target, status=r.status,
                          xyz=r.xyz, std=r.std, samples=r.samples, time_s=r.time_s,
                          temp_c=r.temp_c, detail=r.detail)
            for label, r in ops.campaign_readings(db, campaign_id=campaign_id)]


@router.get("/campaigns/{campaign_id}/measurements.csv", response_class=PlainTextResponse,
            responses={200: {"content": {"text/csv": {}}}})
def export_readings(campaign_id: int, db: DbDep) -> PlainTextResponse:
    """The campaign as a meas.csv."""
    text = ops.export_campaign_csv(db, campaign_id=campaign_id)
    return PlainTextResponse(text, media_type="text/csv", headers={
        "Content-Disposition": f'attachment; filename="campaign-{campaign_id}.csv"'})


@router.post("/measurements/import", status_code=201, dependencies=[Authorized],
             openapi_extra=CSV_BODY)
async def import_readings(request: Request, db: DbDep, settings: SettingsDep,
                          name: str | None = Query(None, min_length=1),
                          filename: str = "meas.csv",
                          cell_id: str = "default") -> CampaignPublic:
    """Store a meas.csv as a done campaign; a bad file is 422 with its line and nothing stored."""
    data = await request.body()
    cell = ops.load_cell(cells_dir=settings.cells_dir, cell_id=cell_id)
    cid = await run_in_threadpool(ops.import_campaign_csv, db, data=data, filename=filename,
                                  cell=cell, name=name or filename)
    info = store.get_campaign(db, campaign_id=cid)
    return CampaignPublic(id=info.id, name=info.name, created_at=info.created_at,
                          status=info.status, actions=allowed(info.status),
                          simulated=info.simulated, notes=info.notes,
                          poses_total=info.n_poses, poses_done=info.n_done)
