"""The store's tables: a campaign, its planned poses, the readings and each pose's outcome.

A campaign is one run on the cell. Its plan (`planned_pose`) is written with it, so a later run
can resume it. Readings arrive one per (pose, target) and are committed one by one; the unique
key (campaign_id, pose_index, target) makes a duplicate impossible. A target the tracker could not
measure after its retries is a `reading` row with status `missing` and no coordinates, so the
record says "tried, beam broken" rather than nothing. `pose_outcome` is written last for a pose
and is its completion mark: a planned pose without one is still to do, which is all resume needs.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    ForeignKeyConstraint,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from robocal.drivers.lifecycle import STATES

# A campaign's status is the engine's life-cycle state (drivers/lifecycle.py), all of them.
STATUSES = STATES
POSE_STATES = ("measured", "missing-target", "skipped")
READING_STATUSES = ("ok", "missing")
JOB_KINDS = ("calibration", "diagnosis", "planning")
JOB_STATES = ("queued", "running", "done", "failed")

# SQLite alters a table by copying it (Alembic batch mode), which can only drop or change
# constraints that have names; this convention names every one.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_N_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


# Ids are 64-bit: SQLite's INTEGER PRIMARY KEY already is (and must be spelled INTEGER to be the
# rowid), PostgreSQL's need BIGINT (migration 0005).
ID = BigInteger().with_variant(Integer(), "sqlite")


def utcnow() -> dt.datetime:
    """The current time, UTC-aware."""
    return dt.datetime.now(dt.UTC)


class UTCDateTime(TypeDecorator):
    """Aware UTC datetimes; SQLite keeps no zone, so naive UTC is stored and the zone reattached."""

    impl = DateTime
    cache_ok = True

    def process_bind_param(self, value, dialect):
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime: store times are UTC-aware")
        return value.astimezone(dt.UTC).replace(tzinfo=None)

    def process_result_value(self, value, dialect):
        return None if value is None else value.replace(tzinfo=dt.UTC)


def one_of(column: str, values) -> str:
    """SQL for a CHECK that the column holds one of these strings."""
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


class Base(DeclarativeBase):
    """The store's declarative base; its metadata names every constraint."""

    metadata = MetaData(naming_convention=NAMING)


class Campaign(Base):
    """One run on the cell: the cell it ran on, its settings, its life-cycle status."""

    __tablename__ = "campaign"
    __table_args__ = (CheckConstraint(one_of("status", STATUSES), name="status"),)

    id: Mapped[int] = mapped_column(ID, primary_key=True)
    name: Mapped[str] = mapped_column(Text)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    status: Mapped[str] = mapped_column(String(16), default="planned")
    cell_json: Mapped[str] = mapped_column(Text)  # the cell.json text (spec section 2)
    settings_json: Mapped[str] = mapped_column(Text, default="{}")  # pause, settle, retries...
    simulated: Mapped[bool] = mapped_column(Boolean, default=False)
    notes: Mapped[str] = mapped_column(Text, default="")
    # The physical arm measured (its serial number), which the fleet view follows; None: unnamed
    arm: Mapped[str | None] = mapped_column(Text, index=True)
    # The process that drives the campaign (host:pid:random) and until when its claim holds;
    # the owner renews it while it runs, so a killed owner's claim lapses.
    lease_owner: Mapped[str | None] = mapped_column(Text)
    lease_expires_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())


class PlannedPose(Base):
    """Pose `pose_index` (0..n-1) of a campaign's plan: its CSV label and commanded joints (deg)."""

    __tablename__ = "planned_pose"
    __table_args__ = (
        UniqueConstraint("campaign_id", "pose_index"),
        UniqueConstraint("campaign_id", "label"),
        CheckConstraint("pose_index >= 0", name="pose_index"),
    )

    id: Mapped[int] = mapped_column(ID, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ID, ForeignKey("campaign.id", ondelete="CASCADE"))
    pose_index: Mapped[int] = mapped_column(Integer)
    label: Mapped[str] = mapped_column(Text)  # the `pose` column of meas.csv
    joints_deg: Mapped[list] = mapped_column(JSON)


def _pose_fk() -> ForeignKeyConstraint:
    # Readings and outcomes can only refer to a pose of the plan.
    return ForeignKeyConstraint(
        ["campaign_id", "pose_index"],
        ["planned_pose.campaign_id", "planned_pose.pose_index"],
        ondelete="CASCADE",
    )


