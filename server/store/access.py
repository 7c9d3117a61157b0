"""Data access: keyword-only functions, each its own transaction, committed before it returns."""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sqlalchemy import CursorResult, Result, and_, delete, exists, func, insert, or_, select, update
from sqlalchemy.orm import Session

from robocal.drivers import lifecycle
from robocal.server.formats.campaign_csv import read_campaign, write_campaign
from robocal.server.formats.cell_json import parse_cell
from robocal.solver.measurements import Measurements
from robocal.solver.robot import Robot

from . import checks
from .db import Database
from .errors import Conflict, NotFound, StoreError
from .models import (
    JOB_KINDS,
    JOB_STATES,
    POSE_STATES,
    STATUSES,
    Campaign,
    Job,
    PlannedPose,
    PoseOutcome,
    Reading,
    utcnow,
)

# Which status may follow which is the engine's table (drivers/lifecycle.py): the store persists
# the engine's state and refuses a jump no request or event makes. Setting the same status again
# is a no-op.
# Readings and outcomes arrive only while the engine owns the campaign; a reading already in
# flight when a pause, an abort or an e-stop was asked for still lands.
RECORDING = ("running", "pausing", "paused", "stopping", "estopped")


@dataclass(frozen=True)
class CampaignInfo:
    """A campaign as the store holds it, with its progress."""

    id: int
    name: str
    created_at: dt.datetime
    status: str
    cell_json: str
    settings: dict
    simulated: bool
    notes: str
    n_poses: int
    n_done: int  # poses with an outcome
    lease_owner: str | None = None  # the process driving it (host:pid:random), if one claimed it
    lease_expires_at: dt.datetime | None = None


@dataclass(frozen=True)
class PoseInfo:
    """A planned pose and, once it has one, its outcome."""

    index: int
    label: str
    joints_deg: tuple[float, ...]
    state: str | None = None
    reached_deg: tuple[float, ...] | None = None
    detail: str = ""


@dataclass(frozen=True)
class ReadingInfo:
    """One stored reading; xyz is None for a `missing` target."""

    pose_index: int
    target: str
    status: str
    xyz: tuple[float, float, float] | None
    std: tuple[float, float, float] | None
    samples: int | None
    time_s: float | None
    temp_c: float | None
    pressure_hpa: float | None
    humidity_pct: float | None
    detail: str
    created_at: dt.datetime


# --- campaigns ---------------------------------------------------------------------------------


def create_campaign(
    db: Database,
    *,
    name: str,
    cell_json: str | Mapping,
    poses_deg,
    settings: Mapping | None = None,
    labels: Sequence[str] | None = None,
    simulated: bool = False,
    notes: str = "",
) -> int:
    """Store a new `planned` campaign and its plan (n poses x N joints, deg) together; its id.

    Labels (the `pose` column of an exported meas.csv) default to "1" ... "n".
    """
    cell, cell_text = checks.cell_text(cell_json)
    q = checks.plan_deg(poses_deg, cell.robot)
    labels = checks.pose_labels(labels, len(q))
    with db.session(write=True) as s:
        campaign = _add_campaign(
            s,
            name=name,
            cell_text=cell_text,
            settings=settings,
            simulated=simulated,
            notes=notes,
            status="planned",
        )
        _add_plan(s, campaign.id, labels, q)
    return campaign.id


def get_campaign(db: Database, *, campaign_id: int) -> CampaignInfo:
    """The campaign with this id; NotFound if there is none."""
    with db.session() as s:
        return _info(s, _campaign(s, campaign_id))


def list_campaigns(db: Database, *, status: str | None = None) -> list[CampaignInfo]:
    """Every campaign (or those with this status), oldest first."""
    with db.session() as s:
        query = select(Campaign).order_by(Campaign.id)
        if status is not None:
            query = query.where(Campaign.status == checks.one_of(status, STATUSES, "status"))
        return [_info(s, c) for c in s.scalars(query)]


def set_status(db: Database, *, campaign_id: int, status: str) -> str:
    """Move the campaign to `status` (one step of the life cycle's table); the status it had.
    Same status: no-op."""
    checks.one_of(status, STATUSES, "status")
    with db.session(write=True) as s:
        campaign = _campaign(s, campaign_id)
        before = campaign.status
        if status == before:
            return before
        if not lifecycle.reachable(before, status):
            after = sorted(set(lifecycle.TRANSITIONS[before].values()))
            raise Conflict(
                f"campaign {campaign_id} is {before}; it can go to "
                f"{', '.join(after) or 'nothing (final)'}, not {status}"
            )
        if status == "done" and _next_unmeasured(s, campaign_id) is not None:
            raise Conflict(
                f"campaign {campaign_id} cannot be done: pose "
                f"{_next_unmeasured(s, campaign_id)} has no outcome yet"
            )
        campaign.status = status
    return before


