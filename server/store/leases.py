"""Leases: one process at a time drives a running campaign."""

from __future__ import annotations

import datetime as dt

from sqlalchemy import or_, update

from .campaigns import _campaign
from .db import Database
from .errors import Conflict
from .models import Campaign, utcnow
from .readings import _rowcount


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
