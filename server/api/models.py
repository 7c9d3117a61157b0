"""Models: the model.json a done calibration job wrote."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse

from .deps import JobsDep

router = APIRouter(prefix="/models", tags=["models"])


@router.get("/{job_id}", response_class=FileResponse,
            responses={200: {"content": {"application/json": {}}}})
def get_model(job_id: int, jobs: JobsDep) -> FileResponse:
    """The model.json of a done job (404 no job, 409 not done)."""
    return FileResponse(jobs.model_path(job_id), media_type="application/json",
                        filename=f"job-{job_id}.model.json")