def take_lease(
    db: Database, *, campaign_id: int, owner: str, ttl_s: float, dead_owner: str | None = None
) -> None:
    """Claim the campaign for `owner` for ttl_s seconds (or renew its claim), in one UPDATE that
    succeeds only if no one holds it, the claim lapsed, it is owner's, or it is `dead_owner`'s (a
    holder the caller knows is gone); LeaseHeld naming the holder otherwise."""
    now = utcnow()
    free = or_(
        Campaign.lease_owner.is_(None),
        Campaign.lease_owner == owner,
        Campaign.lease_expires_at.is_(None),
        Campaign.lease_expires_at < now,
    )
    if dead_owner is not None:
        free = or_(free, Campaign.lease_owner == dead_owner)
    with db.session(write=True) as s:
        done = s.execute(
            update(Campaign)
            .where(Campaign.id == campaign_id, free)
            .values(lease_owner=owner, lease_expires_at=now + dt.timedelta(seconds=ttl_s))
        )
        if _rowcount(done) == 1:
            return
        c = _campaign(s, campaign_id)
        raise LeaseHeld(
            f"campaign {campaign_id} is driven by another process ({c.lease_owner}, "
            f"claim held until {c.lease_expires_at:%H:%M:%S} UTC); stop it there",
            c.lease_owner,
        )


def renew_lease(db: Database, *, campaign_id: int, owner: str, ttl_s: float) -> bool:
    """Extend owner's claim by ttl_s from now; False if it is no longer owner's (never steals)."""
    with db.session(write=True) as s:
        done = s.execute(
            update(Campaign)
            .where(Campaign.id == campaign_id, Campaign.lease_owner == owner)
            .values(lease_expires_at=utcnow() + dt.timedelta(seconds=ttl_s))
        )
        return _rowcount(done) == 1


def release_lease(db: Database, *, campaign_id: int, owner: str) -> None:
    """Drop owner's claim (a no-op if it holds none)."""
    with db.session(write=True) as s:
        s.execute(
            update(Campaign)
            .where(Campaign.id == campaign_id, Campaign.lease_owner == owner)
            .values(lease_owner=None, lease_expires_at=None)
        )


class LeaseHeld(Conflict):
    """Another live process drives the campaign; `.owner` says which."""

    def __init__(self, message: str, owner: str | None):
        super().__init__(message)
        self.owner = owner


def planned_poses(db: Database, *, campaign_id: int) -> list[PoseInfo]:
    """The plan in order, each pose with its outcome if it has one."""
    with db.session() as s:
        _campaign(s, campaign_id)
        rows = s.execute(_poses_query(campaign_id)).all()
    return [
        PoseInfo(
            r.pose_index,
            r.label,
            tuple(r.joints_deg),
            r.state,
            None if r.reached_deg is None else tuple(r.reached_deg),
            r.detail or "",
        )
        for r in rows
    ]


def next_unmeasured_pose(db: Database, *, campaign_id: int) -> int | None:
    """The first planned pose without an outcome (where a run resumes); None when all have one."""
    with db.session() as s:
        _campaign(s, campaign_id)
        return _next_unmeasured(s, campaign_id)


# --- readings and outcomes ---------------------------------------------------------------------


def record_reading(
    db: Database,
    *,
    campaign_id: int,
    pose_index: int,
    target: str,
    xyz,
    std=None,
    samples: int | None = None,
    time_s: float | None = None,
    temp_c: float | None = None,
    pressure_hpa: float | None = None,
    humidity_pct: float | None = None,
    detail: str = "",
) -> bool:
    """Store one target's reading (mm, tracker frame), committed before returning.

    True if stored now, False if the same reading was already there (a retried call); Conflict
    if a different one is, or if the pose already has its outcome.
    """
    x, y, z = checks.vector3(xyz, "xyz")
    sx, sy, sz = (None, None, None) if std is None else checks.vector3(std, "std", minimum=0.0)
    opt = checks.optional
    values = dict(
        status="ok",
        x=x,
        y=y,
        z=z,
        std_x=sx,
        std_y=sy,
        std_z=sz,
        samples=checks.samples(samples),
        time_s=opt(time_s),
        temp_c=opt(temp_c),
        pressure_hpa=opt(pressure_hpa),
        humidity_pct=opt(humidity_pct),
        detail=str(detail),
    )
    return _record(db, campaign_id, pose_index, target, values)


