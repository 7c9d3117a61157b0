"""Models: the model.json a done calibration job wrote."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse

from .deps import CampaignQuery, DbDep, JobId, JobsDep

router = APIRouter(prefix="/models", tags=["models"])


@router.get("/{job_id}", response_class=FileResponse,
            responses={200: {"content": {"application/json": {}}}})
def get_model(job_id: JobId, jobs: JobsDep) -> FileResponse:
    """The model.json of a done job (404 no job, 409 not done)."""
    return FileResponse(jobs.model_path(job_id), media_type="application/json",
                        filename=f"job-{job_id}.model.json")


@router.get("/{job_id}/evaluate")
def evaluate_model(job_id: JobId, campaign_id: CampaignQuery, jobs: JobsDep, db: DbDep) -> dict:
    """Accuracy of a job's model on a campaign's readings, next to the nominal model."""
    from .. import store, workflow
    from ..formats.cell_json import parse_cell
    from ..formats.model_json import read_model

    model = read_model(jobs.model_path(job_id))
    cell = parse_cell(store.get_campaign(db, campaign_id=campaign_id).cell_json)
    meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
    return workflow.evaluate(model, meas)
