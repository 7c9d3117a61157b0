"""Calibration and diagnosis jobs: checked, kept in the store, run in the worker processes of
server.worker, their changes reported on the event bus. A restart fails the ones it cut off."""

from __future__ import annotations

import signal
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from pathlib import Path

from solver.calibrate import parse_method

from . import store
from .events import Events
from .formats.cell_json import parse_cell
from .formats.model_json import model_to_json
from .worker import JobSetup, WorkerPool, campaign_data, job_event, one_line
from .workflow import model_file, run_method

JOB_STATES = ("queued", "running", "done", "failed")
JOB_KINDS = ("calibration", "diagnosis")
RESTART_REASON = "service stopped while running"


Job = store.JobInfo


def check_job(db: store.Database, *, kind: str, campaign_id: int, method: str) -> None:
    """Refuse a job before queueing it: NotFound, Conflict if not done, ValueError if bad."""
    if kind not in JOB_KINDS:
        raise ValueError(f"kind must be one of {', '.join(JOB_KINDS)}, not {kind!r}")
    info = store.get_campaign(db, campaign_id=campaign_id)
    if info.status != "done":
        raise store.Conflict(f"campaign {campaign_id} is {info.status}; {kind} needs a done "
                             "campaign")
    if kind == "calibration":
        targets = sorted(parse_cell(info.cell_json, f"<campaign {campaign_id} cell>").targets)
        parse_method(method, targets)


def check_method(db: store.Database, *, campaign_id: int, method: str) -> None:
    """Refuse a calibration before queueing it (see check_job)."""
    check_job(db, kind="calibration", campaign_id=campaign_id, method=method)


def calibrate_campaign(db: store.Database, *, campaign_id: int, method: str) -> dict:
    """Fit `method` to a stored campaign; the model.json object."""
    cell, meas = campaign_data(db, campaign_id)
    model = model_to_json(model_file(run_method(cell, meas, method), cell, meas))
    model["data"]["campaign"] = campaign_id
    return model