def record_missing(
    db: Database,
    *,
    campaign_id: int,
    pose_index: int,
    target: str,
    detail: str = "",
    time_s: float | None = None,
) -> bool:
    """Record that a target could not be measured at this pose (beam break after retries).

    Same contract as record_reading: True if new, False if already recorded so, else Conflict.
    """
    values = dict(
        status="missing",
        x=None,
        y=None,
        z=None,
        std_x=None,
        std_y=None,
        std_z=None,
        samples=None,
        time_s=checks.optional(time_s),
        temp_c=None,
        pressure_hpa=None,
        humidity_pct=None,
        detail=str(detail),
    )
    return _record(db, campaign_id, pose_index, target, values)


def record_pose_outcome(
    db: Database,
    *,
    campaign_id: int,
    pose_index: int,
    state: str,
    reached_deg=None,
    detail: str = "",
    missing: Sequence[str] | None = None,
) -> bool:
    """Close a pose: `measured` (every target read), `missing-target` (some recorded missing) or
    `skipped` (nothing read). True if new, False if identical to the stored one, else Conflict.

    `reached_deg`: the joints as the controller reported them there; None if it never arrived.
    `missing`: targets to record missing in the same transaction; for `missing-target` it
    defaults to the cell's targets without a reading at this pose.
    """
    state = checks.one_of(state, POSE_STATES, "state")
    reached = None if reached_deg is None else list(checks.floats(reached_deg, "reached_deg"))
    missing = None if missing is None else [checks.target_name(t) for t in missing]
    with db.session(write=True) as s:
        campaign = _campaign(s, campaign_id)
        pose = _planned(s, campaign_id, pose_index)
        old = s.scalar(
            select(PoseOutcome).where(
                PoseOutcome.campaign_id == campaign_id, PoseOutcome.pose_index == pose_index
            )
        )
        if old is not None:
            if (old.state, old.reached_deg, old.detail) == (state, reached, str(detail)):
                return False
            raise Conflict(
                f"campaign {campaign_id} pose {pose_index} is already closed as "
                f"{old.state} with other values"
            )
        _check_recording(campaign)
        if reached is not None and len(reached) != len(pose.joints_deg):
            raise ValueError(
                f"reached_deg has {len(reached)} joints, the plan has {len(pose.joints_deg)}"
            )
        status = dict(
            s.execute(
                select(Reading.target, Reading.status).where(
                    Reading.campaign_id == campaign_id, Reading.pose_index == pose_index
                )
            ).all()
        )
        if missing is None and state == "missing-target":
            targets = parse_cell(campaign.cell_json, f"<campaign {campaign_id} cell>").targets
            missing = [t for t in targets if t not in status]
        for t in missing or ():
            if status.get(t) == "ok":
                raise Conflict(f"pose {pose_index} target {t} has a reading; it is not missing")
            if t not in status:
                s.add(
                    Reading(
                        campaign_id=campaign_id,
                        pose_index=pose_index,
                        target=t,
                        status="missing",
                        detail=str(detail) or "not measured",
                    )
                )
                status[t] = "missing"
        ok, n_missing = (sum(v == k for v in status.values()) for k in ("ok", "missing"))
        checks.outcome_agrees(state, ok, n_missing, pose_index)
        s.add(
            PoseOutcome(
                campaign_id=campaign_id,
                pose_index=pose_index,
                state=state,
                reached_deg=reached,
                detail=str(detail),
            )
        )
    return True


def discard_unfinished_pose(db: Database, *, campaign_id: int, pose_index: int) -> int:
    """Delete the readings of a pose that has no outcome yet (to measure it again whole, at one
    arrival of the arm); how many. Conflict if the pose is closed."""
    with db.session(write=True) as s:
        _planned(s, campaign_id, pose_index)
        closed = s.scalar(
            select(PoseOutcome.state).where(
                PoseOutcome.campaign_id == campaign_id, PoseOutcome.pose_index == pose_index
            )
        )
        if closed is not None:
            raise Conflict(
                f"campaign {campaign_id} pose {pose_index} is closed ({closed}); its readings stay"
            )
        return _rowcount(
            s.execute(
                delete(Reading).where(
                    Reading.campaign_id == campaign_id, Reading.pose_index == pose_index
                )
            )
        )


