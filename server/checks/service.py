"""A model's check run on the service's cell (POST /api/models/{id}/checks/run): the model's check
poses (those of its first check, else planned) stored as a campaign and started on the service's
acquisition worker, with the lease, e-stop and events of any campaign; once it is done, judged
into the model's history exactly as `robocal acquire --check` judges (check_run.judge)."""

from __future__ import annotations

from dataclasses import dataclass

from robocal.server import store
from robocal.server.acquisition import campaigns
from robocal.server.acquisition.acquire import UNFINISHED, AcquireOptions
from robocal.server.checks import run as check_run
from robocal.server.checks.check import CheckResult
from robocal.server.checks.run import RECORD, CheckRunOptions
from robocal.server.formats.cell_json import Cell, parse_cell
from robocal.server.formats.model_json import file_digest, read_model
from robocal.server.store.model_checks import model_checks


@dataclass(frozen=True)
class CheckStarted:
    """What a request for a check did: a run queued, or a check measured earlier judged."""

    campaign_id: int
    started: bool  # False: nothing measured now, `result` is a done campaign's judgement
    result: CheckResult | None
    note: str


def start_check(
    db: store.Database,
    acquisitions,
    *,
    cell: Cell,
    model_path,
    job_id: int,
    poses: int | None = None,
    seed: int = 0,
    pause_s: float = 10.0,
    effects: tuple = (),
    samples: int = AcquireOptions.samples,
    settle: str = AcquireOptions.settle,
    arm: str | None = None,
) -> CheckStarted:
    """Run the model's check on the cell: an unfinished check campaign of the model resumed,
    else a new one of its check poses started; a done one not yet judged (the service stopped
    between) is judged instead. Conflict while the cell runs a campaign."""
    model = read_model(model_path)
    check_run.check_fits(model, cell, model_path)
    sha = file_digest(model_path)
    ours, waiting = check_run.pending(db, sha)
    if waiting is not None:
        res = check_run.judge(db, model, sha, waiting)
        return CheckStarted(waiting, False, res, f"check campaign {waiting} judged: nothing run")
    busy = acquisitions.running()
    if busy is not None:
        raise store.Conflict(f"the cell runs campaign {busy}; one campaign at a time")
    left = [c for c in ours if c.status in UNFINISHED]
    if left:  # its poses and noise as planned; an e-stopped one asks for its reset (409)
        info = left[-1]
        action = "start" if info.status == "planned" else "resume"
        acquisitions.request(campaign_id=info.id, action=action)
        return CheckStarted(info.id, True, None, f"check campaign {info.id}: {action} queued")
    ids, q_deg = check_run.poses_of(db, ours, model, CheckRunOptions(poses=poses))
    opts = AcquireOptions(
        poses=len(q_deg),
        seed=seed,
        name=check_run.campaign_name(sha),
        pause_s=pause_s,
        noise_seed=check_run.noise_seed(cell, seed, len(ours)),
        effects=tuple(effects),
        samples=samples,
        settle=settle,
        arm=arm,
    )
    settings = check_run.stored_settings(model, sha, model_path, job_id=job_id)
    cid = campaigns.plan_given(
        db, cell=cell, opts=opts, poses_deg=q_deg, labels=ids, settings=settings
    )
    acquisitions.request(campaign_id=cid, action="start")
    return CheckStarted(cid, True, None, f"check campaign {cid} of {len(ids)} poses: start queued")


def judge_done(db: store.Database, campaign_id: int) -> str | None:
    """Acquisitions' on_done: a done check campaign judged into its model's history (None for
    any other campaign, or one judged already); the verdict, to join the run's detail."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    record = (info.settings or {}).get(RECORD)
    if record is None or info.status != "done":
        return None
    sha = record["model_sha256"]
    if any(r.source == f"campaign {campaign_id}" for r in model_checks(db, sha)):
        return None
    path = record["model"]
    if file_digest(path) != sha:  # the model file changed under the service: not this model
        raise store.Conflict(f"the model file of check campaign {campaign_id} is not the one run")
    res = check_run.judge(db, read_model(path), sha, campaign_id)
    return f"check {res.history} of the model: {res.verdict}: {res.reason}"


@dataclass(frozen=True)
class ModelSource:
    """Where the model's own campaign was measured: its cell, how it was acquired (the simulated
    arm: seed and effects; the tracker's samples and settling), and its arm."""

    cell: Cell
    acquired: bool  # False: its readings were imported (no simulated arm known)
    seed: int
    effects: tuple
    samples: int
    settle: str
    arm: str | None


def model_source(db: store.Database, campaign_id: int) -> ModelSource:
    """The model's campaign as a check reads it again: the same cell, arm and way of reading."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    was = (info.settings or {}).get("options") or {}
    return ModelSource(
        cell=parse_cell(info.cell_json, f"<campaign {info.id} cell>"),
        acquired=bool(was),
        seed=int(was.get("seed", 0)),
        effects=tuple(was.get("effects", ())),
        samples=int(was.get("samples", AcquireOptions.samples)),
        settle=str(was.get("settle", AcquireOptions.settle)),
        arm=info.arm,
    )


__all__ = ["CheckStarted", "ModelSource", "judge_done", "model_source", "start_check"]
