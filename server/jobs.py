"""Work the API hands off: calibration and diagnosis jobs in a pool of worker processes,
acquisitions on one worker thread, and the event bus both report to.

Jobs live in the store (a restart marks the ones it cut off as failed); acquisition runs are in
memory, and the campaigns keep their state in the store.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import itertools
import signal
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from solver.calibrate import parse_method

from . import store
from .acquire import AcquireOptions, acquire
from .formats.cell_json import parse_cell
from .formats.model_json import model_to_json, to_plain
from .worker import JobSetup, WorkerPool, campaign_data, job_event, one_line
from .workflow import model_file, run_method

JOB_STATES = ("queued", "running", "done", "failed")
JOB_KINDS = ("calibration", "diagnosis")
# A campaign the engine may (re)start: the store resumes planned, paused and failed ones.
STARTABLE = ("planned", "paused", "failed")
FINAL = ("done", "aborted")
RESTART_REASON = "service stopped while running"
# Past this many unread events a slow subscriber loses the oldest rather than holding memory.
QUEUE_SIZE = 1000


def _now() -> dt.datetime:
    return dt.datetime.now(dt.timezone.utc)


class Events:
    """Fans events out from worker threads to asyncio subscribers (the SSE streams)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._subscribers: set[tuple[asyncio.AbstractEventLoop, asyncio.Queue]] = set()
        self._ids = itertools.count(1)

    def subscribe(self) -> asyncio.Queue:
        """A queue of (id, event) for the calling event loop; unsubscribe() it when done."""
        queue: asyncio.Queue = asyncio.Queue(QUEUE_SIZE)
        with self._lock:
            self._subscribers.add((asyncio.get_running_loop(), queue))
        return queue

    def unsubscribe(self, queue: asyncio.Queue) -> None:
        with self._lock:
            self._subscribers = {(l, q) for l, q in self._subscribers if q is not queue}

    def publish(self, event: dict) -> None:
        """Send an event (a dict with a "type") to every subscriber; safe from any thread."""
        with self._lock:
            item = (next(self._ids), dict(event, time=_now().isoformat()))
            subscribers = list(self._subscribers)
        for loop, queue in subscribers:
            try:
                loop.call_soon_threadsafe(_put, queue, item)
            except RuntimeError:  # that loop has closed: its stream is gone
                self.unsubscribe(queue)

    def close(self) -> None:
        """End every stream (at shutdown)."""
        with self._lock:
            subscribers, self._subscribers = list(self._subscribers), set()
        for loop, queue in subscribers:
            try:
                loop.call_soon_threadsafe(_put, queue, None)
            except RuntimeError:
                pass


def _put(queue: asyncio.Queue, item) -> None:
    if queue.full():
        queue.get_nowait()  # drop the oldest: a stalled client must not stall the workers
    queue.put_nowait(item)


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


@dataclass(frozen=True)
class Run:
    """What the acquisition worker did with a campaign since this server started."""

    campaign_id: int
    state: str  # running, finished, failed, stopped (by abort or estop)
    stop_requested: str | None = None  # abort or estop
    detail: str | None = None
    summary: dict | None = None