def pose_readings(db: Database, *, campaign_id: int, pose_index: int) -> dict[str, ReadingInfo]:
    """The readings stored for one pose, by target: on resume, the ones not to measure again."""
    with db.session() as s:
        _planned(s, campaign_id, pose_index)
        rows = s.scalars(
            select(Reading)
            .where(Reading.campaign_id == campaign_id, Reading.pose_index == pose_index)
            .order_by(Reading.id)
        )
        return {r.target: _reading_info(r) for r in rows}


# --- arrays and files --------------------------------------------------------------------------


def campaign_measurements(
    db: Database,
    *,
    campaign_id: int,
    robot: Robot | None = None,
    targets: Sequence[str] | None = None,
) -> Measurements:
    """The campaign's readings as arrays: poses with at least one reading, in plan order.

    Targets sorted by name (or `targets`, in that order), missing ones NaN; q in rad from the
    joints reached (the plan's where no outcome gives them); time_s / temp_c None when no
    reading has one. `robot` defaults to the cell's.
    """
    with db.session() as s:
        campaign = _campaign(s, campaign_id)
        poses = s.execute(_poses_query(campaign_id)).all()
        rows = s.execute(
            select(
                Reading.pose_index,
                Reading.target,
                Reading.x,
                Reading.y,
                Reading.z,
                Reading.time_s,
                Reading.temp_c,
            ).where(Reading.campaign_id == campaign_id, Reading.status == "ok")
        ).all()
        cell_text = campaign.cell_json
    robot = checks.matching_robot(robot, parse_cell(cell_text, f"<campaign {campaign_id} cell>"))
    if targets is None:
        names = tuple(sorted({r.target for r in rows}))
    else:
        names = tuple(checks.target_name(t) for t in targets)
        rows = [r for r in rows if r.target in names]
    used = {r.pose_index for r in rows}
    poses = [p for p in poses if p.pose_index in used]
    row_of = {p.pose_index: i for i, p in enumerate(poses)}
    col = {n: k for k, n in enumerate(names)}
    m, K = len(poses), len(names)
    q = np.array(
        [p.reached_deg if p.reached_deg is not None else p.joints_deg for p in poses], dtype=float
    ).reshape(m, -1 if m else robot.n_joints)
    if q.shape[1] != robot.n_joints:
        raise ValueError(
            f"campaign {campaign_id} has {q.shape[1]} joints per pose, "
            f"{robot.name} has {robot.n_joints}"
        )
    xyz = np.full((m, K, 3), np.nan)
    time_s, temp_c = np.full((m, K), np.nan), np.full((m, K), np.nan)
    for r in rows:
        i, k = row_of[r.pose_index], col[r.target]
        xyz[i, k] = r.x, r.y, r.z
        time_s[i, k] = np.nan if r.time_s is None else r.time_s
        temp_c[i, k] = np.nan if r.temp_c is None else r.temp_c
    some = lambda a: a if np.isfinite(a).any() else None  # noqa: E731
    prev = np.full(q.shape, np.nan)
    for i, p in enumerate(poses):
        if p.prev_deg is not None:
            prev[i] = p.prev_deg
    return Measurements(
        [p.label for p in poses],
        np.deg2rad(q),
        names,
        xyz,
        some(time_s),
        some(temp_c),
        some(np.deg2rad(prev)),
    )


def export_csv(db: Database, *, campaign_id: int, path, robot: Robot | None = None) -> None:
    """Write the campaign's readings as a `meas.csv` (spec section 1), atomically."""
    meas = campaign_measurements(db, campaign_id=campaign_id, robot=robot)
    if meas.n_poses == 0:
        raise StoreError(f"campaign {campaign_id} has no readings to export")
    write_campaign(path, meas)


# Rows per write transaction of an import: each commits in a few milliseconds, so a campaign
# recording readings at the same time never waits near the busy timeout for the write lock.
IMPORT_CHUNK = 2000


