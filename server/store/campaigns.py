"""Campaigns in the store: create, read, list and move through their states."""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sqlalchemy import exists, func, insert, select
from sqlalchemy.orm import Session

from robocal.drivers import lifecycle

from . import checks
from .db import Database
from .errors import Conflict, NotFound
from .models import STATUSES, Campaign, PlannedPose, PoseOutcome


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
    arm: str | None = None  # the physical arm measured (its serial), if named


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
    arm: str | None = None,
) -> int:
    """Store a new `planned` campaign and its plan (n poses x N joints, deg) together; its id.

    Labels (the `pose` column of an exported meas.csv) default to "1" ... "n"; `arm` names the
    physical arm (its serial number) for the fleet view.
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
            arm=arm,
        )
        _add_plan(s, campaign.id, labels, q)
    return campaign.id


def extend_plan(
    db: Database, *, campaign_id: int, poses_deg, labels: Sequence[str] | None = None
) -> int:
    """Append poses (m x N joints, deg) to a campaign's plan, with these labels or numbered on
    from its last (an adaptive campaign's next batch); the first new pose's index."""
    with db.session(write=True) as s:
        campaign = _campaign(s, campaign_id)
        cell, _ = checks.cell_text(campaign.cell_json)
        q = checks.plan_deg(poses_deg, cell.robot)
        first = s.execute(
            select(func.count()).where(PlannedPose.campaign_id == campaign_id)
        ).scalar_one()
        if labels is None:
            labels = [str(first + 1 + i) for i in range(len(q))]
        _add_plan(s, campaign_id, checks.pose_labels(labels, len(q)), q, first=first)
    return int(first)


def update_settings(db: Database, *, campaign_id: int, **values) -> dict:
    """Set these keys of a campaign's settings (plain JSON values); the settings after."""
    with db.session(write=True) as s:
        campaign = _campaign(s, campaign_id)
        settings = {**json.loads(campaign.settings_json), **values}
        try:
            campaign.settings_json = json.dumps(settings, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise ValueError(f"settings must be plain JSON values: {e}") from None
    return settings


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


def _campaign(s: Session, campaign_id: int) -> Campaign:
    campaign = s.get(Campaign, campaign_id)
    if campaign is None:
        raise NotFound(f"no campaign {campaign_id}")
    return campaign


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
        c.arm,
    )


def _add_campaign(
    s: Session, *, name, cell_text, settings, simulated, notes, status, arm=None
) -> Campaign:
    if not isinstance(name, str) or not name.strip():
        raise ValueError("a campaign needs a name")
    arm = checks.arm_name(arm)
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
        arm=arm,
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