class Reading(Base):
    """One target at one pose: the SMR centre (mm, tracker frame) or an explicit `missing`."""

    __tablename__ = "reading"
    __table_args__ = (
        UniqueConstraint("campaign_id", "pose_index", "target"),
        _pose_fk(),
        # a campaign's latest readings without reading all of them (the air temperature a
        # compensated pose is solved at, migration 0011)
        Index("ix_reading_campaign_time", "campaign_id", "time_s", "id"),
        CheckConstraint(one_of("status", READING_STATUSES), name="status"),
        CheckConstraint(
            "(status = 'ok' AND x IS NOT NULL AND y IS NOT NULL AND z IS NOT NULL) OR "
            "(status = 'missing' AND x IS NULL AND y IS NULL AND z IS NULL)",
            name="xyz_present",
        ),
        CheckConstraint("samples IS NULL OR samples >= 1", name="samples"),
    )

    id: Mapped[int] = mapped_column(ID, primary_key=True)  # increasing = order of arrival
    campaign_id: Mapped[int] = mapped_column(ID)
    pose_index: Mapped[int] = mapped_column(Integer)
    target: Mapped[str] = mapped_column(Text)
    status: Mapped[str] = mapped_column(String(16), default="ok")
    x: Mapped[float | None] = mapped_column(Float)
    y: Mapped[float | None] = mapped_column(Float)
    z: Mapped[float | None] = mapped_column(Float)
    std_x: Mapped[float | None] = mapped_column(Float)  # spread of the averaged samples, mm
    std_y: Mapped[float | None] = mapped_column(Float)
    std_z: Mapped[float | None] = mapped_column(Float)
    samples: Mapped[int | None] = mapped_column(Integer)
    time_s: Mapped[float | None] = mapped_column(Float)  # since campaign start
    temp_c: Mapped[float | None] = mapped_column(Float)
    pressure_hpa: Mapped[float | None] = mapped_column(Float)
    humidity_pct: Mapped[float | None] = mapped_column(Float)
    detail: Mapped[str] = mapped_column(Text, default="")  # why missing, tracker remarks
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class PoseOutcome(Base):
    """How a pose ended (measured / missing-target / skipped) and the joints reached (deg)."""

    __tablename__ = "pose_outcome"
    __table_args__ = (
        UniqueConstraint("campaign_id", "pose_index"),
        _pose_fk(),
        CheckConstraint(one_of("state", POSE_STATES), name="state"),
    )

    id: Mapped[int] = mapped_column(ID, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ID)
    pose_index: Mapped[int] = mapped_column(Integer)
    state: Mapped[str] = mapped_column(String(16))
    reached_deg: Mapped[list | None] = mapped_column(JSON)  # None when the arm never got there
    # The joints the arm came from (deg; an imported file's prev_q): None, the visit order says
    prev_deg: Mapped[list | None] = mapped_column(JSON(none_as_null=True))  # None: SQL NULL
    detail: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class Job(Base):
    """Work on a stored campaign (a calibration or a diagnosis), or the planning of a new one
    (no campaign until it is planned), kept so a restart can tell."""

    __tablename__ = "job"
    __table_args__ = (
        CheckConstraint(one_of("kind", JOB_KINDS), name="kind"),
        CheckConstraint(one_of("state", JOB_STATES), name="state"),
        CheckConstraint("progress >= 0 AND progress <= 1", name="progress"),
    )

    id: Mapped[int] = mapped_column(ID, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    campaign_id: Mapped[int | None] = mapped_column(
        ID, ForeignKey("campaign.id", ondelete="CASCADE")
    )
    method: Mapped[str] = mapped_column(Text)
    # A calibration's held-out campaign: same cell, not fitted on (validation, the recording).
    holdout_campaign_id: Mapped[int | None] = mapped_column(
        ID, ForeignKey("campaign.id", ondelete="SET NULL")
    )
    # The accuracy the application needs (mm), which wins over the cell's; None: the cell's.
    tolerance_mm: Mapped[float | None] = mapped_column(Float)
    # The service process that queued it (host:pid:random); None: queued before migration 0012.
    owner: Mapped[str | None] = mapped_column(Text)
    state: Mapped[str] = mapped_column(String(16), default="queued")
    reason: Mapped[str | None] = mapped_column(Text)
    progress: Mapped[float] = mapped_column(Float, default=0.0)  # 0..1
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    started_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    # Paths of what the job wrote: model, recording, report, figures (a list).
    results: Mapped[dict] = mapped_column(JSON, default=dict)


CHECK_VERDICTS = ("ok", "watch", "recalibrate")


class ModelCheck(Base):
    """A quick check of a deployed model (`robocal check`): its figures, verdict and each
    reading's error, so later checks of the same model are judged against the history."""

    __tablename__ = "model_check"
    __table_args__ = (CheckConstraint(one_of("verdict", CHECK_VERDICTS), name="verdict"),)

    id: Mapped[int] = mapped_column(ID, primary_key=True)
    model_sha256: Mapped[str] = mapped_column(String(64), index=True)
    checked_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    source: Mapped[str] = mapped_column(Text)  # the check file's name
    poses: Mapped[int] = mapped_column(Integer)
    rms_mm: Mapped[float] = mapped_column(Float)
    max_mm: Mapped[float] = mapped_column(Float)
    expected_rms_mm: Mapped[float] = mapped_column(Float)
    # the change from the model's first checks: its normal score and the CUSUM after it
    change_z: Mapped[float] = mapped_column(Float)
    cusum: Mapped[float] = mapped_column(Float)
    verdict: Mapped[str] = mapped_column(String(16))
    reason: Mapped[str] = mapped_column(Text)
    # per reading [pose, target, dx, dy, dz]: measured minus the model, mm
    errors: Mapped[list] = mapped_column(JSON)