class Acquisitions:
    """Runs acquisitions (simulated or on a cell's real devices) one at a time (a cell has one
    arm) and holds the running engine, whose controller client is the real one on a real cell,
    so pause, resume, abort and emergency stop reach it from the request threads."""

    def __init__(self, database_url: str, db: store.Database, events: Events | None = None):
        self.database_url, self.db = database_url, db
        self.events = events or Events()
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="robocal-acquire")
        self._lock = threading.Lock()
        self._runs: dict[int, Run] = {}
        self._current: int | None = None
        self._engine = None  # the CampaignEngine of self._current, once acquire() built it
        # Nothing drives a campaign this process did not start: one left running by a stopped
        # service is failed, so POST .../start resumes it at its next unmeasured pose.
        for c in store.list_campaigns(db, status="running"):
            store.set_status(db, campaign_id=c.id, status="failed")

    def start(self, *, campaign_id: int) -> Run:
        """Queue the campaign on the worker; Conflict if one is running or it cannot start."""
        info = store.get_campaign(self.db, campaign_id=campaign_id)
        if "options" not in (info.settings or {}):
            raise store.Conflict(f"campaign {campaign_id} has no acquisition settings (its "
                                 "readings were imported); there is nothing to acquire")
        if info.status not in STARTABLE:
            raise store.Conflict(f"campaign {campaign_id} is {info.status}; it can start when "
                                 f"{', '.join(STARTABLE)}")
        with self._lock:
            if self._current is not None:
                raise store.Conflict(f"campaign {self._current} is running; one at a time")
            self._current = campaign_id
            self._runs[campaign_id] = run = Run(campaign_id, "running")
        self._state(campaign_id, "queued")
        self._pool.submit(self._run, info)
        return run

    def pause(self, *, campaign_id: int) -> str:
        """Ask the running engine to pause after its current pose; the status it had."""
        from drivers.campaign import StateError

        with self._lock:
            engine = self._running_engine(campaign_id, "pause")
            try:
                engine.pause()
            except StateError as e:
                raise store.Conflict(f"campaign {campaign_id}: {e}") from None
            # Readings of the pose in progress still land: the store records while paused.
            before = store.set_status(self.db, campaign_id=campaign_id, status="paused")
        self._state(campaign_id, "pausing")
        return before

    def resume(self, *, campaign_id: int) -> str:
        """Resume a paused engine, or start a campaign paused before this server started."""
        from drivers.campaign import StateError

        with self._lock:
            engine = self._engine if self._current == campaign_id else None
            if engine is not None:
                try:
                    engine.resume()
                except StateError as e:
                    raise store.Conflict(f"campaign {campaign_id}: {e}") from None
                before = store.set_status(self.db, campaign_id=campaign_id, status="running")
        if engine is None:
            before = store.get_campaign(self.db, campaign_id=campaign_id).status
            if before != "paused":
                raise store.Conflict(f"campaign {campaign_id} is {before}, not paused")
            self.start(campaign_id=campaign_id)
            return before
        self._state(campaign_id, "running")
        return before

    def stop(self, *, campaign_id: int, how: str) -> str:
        """Abort (at the next pose) or emergency-stop (the arm halts now); the status it had.

        With no engine running it just marks the campaign aborted in the store (if not final).
        """
        from drivers.campaign import StateError

        error = None
        with self._lock:
            info = store.get_campaign(self.db, campaign_id=campaign_id)
            before = info.status
            if campaign_id in self._runs:
                self._runs[campaign_id] = replace(self._runs[campaign_id], stop_requested=how)
            engine = self._engine if self._current == campaign_id else None
            if engine is not None and how == "estop":
                try:
                    engine.emergency_stop()
                except Exception as e:  # noqa: BLE001 - the state is marked; the caller is told
                    error = e
            elif engine is not None:
                try:
                    engine.abort()
                except StateError as e:
                    raise store.Conflict(f"campaign {campaign_id}: {e}") from None
            elif before not in FINAL:
                store.set_status(self.db, campaign_id=campaign_id, status="aborted")
            elif before == "done" and how != "estop":
                raise store.Conflict(f"campaign {campaign_id} is done; it cannot be aborted")
        self._state(campaign_id, "estop" if how == "estop" else "aborting")
        if error is not None:
            raise ControllerUnreachable(f"emergency stop of campaign {campaign_id}: the "
                                        f"controller did not confirm the stop: {error}")
        return before

    def emergency_stop_all(self) -> int | None:
        """Emergency-stop whatever runs (nothing if nothing does); the campaign id, if any."""
        with self._lock:
            current = self._current
        if current is not None:
            self.stop(campaign_id=current, how="estop")
        return current

    def get(self, campaign_id: int) -> Run | None:
        with self._lock:
            return self._runs.get(campaign_id)

    def shutdown(self) -> None:
        with self._lock:
            engine = self._engine
        if engine is not None:
            try:
                engine.abort()  # the worker thread should not keep moving the arm after us
            except Exception:  # noqa: BLE001 - best effort at shutdown
                pass
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _running_engine(self, campaign_id: int, what: str):
        if self._current != campaign_id or self._engine is None:
            raise store.Conflict(f"campaign {campaign_id} is not running here; cannot {what}")
        return self._engine

    def _attach(self, engine) -> None:
        with self._lock:
            cid = self._current
            if self._runs[cid].stop_requested:
                raise _Stopped()  # stopped while acquire() was setting up
            self._engine = engine
        self._state(cid, "running")

    def _state(self, campaign_id: int, state: str) -> None:
        self.events.publish({"type": "campaign.state", "campaign_id": campaign_id,
                             "state": state})

    def _run(self, info: store.CampaignInfo) -> None:
        cid = info.id
        try:
            with self._lock:
                # Stopped while queued: do not start at all.
                if self._runs[cid].stop_requested:
                    raise _Stopped()
            opts = AcquireOptions(**{**info.settings.get("options", {}), "name": info.name})
            summary = acquire(self.database_url, parse_cell(info.cell_json), opts,
                              campaign_id=cid, on_engine=self._attach,
                              on_event=self.events.publish)
            how = self.get(cid).stop_requested
            change = (dict(state="finished", summary=to_plain(summary))
                      if summary["state"] == "done" else
                      dict(state="stopped", detail=f"stopped by {how or 'abort'}",
                           summary=to_plain(summary)))
        except Exception as e:  # a fault, or a stop before or during the run
            how = self.get(cid).stop_requested
            if how:
                _mark_aborted(self.db, cid)
            change = (dict(state="stopped", detail=f"stopped by {how}")
                      if how else dict(state="failed", detail=f"{type(e).__name__}: {e}"))
        with self._lock:
            self._runs[cid] = run = replace(self._runs[cid], **change)
            self._current, self._engine = None, None
        self.events.publish({"type": "campaign.run", "campaign_id": cid, "state": run.state,
                             "detail": run.detail})


class ControllerUnreachable(RuntimeError):
    """The controller did not confirm an emergency stop (the hardware e-stop must be used)."""


def _mark_aborted(db: store.Database, campaign_id: int) -> None:
    try:
        status = store.get_campaign(db, campaign_id=campaign_id).status
        if status == "paused":
            store.set_status(db, campaign_id=campaign_id, status="running")
        if status not in FINAL:
            store.set_status(db, campaign_id=campaign_id, status="aborted")
    except store.StoreError:
        pass


class _Stopped(Exception):
    """The run was stopped before it began."""


__all__ = ["Acquisitions", "ControllerUnreachable", "Events", "Job", "Jobs", "Run",
           "calibrate_campaign", "check_job", "check_method"]
