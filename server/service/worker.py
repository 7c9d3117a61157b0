"""A calibration, diagnosis or planning job, run in its own worker process (server.service.processes): it writes
its job's state to the store itself and reports each change to the service, which publishes it.

Only picklable things cross to a worker (a JobSetup and a job id); it opens the store itself.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from robocal.server import store
from robocal.server.calibration.identified import arm_parameters
from robocal.server.calibration.validation import with_held_out
from robocal.server.calibration.workflow import held_out_errors, model_file, run_method
from robocal.server.formats.blocks import Validation
from robocal.server.formats.cell_json import parse_cell
from robocal.server.formats.model_json import model_to_json, to_plain, write_json_atomic
from robocal.server.service.processes import one_line

Report = Callable[[dict], None]  # sends a job event to the service

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
    return {
        "type": "job",
        "job_id": job.id,
        "kind": job.kind,
        "campaign_id": job.campaign_id,
        "state": job.state,
        "progress": job.progress,
        "reason": job.reason,
    }


def run_job(setup: JobSetup, job_id: int, report: Report) -> None:
    """Run a queued job to done or failed, writing each step to the store and reporting it."""
    db = _database(setup.database_url)
    job = _update(db, report, job_id, state="running")
    try:
        work = _calibrate if job.kind == "calibration" else _diagnose
        results = work(db, report, setup, job)
    except Exception as e:  # the reason is the job's result, not a server error
        _update(db, report, job_id, state="failed", reason=one_line(e))
        return
    _update(db, report, job_id, state="done", results=results)


# A planning job writes its progress when it rose by this much (each is a write to the store).
PROGRESS_STEP = 0.02


def run_planning(setup: JobSetup, job_id: int, cell, opts, report: Report) -> None:
    """Plan a campaign (server.acquisition.campaigns.plan_campaign) and store it `planned`: the job done with
    results {"campaign": id}, or failed with the reason (a name clash: the Conflict's text)."""
    from robocal.server.acquisition.campaigns import plan_campaign

    db = _database(setup.database_url)
    _update(db, report, job_id, state="running")
    shown = [0.0]

    def progress(fraction: float) -> None:
        fraction = min(max(float(fraction), 0.0), 0.99)  # done, not the planning, says 1
        if fraction - shown[0] >= PROGRESS_STEP:
            shown[0] = fraction
            _update(db, report, job_id, progress=fraction)

    try:
        cid = plan_campaign(db, cell=cell, opts=opts, progress=progress)
    except Exception as e:  # the reason is the job's result, not a server error
        _update(db, report, job_id, state="failed", reason=one_line(e))
        return
    _update(db, report, job_id, state="done", campaign_id=cid, results={"campaign": cid})


def _database(url: str) -> store.Database:
    # Opened once per process: opening checks the migrations, which a job need not repeat.
    if url not in _databases:
        _databases[url] = store.open_database(url)
    return _databases[url]


def _update(db: store.Database, report: Report, job_id: int, **changes) -> store.JobInfo:
    job = store.update_job(db, job_id=job_id, **changes)
    report(job_event(job))
    return job


def campaign_data(db: store.Database, campaign_id: int | None):
    """The cell and the readings of a stored campaign; StoreError if it has none."""
    if campaign_id is None:
        raise store.StoreError("the job names no campaign")
    info = store.get_campaign(db, campaign_id=campaign_id)
    cell = parse_cell(info.cell_json, f"<campaign {campaign_id} cell>")
    meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
    if meas.n_poses == 0:
        raise store.StoreError(f"campaign {campaign_id} has no readings")
    return cell, meas


def job_data(db: store.Database, job: store.JobInfo):
    """A job's campaign_data, the tolerance asked for with the job over the cell's."""
    cell, meas = campaign_data(db, job.campaign_id)
    if job.tolerance_mm is not None:
        cell = replace(cell, tolerance_mm=job.tolerance_mm)
    return cell, meas


def _calibrate(db: store.Database, report: Report, setup: JobSetup, job: store.JobInfo) -> dict:
    from robocal.server.recordings.calibration import (
        record_calibration,  # rerun is heavy; load it with the first job
    )

    cell, meas = job_data(db, job)
    hold = None if job.holdout_campaign_id is None else campaign_data(db, job.holdout_campaign_id)
    _update(db, report, job.id, progress=0.1)
    cal = run_method(cell, meas, job.method)
    fitted = model_file(cal, cell, meas)
    summary = None
    if hold is not None:  # the separate validation figure beside the leave-one-out one
        summary = held_out_errors(fitted, hold[1], campaign_id=job.holdout_campaign_id)
        if fitted.validation is not None:
            with_held_out(fitted.validation, summary)
    model = model_to_json(fitted)
    model["data"]["campaign"] = job.campaign_id
    path = setup.models_dir / f"job-{job.id}.model.json"
    write_json_atomic(path, model)
    _update(db, report, job.id, progress=0.5, results={"model": str(path)})
    rrd = record_calibration(
        setup.recordings_dir / f"job-{job.id}.rrd",
        cell=cell,
        meas=meas,
        calibration=cal,
        held_out=None if hold is None else hold[1],
        viewer_url=setup.viewer_url,
    )
    return {
        "model": str(path),
        "recording": str(rrd),
        # the arm's parameters in the shared database, for the fleet view
        "parameters": to_plain(arm_parameters(fitted)),
        **_verdict(fitted.verdict),
        **({"holdout": summary.to_json()} if summary else {}),
    }


# what a job's results keep of its model's verdict (GET /api/models/{id}/parameters has it all)
SUMMARY = {
    "deployable",
    "reasons",
    "warnings",
    "summary",
    "holdout_rms_mm",
    "holdout_max_mm",
    "fit_rms_mm",
    "tolerance_mm",
    "noise_floor_mm",
    "noise_floor_source",
}


def _verdict(v: Validation) -> dict:
    """A job's results' summary of its model's verdict (a model without one: not deployable)."""
    return {"validation": to_plain(v.model_dump(include=SUMMARY))}


def _diagnose(db: store.Database, report: Report, setup: JobSetup, job: store.JobInfo) -> dict:
    from robocal.server.calibration.workflow import diagnose, write_diagnosis
    from robocal.server.formats.model_json import diagnosis_order
    from robocal.server.recordings.calibration import record_diagnosis

    cell, meas = job_data(db, job)
    _update(db, report, job.id, progress=0.1)
    d, model = diagnose(cell, meas)
    _update(db, report, job.id, progress=0.8)
    report_path = setup.reports_dir / f"job-{job.id}" / "report.json"
    path = setup.models_dir / f"job-{job.id}.model.json"
    _, figures = write_diagnosis(
        d,
        model,
        report_path,
        {"campaign": job.campaign_id, "poses": meas.n_poses, "readings": meas.n_readings},
        path,
        list_figures=True,
    )
    rrd = record_diagnosis(
        setup.recordings_dir / f"job-{job.id}.rrd",
        cell=cell,
        meas=meas,
        diagnosed=d,
        model=model,
        viewer_url=setup.viewer_url,
    )
    verdict = model.verdict
    # what `robocal diagnose` says on stderr: the rows' order taken as the order of motion
    if order := diagnosis_order(model, meas.q, meas.time_s, meas.prev_q):
        verdict = verdict.model_copy(update={"warnings": (*verdict.warnings, order)})
    return {
        "model": str(path),
        "report": str(report_path),
        "recording": str(rrd),
        "figures": [str(p) for p in figures],
        **_verdict(verdict),
    }
