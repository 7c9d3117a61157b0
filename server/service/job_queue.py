"""Calibration, diagnosis and planning jobs: checked, kept in the store, each run in its own worker
process (server.service.processes) under a wall-clock limit, cancellable, their changes reported on the
event bus. A restart fails the ones it cut off."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from contextlib import contextmanager
from multiprocessing.connection import wait
from pathlib import Path

from robocal.server import store
from robocal.server.acquisition.lease import is_dead, process_owner
from robocal.server.calibration.workflow import model_file, run_method
from robocal.server.formats.cell_json import parse_cell
from robocal.server.formats.model_json import model_to_json
from robocal.server.service.events import Events
from robocal.server.service.processes import Child, call, exit_reason, one_line, warm_up
from robocal.server.service.worker import JobSetup, campaign_data, job_event, run_job, run_planning
from robocal.solver.calibrate import MethodDataError, parse_method

JOB_STATES = ("queued", "running", "done", "failed")
JOB_KINDS = ("calibration", "diagnosis")  # of a done campaign; planning makes one
RESTART_REASON = "service stopped while running"
CANCELLED = "cancelled"
# Defaults of the settings job_timeout_s, call_timeout_s and call_workers.
JOB_TIMEOUT_S = 900.0
CALL_TIMEOUT_S = 60.0
CALL_WORKERS = 4
# How long a cancel waits for the worker it killed to be reaped and its job marked.
CANCEL_WAIT_S = 5.0

log = logging.getLogger("robocal.jobs")

Job = store.JobInfo


class DuplicateJob(store.Conflict):
    """A calibration of this campaign with this method is already queued or running."""

    def __init__(self, message: str, job_id: int):
        super().__init__(message)
        self.job_id = job_id

    def __reduce__(self):
        return type(self), (str(self), self.job_id)


class CallTimedOut(TimeoutError):
    """A request's computation ran past its wall-clock limit and was killed."""


class Busy(RuntimeError):
    """Every worker for requests stayed busy for the whole limit."""


def check_job(db: store.Database, *, kind: str, campaign_id: int, method: str) -> None:
    """Refuse a job before queueing it: NotFound, Conflict if not done, ValueError if bad."""
    if kind not in JOB_KINDS:
        raise ValueError(f"kind must be one of {', '.join(JOB_KINDS)}, not {kind!r}")
    info = store.get_campaign(db, campaign_id=campaign_id)
    if info.status != "done":
        raise store.Conflict(
            f"campaign {campaign_id} is {info.status}; {kind} needs a done campaign"
        )
    if kind == "calibration":
        # The SMRs the worker fits are those measured (store.campaign_measurements), not the cell's.
        targets = store.measured_targets(db, campaign_id=campaign_id)
        if not targets:
            raise store.StoreError(f"campaign {campaign_id} has no readings")
        try:
            parse_method(method, targets)
        except MethodDataError as e:
            raise MethodDataError(f"campaign {campaign_id}: {e}") from None


def check_holdout(db: store.Database, *, campaign_id: int, holdout_campaign_id: int) -> None:
    """Refuse a held-out campaign a calibration cannot be validated on: NotFound, Conflict if
    it is not done, ValueError if it is the fitted campaign or of another cell."""
    from robocal.server.calibration.validation import data_mismatch

    if holdout_campaign_id == campaign_id:
        raise ValueError("the held-out campaign must be another than the one fitted")
    try:
        info = store.get_campaign(db, campaign_id=holdout_campaign_id)
    except store.NotFound as e:
        raise store.NotFound(f"held-out campaign: {e}") from None
    if info.status != "done":
        raise store.Conflict(
            f"held-out campaign {holdout_campaign_id} is {info.status}; it must be done"
        )
    fitted = parse_cell(store.get_campaign(db, campaign_id=campaign_id).cell_json)
    held = parse_cell(info.cell_json, f"<campaign {holdout_campaign_id} cell>")
    why = data_mismatch(fitted.robot, list(fitted.targets), held)
    if why:
        raise ValueError(f"held-out campaign {holdout_campaign_id}: {why}")


def check_method(db: store.Database, *, campaign_id: int, method: str) -> None:
    """Refuse a calibration before queueing it (see check_job)."""
    check_job(db, kind="calibration", campaign_id=campaign_id, method=method)


# The job queues of this process that still run (a test may start a service after another).
_LIVE_OWNERS: set[str] = set()


