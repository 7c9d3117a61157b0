"""The service's settings, from ROBOCAL_* environment variables (and DATABASE_URL)."""

from __future__ import annotations

from pathlib import Path

from pydantic import AliasChoices, Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """Where the service keeps its data, where it listens, and who may call it from a browser."""

    model_config = SettingsConfigDict(env_prefix="ROBOCAL_", populate_by_name=True, extra="ignore")

    # A SQLAlchemy URL or a plain SQLite file path; DATABASE_URL is honoured as hosting platforms
    # set it, but ROBOCAL_DATABASE wins so a stray platform variable cannot redirect a cell's data.
    database: str = Field(
        "robocal.db", validation_alias=AliasChoices("ROBOCAL_DATABASE", "DATABASE_URL", "database")
    )
    # Loopback only unless told otherwise: the API can command a robot to move.
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    # Models, recordings, uploaded cells and the token hash live here.
    data_dir: Path = Path("robocal-data")
    # Browser origins allowed to call the API; none by default (the UI is served same-origin).
    cors_origins: list[str] = []
    # Worker processes for calibration and diagnosis jobs, each running one job at a time
    # (CPU-bound numpy); jobs beyond them wait queued.
    job_workers: int = Field(2, ge=1, le=64)
    # Wall clock a job may run before its worker process is killed and the job failed.
    job_timeout_s: float = Field(900.0, gt=0)
    # Evaluations and charts run in short-lived worker processes: this many at once, each
    # killed (504) past its limit.
    call_workers: int = Field(4, ge=1, le=64)
    call_timeout_s: float = Field(60.0, gt=0)
    # Reads (GET) need the token like writes do, so that a shop network sees none of the cell's
    # data; true opens them, and only when `host` is a loopback address (a single-user bench).
    open_reads: bool = False
    # The largest request body (a cell.json or meas.csv upload); beyond it the answer is 413.
    max_upload_bytes: int = Field(32 * 1024 * 1024, ge=1024, le=1024**3)
    # A running rerun viewer to stream calibration recordings to live, e.g.
    # rerun+http://127.0.0.1:9876/proxy; the .rrd files are written either way.
    rerun_viewer_url: str | None = None

    @property
    def models_dir(self) -> Path:
        return self.data_dir / "models"

    @property
    def recordings_dir(self) -> Path:
        return self.data_dir / "recordings"

    @property
    def viewer_dir(self) -> Path:
        """Rerun's web viewer, copied from the installed rerun-sdk on first use (server/service/viewer.py)."""
        return self.data_dir / "viewer"

    @property
    def cells_dir(self) -> Path:
        return self.data_dir / "cells"

    @property
    def token_file(self) -> Path:
        return self.data_dir / "token.sha256"
