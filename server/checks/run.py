"""`robocal acquire --check model.json`: a model's check poses measured on the cell, then judged.

The poses (a `check --plan` file, else those of the model's first check in this database, else the
model's plan) run as a campaign named after the model through `acquire`: the same engine, e-stop and lease as any campaign, every reading stored as it
arrives. A check cut off (an e-stop, a fault, a killed process) is resumed by running it again
(with --reset after an e-stop), keeping what it measured. Once it is done, its readings are judged
(server/checks/check.py) and appended to the model's history in the same database; a done check campaign
not yet in the history (the process ended between the two) is judged on the next run instead of
measuring again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.server import store
from robocal.server.acquisition.acquire import PREDICTOR, AcquireOptions, _opened, acquire
from robocal.server.acquisition.summary import AcquireSummary
from robocal.server.calibration.validation import cell_mismatch
from robocal.server.checks.check import CheckResult, prepare_measured, record
from robocal.server.checks.plan import DEFAULT_POSES, check_poses
from robocal.server.formats.cell_json import Cell, robot_to_json
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import file_digest, read_model
from robocal.server.store.model_checks import model_checks

RECORD = "check"  # the campaign settings' key of the model checked
NOISE_STREAM = 23  # the simulated tracker's draws of a check: a stream of their own


@dataclass
class CheckRunOptions:
    """Which poses (a poses.csv, else `poses` planned, else those of the model's first check in
    the database, else DEFAULT_POSES planned) and how to acquire them."""

    poses_path: str | None = None
    poses: int | None = None
    seed: int = 0  # the simulated arm: the calibration campaign's seed
    pause_s: float = 10.0
    settle: str = "fixed"
    samples: int = 1000
    effects: tuple = ()  # hidden physics of the simulated arm (a change to find)
    beam_break_rate: float = 0.0
    arm: str | None = None  # the physical arm checked (its serial number)


@dataclass(frozen=True)
class CheckRun:
    """The check campaign's acquisition summary and, once it is done, the check's result."""

    campaign: int
    summary: AcquireSummary | None  # None: nothing measured now (a done campaign judged)
    result: CheckResult | None  # None: the campaign did not end done (e-stopped, paused)


def campaign_name(sha: str) -> str:
    """The check campaigns of a model share its name: an unfinished one is resumed."""
    return f"check-{sha[:12]}"


def acquire_check(
    db_path,
    cell: Cell,
    model_path,
    opts: CheckRunOptions,
    *,
    reset: bool = False,
    progress=None,
    log=None,
    on_engine=None,
    on_event=None,
) -> CheckRun:
    """Measure (or resume, or judge) the model's check on the cell; what was done."""
    model = read_model(model_path)
    check_fits(model, cell, model_path)
    sha = file_digest(model_path)
    name = campaign_name(sha)
    with _opened(db_path) as db:
        ours, waiting = pending(db, sha)
        if waiting is not None:
            return CheckRun(waiting, None, judge(db, model, sha, waiting))
        ids, q_deg = poses_of(db, ours, model, opts)
    settings = stored_settings(model, sha, model_path)
    run = AcquireOptions(
        poses=len(q_deg),
        seed=opts.seed,
        name=name,
        settle=opts.settle,
        pause_s=opts.pause_s,
        samples=opts.samples,
        beam_break_rate=opts.beam_break_rate,
        effects=tuple(opts.effects),
        # each check reads the same simulated arm with noise of its own
        noise_seed=noise_seed(cell, opts.seed, len(ours)),
        arm=opts.arm,
    )
    summary = acquire(
        db_path,
        cell,
        run,
        progress,
        log,
        reset=reset,
        on_engine=on_engine,
        on_event=on_event,
        poses_deg=q_deg,
        labels=ids,
        settings=settings,
    )
    cid = summary.campaign
    if summary.state != "done":
        return CheckRun(cid, summary, None)
    with _opened(db_path) as db:
        return CheckRun(cid, summary, judge(db, model, sha, cid))


def check_fits(model, cell: Cell, model_path) -> None:
    """InputError unless the model is one of the cell's arm (validation.cell_mismatch: its robot,
    nominal geometry and SMRs)."""
    why = cell_mismatch(model, cell)
    if why:
        raise InputError(model_path, None, None, f"{why}: not a model of this cell")


def pending(db, sha: str):
    """The model's check campaigns and the oldest done one not yet judged, if any (the history
    keeps the order they were measured in)."""
    ours = [c for c in store.list_campaigns(db) if c.name == campaign_name(sha)]
    judged = {r.source for r in model_checks(db, sha)}
    waiting = [c.id for c in ours if c.status == "done" and _source(c.id) not in judged]
    return ours, min(waiting) if waiting else None


def stored_settings(model, sha: str, model_path, **record) -> dict:
    """The check campaign's own settings: the model checked (and `record`), and its geometry
    for the SMR predictor."""
    geometry = {
        "robot": robot_to_json(model.robot),
        "base": np.asarray(model.base).tolist(),
        "targets": {k: np.asarray(v).tolist() for k, v in model.targets.items()},
    }
    return {
        RECORD: {"model_sha256": sha, "model": str(model_path), **record},
        PREDICTOR: geometry,
    }


def noise_seed(cell: Cell, seed: int, earlier: int):
    """The simulated tracker's draws of a model's check after `earlier` ones: each check reads
    the same simulated arm with noise of its own (None on real devices)."""
    return [seed, NOISE_STREAM, earlier] if cell.simulated else None


def poses_of(db, ours, model, opts: CheckRunOptions) -> tuple[list[str], np.ndarray]:
    """The check's (pose labels, joints deg): those given (a file, a count to plan), else those
    of the model's first check campaign `ours` in the database, else the model's plan."""
    earlier = [c for c in ours if c.n_poses > 0]
    if earlier and opts.poses_path is None and opts.poses is None:
        # a plan made again elsewhere (another numpy, another machine) could differ in a near
        # tie, and the history would no longer match its poses
        planned = store.planned_poses(db, campaign_id=min(c.id for c in earlier))
        return [p.label for p in planned], np.array([p.joints_deg for p in planned])
    ids, q = check_poses(model, opts.poses_path, opts.poses or DEFAULT_POSES)
    return ids, np.rad2deg(q)


def _source(campaign_id: int) -> str:
    return f"campaign {campaign_id}"


def judge(db, model, sha: str, campaign_id: int) -> CheckResult:
    """The done check campaign's readings judged and appended to the model's history."""
    meas = store.campaign_measurements(
        db, campaign_id=campaign_id, robot=model.robot, targets=sorted(model.targets)
    )
    prepared = prepare_measured(model, sha, meas, f"check campaign {campaign_id}")
    return record(db, prepared, _source(campaign_id))
