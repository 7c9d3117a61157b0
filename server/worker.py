"""The process pool jobs run in: a calibration or diagnosis per call, in a worker process that
writes its job's state to the store itself and reports each change on a queue the service reads.

Only picklable things cross to a worker (a JobSetup and a job id); it opens the store itself.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path

from . import store
from .formats.cell_json import parse_cell
from .formats.model_json import model_to_json, to_plain, write_json_atomic
from .workflow import model_file, run_method

# Not fork: the service has threads (uvicorn, the acquisition, the event bus) whose locks a
# forked child would inherit held. The fork server is a single-threaded process that imports
# this module once; workers forked from it start at once, after a crash too.
START_METHOD = "forkserver"
# How often the forwarding thread looks up from the queue to see whether it should stop, and a
# worker checks that the service is still there.
POLL_S = 0.5
REASON_CHARS = 500
# Jobs are batch work: the API and a running acquisition (a robot and a tracker waiting on it)
# get the CPU first.
WORKER_NICENESS = 10

Report = Callable[[int, int, dict], None]  # (job id, worker pid, job event)

_reports: multiprocessing.Queue | None = None  # in a worker: where its job changes go
_databases: dict[str, store.Database] = {}  # in a worker: the stores it has open, by URL


@dataclass(frozen=True)
class JobSetup:
    """Where a worker finds the store and puts a job's files."""

    database_url: str
    models_dir: Path
    recordings_dir: Path
    reports_dir: Path
    viewer_url: str | None = None


def job_event(job: store.JobInfo) -> dict:
    """The `job` event of the SSE bus for a job's current state."""
    return {"type": "job", "job_id": job.id, "kind": job.kind, "campaign_id": job.campaign_id,
            "state": job.state, "progress": job.progress, "reason": job.reason}


def one_line(e: BaseException) -> str:
    """A failure reason: the exception's type and message on one line, never a traceback."""
    text = " ".join(str(e).split())
    text = f"{type(e).__name__}: {text}" if text else type(e).__name__
    return text if len(text) <= REASON_CHARS else text[: REASON_CHARS - 3] + "..."


# --- in the worker process ----------------------------------------------------------------------

def init_worker(reports: multiprocessing.Queue, service_pid: int) -> None:
    """Start of a pool process: keep the report queue; leave Ctrl-C to the service, which ends
    its workers itself on the way out; end with the service if it is killed."""
    global _reports
    _reports = reports
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(WORKER_NICENESS)
    threading.Thread(target=_exit_with_service, args=(service_pid,), daemon=True).start()


def _exit_with_service(pid: int) -> None:
    # A killed service cannot end its workers, and the fork server lives as long as they do: a
    # worker must not outlive it and write to the store of a service that has restarted since.
    while True:
        time.sleep(POLL_S)
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            os._exit(1)


def run_job(setup: JobSetup, job_id: int) -> None:
    """Run a queued job to done or failed, writing each step to the store and reporting it."""
    db = _database(setup.database_url)
    job = _update(db, job_id, state="running")
    try:
        work = _calibrate if job.kind == "calibration" else _diagnose
        results = work(db, setup, job)
    except Exception as e:  # the reason is the job's result, not a server error
        _update(db, job_id, state="failed", reason=one_line(e))
        return
    _update(db, job_id, state="done", results=results)


def _database(url: str) -> store.Database:
    # Opened once per process: opening checks the migrations, which a job need not repeat.
    if url not in _databases:
        _databases[url] = store.open_database(url)
    return _databases[url]


def _update(db: store.Database, job_id: int, **changes) -> store.JobInfo:
    job = store.update_job(db, job_id=job_id, **changes)
    if _reports is not None:
        _reports.put((job.id, os.getpid(), job_event(job)))
    return job