class Jobs:
    """Calibration and diagnosis jobs, kept in the store: queued -> running -> done | failed.

    They run in a pool of worker processes (server.worker), so a job's numpy and Python never
    hold the service's GIL; each worker writes its job's steps to the store and reports them,
    and a thread here forwards the reports to the event bus. A worker that dies fails its job.
    """

    pool_kind = WorkerPool.kind

    def __init__(self, db: store.Database, models_dir: Path, workers: int = 2, *,
                 recordings_dir: Path | None = None, reports_dir: Path | None = None,
                 events: Events | None = None, viewer_url: str | None = None):
        self.db, self.models_dir, self.workers = db, Path(models_dir), workers
        self.recordings_dir = Path(recordings_dir or self.models_dir.parent / "recordings")
        self.reports_dir = Path(reports_dir or self.models_dir.parent / "reports")
        self.events = events or Events()
        self._setup = JobSetup(db.engine.url.render_as_string(hide_password=False),
                               self.models_dir, self.recordings_dir, self.reports_dir, viewer_url)
        self._lock = threading.Lock()
        self._pool: WorkerPool | None = None  # made at the first job, again after a crash
        # Handing a job to the pool may wait seconds for the fork server to start (first job):
        # not on the request's thread. One thread keeps the jobs in order.
        self._sender = ThreadPoolExecutor(1, thread_name_prefix="robocal-job-send")
        self._closing = False
        self._in_flight: set[int] = set()
        self._pids: dict[int, int] = {}  # job id -> the worker process running it
        self._resent: set[int] = set()  # jobs sent again after a crash they never started in
        # Nothing runs a job this process did not queue: fail those a stop cut off.
        for job_id in store.fail_unfinished_jobs(db, reason=RESTART_REASON):
            self._publish(store.get_job(db, job_id=job_id))

    def submit(self, *, campaign_id: int, method: str = "minimax",
               kind: str = "calibration") -> Job:
        """Check and queue a job; the job as queued."""
        if kind == "diagnosis":
            method = "diagnose"
        check_job(self.db, kind=kind, campaign_id=campaign_id, method=method)
        job = store.create_job(self.db, kind=kind, campaign_id=campaign_id, method=method)
        self._publish(job)
        self._send(job.id)
        return job

    def get(self, job_id: int) -> Job:
        return store.get_job(self.db, job_id=job_id)

    def list(self) -> list[Job]:
        return store.list_jobs(self.db)

    def worker_pid(self, job_id: int) -> int | None:
        """The pid of the worker process running this job (None unless it runs)."""
        with self._lock:
            return self._pids.get(job_id)

    def result_path(self, job_id: int, what: str) -> Path:
        """A file a done job wrote (model, recording, report); NotFound / Conflict otherwise."""
        job = self.get(job_id)
        if job.state != "done":
            raise store.Conflict(f"job {job_id} is {job.state}"
                                 + (f": {job.reason}" if job.reason else "") + f"; no {what}")
        path = job.results.get(what)
        if path is None:
            raise store.NotFound(f"job {job_id} ({job.kind}) has no {what}")
        if not Path(path).exists():
            raise store.NotFound(f"job {job_id}'s {what} file is gone from the data dir")
        return Path(path)

    def model_path(self, job_id: int) -> Path:
        """The model file of a done job; NotFound / Conflict otherwise."""
        return self.result_path(job_id, "model")

    def figure_path(self, job_id: int, name: str) -> Path:
        """One figure of a done diagnosis, by file name (only names the job listed)."""
        self.result_path(job_id, "report")
        figures = {Path(p).name: Path(p) for p in self.get(job_id).results.get("figures", [])}
        if name not in figures:
            raise store.NotFound(f"job {job_id} has no figure {name!r}")
        return figures[name]

    def shutdown(self) -> None:
        """End the workers, then fail the jobs they had (a job cannot outlive the service)."""
        with self._lock:
            self._closing = True
            pool, self._pool = self._pool, None
            cut_off = sorted(self._in_flight)
        self._sender.shutdown(wait=False, cancel_futures=True)
        if pool is not None:
            pool.close()
        for job_id in cut_off:
            self._fail(job_id, RESTART_REASON)

    def _publish(self, job: Job) -> None:
        self.events.publish(job_event(job))

    def _send(self, job_id: int) -> None:
        with self._lock:
            if self._closing:
                return  # left queued: the next start fails it
            self._in_flight.add(job_id)
            self._sender.submit(self._dispatch, job_id)

    def _dispatch(self, job_id: int) -> None:
        try:
            pool = self._current_pool()
            try:
                future = pool.submit(self._setup, job_id)
            except BrokenProcessPool:  # a worker died while idle: that pool refuses work
                self._retire(pool)
                pool = self._current_pool()
                future = pool.submit(self._setup, job_id)
        except Exception as e:  # noqa: BLE001 - the job says why it cannot run
            if not self._closing:  # else shutdown() fails it
                with self._lock:
                    self._in_flight.discard(job_id)
                self._fail(job_id, f"no worker process could take it: {one_line(e)}")
            return
        future.add_done_callback(partial(self._finished, job_id, pool))

    def _current_pool(self) -> WorkerPool:
        with self._lock:
            if self._closing:
                raise RuntimeError("the job pool is shut down")
            if self._pool is None:
                self._pool = WorkerPool(self.workers, self._reported)
            return self._pool

    def _reported(self, job_id: int, pid: int, event: dict) -> None:
        with self._lock:
            if event["state"] == "running":
                self._pids[job_id] = pid
            else:
                self._pids.pop(job_id, None)
        self.events.publish(event)

    def _finished(self, job_id: int, pool: WorkerPool, future: Future) -> None:
        # In the pool's thread: the worker wrote done or failed itself unless the call broke.
        error = None if future.cancelled() else future.exception()
        with self._lock:
            self._in_flight.discard(job_id)
            pid = self._pids.pop(job_id, None)
            if self._closing or error is None:
                return
        if not isinstance(error, BrokenProcessPool):
            self._fail(job_id, f"the worker could not run the job: {one_line(error)}")
            return
        self._retire(pool)
        code, state = pool.died.get(pid), self.get(job_id).state
        if state == "queued" and job_id not in self._resent:
            self._resent.add(job_id)  # it never started: another job's worker died
            self._send(job_id)
        elif state == "queued":
            self._fail(job_id, "worker processes died before it could start; see the "
                               "service's log")
        elif pid is None:
            self._fail(job_id, "a worker process died while it ran")
        elif code is None:
            self._fail(job_id, "stopped: another job's worker process died, which ends the "
                               "whole pool")
        else:
            self._fail(job_id, f"its worker process died ({_exit_reason(code)})")

    def _retire(self, pool: WorkerPool) -> None:
        # A broken pool stays broken: the next job gets a new one (and a new report queue).
        with self._lock:
            if self._pool is pool:
                self._pool = None
        pool.close()

    def _fail(self, job_id: int, reason: str) -> None:
        try:
            job = self.get(job_id)
            if job.state not in ("done", "failed"):
                self._publish(store.update_job(self.db, job_id=job_id, state="failed",
                                               reason=reason))
        except store.StoreError:
            pass  # it went done or failed meanwhile, or the store is closing: nothing to mark


def _exit_reason(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


__all__ = ["Job", "Jobs", "RESTART_REASON", "calibrate_campaign", "check_job", "check_method"]
