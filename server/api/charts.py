"""Charts of a done calibration job: AP box plots and per-pose errors (PNG), the paper's Table 3.

Drawn in a short-lived worker process under a wall-clock limit (Jobs.call): a campaign the
numerics choke on costs a 504 and a killed process, never a hung request. Drawn once a job and
kept (server/figures/cache.py): `X-Robocal-Cache` says whether an answer was kept or drawn."""

from __future__ import annotations

import json

from fastapi import APIRouter, Response

from robocal.server import store
from robocal.server.figures import cache as chart_cache
from robocal.server.figures import charts
from robocal.server.formats.cell_json import parse_cell
from robocal.solver.finite import require_inputs

from .deps import DbDep, JobId, JobsDep, SettingsDep
from .problems import Responses
from .worker_calls import CALL_PROBLEMS, call_slot, run_call

router = APIRouter(prefix="/charts", tags=["charts"])
PNG: Responses = {200: {"content": {"image/png": {}}}, **CALL_PROBLEMS}


def _inputs(db, jobs, job_id: int, model: bool = True) -> tuple:
    """(model path, cell JSON, readings, method) of a done job's campaign; checked here, so a
    missing job or campaign answers at once (NotFound / Conflict through jobs.model_path)."""
    path = jobs.model_path(job_id) if model else None
    job = jobs.get(job_id)
    if job.kind == "planning":
        raise store.NotFound(f"job {job_id} planned a campaign; it has no charts")
    info = store.get_campaign(db, campaign_id=job.campaign_id)
    cell = parse_cell(info.cell_json, f"<campaign {job.campaign_id} cell>")
    meas = store.campaign_measurements(db, campaign_id=job.campaign_id, robot=cell.robot)
    if meas.n_poses == 0:
        raise store.StoreError(f"campaign {job.campaign_id} has no readings")
    require_inputs(meas.q, meas.xyz)  # refused here at once, no worker needed
    return path, info.cell_json, meas, job


def _png(data: bytes, kept: bool) -> Response:
    # The job's own picture, kept under a key of the job and its files; the browser must not
    # keep it too: a new database behind the same URL has other jobs of the same ids.
    return Response(
        data,
        media_type="image/png",
        headers={"Cache-Control": "no-store", "X-Robocal-Cache": "hit" if kept else "miss"},
    )


def _folder(settings, db, jobs, job_id: int):
    """The job's chart folder under the data directory (its key: the job, cell and model)."""
    job = jobs.get(job_id)
    if job.kind == "planning":
        raise store.NotFound(f"job {job_id} planned a campaign; it has no charts")
    path = jobs.model_path(job_id)
    info = store.get_campaign(db, campaign_id=job.campaign_id)
    key = chart_cache.job_key(job, info.cell_json, path)
    return settings.data_dir / "charts" / f"job-{job_id}-{key}"


def _chart(name, draw, job_id, settings, db, jobs) -> Response:
    folder = _folder(settings, db, jobs, job_id)

    def drawn() -> bytes:
        with call_slot(jobs):
            path, cell_json, meas, job = _inputs(db, jobs, job_id)
            return run_call(jobs, draw, job_id, path, cell_json, meas, job.method)

    return _png(*chart_cache.cached(folder, name, drawn))


@router.get("/jobs/{job_id}/boxplot.png", response_class=Response, responses=PNG)
def boxplot(job_id: JobId, db: DbDep, jobs: JobsDep, settings: SettingsDep) -> Response:
    """AP error per SMR before (nominal) and after calibration, as the paper's Figures 2-6."""
    return _chart("boxplot.png", charts.boxplot_png, job_id, settings, db, jobs)


@router.get("/jobs/{job_id}/errors.png", response_class=Response, responses=PNG)
def errors(job_id: JobId, db: DbDep, jobs: JobsDep, settings: SettingsDep) -> Response:
    """AP error per pose (worst SMR of the pose) before and after calibration."""
    return _chart("errors.png", charts.errors_png, job_id, settings, db, jobs)


@router.get("/jobs/{job_id}/table3", responses=CALL_PROBLEMS)
def table3(
    job_id: JobId, db: DbDep, jobs: JobsDep, settings: SettingsDep, response: Response
) -> dict:
    """The paper's Table 3 for the job's campaign: every method on its data, side by side."""

    def drawn() -> bytes:
        with call_slot(jobs):  # loading the readings is heavy too: at most call_workers at once
            _, cell_json, meas, _job = _inputs(db, jobs, job_id, model=False)
            return json.dumps(run_call(jobs, charts.table3, cell_json, meas)).encode()

    if jobs.get(job_id).state == "done":  # kept with the job's charts, under the same key
        data, kept = chart_cache.cached(_folder(settings, db, jobs, job_id), "table3.json", drawn)
    else:  # of a job still running: its campaign's readings, drawn each time
        data, kept = drawn(), False
    response.headers["X-Robocal-Cache"] = "hit" if kept else "miss"
    job = jobs.get(job_id)
    return {
        "job_id": job_id,
        "campaign_id": job.campaign_id,
        "method": job.method,
        **json.loads(data),
    }


__all__ = ["router"]