def campaign_data(db: store.Database, campaign_id: int):
    """The cell and the readings of a stored campaign; StoreError if it has none."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    cell = parse_cell(info.cell_json, f"<campaign {campaign_id} cell>")
    meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
    if meas.n_poses == 0:
        raise store.StoreError(f"campaign {campaign_id} has no readings")
    return cell, meas


def _calibrate(db: store.Database, setup: JobSetup, job: store.JobInfo) -> dict:
    from .recording import record_calibration  # rerun is heavy; load it with the first job

    cell, meas = campaign_data(db, job.campaign_id)
    _update(db, job.id, progress=0.1)
    cal = run_method(cell, meas, job.method)
    model = model_to_json(model_file(cal, cell, meas))
    model["data"]["campaign"] = job.campaign_id
    path = setup.models_dir / f"job-{job.id}.model.json"
    write_json_atomic(path, model)
    _update(db, job.id, progress=0.5, results={"model": str(path)})
    rrd = record_calibration(setup.recordings_dir / f"job-{job.id}.rrd", cell=cell, meas=meas,
                             calibration=cal, viewer_url=setup.viewer_url)
    return {"model": str(path), "recording": str(rrd)}


def _diagnose(db: store.Database, setup: JobSetup, job: store.JobInfo) -> dict:
    from .workflow import diagnose, write_diagnosis

    cell, meas = campaign_data(db, job.campaign_id)
    _update(db, job.id, progress=0.1)
    d, model = diagnose(cell, meas)
    _update(db, job.id, progress=0.8)
    report_path = setup.reports_dir / f"job-{job.id}" / "report.json"
    path = setup.models_dir / f"job-{job.id}.model.json"
    d.report = to_plain(d.report)
    _, figures = write_diagnosis(d, model, report_path, {
        "campaign": job.campaign_id, "poses": meas.n_poses, "readings": meas.n_readings}, path,
        list_figures=True)
    return {"model": str(path), "report": str(report_path),
            "figures": [str(p) for p in figures]}


# --- in the service -----------------------------------------------------------------------------

class WorkerPool:
    """A ProcessPoolExecutor of workers from the fork server and the thread that hands their
    reports to `report`. A pool whose worker died is broken for good: the caller makes a new
    one."""

    kind = f"process:{START_METHOD}"

    def __init__(self, workers: int, report: Report):
        context = multiprocessing.get_context(START_METHOD)
        context.set_forkserver_preload([__name__])  # no effect once the fork server runs
        # One queue per pool: a worker killed while writing to it may leave its lock held.
        self._reports = context.Queue()
        self._executor = ProcessPoolExecutor(workers, mp_context=context,
                                             initializer=init_worker,
                                             initargs=(self._reports, os.getpid()))
        # The executor keeps no public list of its processes (3.14 adds terminate_workers()).
        self._processes = self._executor._processes
        self._report, self._stop, self._lock = report, threading.Event(), threading.Lock()
        self.died: dict[int, int] = {}  # pid -> exit code of the workers dead before close()
        threading.Thread(target=self._forward, name="robocal-job-reports", daemon=True).start()

    def submit(self, setup: JobSetup, job_id: int) -> Future:
        """Queue run_job(setup, job_id); BrokenProcessPool if a worker of this pool died."""
        return self._executor.submit(run_job, setup, job_id)

    def close(self, timeout: float = 5.0) -> None:
        """Cancel what waits, end the workers (a running job is cut off), stop forwarding;
        `died` then tells which workers had died on their own."""
        with self._lock:
            if self._stop.is_set():
                return
            self._stop.set()
            # Before shutdown(), whose idle workers then exit on their own. A dead worker's
            # sentinel is ready a moment before its exit code can be read: join() waits for it.
            dead = wait([p.sentinel for p in self._processes.values()], 0)
            self.died = {pid: p.join(timeout) or p.exitcode
                         for pid, p in self._processes.items() if p.sentinel in dead}
            self._executor.shutdown(wait=False, cancel_futures=True)  # then no more processes
            processes = list(self._processes.values())
            for p in processes:
                p.terminate()
            for p in processes:
                p.join(timeout)
                if p.is_alive():
                    p.kill()

    def _forward(self) -> None:
        while not self._stop.is_set():
            try:
                job_id, pid, event = self._reports.get(timeout=POLL_S)
            except queue.Empty:
                continue
            except (EOFError, OSError, ValueError):  # the queue is closed: nothing more comes
                return
            if self._stop.is_set():
                return  # a closed pool's last words would come after the service's verdict
            self._report(job_id, pid, event)