def _gone(owner: str | None) -> bool:
    """Whether a job's owner runs it no more: a process gone, a queue of this process shut
    down, or unknown (a job queued before owners were kept); another live process's are its own."""
    if owner is None:
        return True
    if owner.split(":")[:2] == process_owner().split(":")[:2]:  # this process
        return owner not in _LIVE_OWNERS
    return is_dead(owner)


def calibrate_campaign(db: store.Database, *, campaign_id: int, method: str) -> dict:
    """Fit `method` to a stored campaign; the model.json object."""
    cell, meas = campaign_data(db, campaign_id)
    model = model_to_json(model_file(run_method(cell, meas, method), cell, meas))
    model["data"]["campaign"] = campaign_id
    return model


class Jobs:
    """Calibration and diagnosis jobs, kept in the store: queued -> running -> done | failed.

    Each runs in a worker process of its own (server.service.processes), at most `workers` at once and
    the rest queued, so a job's numpy and Python never hold the service's GIL and one job can be
    killed without touching another: past `timeout_s` of wall clock, on cancel, or when the
    service stops. The worker writes its job's steps to the store and reports them; a thread
    here (the supervisor) starts workers, forwards their reports to the event bus, enforces the
    limits and fails the job of a worker that died. `call` runs a request's computation (an
    evaluation, a chart) in a short-lived worker of the same kind, under its own limit.
    """

    pool_kind = "process-per-job:forkserver"

    def __init__(
        self,
        db: store.Database,
        models_dir: Path,
        workers: int = 2,
        *,
        recordings_dir: Path | None = None,
        reports_dir: Path | None = None,
        events: Events | None = None,
        viewer_url: str | None = None,
        timeout_s: float = JOB_TIMEOUT_S,
        call_timeout_s: float = CALL_TIMEOUT_S,
        call_workers: int = CALL_WORKERS,
    ):
        self.db, self.models_dir, self.workers = db, Path(models_dir), workers
        self.timeout_s, self.call_timeout_s = float(timeout_s), float(call_timeout_s)
        self.recordings_dir = Path(recordings_dir or self.models_dir.parent / "recordings")
        self.reports_dir = Path(reports_dir or self.models_dir.parent / "reports")
        self.events = events or Events()
        self._setup = JobSetup(
            db.engine.url.render_as_string(hide_password=False),
            self.models_dir,
            self.recordings_dir,
            self.reports_dir,
            viewer_url,
        )
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)  # a running job ended
        self._closing = False
        self._queue: deque[int] = deque()
        self._running: dict[int, Child | None] = {}  # None while its process starts
        self._killing: dict[int, str] = {}  # job id -> why the service kills it
        # A queued planning job's cell and options, for its worker (a restart fails the job).
        self._plans: dict[int, tuple] = {}
        self._call_slots = threading.BoundedSemaphore(call_workers)
        self._slot_held = threading.local()
        self._calls: set[Child] = set()
        self._wake_r, self._wake_w = os.pipe()
        # Nothing runs a job its service did not queue: fail those a stop cut off (their
        # service gone), not those another live service on the database runs.
        self.owner = process_owner()
        _LIVE_OWNERS.add(self.owner)
        for job_id in store.fail_unfinished_jobs(db, reason=RESTART_REASON, gone=_gone):
            self._publish(store.get_job(db, job_id=job_id))
        self._supervisor = threading.Thread(
            target=self._supervise, name="robocal-jobs", daemon=True
        )
        self._supervisor.start()
        # The fork server imports the solver once (seconds): now, not in the first request.
        self.warm = threading.Event()  # set once it has (or failed to)
        threading.Thread(target=self._warm_up, name="robocal-fork-server", daemon=True).start()

    def _warm_up(self) -> None:
        try:
            warm_up()
        finally:
            self.warm.set()

    # --- the API's verbs ------------------------------------------------------------------------

    def submit(
        self,
        *,
        campaign_id: int,
        method: str = "minimax",
        kind: str = "calibration",
        holdout_campaign_id: int | None = None,
        tolerance_mm: float | None = None,
    ) -> Job:
        """Check and queue a job; the job as queued. DuplicateJob (a Conflict) if the same
        calibration (store.create_job's unique) is queued or running."""
        if kind == "diagnosis":
            method = "diagnose"
        check_job(self.db, kind=kind, campaign_id=campaign_id, method=method)
        if holdout_campaign_id is not None:
            if kind != "calibration":
                raise ValueError(
                    "holdout_campaign_id: only a calibration takes a held-out campaign (a "
                    f"{kind} holds out its own folds); leave it out, or ask a calibration"
                )
            check_holdout(self.db, campaign_id=campaign_id, holdout_campaign_id=holdout_campaign_id)
        with self._lock:  # the check and the insert together: two clicks make one job
            if self._closing:
                raise store.Conflict("the service is stopping; no new jobs")
            try:  # a calibration once: checked in the insert's transaction (two services)
                job = store.create_job(
                    self.db,
                    kind=kind,
                    campaign_id=campaign_id,
                    method=method,
                    holdout_campaign_id=holdout_campaign_id,
                    tolerance_mm=tolerance_mm,
                    unique=kind == "calibration",
                    owner=self.owner,
                )
            except store.ActiveJob as e:
                raise DuplicateJob(
                    f"campaign {campaign_id} already has {kind} job {e.job.id} "
                    f"({method}) {e.job.state}; cancel it or wait for it",
                    e.job.id,
                ) from None
            self._queue.append(job.id)
        self._publish(job)
        self._wake()
        return job

    def submit_planning(self, *, cell, opts) -> Job:
        """Queue the planning of a campaign (stored `planned` by the job); the job as queued.
        The caller checked the plan's size (server.acquisition.planning.check_plan_size)."""
        method = f"{opts.poses} of {opts.choose_from}" if opts.choose_from else f"{opts.poses}"
        with self._lock:
            if self._closing:
                raise store.Conflict("the service is stopping; no new jobs")
            job = store.create_job(
                self.db, kind="planning", campaign_id=None, method=method, owner=self.owner
            )
            self._plans[job.id] = (cell, opts)
            self._queue.append(job.id)
        self._publish(job)
        self._wake()
        return job

    def cancel(self, job_id: int) -> Job:
        """Take a queued job off the queue, or kill the process of a running one; both end
        failed with reason "cancelled". Conflict if it is already done or failed."""
        with self._lock:
            job = self.get(job_id)
            if job_id in self._queue:
                self._queue.remove(job_id)
                self._plans.pop(job_id, None)
            elif job_id in self._running:
                self._killing.setdefault(job_id, CANCELLED)
                child = self._running[job_id]
                if child is not None:
                    child.kill()
                self._changed.wait_for(lambda: job_id not in self._running, CANCEL_WAIT_S)
                return self.get(job_id)
            elif job.state in ("done", "failed"):
                raise store.Conflict(
                    f"job {job_id} is already {job.state}"
                    + (f" ({job.reason})" if job.reason else "")
                )
        self._fail(job_id, CANCELLED)
        return self.get(job_id)

    @contextmanager
    def call_slot(self):
        """Hold one of the call_workers slots (Busy if none frees up in call_timeout_s): a route
        takes it before loading its inputs, so at most that many requests do heavy work at once
        and the rest wait without the GIL (the e-stop's thread must get it at once)."""
        if getattr(self._slot_held, "held", False):
            yield  # this thread holds one already (the route took it; call() is inside)
            return
        if not self._call_slots.acquire(timeout=self.call_timeout_s):
            raise Busy(
                f"every worker for requests stayed busy for {self.call_timeout_s:g} s; "
                "try again later"
            )
        self._slot_held.held = True
        try:
            yield
        finally:
            self._slot_held.held = False
            self._call_slots.release()

    def call(self, target, *args):
        """target(*args, report) in a short-lived worker process: its result or its exception.
        CallTimedOut past call_timeout_s (the worker killed); Busy if no worker frees up."""
        t0 = time.monotonic()
        with self.call_slot():
            if self._closing:
                raise Busy("the service is stopping")
            left = self.call_timeout_s - (time.monotonic() - t0)
            try:
                return call(target, args, max(left, 0.0), children=self._calls, lock=self._lock)
            except TimeoutError:
                raise CallTimedOut(
                    f"the computation exceeded its wall-clock limit of {self.call_timeout_s:g} s"
                ) from None

    def get(self, job_id: int) -> Job:
        return store.get_job(self.db, job_id=job_id)

    def list(self) -> list[Job]:
        return store.list_jobs(self.db)

    def worker_pid(self, job_id: int) -> int | None:
        """The pid of the worker process running this job (None unless it runs)."""
        with self._lock:
            child = self._running.get(job_id)
            return None if child is None else child.pid

    def result_path(self, job_id: int, what: str) -> Path:
        """A file a done job wrote (model, recording, report); NotFound / Conflict otherwise."""
        job = self.get(job_id)
        if job.state != "done":
            raise store.Conflict(
                f"job {job_id} is {job.state}"
                + (f": {job.reason}" if job.reason else "")
                + f"; no {what}"
            )
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
        """Kill every worker, then fail the jobs they had and those queued (a job cannot
        outlive the service)."""
        with self._lock:
            if self._closing:
                return
            self._closing = True
            _LIVE_OWNERS.discard(self.owner)
            children = [c for c in self._running.values() if c is not None] + list(self._calls)
            cut_off = sorted(self._running) + list(self._queue)
            self._queue.clear()
            self._plans.clear()
        for child in children:
            child.kill()
        self._wake()
        self._supervisor.join(timeout=10)
        for child in children:
            child.reap()
        for job_id in cut_off:
            self._fail(job_id, RESTART_REASON)
        os.close(self._wake_w)
        os.close(self._wake_r)

    # --- the supervisor thread ------------------------------------------------------------------

    def _supervise(self) -> None:
        while True:
            with self._lock:
                if self._closing:
                    return
                starting = []
                while self._queue and len(self._running) < self.workers:
                    job_id = self._queue.popleft()
                    self._running[job_id] = None
                    starting.append(job_id)
            for job_id in starting:
                self._start(job_id)
            with self._lock:
                children = {j: c for j, c in self._running.items() if c is not None}
            now = time.monotonic()
            deadlines = [c.started + self.timeout_s for c in children.values()]
            timeout = max(0.0, min(deadlines) - now) if deadlines else None
            handles = (
                [self._wake_r]
                + [c.answers for c in children.values() if not c.ended]
                + [c.sentinel for c in children.values()]
            )
            try:
                ready = set(wait(handles, timeout))
            except OSError:
                return  # the wake pipe closed under us: shutdown
            if self._wake_r in ready:
                os.read(self._wake_r, 4096)
            now = time.monotonic()
            for job_id, child in children.items():
                if child.answers in ready:
                    self._forward(child)
                if child.sentinel in ready:
                    self._finish(job_id, child)
                elif now >= child.started + self.timeout_s:
                    self._overrun(job_id, child, now)

    def _start(self, job_id: int) -> None:
        with self._lock:
            plan = self._plans.pop(job_id, None)
        target, args = (
            (run_job, (self._setup, job_id))
            if plan is None
            else (run_planning, (self._setup, job_id, *plan))
        )
        try:
            child = Child(target, args, name=f"robocal-job-{job_id}")
        except Exception as e:  # noqa: BLE001 - the job says why it cannot run
            with self._lock:
                self._running.pop(job_id, None)
                self._changed.notify_all()
            self._fail(job_id, f"no worker process could take it: {one_line(e)}")
            return
        with self._lock:
            self._running[job_id] = child
            if job_id in self._killing or self._closing:
                child.kill()  # cancelled (or the service stops) while its process started

    def _overrun(self, job_id: int, child: Child, now: float) -> None:
        with self._lock:
            self._killing.setdefault(
                job_id, f"exceeded its wall-clock limit of {self.timeout_s:g} s"
            )
        child.kill()
        killed = time.monotonic() - child.started - self.timeout_s
        code = child.reap()
        log.info(
            "job %d killed %.1f ms after its wall-clock limit, gone after %.1f ms (%s)",
            job_id,
            killed * 1000,
            (time.monotonic() - child.started - self.timeout_s) * 1000,
            exit_reason(code),
        )
        self._finish(job_id, child)

    def _forward(self, child: Child) -> None:
        for kind, message in child.messages():
            if kind == "report" and isinstance(message, dict):  # what a job's report() sends
                self.events.publish(message)

    def _finish(self, job_id: int, child: Child) -> None:
        # The worker wrote done or failed itself unless it was killed or died.
        self._forward(child)
        code = child.reap()
        with self._lock:
            reason = self._killing.pop(job_id, None)
            closing = self._closing
        if not closing:
            self._fail(job_id, reason or f"its worker process died ({exit_reason(code)})")
        with self._lock:
            self._running.pop(job_id, None)
            self._changed.notify_all()
        self._wake()  # a slot is free

    # --- helpers --------------------------------------------------------------------------------

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except OSError:
            pass  # shut down

    def _publish(self, job: Job) -> None:
        self.events.publish(job_event(job))

    def _fail(self, job_id: int, reason: str) -> None:
        try:
            job = self.get(job_id)
            if job.state not in ("done", "failed"):
                self._publish(
                    store.update_job(self.db, job_id=job_id, state="failed", reason=reason)
                )
        except store.StoreError:
            pass  # it went done or failed meanwhile, or the store is closing: nothing to mark


__all__ = [
    "Busy",
    "CANCELLED",
    "CallTimedOut",
    "DuplicateJob",
    "Job",
    "Jobs",
    "RESTART_REASON",
    "calibrate_campaign",
    "check_job",
    "check_method",
]
