"""Work the API hands off: calibration jobs in a worker pool, acquisitions on one worker thread.

Both tables live in memory for this increment: a restart forgets jobs (their model files stay
in the data dir) and the campaigns keep their state in the store.
"""

from __future__ import annotations

import datetime as dt
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

from solver.calibrate import parse_method

from . import store
from .acquire import AcquireOptions, acquire
from .formats.cell_json import parse_cell
from .formats.model_json import model_to_json, write_json_atomic
from .workflow import model_file, run_method

JOB_STATES = ("queued", "running", "done", "failed")
# A campaign the engine may (re)start: the store resumes planned, paused and failed ones.
STARTABLE = ("planned", "paused", "failed")


def _now() -> dt.datetime:
    return dt.datetime.now(dt.timezone.utc)


@dataclass(frozen=True)
class Job:
    """A calibration job as the API reports it."""

    id: int
    campaign_id: int
    method: str
    state: str
    reason: str | None
    created_at: dt.datetime
    started_at: dt.datetime | None = None
    finished_at: dt.datetime | None = None
    model_file: str | None = None


def check_method(db: store.Database, *, campaign_id: int, method: str) -> None:
    """Refuse a job before queueing it: NotFound, Conflict if not done, ValueError if bad method."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    if info.status != "done":
        raise store.Conflict(f"campaign {campaign_id} is {info.status}; calibrate a done campaign")
    targets = sorted(parse_cell(info.cell_json, f"<campaign {campaign_id} cell>").targets)
    parse_method(method, targets)


def calibrate_campaign(db: store.Database, *, campaign_id: int, method: str) -> dict:
    """Fit `method` to a stored campaign; the model.json object."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    cell = parse_cell(info.cell_json, f"<campaign {campaign_id} cell>")
    meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
    if meas.n_poses == 0:
        raise store.StoreError(f"campaign {campaign_id} has no readings")
    model = model_to_json(model_file(run_method(cell, meas, method), cell, meas))
    model["data"]["campaign"] = campaign_id
    return model


class Jobs:
    """Calibration jobs: queued -> running -> done | failed (with the reason)."""

    def __init__(self, db: store.Database, models_dir: Path, workers: int = 2):
        self.db, self.models_dir = db, Path(models_dir)
        # Threads: numpy and the QP solvers release the GIL in their heavy loops, so the event
        # loop stays responsive; a process pool is the next step if profiles say otherwise.
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="robocal-job")
        self._lock = threading.Lock()
        self._jobs: dict[int, Job] = {}
        self._next = 1

    def submit(self, *, campaign_id: int, method: str) -> Job:
        """Check and queue a job; the job as queued."""
        check_method(self.db, campaign_id=campaign_id, method=method)
        with self._lock:
            job = Job(self._next, campaign_id, method, "queued", None, _now())
            self._jobs[job.id] = job
            self._next += 1
        self._pool.submit(self._run, job.id)
        return job

    def get(self, job_id: int) -> Job:
        with self._lock:
            if job_id not in self._jobs:
                raise store.NotFound(f"no job {job_id}")
            return self._jobs[job_id]

    def list(self) -> list[Job]:
        with self._lock:
            return list(self._jobs.values())

    def model_path(self, job_id: int) -> Path:
        """The model file of a done job; NotFound / Conflict otherwise."""
        job = self.get(job_id)
        if job.state != "done":
            raise store.Conflict(f"job {job_id} is {job.state}"
                                 + (f": {job.reason}" if job.reason else "") + "; no model")
        return Path(job.model_file)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _update(self, job_id: int, **changes) -> Job:
        with self._lock:
            self._jobs[job_id] = job = replace(self._jobs[job_id], **changes)
            return job

    def _run(self, job_id: int) -> None:
        job = self._update(job_id, state="running", started_at=_now())
        try:
            model = calibrate_campaign(self.db, campaign_id=job.campaign_id, method=job.method)
            path = self.models_dir / f"job-{job_id}.model.json"
            write_json_atomic(path, model)
        except Exception as e:  # the reason is the job's result, not a server error
            self._update(job_id, state="failed", reason=f"{type(e).__name__}: {e}",
                         finished_at=_now())
            return
        self._update(job_id, state="done", model_file=str(path), finished_at=_now())


@dataclass(frozen=True)
class Run:
    """What the acquisition worker did with a campaign since this server started."""

    campaign_id: int
    state: str  # running, finished, failed, stopped (by abort or estop)
    stop_requested: str | None = None  # abort or estop
    detail: str | None = None
    summary: dict | None = None


class Acquisitions:
    """Runs simulated acquisitions one at a time: a cell has one arm."""

    def __init__(self, database_url: str, db: store.Database):
        self.database_url, self.db = database_url, db
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="robocal-acquire")
        self._lock = threading.Lock()
        self._runs: dict[int, Run] = {}
        self._current: int | None = None

    def start(self, *, campaign_id: int) -> Run:
        """Queue the campaign on the worker; Conflict if one is running or it cannot start."""
        info = store.get_campaign(self.db, campaign_id=campaign_id)
        if not info.simulated:
            raise store.Conflict(f"campaign {campaign_id} is not simulated; only the simulated "
                                 "cell can be driven in this version")
        if info.status not in STARTABLE:
            raise store.Conflict(f"campaign {campaign_id} is {info.status}; it can start when "
                                 f"{', '.join(STARTABLE)}")
        with self._lock:
            if self._current is not None:
                raise store.Conflict(f"campaign {self._current} is running; one at a time")
            self._current = campaign_id
            self._runs[campaign_id] = run = Run(campaign_id, "running")
        self._pool.submit(self._run, info)
        return run

    def stop(self, *, campaign_id: int, how: str) -> str:
        """Mark the campaign aborted; the status it had. The engine stops at its next reading,
        which the store then refuses (the arm is not halted mid-move in this version)."""
        with self._lock:  # not between _run's check and its own status change
            before = store.set_status(self.db, campaign_id=campaign_id, status="aborted")
            if campaign_id in self._runs:
                self._runs[campaign_id] = replace(self._runs[campaign_id], stop_requested=how)
        return before

    def get(self, campaign_id: int) -> Run | None:
        with self._lock:
            return self._runs.get(campaign_id)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _run(self, info: store.CampaignInfo) -> None:
        cid = info.id
        try:
            with self._lock:
                # Stopped while queued: acquire() would not find it unfinished and would plan
                # a new campaign of the same name, so it must not be called at all.
                if self._runs[cid].stop_requested:
                    raise _Stopped()
                store.set_status(self.db, campaign_id=cid, status="running")
            opts = AcquireOptions(**{**info.settings.get("options", {}), "name": info.name})
            # acquire() resumes the latest unfinished campaign of this name: the one we planned.
            summary = acquire(self.database_url, parse_cell(info.cell_json), opts)
            change = dict(state="finished", summary=_plain(summary))
        except Exception as e:  # a fault, or the store refusing readings after an abort
            how = self.get(cid).stop_requested
            change = (dict(state="stopped", detail=f"stopped by {how} at the next reading")
                      if how else dict(state="failed", detail=f"{type(e).__name__}: {e}"))
        with self._lock:
            self._runs[cid] = replace(self._runs[cid], **change)
            self._current = None


class _Stopped(Exception):
    """The run was stopped before it began."""


def _plain(summary: dict) -> dict:
    return {k: (float(v) if hasattr(v, "item") else v) for k, v in summary.items()}


__all__ = ["Acquisitions", "Job", "Jobs", "Run", "calibrate_campaign", "check_method"]
