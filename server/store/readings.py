"""A campaign's plan, readings and pose outcomes, as they arrive."""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import CursorResult, Result, and_, delete, func, select
from sqlalchemy.orm import Session

from robocal.server.formats.cell_json import parse_cell

from . import checks
from .campaigns import _campaign, _next_unmeasured
from .db import Database
from .errors import Conflict, NotFound
from .models import POSE_STATES, Campaign, PlannedPose, PoseOutcome, Reading

# Which status may follow which is the engine's table (drivers/lifecycle.py): the store persists
# the engine's state and refuses a jump no request or event makes. Setting the same status again
# is a no-op.
# Readings and outcomes arrive only while the engine owns the campaign; a reading already in
# flight when a pause, an abort or an e-stop was asked for still lands.
RECORDING = ("running", "pausing", "paused", "stopping", "estopped")


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


@dataclass(frozen=True)
class AirReading:
    """The air temperature of one stored reading (degC) and its time (s since campaign start)."""

    temp_c: float
    time_s: float


def latest_air(db: Database, *, campaign_id: int) -> AirReading | None:
    """The air temperature of the campaign's latest reading that has one (and a time); None if
    no reading has. One indexed row (ix_reading_campaign_time), however long the campaign."""
    with db.session() as s:
        row = s.execute(
            select(Reading.temp_c, Reading.time_s)
            .where(
                Reading.campaign_id == campaign_id,
                Reading.status == "ok",
                Reading.temp_c.is_not(None),
                Reading.time_s.is_not(None),
            )
            .order_by(Reading.time_s.desc(), Reading.id.desc())
            .limit(1)
        ).first()
    return None if row is None else AirReading(float(row.temp_c), float(row.time_s))


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


# what a reading has that a missing one lacks
MEASURED = (
    "x",
    "y",
    "z",
    "std_x",
    "std_y",
    "std_z",
    "samples",
    "temp_c",
    "pressure_hpa",
    "humidity_pct",
)


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
    values = dict.fromkeys(MEASURED) | {
        "status": "missing",
        "time_s": checks.optional(time_s),
        "detail": str(detail),
    }
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


def readings_of_poses(
    db: Database, *, campaign_id: int, first: int, stop: int
) -> list[ReadingInfo]:
    """The readings of poses first <= index < stop, in plan order (pose, then arrival)."""
    with db.session() as s:
        _campaign(s, campaign_id)
        rows = s.scalars(
            select(Reading)
            .where(
                Reading.campaign_id == campaign_id,
                Reading.pose_index >= first,
                Reading.pose_index < stop,
            )
            .order_by(Reading.pose_index, Reading.id)
        )
        return [_reading_info(r) for r in rows]


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
