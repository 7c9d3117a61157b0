"""Measurements: a campaign's readings as JSON or meas.csv, and meas.csv import."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import StreamingResponse
from starlette.concurrency import iterate_in_threadpool, run_in_threadpool

from robocal.server import store
from robocal.server.acquisition import campaigns, cells
from robocal.server.recordings import live as recording_live
from robocal.server.service import uploads

from .bodies import csv_body
from .campaigns import public_campaign
from .deps import AcquisitionsDep, Authorized, CampaignId, DbDep, JobsDep, SettingsDep
from .schemas import MAX_ID, PRINTABLE, CampaignPublic, ReadingPublic
from .worker_calls import CALL_PROBLEMS, run_call

router = APIRouter(tags=["measurements"])
# Readings per page of GET .../measurements: a page stays a few megabytes whatever the campaign.
PAGE_MAX = 10_000
TOTAL_HEADER = "X-Total-Count"
CSV_BODY = csv_body("a meas.csv (spec section 1): a header row, then readings")


@router.get(
    "/campaigns/{campaign_id}/measurements",
    responses={
        200: {
            "headers": {
                TOTAL_HEADER: {
                    "description": "readings the campaign has in all",
                    "schema": {"type": "integer"},
                }
            }
        }
    },
)
def list_readings(
    campaign_id: CampaignId,
    db: DbDep,
    response: Response,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
    limit: Annotated[int, Query(ge=1, le=PAGE_MAX)] = 1000,
) -> list[ReadingPublic]:
    """A page of the campaign's readings (missing targets included), in plan order: `limit`
    from `offset`; the X-Total-Count header says how many there are in all."""
    total, page = store.readings_page(db, campaign_id=campaign_id, offset=offset, limit=limit)
    response.headers[TOTAL_HEADER] = str(total)
    return [
        ReadingPublic(
            pose=label,
            pose_index=r.pose_index,
            target=r.target,
            status=r.status,
            xyz=r.xyz,
            std=r.std,
            samples=r.samples,
            time_s=r.time_s,
            temp_c=r.temp_c,
            detail=r.detail,
        )
        for label, r in page
    ]


@router.get(
    "/campaigns/{campaign_id}/measurements.csv",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}}}},
)
async def export_readings(campaign_id: CampaignId, db: DbDep) -> StreamingResponse:
    """The campaign as a meas.csv, streamed (409 if it has no readings yet)."""
    lines = store.export_lines(db, campaign_id=campaign_id)
    # The first chunk (header) is read here, so a missing campaign is a 404 before streaming.
    first = await run_in_threadpool(next, lines)

    async def body():
        yield first
        async for chunk in iterate_in_threadpool(lines):
            yield chunk

    return StreamingResponse(
        body(),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="campaign-{campaign_id}.csv"'},
    )


@router.post(
    "/measurements/import",
    status_code=201,
    dependencies=[Authorized],
    openapi_extra=CSV_BODY,
    responses=CALL_PROBLEMS,
)
async def import_readings(
    request: Request,
    db: DbDep,
    settings: SettingsDep,
    acquisitions: AcquisitionsDep,
    jobs: JobsDep,
    name: Annotated[str | None, Query(max_length=200, pattern=PRINTABLE)] = None,
    filename: Annotated[str, Query(max_length=255, pattern=PRINTABLE)] = "meas.csv",
    cell_id: Annotated[str, Query(max_length=64)] = "default",
    arm: Annotated[
        str | None,
        Query(
            min_length=1,
            max_length=64,
            pattern=PRINTABLE,
            description="the physical arm measured (its serial number), for the fleet view",
        ),
    ] = None,
) -> CampaignPublic:
    """Store a meas.csv as a done campaign; a bad file is 422 with its line and nothing stored."""
    data = await request.body()
    cell = cells.load_cell(cells_dir=settings.cells_dir, cell_id=cell_id)
    cid = await run_in_threadpool(_import, jobs, db, data, filename, cell, name or filename, arm)
    return public_campaign(store.get_campaign(db, campaign_id=cid), acquisitions)


def _import(jobs, db, data: bytes, filename: str, cell, name: str, arm: str | None) -> int:
    """The file read in a worker process (no parse holds this one's GIL), stored from here."""
    meas = run_call(jobs, uploads.read_measurements, data, filename, cell.robot, list(cell.targets))
    return campaigns.import_campaign(
        db, measurements=meas, filename=filename, cell=cell, name=name, arm=arm
    )


NEXT_POSE_HEADER = "X-Next-Pose"


@router.get(
    "/campaigns/{campaign_id}/recording",
    response_class=Response,
    responses={
        200: {
            "content": {"application/octet-stream": {}},
            "headers": {
                NEXT_POSE_HEADER: {
                    "description": "the from_pose of the next piece",
                    "schema": {"type": "integer"},
                }
            },
        }
    },
)
def get_live_recording(
    campaign_id: CampaignId,
    db: DbDep,
    from_pose: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> Response:
    """The campaign's readings as a Rerun recording (.rrd), live: the poses from `from_pose` on
    that have an outcome; X-Next-Pose says where the next piece starts (an empty body: nothing
    new yet). Pieces of one campaign add up to one recording in the viewer."""
    piece = recording_live.campaign_piece(db, campaign_id, from_pose)
    return Response(
        piece.rrd,
        media_type="application/octet-stream",
        headers={NEXT_POSE_HEADER: str(piece.next_pose), "Cache-Control": "no-store"},
    )