def import_csv(
    db: Database,
    *,
    path,
    cell_json: str | Mapping,
    name: str,
    robot: Robot | None = None,
    notes: str = "",
    measurements: Measurements | None = None,
) -> int:
    """Store a `meas.csv` as a `done` campaign; its id. All or nothing: InputError on a bad file
    (or cell), and then nothing is written. `measurements`: the file at `path` read already (by
    a worker process), for this robot.

    The whole file is checked first; then the campaign is written in short transactions
    (IMPORT_CHUNK rows each), marked `failed` ("import in progress") until the last one turns
    it `done`; a write that fails removes what was written.
    Joints are the file's (planned = reached); a target absent at a pose is recorded missing.
    """
    cell, cell_text = checks.cell_text(cell_json)
    robot = checks.matching_robot(robot, cell)
    # the whole file is checked before the database is touched
    meas = read_campaign(path, robot) if measurements is None else measurements
    q = np.rad2deg(meas.q)
    prev = None if meas.prev_q is None else np.rad2deg(meas.prev_q)
    mask = meas.mask
    settings = {"source": "csv", "file": os.path.basename(os.fspath(path))}
    with db.session(write=True) as s:
        # `failed` until complete: a process killed mid-import leaves a campaign that says so,
        # never one that looks done with readings missing.
        campaign = _add_campaign(
            s,
            name=name,
            cell_text=cell_text,
            settings=settings,
            simulated=False,
            notes=IMPORTING,
            status="failed",
        )
        cid = campaign.id
    step = max(1, IMPORT_CHUNK // len(meas.target_names))  # poses per transaction
    try:
        for start in range(0, meas.n_poses, step):
            stop = min(meas.n_poses, start + step)
            with db.session(write=True) as s:
                _add_plan(s, cid, meas.pose_ids[start:stop], q[start:stop], first=start)
                s.execute(
                    insert(Reading),
                    [
                        _imported_reading(meas, cid, i, k, target, mask[i, k])
                        for i in range(start, stop)
                        for k, target in enumerate(meas.target_names)
                    ],
                )
                s.execute(
                    insert(PoseOutcome),
                    [
                        dict(
                            campaign_id=cid,
                            pose_index=i,
                            reached_deg=q[i].tolist(),
                            prev_deg=_given(prev, i),
                            state="measured" if mask[i].all() else "missing-target",
                            detail="imported",
                        )
                        for i in range(start, stop)
                    ],
                )
        with db.session(write=True) as s:
            done = _campaign(s, cid)
            done.status, done.notes = "done", str(notes)
    except BaseException:
        with db.session(write=True) as s:
            for table in (Reading, PoseOutcome, PlannedPose):
                s.execute(delete(table).where(table.campaign_id == cid))
            s.execute(delete(Campaign).where(Campaign.id == cid))
        raise
    return cid


def _prev_fields(prev_deg, n: int) -> list[str]:
    """A row's n prev_q fields as meas.csv writes them (blank where the pose gives none)."""
    if not n:
        return []
    return [f"{v:.9f}" for v in prev_deg] if prev_deg is not None else [""] * n


def _given(prev: np.ndarray | None, i: int) -> list | None:
    """Pose i's prev_q row (deg) as stored, None where the file gives none."""
    if prev is None or not np.isfinite(prev[i]).all():
        return None
    return prev[i].tolist()


def export_lines(db: Database, *, campaign_id: int, chunk: int = 5000):
    """The campaign's meas.csv, line by line (the text export_csv writes), read in short
    transactions of `chunk` readings so that any size streams in bounded memory; Conflict if it
    has no readings."""
    with db.session() as s:
        campaign = _campaign(s, campaign_id)
        ok = and_(Reading.campaign_id == campaign_id, Reading.status == "ok")
        if not s.scalar(select(func.count()).where(ok)):
            raise Conflict(f"campaign {campaign_id} has no readings to export yet")
        extras = [
            c
            for c, col in (("time_s", Reading.time_s), ("temp_c", Reading.temp_c))
            if s.scalar(select(func.count()).where(ok, col.is_not(None)))
        ]
        n_joints = parse_cell(campaign.cell_json).robot.n_joints
        given = PoseOutcome.campaign_id == campaign_id, PoseOutcome.prev_deg.is_not(None)
        has_prev = bool(s.scalar(select(func.count()).where(*given)))
    prev_cols = [f"prev_q{i}" for i in range(1, n_joints + 1)] if has_prev else []
    yield (
        ",".join(
            [
                "pose",
                *[f"q{i}" for i in range(1, n_joints + 1)],
                "target",
                "x",
                "y",
                "z",
                *extras,
                *prev_cols,
            ]
        )
        + "\n"
    )
    after = (-1, "")  # keyset: (pose_index, target) of the last line written
    on = and_(
        PlannedPose.campaign_id == Reading.campaign_id, PlannedPose.pose_index == Reading.pose_index
    )
    done = and_(
        PoseOutcome.campaign_id == Reading.campaign_id, PoseOutcome.pose_index == Reading.pose_index
    )
    while True:
        with db.session() as s:
            rows = s.execute(
                select(
                    Reading.pose_index,
                    Reading.target,
                    Reading.x,
                    Reading.y,
                    Reading.z,
                    Reading.time_s,
                    Reading.temp_c,
                    PlannedPose.label,
                    PlannedPose.joints_deg,
                    PoseOutcome.reached_deg,
                    PoseOutcome.prev_deg,
                )
                .join(PlannedPose, on)
                .outerjoin(PoseOutcome, done)
                .where(
                    Reading.campaign_id == campaign_id,
                    Reading.status == "ok",
                    (Reading.pose_index > after[0])
                    | ((Reading.pose_index == after[0]) & (Reading.target > after[1])),
                )
                .order_by(Reading.pose_index, Reading.target)
                .limit(chunk)
            ).all()
        if not rows:
            return
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        for r in rows:
            q = r.reached_deg if r.reached_deg is not None else r.joints_deg
            more = {"time_s": r.time_s, "temp_c": r.temp_c}
            w.writerow(
                [
                    r.label,
                    *[f"{v:.9f}" for v in q],
                    r.target,
                    *[f"{v:.6f}" for v in (r.x, r.y, r.z)],
                    *["" if more[c] is None else f"{more[c]:.6f}" for c in extras],
                    *_prev_fields(r.prev_deg, n_joints if has_prev else 0),
                ]
            )
        yield buf.getvalue()
        after = (rows[-1].pose_index, rows[-1].target)


IMPORTING = "import in progress (or interrupted: delete and import again)"


def readings_page(
    db: Database, *, campaign_id: int, offset: int = 0, limit: int = 1000
) -> tuple[int, list[tuple[str, ReadingInfo]]]:
    """(total, page): the campaign's readings in plan order (pose, then arrival), with their pose
    labels, `limit` of them from `offset`; one bounded query, whatever the campaign's size."""
    if offset < 0 or limit < 1:
        raise ValueError("offset must be >= 0 and limit >= 1")
    with db.session() as s:
        _campaign(s, campaign_id)
        total = s.execute(
            select(func.count()).where(Reading.campaign_id == campaign_id)
        ).scalar_one()
        on = and_(
            PlannedPose.campaign_id == Reading.campaign_id,
            PlannedPose.pose_index == Reading.pose_index,
        )
        rows = s.execute(
            select(PlannedPose.label, Reading)
            .join(PlannedPose, on)
            .where(Reading.campaign_id == campaign_id)
            .order_by(Reading.pose_index, Reading.id)
            .offset(offset)
            .limit(limit)
        ).all()
        return total, [(label, _reading_info(r)) for label, r in rows]


# --- jobs --------------------------------------------------------------------------------------

# queued -> running -> done | failed; a queued job may fail without running (a restart).
JOB_TRANSITIONS = {
    "queued": {"running", "failed"},
    "running": {"done", "failed"},
    "done": set(),
    "failed": set(),
}
JOB_FIELDS = ("progress", "reason", "results", "campaign_id")  # campaign: a planning job's


@dataclass(frozen=True)
class JobInfo:
    """A job as the store holds it."""

    id: int
    kind: str
    campaign_id: int | None  # None for a planning job until it planned its campaign
    method: str
    state: str
    reason: str | None
    progress: float
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    results: dict
    holdout_campaign_id: int | None = None  # a calibration's held-out campaign, if it has one
    tolerance_mm: float | None = None  # the accuracy asked for, over the cell's; None: the cell's


def create_job(
    db: Database,
    *,
    kind: str,
    campaign_id: int | None,
    method: str,
    holdout_campaign_id: int | None = None,
    tolerance_mm: float | None = None,
) -> JobInfo:
    """Store a queued job on an existing campaign (none for a planning job); the job."""
    checks.one_of(kind, JOB_KINDS, "kind")
    if (campaign_id is None) != (kind == "planning"):
        raise ValueError("a planning job has no campaign yet; every other job has one")
    with db.session(write=True) as s:
        for cid in (campaign_id, holdout_campaign_id):
            if cid is not None:
                _campaign(s, cid)
        job = Job(
            kind=kind,
            campaign_id=campaign_id,
            holdout_campaign_id=holdout_campaign_id,
            tolerance_mm=None if tolerance_mm is None else float(tolerance_mm),
            method=str(method),
            state="queued",
            progress=0.0,
            results={},
            created_at=utcnow(),
        )
        s.add(job)
        s.flush()
        return _job_info(job)


def get_job(db: Database, *, job_id: int) -> JobInfo:
    """The job with this id; NotFound if there is none."""
    with db.session() as s:
        return _job_info(_job(s, job_id))


def list_jobs(db: Database, *, state: str | None = None) -> list[JobInfo]:
    """Every job (or those in this state), oldest first."""
    with db.session() as s:
        query = select(Job).order_by(Job.id)
        if state is not None:
            query = query.where(Job.state == checks.one_of(state, JOB_STATES, "state"))
        return [_job_info(j) for j in s.scalars(query)]


def update_job(db: Database, *, job_id: int, state: str | None = None, **changes) -> JobInfo:
    """Move a job along (see JOB_TRANSITIONS) and/or set progress, reason, results; the job."""
    unknown = set(changes) - set(JOB_FIELDS)
    if unknown:
        raise ValueError(f"cannot set {', '.join(sorted(unknown))} of a job")
    if "progress" in changes and not 0.0 <= float(changes["progress"]) <= 1.0:
        raise ValueError("progress is a fraction in [0, 1]")
    with db.session(write=True) as s:
        job = _job(s, job_id)
        if state is not None and state != job.state:
            checks.one_of(state, JOB_STATES, "state")
            if state not in JOB_TRANSITIONS[job.state]:
                raise Conflict(f"job {job_id} is {job.state}; it cannot go to {state}")
            job.state = state
            if state == "running":
                job.started_at = utcnow()
            if state in ("done", "failed"):
                job.finished_at = utcnow()
                if state == "done":
                    job.progress = 1.0
        for key, value in changes.items():
            setattr(job, key, dict(value) if key == "results" else value)
        s.flush()
        return _job_info(job)


def fail_unfinished_jobs(db: Database, *, reason: str) -> list[int]:
    """Mark every queued or running job failed with `reason` (nothing runs them any more); ids."""
    with db.session(write=True) as s:
        jobs = list(s.scalars(select(Job).where(Job.state.in_(("queued", "running")))))
        for job in jobs:
            job.state, job.reason, job.finished_at = "failed", reason, utcnow()
        return [j.id for j in jobs]


# --- helpers -----------------------------------------------------------------------------------


def _campaign(s: Session, campaign_id: int) -> Campaign:
    campaign = s.get(Campaign, campaign_id)
    if campaign is None:
        raise NotFound(f"no campaign {campaign_id}")
    return campaign


def _job(s: Session, job_id: int) -> Job:
    job = s.get(Job, job_id)
    if job is None:
        raise NotFound(f"no job {job_id}")
    return job


def _job_info(j: Job) -> JobInfo:
    return JobInfo(
        j.id,
        j.kind,
        j.campaign_id,
        j.method,
        j.state,
        j.reason,
        j.progress,
        j.created_at,
        j.started_at,
        j.finished_at,
        dict(j.results or {}),
        j.holdout_campaign_id,
        j.tolerance_mm,
    )


def _planned(s: Session, campaign_id: int, pose_index: int) -> PlannedPose:
    pose = s.scalar(
        select(PlannedPose).where(
            PlannedPose.campaign_id == campaign_id, PlannedPose.pose_index == pose_index
        )
    )
    if pose is None:
        _campaign(s, campaign_id)
        raise NotFound(f"campaign {campaign_id} has no planned pose {pose_index}")
    return pose


def _next_unmeasured(s: Session, campaign_id: int) -> int | None:
    closed = exists().where(
        PoseOutcome.campaign_id == PlannedPose.campaign_id,
        PoseOutcome.pose_index == PlannedPose.pose_index,
    )
    return s.scalar(
        select(func.min(PlannedPose.pose_index)).where(
            PlannedPose.campaign_id == campaign_id, ~closed
        )
    )


def _poses_query(campaign_id: int):
    on = and_(
        PoseOutcome.campaign_id == PlannedPose.campaign_id,
        PoseOutcome.pose_index == PlannedPose.pose_index,
    )
    return (
        select(
            PlannedPose.pose_index,
            PlannedPose.label,
            PlannedPose.joints_deg,
            PoseOutcome.state,
            PoseOutcome.reached_deg,
            PoseOutcome.detail,
            PoseOutcome.prev_deg,
        )
        .outerjoin(PoseOutcome, on)
        .where(PlannedPose.campaign_id == campaign_id)
        .order_by(PlannedPose.pose_index)
    )


def _info(s: Session, c: Campaign) -> CampaignInfo:
    n_poses = s.execute(select(func.count()).where(PlannedPose.campaign_id == c.id)).scalar_one()
    n_done = s.execute(select(func.count()).where(PoseOutcome.campaign_id == c.id)).scalar_one()
    return CampaignInfo(
        c.id,
        c.name,
        c.created_at,
        c.status,
        c.cell_json,
        json.loads(c.settings_json),
        c.simulated,
        c.notes,
        n_poses,
        n_done,
        c.lease_owner,
        c.lease_expires_at,
    )


def _add_campaign(s: Session, *, name, cell_text, settings, simulated, notes, status) -> Campaign:
    if not isinstance(name, str) or not name.strip():
        raise ValueError("a campaign needs a name")
    try:
        settings_text = json.dumps(dict(settings or {}), sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"settings must be plain JSON values: {e}") from None
    campaign = Campaign(
        name=name.strip(),
        cell_json=cell_text,
        settings_json=settings_text,
        simulated=bool(simulated),
        notes=str(notes),
        status=status,
    )
    s.add(campaign)
    s.flush()  # assigns the id
    return campaign


def _add_plan(s: Session, campaign_id: int, labels, q_deg: np.ndarray, first: int = 0) -> None:
    s.execute(
        insert(PlannedPose),
        [
            dict(
                campaign_id=campaign_id,
                pose_index=first + i,
                label=str(label),
                joints_deg=[float(v) for v in q_deg[i]],
            )
            for i, label in enumerate(labels)
        ],
    )


def _record(db: Database, campaign_id: int, pose_index: int, target: str, values: dict) -> bool:
    checks.target_name(target)
    with db.session(write=True) as s:
        campaign = _campaign(s, campaign_id)
        _planned(s, campaign_id, pose_index)
        old = s.scalar(
            select(Reading).where(
                Reading.campaign_id == campaign_id,
                Reading.pose_index == pose_index,
                Reading.target == target,
            )
        )
        if old is not None:
            differ = [k for k, v in values.items() if getattr(old, k) != v]
            if not differ:
                return False
            raise Conflict(
                f"campaign {campaign_id} pose {pose_index} target {target} is already "
                f"recorded with other {', '.join(differ)}"
            )
        _check_recording(campaign)
        closed = s.scalar(
            select(PoseOutcome.state).where(
                PoseOutcome.campaign_id == campaign_id, PoseOutcome.pose_index == pose_index
            )
        )
        if closed is not None:
            raise Conflict(
                f"campaign {campaign_id} pose {pose_index} is already closed "
                f"({closed}); no new readings"
            )
        s.add(Reading(campaign_id=campaign_id, pose_index=pose_index, target=target, **values))
    return True


def _imported_reading(meas: Measurements, cid: int, i: int, k: int, target: str, present) -> dict:
    row = dict(
        campaign_id=cid,
        pose_index=i,
        target=target,
        std_x=None,
        std_y=None,
        std_z=None,
        samples=None,
        pressure_hpa=None,
        humidity_pct=None,
    )
    if not present:
        return row | dict(
            status="missing",
            x=None,
            y=None,
            z=None,
            time_s=None,
            temp_c=None,
            detail="absent from the imported file",
        )
    extra = {
        c: None if a is None else checks.optional(a[i, k])
        for c, a in (("time_s", meas.time_s), ("temp_c", meas.temp_c))
    }
    x, y, z = (float(v) for v in meas.xyz[i, k])
    return row | extra | dict(status="ok", x=x, y=y, z=z, detail="")


def _rowcount(result: Result) -> int:
    """Rows an UPDATE or DELETE matched: a session returns such results as a CursorResult."""
    assert isinstance(result, CursorResult)
    return result.rowcount


def _check_recording(campaign: Campaign) -> None:
    if campaign.status not in RECORDING:
        raise Conflict(
            f"campaign {campaign.id} is {campaign.status}: readings are recorded "
            f"only while it is {', '.join(RECORDING)}"
        )


def _reading_info(r: Reading) -> ReadingInfo:
    xyz: tuple[float, float, float] | None = None
    std: tuple[float, float, float] | None = None
    if r.status == "ok":
        assert r.x is not None and r.y is not None and r.z is not None, "the xyz_present check"
        xyz = (r.x, r.y, r.z)
    if r.std_x is not None:
        assert r.std_y is not None and r.std_z is not None, "a reading's spread is stored whole"
        std = (r.std_x, r.std_y, r.std_z)
    return ReadingInfo(
        r.pose_index,
        r.target,
        r.status,
        xyz,
        std,
        r.samples,
        r.time_s,
        r.temp_c,
        r.pressure_hpa,
        r.humidity_pct,
        r.detail,
        r.created_at,
    )
