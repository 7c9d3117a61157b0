"""Models: the model.json a done calibration job wrote, and its accuracy on a campaign."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse
from robocal.server import charts, store
from robocal.server.formats.cell_json import parse_cell
from robocal.solver.finite import require_inputs

from .deps import CampaignQuery, DbDep, JobId, JobsDep
from .worker_calls import CALL_PROBLEMS, call_slot, run_call

router = APIRouter(prefix="/models", tags=["models"])


@router.get(
    "/{job_id}", response_class=FileResponse, responses={200: {"content": {"application/json": {}}}}
)
def get_model(job_id: JobId, jobs: JobsDep) -> FileResponse:
    """The model.json of a done job (404 no job, 409 not done)."""
    return FileResponse(
        jobs.model_path(job_id), media_type="application/json", filename=f"job-{job_id}.model.json"
    )


@router.get("/{job_id}/evaluate", responses=CALL_PROBLEMS)
def evaluate_model(job_id: JobId, campaign_id: CampaignQuery, jobs: JobsDep, db: DbDep) -> dict:
    """Accuracy of a job's model on a campaign's readings, next to the nominal model (computed
    in a worker process under a wall-clock limit: 504 past it)."""
    path = jobs.model_path(job_id)
    with call_slot(jobs):  # loading the readings is heavy too: at most call_workers at once
        cell = parse_cell(store.get_campaign(db, campaign_id=campaign_id).cell_json)
        meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
        require_inputs(meas.q, meas.xyz)  # a non-finite campaign: 422 at once, no worker
        return run_call(jobs, charts.evaluation, path, meas)
